"""Rigid bodies made of particles: a body with `rigid = true` carries no stress; its
particles move as one rigid body, either as [[bc]] prescribe (a tool or a plate with a
velocity history: the conditions hold every particle of the body) or freely under the
forces on its particles (contact, body force): Newton-Euler.

Free motion, in the kick-drift-kick step: after each half kick of the particles (each by
its own force) the body takes the linear and angular momentum of its particles,
    V = P / M,   omega = I^-1 L,   P = sum m v,   L = sum m r x v,   r = x - c,
I = R I0 R^T (3D; I0 in 2D) the inertia about the centre of mass c in the current orientation R, and its
particles the rigid velocities v = V + omega x r (impulse and angular impulse as Newton's
and Euler's equations give them; the sums exact, so the same on any number of ranks); the
drift moves the centre by dt V and turns R by omega dt (Rodrigues' formula in 3D), and
puts the particles at x = c + R (X - c0) with the body's velocities there. The particles' F is R: no strain, no stress.
The state (c, R, V, omega) is checkpointed.

Against walls and tools (parsph.walls) a free body meets the obstacles' law, perfectly
plastic and frictionless, as a whole (`strike`): after the drift it is moved out of them by
the shortest translation, and its velocity becomes the one nearest in kinetic energy with
which no point in contact approaches its obstacle: the inelastic impact of J. J. Moreau
(Unilateral contact and dry friction in finite freedom dynamics, in Nonsmooth Mechanics and
Applications, CISM Courses and Lectures 302, 1988: the velocity after the impact is the
projection, in the kinetic metric, of the velocity before it onto the admissible ones),
which for a single particle is the particle law. A disk thrown
head-on at a wall stops in the step it meets it (its kinetic energy goes into the
obstacle's work); thrown obliquely it slides on along the wall.
"""

from __future__ import annotations

import math

import numpy as np

from parsph.errors import InputError, ParsphError
from parsph.exact_sum import allsum, totals


def cross(omega: np.ndarray, r: np.ndarray) -> np.ndarray:
    """omega x r for rows r (n, dim): omega a scalar (1,) in 2D, a vector in 3D, empty in 1D."""
    if r.shape[1] == 2:
        return omega[0] * np.stack([-r[:, 1], r[:, 0]], axis=1)
    if r.shape[1] == 3:
        return np.cross(omega, r)
    return np.zeros_like(r)


def moments(r: np.ndarray, p: np.ndarray) -> np.ndarray:
    """r x p per row: (n, 1) in 2D, (n, 3) in 3D, (n, 0) in 1D."""
    if r.shape[1] == 2:
        return (r[:, 0] * p[:, 1] - r[:, 1] * p[:, 0])[:, None]
    if r.shape[1] == 3:
        return np.cross(r, p)
    return np.zeros((len(r), 0))


def rotation(angle: np.ndarray, dim: int) -> np.ndarray:
    """The rotation by the angle (2D, (1,)) or the rotation vector (3D)."""
    if dim == 2:
        c, s = np.cos(angle[0]), np.sin(angle[0])
        return np.array([[c, -s], [s, c]])
    if dim == 3:
        theta = float(np.sqrt(angle @ angle))
        if theta == 0.0:
            return np.eye(3)
        k = angle / theta
        K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        return np.eye(3) + np.sin(theta) * K + (1.0 - np.cos(theta)) * (K @ K)
    return np.eye(dim)


def least_distance(G: np.ndarray, h: np.ndarray) -> tuple | None:
    """The shortest y with G y >= h, and multipliers lam >= 0 with y = G^T lam (the impulses
    of the constraints): C. L. Lawson and R. J. Hanson's least distance programming by
    non-negative least squares (Solving Least Squares Problems, 1974, ch. 23, Algorithm
    LDP), on rows scaled to unit length and h to at most 1; None if no y satisfies G y >= h."""
    from scipy.optimize import nnls  # here: scipy.optimize takes a tenth of a second to import

    norms = np.sqrt(np.einsum("ca,ca->c", G, G))
    scale = float(np.max(h / norms))
    if not scale > 0.0:  # y = 0 satisfies them all
        return np.zeros(G.shape[1]), np.zeros(len(h))
    E = np.vstack([(G / norms[:, None]).T, h / (norms * scale)])
    f = np.zeros(len(E))
    f[-1] = 1.0
    u = nnls(E, f)[0]
    r = E @ u - f
    if not -r[-1] > 1e-12:  # E u = f: the constraints exclude each other
        return None
    return -r[:-1] / r[-1] * scale, u / -r[-1] * scale / norms


