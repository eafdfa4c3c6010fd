"""Global diagnostics and probes: exact sums over all particles (exact_sum), the same bit
for bit on any number of ranks.

Disorder: the mass-weighted RMS and the maximum of the hourglass error eta_i
(formulations.tlsph.hourglass_error). Energies: kinetic, strain (sum V psi), plastic work
(dissipated), damage work (taken by damaged and failed particles beyond their strain
energy: materials.damage), viscous work (absorbed by the artificial viscosity), hourglass
(minus the work done by the hourglass forces), external work (body force, constraint
reactions, obstacles' contact and the work that changes the kinetic energy of prescribed
motions) and the balance total = kinetic + strain + plastic + damage + viscous + hourglass
- external, which is constant for an exact integration. Momenta: linear (vector) and
angular (scalar in 2D, vector in 3D).
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from parsph.exact_sum import allsum, sums, total


def angular_momentum(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    """x cross p of each particle: (n, 1) in 2D, (n, 3) in 3D, (n, 0) in 1D."""
    if x.shape[1] == 2:
        return (x[:, 0] * p[:, 1] - x[:, 1] * p[:, 0])[:, None]
    if x.shape[1] == 3:
        return np.cross(x, p)
    return np.zeros((len(x), 0))


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
            value = float(allsum(comm, [total(q)])[0])
            out[probe["name"]] = value / comm.allreduce(len(q)) if how == "mean" else value
        elif how == "max":
            out[probe["name"]] = comm.allreduce(q.max() if len(q) else -np.inf, op=MPI.MAX)
        else:
            out[probe["name"]] = comm.allreduce(q.min() if len(q) else np.inf, op=MPI.MIN)
    return out


def global_diagnostics(state) -> dict:
    """Energies, momenta and disorder of all bodies together, and with more than one body
    each body's energies as "NAME.BODY" (collective)."""
    n, dim = state.n_owned, state.dim
    m = state.mass[:n]
    v = state.v[:n]
    x = state.X[:n] + state.u[:n]
    p = m[:, None] * v
    eta = state.disorder()
    # per-particle columns: m eta^2, m, kinetic energy per component, momentum, angular momentum
    columns = np.column_stack([m * eta * eta, m, 0.5 * m[:, None] * v * v, p, angular_momentum(x, p)])
    energies = state.energy_sums()
    bodies = state.bodies
    kinetic_parts = [sums(columns[b.lo:b.hi, 2:2 + dim]) for b in bodies] if len(bodies) > 1 else []
    keys = ("strain", "plastic", "damage", "viscous", "hourglass", "external")
    local = [*sums(columns), *(e for key in keys for e in energies[key]),
             *(k for part in kinetic_parts for k in part)]
    parts = allsum(state.comm, local)
    count = len(bodies)
    weighted, mass, kinetic = parts[0], parts[1], parts[2:2 + dim]
    momentum, angular = parts[2 + dim:2 + 2 * dim], parts[2 + 2 * dim:columns.shape[1]]
    rest = parts[columns.shape[1]:]
    strain, plastic, damaged, viscous, hourglass, external = (rest[k * count:(k + 1) * count]
                                                             for k in range(len(keys)))
    per_body_kinetic = rest[len(keys) * count:]
    kinetic = sum(kinetic[1:], kinetic[0])
    strain_all, plastic_all, damage_all, viscous_all, hourglass_all, external_all = (
        sum(e[1:], e[0]) for e in (strain, plastic, damaged, viscous, hourglass, external))
    out = {
        "kinetic_energy": float(kinetic), "strain_energy": float(strain_all), "plastic_work": float(plastic_all),
        "damage_work": float(damage_all), "viscous_work": float(viscous_all), "hourglass_energy": float(hourglass_all),
        "external_work": float(external_all),
        "total_energy": float(kinetic + strain_all + plastic_all + damage_all + viscous_all + hourglass_all
                              - external_all),
        "disorder": math.sqrt(float(weighted) / float(mass)),
        "disorder_max": state.comm.allreduce(eta.max() if len(eta) else 0.0, op=MPI.MAX),
    }
    for a, name in enumerate("xyz"[:dim]):
        out[f"momentum_{name}"] = float(momentum[a])
    if dim == 2:
        out["angular_momentum"] = float(angular[0])
    for a, name in enumerate("xyz" if dim == 3 else ""):
        out[f"angular_momentum_{name}"] = float(angular[a])
    if count > 1:
        for k, b in enumerate(bodies):
            comps = per_body_kinetic[k * dim:(k + 1) * dim]
            kin = sum(comps[1:], comps[0])
            out[f"kinetic_energy.{b.name}"] = float(kin)
            out[f"strain_energy.{b.name}"] = float(strain[k])
            out[f"plastic_work.{b.name}"] = float(plastic[k])
            out[f"damage_work.{b.name}"] = float(damaged[k])
            out[f"viscous_work.{b.name}"] = float(viscous[k])
            out[f"hourglass_energy.{b.name}"] = float(hourglass[k])
            out[f"external_work.{b.name}"] = float(external[k])
            out[f"total_energy.{b.name}"] = float(kin + strain[k] + plastic[k] + damaged[k] + viscous[k]
                                                  + hourglass[k] - external[k])
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


def check_finite(values: dict, state) -> None:
    """Stop the run (collective: `values` are the same global row on every rank) if a
    history value about to be written is not finite, naming the series, the step and the
    particle where the state first leaves the range of double precision: the lowest global
    id whose position, velocity, force or kinetic energy is not finite."""
    from parsph.errors import ParsphError

    bad = [f"{name} = {value}" for name, value in values.items() if not math.isfinite(value)]
    if not bad:
        return
    n = state.n_owned
    v = state.v[:n]
    with np.errstate(over="ignore", invalid="ignore"):
        kinetic = 0.5 * state.mass[:n] * np.einsum("na,na->n", v, v)
        columns = {"position": state.X[:n] + state.u[:n], "velocity": v, "force": state.force[:n],
                   "kinetic energy": kinetic[:, None]}
    mine = []
    for what, column in columns.items():
        rows = np.flatnonzero(~np.isfinite(column).all(axis=1))
        if len(rows):
            k = rows[np.argmin(state.gid[rows])]
            mine.append((int(state.gid[k]), what, tuple(column[k].tolist())))
    found = [c for part in state.comm.allgather(mine) for c in part]
    where = ""
    if found:
        gid, what, value = min(found)
        where = f"; particle {gid} is the first whose {what} is not finite ({', '.join(f'{c:.3g}' for c in value)})"
    error = ParsphError(
        f"the history row at step {state.step_count}, t = {state.t:.6g} s is not finite: "
        f"{', '.join(bad[:4])}{', ...' if len(bad) > 4 else ''}{where}; the run is stopped (the output written "
        "so far is intact): check the initial conditions, loads and material constants for values beyond the "
        "range of double precision (1.8e308)")
    error.agreed = True  # the row is the same global reduction on every rank
    raise error
