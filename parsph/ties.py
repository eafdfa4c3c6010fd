"""Ties: two bodies bonded along their common face (a tied interface that fails, as LS-DYNA's
*CONTACT_TIED_..._FAILURE or a cohesive bond), the glue carrying normal and shear traction
until a failure stress, then releasing for good (after which [[contact]] between the bodies,
if given, takes over).

Pairs: each particle of one body is tied to the particles of the other within `distance` of
it in the reference configuration, found once at set-up and kept by global ids (the same
pairs on any number of ranks and after a restart, which finds them again in the unchanged
reference; the broken ones travel in the checkpoint). A pair (p, q) has an interface normal
n = (m_p - m_q) / |m_p - m_q|, m_i the sum of the unit vectors from particle i to its
partners (along the face normal on a flat face), a tied area A = (a_p / c_p + a_q / c_q) / 2
(a_i the particle's face area, its measure^((d-1)/d) times the thickness in 2D or the
cross-section in 1D; c_i its count of partners: the pairs share the face) and a normal gap
g = |(X_q - X_p) . n|. It is a linear penalty on the displacement jump w = u_q - u_p (a
cohesive zone for small rotations of the face), with the opening s = w . n:
    traction  t = k_n s n + k_t (w - s n),   k_n = 2 / (g (1/M_p + 1/M_q)),
                                               k_t = 2 / (g (1/G_p + 1/G_q)),
the moduli those of uniaxial strain M = lam + 2 mu and of shear G = mu of the two bodies
across the gap, in series (the glue is as stiff as the material between the two particles),
times the entry's `stiffness`. The force on p is A t, on q -A t (equal and opposite: momentum
is exact); the tie energy A (k_n s^2 + k_t |w - s n|^2) / 2, half to each particle, is a term
of the energy balance. A pair breaks, never to heal, when its elastic traction meets
    (max(sigma_n, 0) / N)^2 + (tau / S)^2 >= 1,   sigma_n = k_n s, tau = k_t |w - s n|
(the quadratic criterion of tied-with-failure interfaces; N = normal_strength, S =
shear_strength). Then its energy leaves the tie energy for the released energy, with the
part of the step the half kick booked at the broken pair's force, so that the balance stays
closed (R = E + (F . (du_p - du_q)) / 2, the step's displacements du since the last
evaluation). A dashpot of damping ratio `damping` on the relative velocity (normal and
tangential, c = 2 zeta sqrt(A k m*), m* the pair's reduced mass) is optional; its work is
the tie work. Each pair's stiffness adds 2 A k_n / m_i to the particle's bound on the
squared frequency (as contact's springs: formulations.tlsph.stable_time_step).

Every pair is evaluated by both of its particles' owners with the same operands in the same
order (the pair's lower global id first), so that its force and its break are the same bits
on either side: the partner of an owned particle is an owned particle or a ghost of the halo
(add_ghosts: every particle within the largest kernel support), whose displacement and
velocity the halo refreshes; a `distance` beyond that reach is refused.
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI
from numba import njit

from parsph.balance import Term
from parsph.cells import close_pairs
from parsph.contact import clear_row
from parsph.errors import InputError
from parsph.keys import REQUIRED, Key, in_range, non_negative, positive
from parsph.neighbors import pair_keys

SPACINGS = 1.2  # the default distance, in the larger of the two bodies' largest particle spacings: on
#               matching lattices the particle facing it only (a diagonal partner, at sqrt(2), would
#               leave the face's edges softer than its middle)

TIE_KEYS = {
    "bodies": Key("strlist", REQUIRED, doc="the names of the two bodies bonded along their common face "
                                           "(parsph.ties)"),
    "distance": Key("float", 0.0, non_negative,
                    "a particle is tied to the other body's particles within this distance of it in the "
                    "reference [m] (0: 1.2 times the larger particle spacing of the two bodies, the facing "
                    "particle on matching lattices; at most the largest kernel support, the halo's reach)"),
    "stiffness": Key("float", 1.0, in_range(0.01, 1.0e4),
                     "factor on the tie's penalty stiffness (1: the bodies' moduli over the gap between the tied "
                     "particles, as stiff as the material; a larger factor shortens the step)"),
    "normal_strength": Key("float", REQUIRED, positive, "tensile traction at which a tie fails alone [Pa]"),
    "shear_strength": Key("float", REQUIRED, positive, "shear traction at which a tie fails alone [Pa]"),
    "damping": Key("float", 0.0, in_range(0.0, 1.0), "damping ratio of a dashpot across each tie (0: none)"),
}

TERMS = (Term("tie", "tie_energy", present=lambda sim: sim.interactions.ties is not None),
         Term("tie_released", "tie_released", present=lambda sim: sim.interactions.ties is not None),
         Term("tie_work", "tie_work", present=lambda sim: sim.interactions.ties is not None and sim.interactions.ties.dissipative))
RUNNING = ("tie_released",  # the tie energy broken ties released
           "tie_work")  # absorbed by the ties' dashpots


def check(entries: list, symmetry: list, bodies: list, moves) -> list:
    """The validated [[ties]] tables (`entries`, keys filled in, each naming two bodies of the
    scene: config): distinct bodies (`bodies`, resolved), total-Lagrangian (`moves(body)`
    false) and not rigid, every pair once, no symmetry planes."""
    names = [b["name"] for b in bodies]
    seen = set()
    for i, item in enumerate(entries):
        path = f"ties[{i}]"
        pair = item["bodies"]
        if pair[0] == pair[1]:
            raise InputError(f"{path}.bodies: body '{pair[0]}' is tied to itself; a tie joins two bodies")
        if frozenset(pair) in seen:
            raise InputError(f"{path}.bodies: bodies '{pair[0]}' and '{pair[1]}' are tied twice")
        seen.add(frozenset(pair))
        for name in pair:
            body = bodies[names.index(name)]
            if body.get("rigid", False) or moves(body):
                what = "rigid" if body.get("rigid", False) else "of an updated reference"
                raise InputError(f"{path}.bodies: body '{name}' is {what}; ties join total-Lagrangian bodies "
                                 "(their partners are found once in the reference)")
    if entries and symmetry:
        raise InputError("[[ties]] with [[symmetry]] planes is not supported: the mirror images are not tied; "
                         "model both sides")
    return entries


class Ties:
    """The scene's tied pairs of bodies, on this rank's owned particles."""

    name = "ties"  # parsph.interactions
    work = "tie_work"

    def __init__(self, specs: list, state, ledger, thickness: float):
        """specs: the scene's [[ties]] tables; state (state.RankState, adopted: bodies, local
        rows of X, u, v, gid, body, measure, mass, the halo) whose particles are tied; the
        ledger books the work of the ties' damping (collective)."""
        n, dim, comm = state.n_owned, state.dim, state.comm
        index = {b.name: b.index for b in state.bodies}
        self.entries = [(index[s.bodies[0]], index[s.bodies[1]]) for s in specs]
        self.labels = [f"{s['bodies'][0]}.{s['bodies'][1]}" for s in specs]
        self.n, self.dim, self.comm, self.ledger = n, dim, comm, ledger
        self.u, self.v = state.u, state.v  # the local rows, the ghosts refreshed by the halo
        self.zeta = np.array([s.damping for s in specs])
        self.dissipative = bool((self.zeta > 0).any())
        self.reads = ("d", "v") if self.dissipative else ("d",)  # total-Lagrangian: d is u
        rows = len(state.X)
        real = state.gid < state.decomp.total  # no mirror images
        spacing = state.measure ** (1.0 / dim)
        largest = np.array([float(spacing[:n][state.body[:n] == b.index].max(initial=0.0)) for b in state.bodies])
        comm.Allreduce(MPI.IN_PLACE, largest, op=MPI.MAX)
        reach = comm.allreduce(float(state.support[:n].max()) if n else 0.0, op=MPI.MAX)  # add_ghosts'
        self.distance = []
        for k, (s, (a, b)) in enumerate(zip(specs, self.entries)):
            d = s.distance or min(SPACINGS * max(largest[a], largest[b]), reach)
            if d > reach:
                error = InputError(f"ties[{k}].distance = {d:g} m exceeds the halo's reach, the largest kernel "
                                   f"support {reach:g} m: give at most that, or a larger kernel.support")
                error.agreed = True  # the same reduction on every rank
                raise error
            self.distance.append(d)
        # the pairs: owned particles of a tied body (rows) and the other body's local rows within distance
        entry_of = np.full((len(state.bodies),) * 2, -1, np.int64)
        for k, (a, b) in enumerate(self.entries):
            entry_of[a, b] = entry_of[b, a] = k
        points = np.flatnonzero(real & (entry_of[state.body].max(axis=1) >= 0))
        i, j = close_pairs(state.X[points], max(self.distance, default=0.0), state.body[points], entry_of >= 0) \
            if len(points) else (np.zeros(0, np.int64), np.zeros(0, np.int64))
        i, j = points[i], points[j]
        entry = entry_of[state.body[i], state.body[j]]
        sep = state.X[j] - state.X[i]
        keep = (entry >= 0) & (np.sqrt(np.einsum("pa,pa->p", sep, sep)) < np.array(self.distance + [0.0])[entry])
        i, j = np.concatenate([i[keep], j[keep]]), np.concatenate([j[keep], i[keep]])
        order = np.lexsort((state.gid[j], i))
        i, j = i[order], j[order]
        # each particle's partner count and direction sum, the owned rows' sent to the ghosts
        count = np.bincount(i, minlength=rows).astype(np.float64)
        sep = state.X[j] - state.X[i]
        toward = np.zeros((rows, dim))
        np.add.at(toward, i, sep / np.sqrt(np.einsum("pa,pa->p", sep, sep))[:, None])
        state.decomp.refresh(count, toward)
        owned = i < n
        i, j = i[owned], j[owned]
        self.ptr = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(i, minlength=n), out=self.ptr[1:])
        self.idx = j
        self.first = state.gid[i] < state.gid[j]  # i is the pair's p (its lower global id)
        p, q = np.where(self.first, i, j), np.where(self.first, j, i)
        self.keys = pair_keys(state.gid[i], state.gid[j])
        self.entry = entry_of[state.body[i], state.body[j]]
        normal = toward[p] - toward[q]
        size = np.sqrt(np.einsum("pa,pa->p", normal, normal))
        gap_vec = state.X[q] - state.X[p]
        along = np.sqrt(np.einsum("pa,pa->p", gap_vec, gap_vec))
        flat = size > 1e-6  # else (the directions cancel) the pair's own
        self.normal = np.where(flat[:, None], normal / np.where(flat, size, 1.0)[:, None],
                               gap_vec / along[:, None])
        gap = np.maximum(np.abs(np.einsum("pa,pa->p", gap_vec, self.normal)), 0.5 * along)  # never along the face
        face = state.measure ** ((dim - 1.0) / dim) * thickness
        self.area = 0.5 * (face[p] / count[p] + face[q] / count[q])
        c = [b.constants for b in state.bodies]
        M = np.array([x.lam + 2.0 * x.mu for x in c])[state.body]
        G = np.array([x.mu for x in c])[state.body]
        factor = np.array([s.stiffness for s in specs])[self.entry] if len(specs) else np.zeros(0)
        self.k_n = factor * 2.0 / (gap * (1.0 / M[p] + 1.0 / M[q]))
        self.k_t = np.where((G[p] > 0) & (G[q] > 0), factor * 2.0 / (gap * (1.0 / np.where(G[p] > 0, G[p], 1.0)
                                                                              + 1.0 / np.where(G[q] > 0, G[q], 1.0))),
                            0.0)
        strength = np.array([[s.normal_strength, s.shear_strength] for s in specs]).reshape(-1, 2)
        self.strength = strength[self.entry]
        self.reduced = state.mass[p] * state.mass[q] / (state.mass[p] + state.mass[q])
        self.broken = np.zeros(len(j), np.bool_)
        self.jump = np.zeros((len(j), dim))  # w at the last evaluation
        self.mass = state.mass[:n]
        self.force = np.zeros((n, dim))
        self.dissipation = np.zeros((n if self.dissipative else 0, dim))
        self.energy = np.zeros(n)
        self.omega2 = np.zeros(n)
        self.released = np.zeros(n)  # at the last evaluation
        self.entry_force = np.zeros((len(self.entries), n, dim))  # on each owned particle from the entry's other body

    def evaluate(self, x: np.ndarray, v: np.ndarray, step_limit: np.ndarray) -> None:
        """The tie forces, energies and spring bounds at the current displacements and
        velocities of the local rows (the halo refreshed them: `reads`); the pairs whose
        traction meets the criterion break, their energy to the released energy. The owned
        x, v and step_limit are those every interaction takes (a tie needs no step limit)."""
        broke = _tie(self.n, self.ptr, self.idx, self.first, self.u, self.v, self.normal, self.area, self.k_n,
                     self.k_t, self.strength, self.reduced, self.zeta, self.entry, self.mass, self.broken, self.jump,
                     self.force, self.dissipation, self.energy, self.omega2, self.released, self.entry_force)
        if broke:
            self.ledger.add("tie_released", self.released)

    def broken_keys(self) -> np.ndarray:
        """The pair keys (neighbors.pair_keys) of all ranks' broken ties, sorted (collective)."""
        mine = self.keys[self.broken]
        return np.unique(np.concatenate([np.zeros(0, np.int64)] + self.comm.allgather(mine)))

    def checkpoint(self) -> dict:
        """What a checkpoint's totals keep of the ties: the broken ones' keys (collective)."""
        return {"ties_broken": self.broken_keys().tolist()}

    def restore(self, carried: dict) -> None:
        """The broken ties of a checkpoint (none if it predates ties)."""
        self.broken |= np.isin(self.keys, np.asarray(carried.get("ties_broken", []), np.int64))


