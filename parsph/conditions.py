"""The conditions on the particles: the constraints (parsph.bc, collocated on EFG bodies:
parsph.collocation), the free rigid bodies' motion (parsph.rigid), the body force and
tractions; the external force they exert and the constraints' reactions.
"""

from __future__ import annotations

import numpy as np

from parsph import rigid
from parsph.errors import InputError
from parsph.parallel.runtime import collective
from parsph.rigid import RigidBody


def prescribe_velocity(sim, t: float) -> None:
    """The constrained velocities at t (collocated on EFG bodies: parsph.collocation),
    and the rigid velocities of the free rigid bodies' particles."""
    sim.bcs.set_velocity(sim.v[: sim.n_owned], t)
    if sim.collocation:
        sim.collocation.velocity(t)
    n = sim.n_owned
    for body in sim.rigid_bodies:
        body.project(sim.mass, sim.X[:n] + sim.u[:n], sim.v)


def prescribe_displacement(sim, t: float) -> None:
    """The constrained displacements at t (collocated on EFG bodies)."""
    sim.bcs.set_displacement(sim.u[: sim.n_owned], t)
    if sim.collocation:
        sim.collocation.displacement(t)


def external_force(sim) -> np.ndarray:
    """Body force, tractions and constraint reactions on the owned particles."""
    n = sim.n_owned
    ext = np.zeros((n, sim.dim))
    if sim.body_acc is not None:
        ext += sim.mass[:n, None] * sim.body_acc
    if sim.tractions:
        sim.tractions.add(ext, sim.t)
    ext[sim.bcs.mask] -= sim.force[sim.bcs.mask]
    return ext


def reaction(sim) -> np.ndarray:
    """Force the constraints exert on each owned particle (zero where unconstrained)."""
    r = np.zeros((sim.n_owned, sim.dim))
    r[sim.bcs.mask] = -sim.force[sim.bcs.mask]
    return r


def free_rigid_bodies(sim, restart: dict | None) -> list:
    """The freely moving rigid bodies (parsph.rigid), from the particles' initial
    velocities or the checkpoint (collective)."""
    out = []
    for b in sim.bodies:
        with collective(sim.comm):
            free = b.rigid and not rigid.held(b, sim.bcs.items, sim.dim, sim.comm)
            if b.rigid and restart is None:
                check_rigid_motion(sim, b, free)
        if free:
            body = RigidBody(b, sim.mass, sim.X, sim.comm)
            if restart is None:
                body.project(sim.mass, sim.X + sim.u, sim.v)
            else:
                body.restore(restart["totals"]["rigid"][len(out)])
            out.append(body)
    return out


def check_rigid_motion(sim, b, free: bool) -> None:
    """InputError unless the conditions at t = 0 move the rigid body `b` rigidly
    (collective): each [[bc]] that holds it gives all its particles one value (not an
    expression of position), and no initial displacement moves its particles (a free body
    starts where its parts put it, a held one where its [[bc]] put it: uniformly)."""
    for i, c in enumerate(sim.bcs.items):
        mine = (c.index >= b.lo) & (c.index < b.hi)
        if _spread(sim.comm, c.value.reshape(len(c.index), len(c.components))[mine]) > 0.0:
            raise InputError(f"bc[{i}] gives the particles of rigid body '{b.name}' different values (an "
                             "expression of position), which would deform it: hold a rigid body with one value")
    u = sim.u[b.lo:b.hi]
    if _spread(sim.comm, np.vstack([u, np.zeros((1, sim.dim))]) if free else u) > 0.0:
        raise InputError(f"an [[initial]] displacement moves the particles of rigid body '{b.name}': a rigid body "
                         "starts where its parts put it (give it an initial velocity, or move it with [[bc]])")


def _spread(comm, rows: np.ndarray) -> float:
    """The largest difference between two rows of `rows` in a component, over all ranks
    (collective)."""
    bounds = [b for b in comm.allgather((rows.min(axis=0), rows.max(axis=0)) if len(rows) else None) if b]
    if not bounds:
        return 0.0
    return float(np.max(np.max([hi for _, hi in bounds], axis=0) - np.min([lo for lo, _ in bounds], axis=0),
                        initial=0.0))