def held(body, constraints: list, dim: int, comm) -> bool:
    """Whether [[bc]] `constraints` (bc.Constraint, on owned particles) hold the rigid `body`;
    InputError if one holds only part of it: some particles, some components or for a
    duration (collective)."""
    count, out = body.last - body.first, False
    for i, c in enumerate(constraints):
        total = comm.allreduce(int(np.count_nonzero((c.index >= body.lo) & (c.index < body.hi))))
        if total and (total != count or len(c.components) != dim or c.duration < math.inf):
            raise InputError(f"bc[{i}] holds part of rigid body '{body.name}' ({total} of its {count} particles, "
                             "or some components, or for a duration): a rigid body is held whole, every particle "
                             "in every component for the whole run, or not at all")
        out = out or total > 0
    return out


def stable_step(body, omega2: np.ndarray, step_limit: np.ndarray, v: np.ndarray, contact) -> tuple:
    """(stable step, 0, its particle) of a rigid body (rows lo..hi): no strain; its
    particles' contact springs (omega2, parsph.contact) and the steps their motion allows
    (step_limit: no particle moving more than a quarter of the contact skin, no pair closing
    in by more than its separation in a step: its contacts are seen coming); (inf, 0, -1) if
    nothing bounds it."""
    lo, hi = body.lo, body.hi
    if contact is None or hi == lo:
        return np.inf, 0.0, -1
    springs = omega2[lo:hi]
    steps = np.full(hi - lo, np.inf)
    np.divide(2.0, np.sqrt(springs), out=steps, where=springs > 0)
    np.minimum(steps, step_limit[lo:hi], out=steps)
    first = int(np.argmin(steps))
    return (steps[first], 0.0, lo + first) if steps[first] < np.inf else (np.inf, 0.0, -1)