def columns(ties, state, reduction):
    """The ties' history series: each entry's force on its first body from its second,
    "tie_force_X.FIRST.SECOND" [N], and its broken ties, "ties_broken.FIRST.SECOND" (each
    counted on both sides, halved). Returns the function that gives them once `reduction`
    (diagnostics.RowReduction) is reduced."""
    dim = state.dim
    at = reduction.add_sums([ties.entry_force[k, state.bodies[first].lo:state.bodies[first].hi]
                             for k, (first, _) in enumerate(ties.entries)])
    broken = np.bincount(ties.entry[ties.broken], minlength=len(ties.entries)).astype(np.float64)
    counts = reduction.add_sums([broken[None, :]])

    def values() -> dict:
        out = {}
        for k, label in enumerate(ties.labels):
            for a, name in enumerate("xyz"[:dim]):
                out[f"tie_force_{name}.{label}"] = float(reduction.sums[at + k * dim + a])
            out[f"ties_broken.{label}"] = 0.5 * float(reduction.sums[counts + k])
        return out

    return values


def build(scene, state, ledger, topology) -> Ties | None:
    """The ties of the scene's [[ties]], or None."""
    if not scene.ties:
        return None
    from parsph import config  # config imports the ties' keys
    return Ties(scene.ties, state, ledger, config.thickness(scene))


