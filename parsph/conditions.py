"""The conditions on the particles: the constraints (parsph.bc, collocated on EFG bodies:
parsph.collocation), the free rigid bodies' motion (parsph.rigid), the body force and
tractions; the external force they exert and the constraints' reactions.
"""

from __future__ import annotations

import numpy as np

from parsph import config, rigid
from parsph.bc import BoundaryConditions, Tractions
from parsph.collocation import BoundaryCollocation, collocated
from parsph.errors import InputError
from parsph.parallel.runtime import collective
from parsph.rigid import RigidBody


class Conditions:
    """The scene's constraints ([[bc]], collocated on EFG bodies), tractions, body force
    (`loads.body_acceleration`), mass-proportional damping (`time.damping`) and free rigid
    bodies on a rank's particles."""

    def __init__(self, scene: config.Scene):
        self.scene = scene
        body_acc = scene.loads.body_acceleration
        self.body_acc = None if body_acc is None else np.asarray(body_acc)
        self.damping = scene.time.damping
        self.rigid_bodies = []  # the freely moving ones, made after the initial conditions
        self.bcs = self.tractions = self.collocation = None

    def adopt(self, state, t: float) -> None:
        """The constraints and tractions on the adopted `state` (state.RankState) at time t
        (collective)."""
        scene, n = self.scene, state.n_owned
        with collective(state.comm):
            parameters = scene.parameters
            self.bcs = BoundaryConditions(scene.bc, state.groups, state.X[:n], state.gid[:n], parameters, t)
            self.tractions = Tractions(scene.tractions, state.groups, state.X[:n], state.gid[:n],
                                       state.measure[:n], config.thickness(scene), parameters)
        efg = any(collocated(b.formulation) for b in state.bodies)
        self.collocation = BoundaryCollocation(state, self.bcs) if efg and scene.bc else None

    def recollocate(self, state) -> None:
        """The collocation in a new reference of the EFG bodies (on the kept lists)."""
        if self.collocation:
            self.collocation = BoundaryCollocation(state, self.bcs)

    def prescribe_velocity(self, state, t: float) -> None:
        """The constrained velocities at t (collocated on EFG bodies: parsph.collocation),
        and the rigid velocities of the free rigid bodies' particles."""
        n = state.n_owned
        self.bcs.set_velocity(state.v[:n], t)
        if self.collocation:
            self.collocation.velocity(t)
        for body in self.rigid_bodies:
            body.project(state.mass, state.X[:n] + state.u[:n], state.v)

    def prescribe_displacement(self, state, t: float) -> None:
        """The constrained displacements at t (collocated on EFG bodies)."""
        self.bcs.set_displacement(state.u[: state.n_owned], t)
        if self.collocation:
            self.collocation.displacement(t)

    def add_loads(self, state, force: np.ndarray, t: float) -> None:
        """force += the body force and the tractions at t (owned particles)."""
        if self.body_acc is not None:
            force += state.mass[: state.n_owned, None] * self.body_acc
        if self.tractions:
            self.tractions.add(force, t)

    def external_force(self, state, t: float) -> np.ndarray:
        """Body force, tractions and constraint reactions on the owned particles."""
        ext = np.zeros((state.n_owned, state.dim))
        self.add_loads(state, ext, t)
        ext[self.bcs.mask] -= state.force[self.bcs.mask]
        return ext

    def reaction(self, state) -> np.ndarray:
        """Force the constraints exert on each owned particle (zero where unconstrained)."""
        r = np.zeros((state.n_owned, state.dim))
        r[self.bcs.mask] = -state.force[self.bcs.mask]
        return r

    def free_rigid_bodies(self, state, restart: dict | None) -> None:
        """The freely moving rigid bodies (parsph.rigid), from the particles' initial
        velocities or the checkpoint (collective)."""
        out = []
        for b in state.bodies:
            with collective(state.comm):
                free = b.rigid and not rigid.held(b, self.bcs.items, state.dim, state.comm)
                if b.rigid and restart is None:
                    check_rigid_motion(self.bcs, state, b, free)
            if free:
                body = RigidBody(b, state.mass, state.X, state.comm)
                if restart is None:
                    body.project(state.mass, state.X + state.u, state.v)
                else:
                    body.restore(restart["totals"]["rigid"][len(out)])
                out.append(body)
        self.rigid_bodies = out


def check_rigid_motion(bcs, state, b, free: bool) -> None:
    """InputError unless the conditions at t = 0 move the rigid body `b` rigidly
    (collective): each [[bc]] that holds it gives all its particles one value (not an
    expression of position), and no initial displacement moves its particles (a free body
    starts where its parts put it, a held one where its [[bc]] put it: uniformly)."""
    for i, c in enumerate(bcs.items):
        mine = (c.index >= b.lo) & (c.index < b.hi)
        if _spread(state.comm, c.value.reshape(len(c.index), len(c.components))[mine]) > 0.0:
            raise InputError(f"bc[{i}] gives the particles of rigid body '{b.name}' different values (an "
                             "expression of position), which would deform it: hold a rigid body with one value")
    u = state.u[b.lo:b.hi]
    if _spread(state.comm, np.vstack([u, np.zeros((1, state.dim))]) if free else u) > 0.0:
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
