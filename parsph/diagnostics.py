"""Global diagnostics and probes, reduced over ranks in a fixed order.

Disorder: the mass-weighted RMS and the maximum of the hourglass error eta_i
(formulations.tlsph.hourglass_error). Energies: kinetic, strain (sum V psi), hourglass (minus the work done by the hourglass
forces), external work (body force and constraint reactions) and the balance
total = kinetic + strain + hourglass - external, which is constant for an exact
integration. Momenta: linear (vector) and angular (scalar in 2D, vector in 3D).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI


def _sum(comm, values: np.ndarray) -> np.ndarray:
    """Sum over ranks that is independent of the rank count up to the per-rank partial sums."""
    parts = comm.allgather(np.asarray(values, dtype=np.float64))
    total = np.zeros_like(parts[0])
    for p in parts:
        total = total + p
    return total


def angular_momentum(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    if x.shape[1] == 2:
        return np.array([np.sum(x[:, 0] * p[:, 1] - x[:, 1] * p[:, 0])])
    if x.shape[1] == 3:
        return np.cross(x, p).sum(axis=0)
    return np.zeros(0)


def probe_values(probes: list, state) -> dict:
    """Each probe's value: the reduction of a particle quantity over its group."""
    out = {}
    comm = state.comm
    for probe in probes:
        sel = state.group_index(probe["group"])
        q = state.quantity(probe["quantity"], sel)
        if q.ndim == 2:
            q = np.linalg.norm(q, axis=1) if probe["component"] < 0 else q[:, probe["component"]]
        how = probe["reduce"]
        if how in ("mean", "sum"):
            total, count = _sum(comm, np.array([q.sum(), float(len(q))]))
            out[probe["name"]] = total / count if how == "mean" else total
        elif how == "max":
            out[probe["name"]] = comm.allreduce(q.max() if len(q) else -np.inf, op=MPI.MAX)
        else:
            out[probe["name"]] = comm.allreduce(q.min() if len(q) else np.inf, op=MPI.MIN)
    return out


def global_diagnostics(state) -> dict:
    """Energies and momenta of the whole body (collective)."""
    n = state.n_owned
    m = state.mass[:n, None]
    v = state.v[:n]
    x = state.X[:n] + state.u[:n]
    p = m * v
    eta = state.disorder()
    local = np.concatenate([
        [np.sum(m[:, 0] * eta * eta), np.sum(m)],
        [0.5 * np.sum(m * v * v), state.strain_energy_local,
         state.hourglass_energy_local + state.hourglass_released_local,
         state.external_work_local],
        p.sum(axis=0), angular_momentum(x, p),
    ])
    total = _sum(state.comm, local)
    disorder = np.sqrt(total[0] / total[1])
    total = total[2:]
    kinetic, strain, hourglass, external = total[:4]
    dim = state.dim
    out = {
        "kinetic_energy": kinetic, "strain_energy": strain, "hourglass_energy": hourglass,
        "external_work": external, "total_energy": kinetic + strain + hourglass - external,
        "disorder": disorder,
        "disorder_max": state.comm.allreduce(eta.max() if len(eta) else 0.0, op=MPI.MAX),
    }
    for a, name in enumerate("xyz"[:dim]):
        out[f"momentum_{name}"] = total[4 + a]
    ang = total[4 + dim:]
    if dim == 2:
        out["angular_momentum"] = ang[0]
    for a, name in enumerate("xyz" if dim == 3 else ""):
        out[f"angular_momentum_{name}"] = ang[a]
    return out


def check_particle_ids(state) -> None:
    """Debug check (collective): the owned particles of all ranks are exactly the ids
    0..N-1, each once. Compares the count, the sum and the sum of squares of the ids
    (exact integer arithmetic) with those of 0..N-1."""
    from parsph.errors import ParsphError

    gid = state.gid[: state.n_owned].astype(object)
    count, total, squares = (sum(x) for x in zip(*state.comm.allgather(
        (len(gid), int(gid.sum()), int((gid * gid).sum())))))
    n = state.decomp.total
    expected = (n, n * (n - 1) // 2, (n - 1) * n * (2 * n - 1) // 6)
    if (count, total, squares) != expected:
        raise ParsphError(f"particles lost or duplicated at step {state.step_count}: ranks own {count} "
                          f"particles, expected {n} (id sums {total}, {squares} vs {expected[1:]})")