class RigidBody:
    """A freely moving rigid body: its mass, reference centre and inertia, and its state."""

    def __init__(self, body, mass: np.ndarray, X: np.ndarray, comm):
        """body: the simulation's Body (its owned rows lo..hi); mass, X: of the local
        particles; at rest until `project` gives it its particles' momenta (collective)."""
        self.body, self.comm = body, comm
        lo, hi = body.lo, body.hi
        dim = X.shape[1]
        m = mass[lo:hi]
        first = allsum(comm, totals([m, m[:, None] * X[lo:hi]]))
        self.mass = float(first[0])
        self.centre0 = np.array([float(s) for s in first[1:]]) / self.mass
        r = X[lo:hi] - self.centre0
        self.inertia0 = self._inertia(m, r, dim)
        self.centre = self.centre0.copy()
        self.R = np.eye(dim)
        self.V = np.zeros(dim)
        self.omega = np.zeros({1: 0, 2: 1, 3: 3}[dim])

    def _inertia(self, m: np.ndarray, r: np.ndarray, dim: int) -> np.ndarray:
        """The inertia tensor about the centre (collective): (1, 1) in 2D, (3, 3) in 3D."""
        if dim == 1:
            return np.zeros((0, 0))
        if dim == 2:
            return np.array([[float(allsum(self.comm, totals([m * np.einsum("na,na->n", r, r)]))[0])]])
        parts = [m * (np.einsum("na,na->n", r, r) * (a == b) - r[:, a] * r[:, b]) for a in range(3) for b in range(3)]
        return np.array([float(s) for s in allsum(self.comm, totals(parts))]).reshape(3, 3)

    def project(self, mass: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
        """Take the momenta of the body's particles (rows lo..hi of the masses, current
        positions x and velocities v) as the body's, and give its particles the rigid
        velocities (collective)."""
        lo, hi = self.body.lo, self.body.hi
        r = x[lo:hi] - self.centre
        p = mass[lo:hi, None] * v[lo:hi]
        sums = allsum(self.comm, totals([p, moments(r, p)]))
        dim = x.shape[1]
        self.V = np.array([float(s) for s in sums[:dim]]) / self.mass
        if len(self.omega):
            L = np.array([float(s) for s in sums[dim:]])
            inertia = self.inertia0 if dim == 2 else self.R @ self.inertia0 @ self.R.T
            self.omega = np.linalg.solve(inertia, L)
        v[lo:hi] = self.V + cross(self.omega, r)

    def drift(self, dt: float, X: np.ndarray, u: np.ndarray, v: np.ndarray, F: np.ndarray) -> None:
        """Move the body by dt: the centre, the orientation, its particles' displacements u,
        velocities v (the body's, at their new places) and deformation gradients F (rows lo..hi)."""
        self.centre = self.centre + dt * self.V
        self.R = rotation(dt * self.omega, X.shape[1]) @ self.R
        self._place(X, u, v)
        F[self.body.lo:self.body.hi] = self.R

    def _place(self, X: np.ndarray, u: np.ndarray, v: np.ndarray) -> None:
        """Put the body's particles (rows lo..hi) at their places, x = c + R (X - c0), with the
        body's velocities there."""
        lo, hi = self.body.lo, self.body.hi
        r = (X[lo:hi] - self.centre0) @ self.R.T
        u[lo:hi] = self.centre + r - X[lo:hi]
        v[lo:hi] = self.V + cross(self.omega, r)

    def strike(self, hits: list, X: np.ndarray, u: np.ndarray, v: np.ndarray) -> list:
        """Meet the obstacles (the module's docstring): `hits` lists per obstacle (rows,
        gaps < 0, unit normals out of the obstacle, the obstacle's velocity) of the body's
        owned particles found inside it. The body is translated out of all of them and its
        velocity (V, omega) projected onto the admissible ones in the kinetic metric (both by
        least_distance), and its particles take their new places and velocities (rows of X,
        u, v). Returns each obstacle's impulses on the rows it hit (collective: every rank
        solves for the contacts of all, ordered by reference position)."""
        dim = X.shape[1]
        local = [np.column_stack([X[rows], np.full(len(rows), k), gap, normal, X[rows] + u[rows] - self.centre,
                                  np.broadcast_to(velocity, (len(rows), dim))])
                 for k, (rows, gap, normal, velocity) in enumerate(hits)]
        mine = np.concatenate(local)
        parts = self.comm.allgather(mine)
        table = np.concatenate(parts)
        if not len(table):
            return [np.zeros((0, dim)) for _ in hits]
        order = np.lexsort([table[:, dim]] + [table[:, a] for a in reversed(range(dim))])
        table = table[order]
        gap, normal = table[:, dim + 1], table[:, dim + 2: 2 * dim + 2]
        r, velocity = table[:, 2 * dim + 2: 3 * dim + 2], table[:, 3 * dim + 2:]
        shift = least_distance(normal, -gap)
        A = np.column_stack([normal, moments(r, normal)])  # the normal velocities of the contacts: A (V, omega)
        inertia = self.inertia0 if dim < 3 else self.R @ self.inertia0 @ self.R.T
        metric = np.zeros((len(A[0]), len(A[0])))
        metric[:dim, :dim] = self.mass * np.eye(dim)
        metric[dim:, dim:] = inertia
        L = np.linalg.cholesky(metric)
        w = np.concatenate([self.V, self.omega])
        change = None if shift is None else least_distance(
            np.linalg.solve(L, A.T).T, np.einsum("ca,ca->c", normal, velocity) - A @ w)
        if change is None:
            raise ParsphError(f"rigid body '{self.body.name}' is caught between obstacles that close in on it: "
                              "no motion of it leaves them all")
        self.centre = self.centre + shift[0]
        w = w + np.linalg.solve(L.T, change[0])
        self.V, self.omega = w[:dim], w[dim:]
        self._place(X, u, v)
        start = sum(len(p) for p in parts[: self.comm.rank])
        impulse = (change[1][:, None] * normal)[np.argsort(order)[start: start + len(mine)]]
        return np.split(impulse, np.cumsum([len(rows) for rows, *_ in hits])[:-1])

    def state(self) -> dict:
        return {"centre": self.centre.tolist(), "R": self.R.tolist(), "V": self.V.tolist(),
                "omega": self.omega.tolist()}

    def restore(self, state: dict) -> None:
        self.centre = np.array(state["centre"])
        self.R = np.array(state["R"])
        self.V = np.array(state["V"])
        self.omega = np.array(state["omega"])
