"""Rigid obstacles with prescribed motion: walls, tools and surfaces (parsph.surfaces).

A wall is the plane through p(t) = point + velocity t with unit normal n pointing into the
material, optionally limited to a box of current positions. A tool is a rigid box
lower..upper moving at `velocity`, its edges rounded with `radius` (the signed distance of
a rounded box: a smaller box grown by the radius), as the punch of [V §2.4.3].

After each drift a particle of the obstacle's group found inside it (signed gap < 0) is
put back on its surface along the outward normal n and loses the part of its velocity
relative to the obstacle that moves into it: a perfectly plastic, frictionless contact
(the tangential velocity is untouched). A free rigid body meets the obstacles with the
same law as a whole (parsph.rigid.RigidBody.strike): it is moved out of them, and the
velocities of its particles inside them lose their approach, by the impulses of least
kinetic energy. The impulse the obstacle gives a particle, over the time it stands for,
is its contact force on that particle; the obstacle's force is their exact sum
(exact_sum), the same on any number of ranks. That time is the two half steps before the
drift, (dt_(n-1) + dt_n) / 2: the impulse cancels the approach the particle took from the
forces of the last half kick of the step before and the first of this one, so that a
particle pressed against an obstacle shows the force that presses it, on a shortened step
too. A surface's contact is the same, relative to its velocity at the particle, with
Coulomb friction; its torque about its centre is the sum of the levers times the forces.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from parsph.exact_sum import sums
from parsph.surfaces import Surface


@njit(cache=True, _nrt=False)
def _press(rows, gap, normal, velocity, u, v, mass, span, out, force):
    """A plane's contact on the candidate `rows` with their signed `gap`s: each row inside
    (gap < 0) is put back on the plane along its unit `normal`, its velocity relative to the
    plane's `velocity` loses its approach (the component into the plane), and its force is
    the impulse over `span`; writes the rows inside to `out` and their forces to `force`,
    returns their number. The approach is summed component by component (numpy's einsum, of
    the generic contact, adds 3 components as (0 + 2) + 1: an inclined 3D plane may differ from
    it in the last bit; any 2D plane and a 3D plane along an axis are the same)."""
    count = 0
    dim = u.shape[1]
    for k in range(len(rows)):
        if not gap[k] < 0.0:
            continue
        r = rows[k]
        approach = 0.0
        for a in range(dim):
            u[r, a] -= gap[k] * normal[a]
            approach += (v[r, a] - velocity[a]) * normal[a]
        if approach > 0.0:
            approach = 0.0
        for a in range(dim):
            v[r, a] -= approach * normal[a]
            force[count, a] = -(mass[r] * approach) * normal[a] / span
        out[count] = r
        count += 1
    return count


class Wall:
    """A moving plane, optionally acting only inside a box of current positions."""

    def __init__(self, spec: dict):
        self.group = spec.group  # the particles that can touch it
        self.index = np.zeros(0, np.int64)  # of them, the owned ones (Walls.select)
        self.point = np.asarray(spec.point, float)
        normal = np.asarray(spec.normal, float)
        self.normal = normal / np.linalg.norm(normal)  # unit, into the material
        self.velocity = np.asarray(spec.velocity, float)
        self.lower = None if spec.lower is None else np.asarray(spec.lower, float)
        self.upper = None if spec.upper is None else np.asarray(spec.upper, float)

    def gap(self, x: np.ndarray, t: float) -> np.ndarray:
        """The signed gaps of the points x; < 0 inside."""
        gap = (x - (self.point + self.velocity * t)) @ self.normal
        if self.lower is not None:
            outside = ~np.all((x >= self.lower) & (x <= self.upper), axis=1)
            gap = np.where(outside, np.inf, gap)
        return gap

    def contact(self, x: np.ndarray, t: float) -> tuple:
        """(signed gaps, unit normals into the material) of the points x; gap < 0 inside."""
        return self.gap(x, t), np.broadcast_to(self.normal, x.shape)

    def press(self, X: np.ndarray, u: np.ndarray, v: np.ndarray, mass: np.ndarray, rows: np.ndarray, t: float,
              span: float) -> tuple:
        """The contact of the owned `rows` (Walls.enforce): (the rows inside, their forces).
        The gaps are numpy's of all the rows in one array, as the obstacles' generic contact
        has them: its matrix-vector product rounds a row's sum by the row's place in the array."""
        gap = self.gap(X.take(rows, axis=0) + u.take(rows, axis=0), t)
        out, force = np.empty(len(rows), np.int64), np.empty((len(rows), len(self.normal)))
        count = _press(rows, gap, self.normal, self.velocity, u, v, mass, span, out, force)
        return out[:count], force[:count]


class Tool:
    """A moving rigid box with rounded edges (radius r): the points within r of the box
    shrunk by r on every side."""

    def __init__(self, spec: dict):
        self.group = spec.group
        self.index = np.zeros(0, np.int64)
        lower, upper = np.asarray(spec.lower, float), np.asarray(spec.upper, float)
        self.center = 0.5 * (lower + upper)
        self.radius = float(spec.radius)
        self.core = 0.5 * (upper - lower) - self.radius  # half-sizes of the shrunk box
        self.velocity = np.asarray(spec.velocity, float)

    def contact(self, x: np.ndarray, t: float) -> tuple:
        rel = x - (self.center + self.velocity * t)
        side = np.where(rel < 0.0, -1.0, 1.0)
        q = np.abs(rel) - self.core  # > 0 along the axes on which x is beyond the core
        beyond = np.maximum(q, 0.0)
        out = np.linalg.norm(beyond, axis=1)
        deepest = np.max(q, axis=1)
        gap = out + np.minimum(deepest, 0.0) - self.radius
        normal = np.zeros_like(x)
        corner = out > 0.0
        normal[corner] = beyond[corner] / out[corner, None]
        face = np.flatnonzero(~corner)  # inside the core: out through the nearest face
        normal[face, np.argmax(q[face], axis=1)] = 1.0
        return gap, normal * side


class Walls:
    """The scene's walls, tools and surfaces acting on this rank's owned particles."""

    def __init__(self, walls: list, tools: list, dim: int, surfaces: list = (), parameters: dict = None):
        self.items = [Wall(s) for s in walls] + [Tool(s) for s in tools] + [
            Surface(s, dim, parameters or {}, f"surfaces[{k}]") for k, s in enumerate(surfaces)]
        self.names = [f"wall{k}" for k in range(len(walls))] + [f"tool{k}" for k in range(len(tools))] + [
            f"surface{k}" for k in range(len(surfaces))]
        self.dim = dim
        # each obstacle's force on each particle it touched in the last step, kept across select
        self.contacts = [np.zeros((0, dim)) for _ in self.items]
        # each surface's torque about its centre on those particles ([z] in 2D)
        self.turning = [k for k, item in enumerate(self.items) if isinstance(item, Surface)]
        self.torques = [np.zeros((0, 1 if dim == 2 else 3)) for _ in self.turning]

    def select(self, masks: dict) -> None:
        """Find each obstacle's particles among this rank's owned ones (group name -> bool
        mask over them); again whenever ownership changes."""
        for item in self.items:
            item.index = np.flatnonzero(masks[item.group])

    def enforce(self, X: np.ndarray, u: np.ndarray, v: np.ndarray, mass: np.ndarray, t: float, span: float,
                rigid_bodies: list = ()) -> None:
        """Put owned particles found inside an obstacle back on its surface, and the free
        `rigid_bodies` (rigid.RigidBody) found inside any, whole; record each obstacle's
        force on each particle: its impulse over `span`, the time the impulse stands for
        ((dt_(n-1) + dt_n) / 2, the module's docstring)."""
        free = np.zeros(len(X), bool)  # the free rigid bodies' rows: they meet the obstacles as bodies
        self._rows = {}  # obstacle -> the rows of its contacts
        for body in rigid_bodies:
            free[body.body.lo:body.body.hi] = True
        for k, item in enumerate(self.items):
            sel = item.index[~free[item.index]] if rigid_bodies else item.index
            if isinstance(item, Wall):  # compiled
                self._rows[k], self.contacts[k] = item.press(X, u, v, mass, sel, t, span)
                continue
            gap, normal = item.contact(X[sel] + u[sel], t)
            hit = gap < 0.0
            sel, gap, normal = sel[hit], gap[hit], normal[hit]
            u[sel] -= gap[:, None] * normal
            self._rows[k] = sel
            if isinstance(item, Surface):
                self.contacts[k] = self._slide(item, sel, normal, X[sel] + u[sel], v, mass, t) / span
                continue
            approach = np.minimum(np.einsum("na,na->n", v[sel] - item.velocity, normal), 0.0)
            v[sel] -= approach[:, None] * normal
            self.contacts[k] = -(mass[sel] * approach)[:, None] * normal / span
        for body in rigid_bodies:
            hits = []
            for item in self.items:
                rows = item.index[(item.index >= body.body.lo) & (item.index < body.body.hi)]
                gap, normal = item.contact(X[rows] + u[rows], t)
                hit = gap < 0.0
                velocity = item.velocity_at(X[rows[hit]] + u[rows[hit]], t) if isinstance(item, Surface) \
                    else item.velocity
                hits.append((rows[hit], gap[hit], normal[hit], velocity))
            impulses = body.strike(hits, X, u, v)
            for k, impulse in enumerate(impulses):
                self.contacts[k] = np.concatenate([self.contacts[k], impulse / span])
                self._rows[k] = np.concatenate([self._rows[k], hits[k][0]])
        for j, k in enumerate(self.turning):
            self.torques[j] = self._moments(self.items[k], k, X, u, t)

    @staticmethod
    def _slide(item: Surface, sel: np.ndarray, normal: np.ndarray, x: np.ndarray, v: np.ndarray,
               mass: np.ndarray, t: float) -> np.ndarray:
        """A surface's change of the velocities v[sel] of the particles it holds at x: their
        approach relative to its velocity there, and as much of their sliding as Coulomb's
        law lets the normal impulse stop; returns the impulses."""
        relative = v[sel] - item.velocity_at(x, t)
        normal_speed = np.einsum("na,na->n", relative, normal)
        approach = np.minimum(normal_speed, 0.0)
        change = -approach[:, None] * normal
        if item.friction > 0.0:
            sliding = relative - normal_speed[:, None] * normal
            speed = np.linalg.norm(sliding, axis=1)
            held = np.minimum(item.friction * -approach, speed)  # the tangential speed friction takes
            change -= np.divide(held, speed, out=np.zeros_like(speed), where=speed > 0.0)[:, None] * sliding
        v[sel] += change
        return mass[sel, None] * change

    def _moments(self, item: Surface, k: int, X: np.ndarray, u: np.ndarray, t: float) -> np.ndarray:
        """The moments about a surface's centre of its forces on the particles it touched
        (the rows it holds, then the free rigid bodies' rows, as self.contacts[k])."""
        rows = self._rows[k]
        r, f = item.lever(X[rows] + u[rows], t), self.contacts[k]
        if self.dim == 2:
            return (r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0])[:, None]
        return np.cross(r, f)

    def limit_steps(self, x: np.ndarray, v: np.ndarray, t: float, step_limit: np.ndarray) -> None:
        """Bound the steps of the owned particles (at x, with velocities v) that can touch a
        surface: none may move by more than a quarter of its margin relative to it (it sees
        a particle within half the margin)."""
        for k in self.turning:
            item, rows = self.items[k], self.items[k].index
            speed = np.linalg.norm(v[rows] - item.velocity_at(x[rows], t), axis=1)
            moving = rows[speed > 0.0]
            step_limit[moving] = np.minimum(step_limit[moving], 0.25 * item.margin / speed[speed > 0.0])

    def force_sums(self) -> list:
        """Each obstacle's force on this rank's particles, exact (obstacle-major, then
        component)."""
        return [s for c in self.contacts for s in sums(c)]

    @property
    def force(self) -> np.ndarray:
        """Each obstacle's force on this rank's particles, (obstacles, dim)."""
        return np.array([float(s) for s in self.force_sums()]).reshape(len(self.items), self.dim)

    def restore(self, forces, torques=()) -> None:
        """Take `forces` (obstacles x dim) and the surfaces' `torques` as the last step's
        (restart: the global ones, carried by one rank)."""
        self.contacts = [np.array([f], float) for f in forces]
        if len(torques):
            self.torques = [np.array([m], float) for m in torques]

    def torque_sums(self) -> list:
        """Each surface's torque on this rank's particles, exact (surface-major, then
        component)."""
        return [s for m in self.torques for s in sums(m)]