@njit(cache=True, _nrt=False)
def _tie(n, ptr, idx, first, u, v, normal, area, k_n, k_t, strength, reduced, zeta, entry, mass, broken, jump,
         force, dissipation, energy, omega2, released, entry_force):
    """The ties' forces (elastic and, with damping, dissipative), energies (half of each
    pair's), frequency bounds and released energies (of the pairs breaking now) of the owned
    particles 0..n-1, the pairs in their rows' order (global ids); each pair's values from
    its lower global id's side p: w = u_q - u_p, the force A t on p. Returns whether a pair
    broke."""
    dim = u.shape[1]
    broke = False
    for i in range(n):
        clear_row(i, force, dissipation, entry_force)
        energy[i] = 0.0
        omega2[i] = 0.0
        released[i] = 0.0
        for e in range(ptr[i], ptr[i + 1]):
            if broken[e]:
                continue
            j = idx[e]
            p, q = (i, j) if first[e] else (j, i)
            sign = 1.0 if first[e] else -1.0
            s = 0.0
            for a in range(dim):
                s += (u[q, a] - u[p, a]) * normal[e, a]
            slide2 = 0.0
            for a in range(dim):
                t = u[q, a] - u[p, a] - s * normal[e, a]
                slide2 += t * t
            sigma = k_n[e] * s
            tau = k_t[e] * math.sqrt(slide2)
            opening = max(sigma, 0.0) / strength[e, 0]
            sliding = tau / strength[e, 1]
            pair_energy = 0.5 * area[e] * (k_n[e] * s * s + k_t[e] * slide2)
            if opening * opening + sliding * sliding >= 1.0:  # it fails: its energy is released
                broken[e] = True
                broke = True
                work = 0.0  # F . (du_p - du_q), F = A t on p
                for a in range(dim):
                    w_a = u[q, a] - u[p, a]
                    t_a = k_n[e] * s * normal[e, a] + k_t[e] * (w_a - s * normal[e, a])
                    work -= area[e] * t_a * (w_a - jump[e, a])
                released[i] += 0.5 * (pair_energy + 0.5 * work)
                continue
            energy[i] += 0.5 * pair_energy
            omega2[i] += 2.0 * area[e] * k_n[e] / mass[i] * _slower(zeta[entry[e]])
            c_n = 2.0 * zeta[entry[e]] * math.sqrt(area[e] * k_n[e] * reduced[e])
            c_t = 2.0 * zeta[entry[e]] * math.sqrt(area[e] * k_t[e] * reduced[e])
            closing = 0.0
            if c_n > 0.0:
                for a in range(dim):
                    closing += (v[q, a] - v[p, a]) * normal[e, a]
            for a in range(dim):
                w_a = u[q, a] - u[p, a]
                jump[e, a] = w_a
                push = sign * area[e] * (k_n[e] * s * normal[e, a] + k_t[e] * (w_a - s * normal[e, a]))
                force[i, a] += push
                entry_force[entry[e], i, a] += push
                if c_n > 0.0:
                    dv = v[q, a] - v[p, a]
                    drag = sign * (c_n * closing * normal[e, a] + c_t * (dv - closing * normal[e, a]))
                    force[i, a] += drag
                    dissipation[i, a] += drag
                    entry_force[entry[e], i, a] += drag
    return broke


@njit(cache=True, inline="always")
def _slower(z):
    """The factor on a spring's squared frequency bound with a dashpot of damping ratio z
    (the step shortens by sqrt(1 + z^2) - z)."""
    return 1.0 if z == 0.0 else 1.0 / (math.sqrt(1.0 + z * z) - z) ** 2
