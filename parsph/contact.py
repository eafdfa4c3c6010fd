"""Contact between bodies: particles of two bodies that come closer than the sum of their
contact radii repel each other through a force derived from a potential, so that momentum
is conserved exactly and energy to the time integration's error ([G §4.3]: tools and body
pressed together through a repulsive Hertzian potential with the bodies' moduli).

A particle's contact radius is `radius` times half its spacing (the d-th root of its
measure); a pair overlaps by delta = r_i + r_j - |x_j - x_i| > 0 in the current
configuration, and pushes apart along x_j - x_i with
    3D: F = 4/3 E* sqrt(R*) delta^(3/2)       (Hertz, two spheres: R* = r_i r_j / (r_i + r_j))
    2D: F = pi/4 E* t delta                    (Hertz, two parallel cylinders of length t,
                                                the thickness: plane strain)
    1D: F = A delta / (r_i / M_i + r_j / M_j)  (the two half-slabs of the contact radii in
                                                series: the bar's own stiffness, cross-section A)
with 1/E* = (1 - nu_i^2) / E_i + (1 - nu_j^2) / E_j and M the P-wave modulus of uniaxial
strain, each times the entry's `stiffness` factor (1 by default). Its potential,
F delta / (k + 1) for F proportional to delta^k, is the contact energy (half of it for
each particle), part of the total energy. The stiffness dF/ddelta of each pair enters the
stable time step as a spring (formulations.tlsph.stable_time_step): of each overlapping
pair in 3D (where it grows from zero with the overlap), of each pair closer than its
contact distance plus the skin in 1D and 2D (a linear spring: the step that brings a pair
into contact must be stable for it too).

Optionally dissipative, per [[contact]] entry, with the pairs' relative velocity
v_ij = v_j - v_i (the step's mid-point velocities) and the effective mass
m* = m_i m_j / (m_i + m_j), in which a particle of a rigid body counts with the body's
mass (a force on it moves the whole body, or nothing if the body is held):
  - damping (`restitution` e < 1): a normal dashpot c (v_ij . n) n on i, c = 2 zeta
    sqrt(k m*), k = dF/ddelta, zeta = -ln e / sqrt(pi^2 + ln^2 e) (the restitution of a
    linear spring-dashpot), never pulling the pair together (at most the elastic force);
  - Coulomb friction (`friction` mu): along the tangential relative velocity v_t, of size
    min(mu |F_n|, m* |v_t| / dt), so that friction never reverses a pair's sliding
    within the step (sticking without a regularising speed).
Their work, accumulated over each step (trapezoidal rule), is the contact work, part of
the balance; the dashpot shortens the stable step by (sqrt(1 + zeta^2) - zeta).

Self-contact (an entry naming one body twice, `self_contact = true`): particles of the body
that are not kernel neighbours of each other in its reference (the pairs the formulation
sums over) touch as particles of two bodies do: the faces of a crack whose pairs have broken
(materials.damage, `break_pairs`), or parts of a body folded onto each other.

The pairs are found in the current configuration with a skin s of half the largest contact
distance: candidate lists (the pairs within their contact distance plus 2 s; rows: owned
particles, columns in global-id order, so that every sum runs in the same order on any
number of ranks) and contact ghosts (the particles of other ranks within that reach of this
rank's contact particles, their positions refreshed at every step: a plan of the halo of
parallel.halo, as the kernel's ghosts are) are kept until a
particle has moved s/2 since they were made: until then they hold every pair within its
contact distance plus s.
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from numba import njit

from parsph import fields
from parsph.cells import close_pairs
from parsph.errors import InputError, ParsphError
from parsph.exact_sum import allsum, total
from parsph.neighbors import pair_keys
from parsph.parallel.halo import Halo, gather, within_reach
from parsph.parallel.mirrors import Mirrors, plane_images
from parsph.relations import Relation, Skin

SKIN = 0.5  # of the largest contact distance
POINT, VECTOR = fields.get("X"), fields.get("v")  # how the images' positions and velocities reflect
INSIDE = 0.25  # two particles of two bodies closer than this fraction of their contact distance:
#                one is inside the other (the contact has failed)


def contact_modulus(c, dim: int) -> float:
    """A body's modulus in the contact stiffness, from its law's small-strain constants c:
    M = lam + 2 mu in 1D; E / (1 - nu^2) = 4 mu (lam + mu) / (lam + 2 mu) in 2D and 3D, the
    bulk modulus for a fluid (mu = 0)."""
    if dim == 1:
        return c.lam + 2.0 * c.mu
    return 4.0 * c.mu * (c.lam + c.mu) / (c.lam + 2.0 * c.mu) if c.mu > 0 else c.bulk


def damping_ratio(restitution: float) -> float:
    """The damping ratio of a linear spring-dashpot whose impact has this coefficient of
    restitution e: zeta = -ln e / sqrt(pi^2 + ln^2 e) (1 for e = 0, 0 for e = 1)."""
    if restitution <= 0.0:
        return 1.0
    log = -math.log(restitution)
    return log / math.sqrt(math.pi ** 2 + log ** 2)


class Contact:
    """The scene's contact pairs of bodies, on this rank's particles."""

    name, reads, work = "contact", (), "contact_work"  # parsph.interactions: its own ghosts (a halo plan)

    def checkpoint(self) -> dict:  # parsph.interactions: the lists are found again on restart
        return {}

    def restore(self, totals: dict) -> None:
        pass

    def __init__(self, specs: list, bodies: list, body: np.ndarray, measure: np.ndarray, mass: np.ndarray,
                 gid: np.ndarray, n_owned: int, dim: int, thickness: float, comm, planes: list = (),
                 kernel=None):
        """specs: the scene's [[contact]] tables; bodies: the simulation's bodies (names,
        constants); body, measure, mass, gid: of the local particles (the owned first);
        planes: the scene's [[symmetry]] planes; kernel: the kernel relations
        (topology.Topology: `kernel_pairs()`, and `builds`, which counts their builds), whose
        pairs a self-contact leaves out."""
        n = n_owned
        index = {b.name: b.index for b in bodies}
        self.entries = [(index[s["bodies"][0]], index[s["bodies"][1]]) for s in specs]
        self.labels = [f"{s['bodies'][0]}.{s['bodies'][1]}" for s in specs]
        count = len(bodies)
        self.entry_of = np.full((count, count), -1, np.int64)  # body pair -> entry
        for k, (a, b) in enumerate(self.entries):
            self.entry_of[a, b] = self.entry_of[b, a] = k
        self.factor = np.array([s["stiffness"] for s in specs])  # on the stiffness, per entry
        self.zeta = np.array([damping_ratio(s["restitution"]) for s in specs])
        self.friction = np.array([s["friction"] for s in specs])
        self.dissipative = bool((self.zeta > 0).any() or (self.friction > 0).any())
        self.dt = math.inf  # the step the forces are for (the friction's limit)
        touching = np.zeros(count, bool)
        touching[[b for pair in self.entries for b in pair]] = True
        radius_factor = np.zeros(count)
        for s in specs:  # each body's: its entries agree (config)
            radius_factor[[index[name] for name in s["bodies"]]] = s["radius"]
        modulus = np.array([contact_modulus(b.constants, dim) for b in bodies])
        self.dim, self.comm, self.n = dim, comm, n
        self.scale = thickness if dim < 3 else 1.0  # the thickness (2D) or the cross-section (1D)
        self.body = body[:n]
        self.gid = gid[:n]
        self.mass = mass[:n]
        self.inertia = mass[:n].copy()  # the mass a pair's force moves: a rigid body's, for its particles
        for b in bodies:
            if b.rigid:
                self.inertia[b.lo:b.hi] = float(allsum(comm, [total(mass[b.lo:b.hi])])[0])
        self.radius = 0.5 * radius_factor[body[:n]] * measure[:n] ** (1.0 / dim)
        self.modulus = modulus[body[:n]]
        self.owned = dict(gid=self.gid, body=self.body, radius=self.radius, modulus=self.modulus, mass=self.mass,
                          inertia=self.inertia)  # the constants of the contact points, owned
        self.mine = np.flatnonzero(touching[body[:n]])  # owned particles of bodies in contact
        largest = float(self.radius.max()) if n else 0.0
        self.distance = 2.0 * comm.allreduce(largest, op=MPI.MAX)  # the largest contact distance
        self.skin = SKIN * self.distance
        self.force = np.zeros((n, dim))
        self.dissipation = np.zeros((n if self.dissipative else 0, dim))  # the damping and friction forces
        self.energy = np.zeros(n)
        self.omega2 = np.zeros(n)  # the springs' bound on the squared frequency
        self.entry_force = np.zeros((len(self.entries), n, dim))  # each entry's force from the other body
        self.closest = np.ones(n)  # |x_ij| / (r_i + r_j) of the closest candidate
        self.rule = Skin(self.skin, comm)  # when the lists are searched again
        self.self_contact = bool((np.diag(self.entry_of) >= 0).any())  # a body in contact with itself
        self.kernel_pairs = np.zeros(0, np.int64)  # pair_keys of the kernel's pairs (self-contact leaves them)
        self.kernel, self.local_gid, self.seen = kernel, gid, None  # the kernel relations' build last seen
        self.planes = list(planes)
        self.total = comm.allreduce(n)  # the particles of all ranks: an image's id is its source's plus a multiple
        self.points = self.owned  # the contact points: owned, contact ghosts, then mirror images (search)
        self.halo = None  # the contact ghosts' refresh (parallel.halo)
        self.images = None  # the mirror images' (parallel.mirrors), with planes
        self.pairs = None  # the candidate lists: a relation of the owned rows to the contact points

    def evaluate(self, x: np.ndarray, v: np.ndarray, step_limit: np.ndarray) -> None:
        """The contact forces, energies and spring bounds at the owned particles' current
        positions x and velocities v (n, dim) (collective: ghost positions and, with
        dissipation, velocities; the lists when due). `step_limit` (owned particles) is
        lowered to the step in which a particle in contact moves a quarter of the skin, so
        that the lists see every contact coming (a pair closes in by at most half the skin
        between searches), whatever the speed."""
        if self.self_contact and self.kernel.builds != self.seen:  # the kernel's pairs changed
            self.exclude(self.kernel.kernel_pairs(), self.local_gid)
            self.seen = self.kernel.builds
        if self.rule.due(x, self.mine):
            self.search(x)
        else:
            self.halo.exchange(x, self.x)
        self.x[: self.n] = x
        if self.dissipative:
            self.halo.exchange(v, self.v)
            self.v[: self.n] = v
        if self.images is not None:
            self.images.fill_all(self.x, POINT)
            if self.dissipative:
                self.images.fill_all(self.v, VECTOR)
        c = self.points
        _repulsion(self.n, self.pairs.ptr, self.pairs.idx, self.x, self.v, c["radius"], c["modulus"], c["mass"],
                   c["inertia"], c["body"], self.entry_of, self.factor, self.zeta, self.friction, self.dt,
                   self.dim, self.scale, self.skin, self.force, self.dissipation, self.energy, self.omega2,
                   self.entry_force, self.closest)
        mine = self.mine
        speed = np.sqrt(np.einsum("na,na->n", v[mine], v[mine]))
        moving = speed > 0.0
        step_limit[mine[moving]] = np.minimum(step_limit[mine[moving]], 0.25 * self.skin / speed[moving])

    def check_inside(self, gid: np.ndarray, body: np.ndarray, names: list, step: int, t: float) -> None:
        """Raise (every rank alike) the error naming both bodies if a particle of one has come
        within INSIDE of the contact distance of a particle of another: it is inside that body,
        which contact exists to prevent (collective)."""
        found = self._closest(gid, body, None, INSIDE)
        if found is None:
            return
        first, first_body, _, (other, other_body, ratio) = found
        error = ParsphError(
            f"bodies '{names[first_body]}' and '{names[other_body]}' are passing through each other at step {step}, "
            f"t = {t:.6g} s: particle {first} of '{names[first_body]}' is at {ratio:.3g} of the contact distance from "
            f"particle {other} of '{names[other_body]}', inside it; the contact springs cannot stop the bodies at "
            f"this speed (their energy exceeds what the springs store over the contact distance): raise "
            f"contact.stiffness or slow the impact")
        error.agreed = True  # the same reduction on every rank
        raise error

    def check_apart(self, gid: np.ndarray, body: np.ndarray, x: np.ndarray, names: list) -> None:
        """At the start, before any force: refuse bodies in contact that overlap (two particles
        closer than 0.99 of their contact distance, coincident ones too), naming both and the
        closest pair (collective). The lists it searches are searched again at the first
        evaluation, as without the check."""
        self.search(x)
        rows, cols, radius = self.pairs.row_of_pair(), self.pairs.idx, self.points["radius"]
        sep = self.x[cols] - self.x[rows]
        ratio = np.sqrt(np.einsum("pa,pa->p", sep, sep)) / (radius[rows] + radius[cols])
        self.closest[:] = 1.0
        np.minimum.at(self.closest, rows, ratio)
        self.rule.forget()
        found = self._closest(gid, body, x, 0.99)
        if found is None:
            return
        first, first_body, at, (other, other_body, ratio) = found
        where = ", ".join(f"{c:.6g}" for c in at)
        error = InputError(
            f"bodies '{names[first_body]}' and '{names[other_body]}' overlap at the start: particle {first} of "
            f"'{names[first_body]}' at ({where}) is at {ratio:.3g} of the contact distance from particle {other} of "
            f"'{names[other_body]}' (the contact distance is contact.radius times the spacing); " +
            ("the bodies interpenetrate: place them apart" if ratio < 0.5 else
             f"move the bodies apart by at least {(1.0 - ratio) * 100:.3g} % of it, or lower contact.radius"))
        error.agreed = True
        raise error

    def _closest(self, gid: np.ndarray, body: np.ndarray, x: np.ndarray | None, below: float) -> tuple | None:
        """(global id, body, position (if x is given), partner) of the particle of all ranks
        closest to another body's over their contact distance if that is below `below`, else
        None (collective: every rank gets the same)."""
        mine = self.closest[self.mine]
        lowest = float(mine.min()) if len(mine) else 1.0
        if self.comm.size > 1:
            lowest = self.comm.allreduce(lowest, op=MPI.MIN)
        if lowest >= below:
            return None
        found = []
        if len(mine) and mine.min() == lowest:
            i = int(self.mine[np.argmin(mine)])
            found = [(int(gid[i]), int(body[i]), None if x is None else tuple(x[i].tolist()), self.partner(i))]
        return min(c for part in self.comm.allgather(found) for c in part)

    def partner(self, i: int) -> tuple | None:
        """(global id, body, distance over the contact distance) of owned particle i's closest
        candidate in contact, or None if it touches nothing."""
        if self.closest[i] >= 1.0:
            return None
        c = self.points
        row = self.pairs.idx[self.pairs.ptr[i]:self.pairs.ptr[i + 1]]
        sep = self.x[row] - self.x[i]
        ratio = np.sqrt(np.einsum("pa,pa->p", sep, sep)) / (c["radius"][row] + c["radius"][i])
        k = int(np.argmin(ratio))
        return int(c["gid"][row[k]] % self.total), int(c["body"][row[k]]), float(ratio[k])

    def exclude(self, pairs, gid: np.ndarray) -> None:
        """The kernel's pairs (a relation of the owned rows; gid: the local rows' global ids),
        which self-contact leaves out, after the reference's pairs changed: the lists are
        searched again at the next evaluation."""
        if self.self_contact:
            rows = np.repeat(np.arange(len(pairs.ptr) - 1), np.diff(pairs.ptr))
            self.kernel_pairs = np.unique(pair_keys(gid[rows], gid[pairs.idx]))
            self.rule.forget()

    def search(self, x: np.ndarray) -> None:
        """Contact ghosts (the other ranks' contact particles within the largest contact
        distance plus two skins of this rank's, by parallel.halo), their mirror images and
        the candidate lists."""
        n, comm, reach = self.n, self.comm, self.distance + 2.0 * self.skin
        self.rule.searched(x, self.mine)
        mine = self.mine
        send = {r: mine[rows] for r, rows in within_reach(x[mine], reach, comm).items()}
        ghosts = gather(self.owned, send, comm)
        self.halo = Halo(comm, send, ghosts["owner"], n)
        self.points = {k: np.concatenate([v, ghosts[k]]) for k, v in self.owned.items()}
        start = n + len(ghosts["gid"])
        self.x = np.zeros((start, self.dim))
        self.v = np.zeros((start if self.dissipative else 0, self.dim))
        self.x[:n] = x
        self.halo.exchange(x, self.x)
        points = np.concatenate([mine, np.arange(n, start)])
        if self.planes:
            points = np.concatenate([points, self._mirror(points, reach)])
        self.pairs = self._lists(points, n, reach)

    def _lists(self, points: np.ndarray, n: int, reach: float) -> Relation:
        """The candidate lists: each owned contact point's pairs with the contact `points`
        (rows of self.x) of the other body of an entry (or of its own body beyond the
        kernel's pairs, in a self-contact) within their contact distance plus two skins,
        the columns in global-id order."""
        c = self.points
        i, j = close_pairs(self.x[points], reach, c["body"][points], self.entry_of >= 0)
        i, j = points[i], points[j]
        sep = self.x[j] - self.x[i]
        dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
        keep = (dist < c["radius"][i] + c["radius"][j] + 2.0 * self.skin) & \
            (self.entry_of[c["body"][i], c["body"][j]] >= 0)
        i, j = i[keep], j[keep]
        if self.self_contact:  # a body touches itself only where the kernel does not join it
            kernel = np.isin(pair_keys(c["gid"][i], c["gid"][j]), self.kernel_pairs)
            keep = ~(kernel & (c["body"][i] == c["body"][j]))
            i, j = i[keep], j[keep]
        i, j = np.concatenate([i, j]), np.concatenate([j, i])
        rows = i < n
        i, j = i[rows], j[rows]
        order = np.lexsort((c["gid"][j], i))
        ptr = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(i, minlength=n), out=ptr[1:])
        return Relation(ptr, j[order], "particles", "contact")

    def _mirror(self, points: np.ndarray, reach: float) -> np.ndarray:
        """Append the mirror images (parallel.mirrors.plane_images) of the contact points
        `points` (rows of self.x) within `reach` of the symmetry planes (on either side: in
        the current configuration), across each plane and each combination of planes near
        their corner, with their sources' constants, global ids as parallel.mirrors numbers
        them (the kernel's pairs of a self-contact are known by them) and reflected
        positions; return their rows. An image's force is not applied: its source feels the
        mirrored force from the mirrored pair."""
        source, sign, offset, gid = plane_images(self.x[points], self.points["gid"][points], self.planes, self.total,
                                                 reach, 1e-9 * self.distance)
        source = points[source]
        start = len(self.x)
        self.images = Mirrors.one_layer(start, source, sign, offset)
        self.points = {k: np.concatenate([a, gid if k == "gid" else a[source]]) for k, a in self.points.items()}
        self.x = np.concatenate([self.x, np.zeros((len(source), self.dim))])
        self.v = np.zeros((len(self.x) if self.dissipative else 0, self.dim))
        self.images.fill_all(self.x, POINT)
        return np.arange(start, len(self.x))


@njit(cache=True, inline="always")
def clear_row(i, force, dissipation, entry_force):
    """Row i of an interaction's force, its dissipative part (if kept) and each entry's force: 0."""
    for a in range(force.shape[1]):
        force[i, a] = 0.0
        if len(dissipation):
            dissipation[i, a] = 0.0
        for k in range(entry_force.shape[0]):
            entry_force[k, i, a] = 0.0


@njit(cache=True, _nrt=False)
def _repulsion(n, ptr, idx, x, v, radius, modulus, mass, inertia, body, entry_of, factor, zeta, friction, dt, dim,
               scale, skin, force, dissipation, energy, omega2, entry_force, closest):
    """The contact force, its dissipative part (with damping or friction), energy (half of
    each pair's potential), spring bound 2 sum_j dF/ddelta / m_i (of the pairs closer than
    the contact distance plus the skin in 1D and 2D; over (sqrt(1 + zeta^2) - zeta)^2 with
    damping) and closest approach of the owned particles 0..n-1, and the force on each of
    them from the other body of each contact entry (mass: the particles', inertia: what a
    pair's force moves, Contact.inertia); the pairs' forces summed in the rows'
    order (global ids)."""
    for i in range(n):
        clear_row(i, force, dissipation, entry_force)
        energy[i] = 0.0
        omega2[i] = 0.0
        closest[i] = 1.0
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            r2 = 0.0
            for a in range(dim):
                e = x[j, a] - x[i, a]
                r2 += e * e
            r = math.sqrt(r2)
            reach = radius[i] + radius[j]
            closest[i] = min(closest[i], r / reach)
            delta = reach - r
            entry = entry_of[body[i], body[j]]
            z = zeta[entry]
            slow = 1.0 if z == 0.0 else 1.0 / (math.sqrt(1.0 + z * z) - z) ** 2  # a dashpot's shorter step
            if dim < 3 and delta > -skin:
                if dim == 2:
                    k = factor[entry] * 0.25 * math.pi * scale / (1.0 / modulus[i] + 1.0 / modulus[j])
                else:
                    k = factor[entry] * scale / (radius[i] / modulus[i] + radius[j] / modulus[j])
                omega2[i] += 2.0 * k / mass[i] * slow
            if not delta > 0.0:
                continue
            if dim == 3:
                k = factor[entry] * 4.0 / 3.0 * math.sqrt(radius[i] * radius[j] / reach) / (1.0 / modulus[i]
                                                                                          + 1.0 / modulus[j])
                f = k * delta * math.sqrt(delta)
                stiffness = 1.5 * k * math.sqrt(delta)
                omega2[i] += 2.0 * stiffness / mass[i] * slow
                energy[i] += 0.5 * 0.4 * f * delta
            else:
                f = k * delta
                stiffness = k
                energy[i] += 0.5 * 0.5 * f * delta
            for a in range(dim):
                push = -f * (x[j, a] - x[i, a]) / r  # away from j
                force[i, a] += push
                entry_force[entry, i, a] += push
            if z > 0.0 or friction[entry] > 0.0:
                _dissipate(i, j, x, v, inertia, r, f, stiffness, z, friction[entry], dt, dim, force,
                           dissipation, entry_force[entry])


@njit(cache=True, inline="always")
def _dissipate(i, j, x, v, inertia, r, f, stiffness, z, mu, dt, dim, force, dissipation, entry_force):
    """Add the dashpot (damping ratio z) and Coulomb friction (mu) of pair (i, j) to
    particle i's force (elastic force f, stiffness dF/ddelta; inertia: the masses the
    pair's force moves)."""
    m = inertia[i] * inertia[j] / (inertia[i] + inertia[j])
    closing = 0.0  # v_ij . n, n from i to j
    for a in range(dim):
        closing += (v[j, a] - v[i, a]) * (x[j, a] - x[i, a]) / r
    damp = min(2.0 * z * math.sqrt(stiffness * m) * closing, f)  # along n; never attractive
    normal = f - damp  # the size of the normal force on i, away from j
    sliding = 0.0
    for a in range(dim):
        t = v[j, a] - v[i, a] - closing * (x[j, a] - x[i, a]) / r
        sliding += t * t
    sliding = math.sqrt(sliding)
    stop = m * sliding / dt if dt < math.inf else math.inf  # what stops the sliding within the step
    drag = 0.0 if sliding == 0.0 else min(mu * normal, stop) / sliding
    for a in range(dim):
        n_a = (x[j, a] - x[i, a]) / r
        extra = damp * n_a + drag * (v[j, a] - v[i, a] - closing * n_a)
        force[i, a] += extra
        dissipation[i, a] += extra
        entry_force[i, a] += extra
