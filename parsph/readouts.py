"""Read-outs of a simulation's state on this rank's owned particles: the registered
quantities (parsph.quantities), the stress from the material laws, the laws' own
read-outs, the disorder measures, the quadrature of the integration points and the
obstacles' forces.
"""

from __future__ import annotations

import difflib

import numpy as np

from parsph import fields, materials, quantities
from parsph.errors import InputError
from parsph.exact_sum import allsum
from parsph.formulations import tlsph
from parsph.kernels.functions import KERNEL_NAMES
from parsph.materials import update


def quantity(sim, name: str, sel: np.ndarray | None = None) -> np.ndarray:
    """A particle quantity on the owned particles `sel` (all of them if None): computed as
    parsph.quantities registers it, or a registered field's values."""
    sel = np.arange(sim.state.n_owned) if sel is None else sel
    q = quantities.BUILT_IN.get(name)
    if q is not None and q.compute is not None:
        return q.compute(sim, sel)
    if fields.known(name) and fields.get(name).units is not None:  # a registered field
        return sim.state.particles.arrays[name][sel]
    known = quantities.snapshot_names()
    close = difflib.get_close_matches(str(name), known, n=1)
    raise InputError(f"unknown quantity {name!r}{f' (did you mean {close[0]!r}?)' if close else ''}; the known "
                     f"ones: {', '.join(known)}")


def quadrature(sim) -> tuple:
    """(X, F, w): reference positions, deformation gradients and quadrature weights of
    this rank's owned integration points, body after body (the particles for the nodal
    methods; particles, stress or Gauss points for the Galerkin ones)."""
    parts = [q for b in sim.state.bodies for q in b.formulation.quadrature(sim.state, b)]
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))


def disorder(sim) -> np.ndarray:
    """Hourglass error eta_i of each owned particle (formulations.tlsph.hourglass_error)."""
    error, state = tlsph.hourglass_error(sim.state.dim), sim.state
    return by_relation(sim, lambda r, out: error(state.n_owned, r.ref.ptr, r.ref.idx, state.reference_positions,
                                                 state.support, KERNEL_NAMES.index(r.kernel), state.d, state.fs, out,
                                                 state.scratch33))


def spacing_ratio(sim) -> np.ndarray:
    """Current-configuration disorder of each owned particle (tlsph.spacing_ratio), with the
    ghosts where the last force evaluation saw them."""
    x = sim.state.reference_positions + sim.state.d  # (d is u itself in the total-Lagrangian case)
    return by_relation(sim, lambda r, out: tlsph.spacing_ratio(sim.state.n_owned, r.ref.ptr, r.ref.idx, x, sim.state.measure,
                                                               sim.state.F, sim.state.dim, out, sim.state.scratch33))


def by_relation(sim, fill) -> np.ndarray:
    """A value per owned particle that `fill(relation, out)` writes row by row from a kernel
    relation (its reference data): each body's rows from its own relation."""
    out = np.empty(sim.state.n_owned)
    for r in sim.topology.relations:
        if r.whole:
            fill(r, out)
            continue
        part = np.empty(sim.state.n_owned)
        fill(r, part)
        for b in r.bodies:
            out[b.lo:b.hi] = part[b.lo:b.hi]
    return out


def cauchy_stress(sim, sel: np.ndarray, full: bool = False) -> np.ndarray:
    """sigma = J^-1 P(F) F^T at the owned particles `sel`, from the material law (with the
    committed state: the stress of the last evaluation) and its failure model: the dim x dim
    block, or (full) all 3 x 3 components, the out-of-plane ones of plane strain (2D) and
    uniaxial strain (1D) included (the law evaluated with F padded by unit stretches)."""
    d = 3 if full else sim.state.dim
    F = np.zeros((len(sel), d, d))
    F[:, :sim.state.dim, :sim.state.dim] = sim.state.F[sel]
    for a in range(sim.state.dim, d):
        F[:, a, a] = 1.0
    P = np.empty_like(F)
    body = sim.state.body[sel]
    one = len(sim.state.bodies) == 1  # then F and P themselves, no copies (a snapshot's peak memory)
    for b in sim.state.bodies:
        rows = np.arange(len(sel)) if one else np.flatnonzero(body == b.index)
        state = np.ascontiguousarray(sim.state.material_state(b)[0][sel[rows]]) if b.law.state else sim.state.no_state
        Fb = F if one else np.ascontiguousarray(F[rows])
        part = P if one else np.empty_like(Fb)
        update.stresses(b.law.law_id, Fb, d, b.constants.values, state, state.copy(), part, np.empty(len(rows)),
                        sim.step_dt)
        if b.failure:
            materials.FAILURES[b.failure].stresses(part, Fb, d,
                                                   np.ascontiguousarray(sim.state.damage_state(b)[0][sel[rows]]))
        if not one:
            P[rows] = part
    sigma = np.einsum("nab,ncb->nac", P, F)
    sigma /= sim.state.J[sel, None, None]
    return sigma


def von_mises(sim, sel: np.ndarray) -> np.ndarray:
    """sqrt(3/2 s:s) of the full Cauchy stress (out-of-plane components included)."""
    dev = cauchy_stress(sim, sel, full=True)
    dev -= np.trace(dev, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
    return np.sqrt(1.5 * np.einsum("nab,nab->n", dev, dev))


def wall_forces(sim) -> np.ndarray:
    """Each wall's and tool's force on the body in the last step, (obstacles, dim), exact
    sums over all ranks (collective)."""
    sums = allsum(sim.comm, sim.walls.force_sums())
    return np.array([float(s) for s in sums]).reshape(len(sim.walls.items), sim.state.dim)


def surface_torques(sim) -> np.ndarray:
    """Each surface's torque about its centre in the last step, (surfaces, 1 in 2D or 3),
    exact sums over all ranks (collective)."""
    sums = allsum(sim.comm, sim.walls.torque_sums())
    return np.array([float(s) for s in sums]).reshape(len(sim.walls.torques), 1 if sim.state.dim == 2 else 3)
