"""Meshfree Galerkin methods: F and the stress at integration points, forces from
test-function gradients [R §4.3-5.3; eq. 26-32, 37-43, 60, 63-69; in the forms below,
where [R] leaves them open]; a Lagrangian kernel, or for kbm and nodal efg an Eulerian one [R Table 2]
(the same sums in the updated reference, rebuilt at every step; the stress points move with
the body, `moved`).

  kbm          Krongauz-Belytschko: trial gradients G_J = A^-T grad W^S_J corrected from
               the Shepard functions W^S_J = W_J / S, S = sum_K W_K [R eq. 28-32]; Shepard
               test functions (Petrov-Galerkin [R eq. 64]); integration points: particles
               and stress points, weights the Voronoi volumes of both together [R eq. 65]
  efg nodal    element-free Galerkin: MLS shape functions with a linear basis [R eq. 37-42]
               as trial and test functions (Bubnov-Galerkin), the particles as integration
               points with their volumes [R eq. 60]
  efg cells    the same at the Gauss points of background cells [R eq. 66-69]

At each integration point q, from the particles J whose kernel covers it (|X_q - X_J| < h_J,
the particle itself included):

    F_q = I + sum_J (u_J - u_b) (x) G_J(X_q),    f_I = - sum_q w_q P(X_q) grad N_I(X_q)

with G the trial and N the test functions, u_b the displacement of the point itself (a
particle) or of its first particle (sum_J G_J = 0 to round-off: a rigid translation gives
F = I exactly). F and the stress are evaluated at the particles in every method (the time
step and the read-outs use them). The test gradient of particle I at a point q needs sums
over q's whole neighbourhood (S, grad S; or the MLS moment matrix and its gradient): the
owner of q computes them and they are copied to q's ghosts at each build. sum_I grad N_I = 0
at every q, so linear momentum is conserved; the sums run over particles, then the other
set, each in global-id order.

MLS gradient (the derivative of [R eq. 40]), with the basis centred at X_q and scaled by a length l of q,
p_J = (1, (X_J - X_q) / l), M = sum_J W_J p_J p_J^T, gamma = M^-1 e_0:
    d_a Phi_J = (M^-1 p_J)_(1+a) W_J / l - gamma . (d_a M) M^-1 p_J W_J + (gamma . p_J) d_a W_J.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from parsph import COMPILED_SOURCE
from parsph.errors import InputError
from parsph.fields import Field, register
from parsph.formulations.base import CompiledOnce, Stage
from parsph.formulations.reference import PairOptions
from parsph.formulations.tlsph import gradient_row, stress_at
from parsph.kernels.correction import MAX_CONDITION
from parsph.kernels.functions import evaluate
from parsph.materials import update
from parsph.relations import find_relation

STRESS_POINTS, GAUSS_POINTS = "stress_points", "gauss_points"
TYPES = ("kbm", "efg")

register(Field("weight", "scalar", owner="kbm", doc="quadrature weight among particles and stress points [m^3]"))
for _set in (STRESS_POINTS, GAUSS_POINTS):
    register(
        Field("gid", "id", points=_set, doc="global id"),
        Field("X", "point", points=_set, doc="reference position [m]"),
        Field("volume", "scalar", points=_set, doc="quadrature weight [m^3]"),
        Field("body", "id", points=_set, doc="index of the body"),
    )
# the stress points of an Eulerian kernel move with the body: their updated reference
register(
    Field("Xr", "point", points=STRESS_POINTS, owner="updated", initial=lambda X, gid: X,
          doc="position in the updated reference [m]"),
    Field("Fr", "tensor", points=STRESS_POINTS, owner="updated",
          initial=lambda X, gid: np.broadcast_to(np.eye(X.shape[1]), (len(X), X.shape[1], X.shape[1])),
          doc="deformation gradient of the updated reference"),
)


def integration_set(formulation: dict) -> str | None:
    """The point set of integration points a formulation table needs besides the particles."""
    if formulation["type"] == "kbm":
        return STRESS_POINTS
    if formulation["type"] == "efg" and formulation.get("integration") == "cells":
        return GAUSS_POINTS
    return None


# ------------------------------------------------------------------ shape functions
def _kernel_pairs(relation, x_eval, x_node, support, kernel, node_of_pair, eval_of_pair):
    """Per pair: W_J(X_q) and its gradient with respect to X_q, J = node, q = evaluation point."""
    dim = x_eval.shape[1]
    sep = x_eval[eval_of_pair] - x_node[node_of_pair]
    dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
    w, dwdr, _ = evaluate(kernel, dist, support[node_of_pair], dim)
    scale = np.divide(dwdr, dist, out=np.zeros_like(dist), where=dist > 0)
    return w, scale[:, None] * sep, sep


def _inverse(matrices, active, counts, x_rows, gid_rows, matrix, what):
    """Inverses of the active rows' matrices (the others are set to the identity); raises
    InputError naming the first active point whose matrix is singular or ill-conditioned."""
    n = len(matrices)
    matrices[~active] = np.eye(matrices.shape[1])
    condition = np.linalg.cond(matrices) if n else np.zeros(0)
    bad = active & ~(condition < MAX_CONDITION)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        where = ", ".join(f"{c:.6g}" for c in x_rows[first])
        raise InputError(
            f"the {matrix} of {what} {int(gid_rows[first])} at ({where}) is singular or ill-conditioned "
            f"(condition number {condition[first]:.3g}, {int(counts[first])} particles in reach); "
            f"{int(bad.sum())} point(s) affected. Increase kernel.support")
    return np.linalg.inv(matrices) if n else matrices


def trial_gradients(shape, relation, x_rows, x_cols, support, kernel, gid_rows, active, what):
    """(G per pair of `relation` from integration points to particles, per-row data the
    test gradients need, the shape function values Phi_J(X_q) per pair): shape "kbm" (row
    data S, grad S; Phi_J = W_J / S) or "mls" (M^-1, grad M; Phi_J = (M^-1 p_J)_0 W_J).
    Rows not `active` get the identity; an active row with no particle or a singular matrix
    raises InputError naming it."""
    dim = x_rows.shape[1]
    n = len(relation.ptr) - 1
    row, j = relation.row_of_pair(), relation.idx
    counts = np.diff(relation.ptr)
    empty = active & (counts == 0)
    if empty.any():
        first = int(np.flatnonzero(empty)[0])
        where = ", ".join(f"{c:.6g}" for c in x_rows[first])
        raise InputError(f"{what} {int(gid_rows[first])} at ({where}) lies in no particle's kernel support; "
                         "increase kernel.support")
    w, grad, _ = _kernel_pairs(relation, x_rows, x_cols, support, kernel, j, row)
    if shape == "kbm":
        S = np.bincount(row, w, n)
        dS = np.stack([np.bincount(row, grad[:, a], n) for a in range(dim)], axis=1)
        S[~active] = 1.0
        gws = (grad - (w / S[row])[:, None] * dS[row]) / S[row][:, None]
        A = np.zeros((n, dim, dim))
        np.add.at(A, row, np.einsum("pa,pb->pab", x_cols[j] - x_rows[row], gws))
        Ainv = _inverse(A, active, counts, x_rows, gid_rows, "correction matrix A", what)
        G = np.einsum("pba,pb->pa", Ainv[row], gws)
        return np.ascontiguousarray(G), np.column_stack([S, dS]), w / S[row]
    m = dim + 1
    # the basis scaled by a length of the row (the support of its first particle) keeps M
    # well conditioned at any size; the shape functions do not depend on it
    scale = np.ones(n)
    has = counts > 0
    scale[has] = support[j[relation.ptr[:-1][has]]]
    p = np.concatenate([np.ones((len(j), 1)), (x_cols[j] - x_rows[row]) / scale[row, None]], axis=1)
    M = np.zeros((n, m, m))
    np.add.at(M, row, w[:, None, None] * np.einsum("pa,pb->pab", p, p))
    dM = np.zeros((n, dim, m, m))
    np.add.at(dM, row, grad[:, :, None, None] * np.einsum("pa,pb->pab", p, p)[:, None])
    Minv = _inverse(M, active, counts, x_rows, gid_rows, "moment matrix M", what)
    data = np.concatenate([scale[:, None], Minv.reshape(n, m * m), dM.reshape(n, dim * m * m)], axis=1)
    phi = np.einsum("pa,pa->p", Minv[row, 0], p) * w
    return _mls_gradients(p, w, grad, data[row], dim), data, phi


def _mls_gradients(p, w, grad, data, dim):
    """d Phi_J(X_q) per pair from p_J = (1, (X_J - X_q) / l), W_J(X_q), grad W_J(X_q) and
    the row data (l, M^-1, grad M) of its point q (see the module docstring)."""
    m = dim + 1
    scale = data[:, 0]
    Minv = data[:, 1: 1 + m * m].reshape(-1, m, m)
    dM = data[:, 1 + m * m:].reshape(-1, dim, m, m)
    gamma = Minv[:, :, 0]
    Mp = np.einsum("pab,pb->pa", Minv, p)
    first = Mp[:, 1:] * (w / scale)[:, None]
    second = np.einsum("pa,pkab,pb->pk", gamma, dM, Mp) * w[:, None]
    third = np.einsum("pa,pa->p", gamma, p)[:, None] * grad
    return np.ascontiguousarray(first - second + third)


def test_function_gradients(shape, relation, x_rows, x_cols, data, support, kernel):
    """grad N_I(X_q) per pair of `relation` from particles I to integration points q, from
    the row data of q (trial_gradients)."""
    dim = x_rows.shape[1]
    row, q = relation.row_of_pair(), relation.idx
    w, grad, sep = _kernel_pairs(relation, x_cols, x_rows, support, kernel, row, q)
    if shape == "kbm":
        S, dS = data[q, 0], data[q, 1:]
        return np.ascontiguousarray((grad - (w / S)[:, None] * dS) / S[:, None])
    p = np.concatenate([np.ones((len(q), 1)), -sep / data[q, :1]], axis=1)  # (1, (X_I - X_q) / l)
    return _mls_gradients(p, w, grad, data[q], dim)


# ------------------------------------------------------------------ the formulation
@dataclass
class Coupling:
    """The relations of one set of integration points with the particles of one body, in
    local rows, and their per-pair coefficients."""

    points: str  # "particles" or the set's name
    ptr: np.ndarray  # owned integration points -> particles: trial gradients
    idx: np.ndarray
    G: np.ndarray
    phi: np.ndarray  # trial shape function values Phi_J(X_q) per pair (boundary collocation)
    base: np.ndarray  # the particle whose displacement is subtracted
    test_ptr: np.ndarray  # owned particles -> integration points (owned and ghosts): test gradients
    test_idx: np.ndarray
    test_g: np.ndarray
    integrates: bool  # False: the particles of efg cells carry F and stress as read-outs only


class GalerkinFormulation:
    """One body's Galerkin formulation: shape functions, integration points, compiled
    stages, strain energy."""

    eta = 0.0  # what the loop asks of every formulation: no Hessian stabilisation,
    hourglass_form = 0  # no hourglass control, no strain trigger of reference updates
    weighted_hessian = True
    update_strain = 0

    def __init__(self, options: dict, dim: int, law: int, damaged: bool = False):  # damage: particle methods only
        self.type = options["type"]
        self.shape = "kbm" if self.type == "kbm" else "mls"
        self.points = integration_set(options)  # the other set, if any
        # the Eulerian kernel: the updated reference rebuilt at every step (as for sph, rlm)
        self.updated = options.get("kernel") == "eulerian"
        self.update_every = 1 if self.updated else 0
        self.kinematics_stress, self.forces = compile_stages(dim, law, self.updated)
        self.couplings = []

    @property
    def pair_options(self) -> PairOptions:
        """The nodal pair data every particle has (nearest spacing for the time step, disorder)."""
        return PairOptions(corrected=True, hourglass_form=0, alpha=0.0)

    def build(self, sim, body, kernel: str) -> None:
        """The relations and coefficients of `body` in the reference configuration: X (once,
        Lagrangian kernel) or the updated reference X^r (Eulerian kernel, at every step); the
        row data of the ghost integration points is copied from their owners."""
        P = sim.particles.arrays
        n = sim.n_owned
        X, support, gid = P["Xr" if self.updated else "X"], P["support"], P["gid"]
        mine = sim.body == body.index
        group_rows = np.where(mine, 0, -1)
        group_cols = np.where(mine, 0, -2)
        sets = [("particles", sim.particles)] + ([(self.points, sim.sets[self.points])] if self.points else [])
        self.couplings = []
        for name, points in sets:
            A = points.arrays
            Y = X if name == "particles" else A["Xr" if self.updated else "X"]  # positions in the reference
            rows = len(A["gid"])
            active = (A["body"] == body.index) if name != "particles" else mine
            key = f"{self.shape}_data"
            trial = find_relation(name, "particles", Y[: points.n_owned], X, gid, support, "cols",
                                 np.where(active, 0, -1)[: points.n_owned], group_cols)
            G, data, phi = trial_gradients(self.shape, trial, Y[: points.n_owned], X, support, kernel, A["gid"],
                                           active[: points.n_owned], "particle" if name == "particles" else
                                           name[:-1].replace("_", " "))
            if key not in A:
                A[key] = np.zeros((rows,) + data.shape[1:])
            rows_of_body = np.flatnonzero(active[: points.n_owned])
            A[key][rows_of_body] = data[rows_of_body]
            points.refresh(key)
            test = find_relation("particles", name, X[:n], Y, A["gid"], support, "rows", group_rows[:n],
                                np.where(active, 0, -2))
            if name == "particles":
                base = np.arange(points.n_owned, dtype=np.int64)
            else:  # a point's first particle (rows of other bodies, never run, take any)
                base = trial.idx[np.minimum(trial.ptr[:-1], len(trial.idx) - 1)] if len(trial.idx) else \
                    np.zeros(points.n_owned, np.int64)
            integrates = name != "particles" or self.type == "kbm" or self.points is None
            self.couplings.append(Coupling(
                name, trial.ptr, trial.idx, G, phi, base, test.ptr, test.idx,
                test_function_gradients(self.shape, test, X[:n], Y, A[key], support, kernel), integrates))

    def moved(self, sim, body) -> np.ndarray:
        """Positions of the body's owned stress points in the current configuration: their
        updated reference moved by the Shepard interpolation of the particles' displacement
        since it, x_q = X^r_q + sum_J Phi_J(X^r_q) d_J (the Eulerian kernel's update)."""
        coupling = self.couplings[1]
        lo, hi = body.set_rows[coupling.points]
        A = sim.sets[coupling.points].arrays
        rows = np.repeat(np.arange(len(coupling.ptr) - 1), np.diff(coupling.ptr))
        move = np.stack([np.bincount(rows, coupling.phi * sim.d[coupling.idx, a], len(coupling.ptr) - 1)
                         for a in range(sim.dim)], axis=1)
        return A["Xr"][lo:hi] + move[lo:hi]

    def weights(self, sim, points: str) -> np.ndarray:
        """Quadrature weights of the integration points of set `points` (zeros: read-out only)."""
        if points != "particles":
            return sim.sets[points].arrays["volume"]
        if self.type == "kbm":
            return sim.particles.arrays["weight"]
        return sim.volume if self.points is None else np.zeros(len(sim.volume))

    def stages(self, sim, body) -> list:
        c = body.constants.values
        runs = []
        for coupling in self.couplings:
            if coupling.points == "particles":
                arrays, (lo, hi), fail = dict(fs=sim.fs, F=sim.F, Fr=sim.Fr if self.updated else sim.F, VP=sim.VP,
                                              J=sim.J, psi=sim.psi), (body.lo, body.hi), sim.unstable_particle
            else:
                A = sim.sets[coupling.points].arrays
                arrays = A if self.updated else dict(A, fs=A["F"], Fr=A["F"])  # total-Lagrangian: F^r = I
                lo, hi = body.set_rows[coupling.points]
                fail = (lambda q, name=coupling.points: sim.unstable_point(name, q))
            runs.append((coupling, arrays, lo, hi, fail, self.weights(sim, coupling.points),
                         coupling.points))

        def displacement():  # from the updated reference, d = u - (X^r - X)
            np.subtract(sim.u[body.lo:body.hi], sim.shift[body.lo:body.hi], out=sim.d[body.lo:body.hi])

        scratch = (np.empty((sim.dim, sim.dim)), np.empty((update.WORK, 3, 3)))  # the kernel's

        def kinematics_stress():
            for coupling, arrays, lo, hi, fail, weight, points in runs:
                bad = self.kinematics_stress(lo, hi, coupling.ptr, coupling.idx, coupling.G, coupling.base, sim.d,
                                             weight, c, *sim.material_state(body, points), arrays["fs"],
                                             arrays["F"], arrays["Fr"], arrays["VP"], arrays["J"], arrays["psi"],
                                             *scratch)
                if bad >= 0:
                    raise fail(bad)

        def forces():
            sim.f_int[body.lo:body.hi] = 0.0
            for coupling, arrays, *_ in runs:
                if coupling.integrates:
                    self.forces(body.lo, body.hi, coupling.test_ptr, coupling.test_idx, coupling.test_g,
                                arrays["VP"], sim.f_int)

        prefix = f"{self.points}." if self.points else ""
        written = ("fs", "F", "VP", "J", "psi") + tuple(prefix + k for k in ("F", "VP", "J", "psi") if prefix)
        reads = tuple(("VP",) if self.points is None or self.type == "kbm" else ()) + \
            ((prefix + "VP",) if prefix else ())
        return [Stage("kinematics+stress", displacement, writes=("d",))] * self.updated + [
            Stage("kinematics+stress", kinematics_stress, reads=("d",), writes=written),
            Stage("forces", forces, reads=reads, writes=("f_int",))]

    def quadrature(self, sim, body) -> list:
        """[(X, F, w)] of the body's owned integration points, set by set."""
        out = []
        for coupling in self.couplings:
            if coupling.integrates:
                weight = self.weights(sim, coupling.points)
                if coupling.points == "particles":
                    lo, hi = body.lo, body.hi
                    out.append((sim.X[lo:hi], sim.F[lo:hi], weight[lo:hi]))
                else:
                    lo, hi = body.set_rows[coupling.points]
                    A = sim.sets[coupling.points].arrays
                    out.append((A["X"][lo:hi], A["F"][lo:hi], weight[lo:hi]))
        return out

    def integrated(self, sim, body, density) -> np.ndarray:
        """w_q q_q over the body's owned integration points, q = density(arrays) per row of
        a point set's arrays (a density per unit reference volume: psi, plastic work)."""
        terms = []
        for coupling in self.couplings:
            if not coupling.integrates:
                continue
            weight = self.weights(sim, coupling.points)
            if coupling.points == "particles":
                lo, hi = body.lo, body.hi
            else:
                lo, hi = body.set_rows[coupling.points]
            terms.append(weight[lo:hi] * density(sim.point_set(coupling.points).arrays)[lo:hi])
        return np.concatenate(terms)


# ------------------------------------------------------------------ compiled stages


def compile_stages(dim: int, law: int, updated: bool = False):
    """(kinematics_stress, forces) for one body's dimension, material law and reference
    (the initial one, or the updated one of the Eulerian kernel)."""
    @njit(cache=True, _nrt=False)
    def kinematics_stress(lo, hi, ptr, idx, G, base, d, weight, c, state, trial, fs, F, Fr, VP, J, psi, P, work):
        """F = I + sum_J (d_J - d_base) (x) G_J, the stress, w P, J and psi at integration
        points lo..hi-1; returns the first inverted point or -1. With an updated reference
        (Eulerian kernel) that gradient is the motion fs from the reference, F = fs F^r, and
        the forces take V^0 P F^rT = V^r P^r [V eq. 14]; in the total-Lagrangian case fs and
        F are one array. P (dim x dim) and work (update.WORK x 3 x 3): scratch."""
        undamaged = state[:, :0]  # damage is computed at particles only (config)
        first_bad = -1
        for q in range(lo, hi):
            gradient_row(dim, q, base[q], ptr, idx, G, d, fs)
            bad = stress_at(dim, law, updated, False, q, fs, Fr, weight[q], c, state, trial, undamaged, undamaged, P,
                            work, F, VP, J, psi)
            if bad and first_bad < 0:
                first_bad = q
        return first_bad

    @njit(cache=True, _nrt=False)
    def forces(lo, hi, ptr, idx, g, VP, f_int):
        """f_I -= sum_q w_q P_q grad N_I(X_q) over one set of integration points, for
        particles lo..hi-1."""
        for i in range(lo, hi):
            for p in range(ptr[i], ptr[i + 1]):
                q = idx[p]
                for a in range(dim):
                    s = 0.0
                    for b in range(dim):
                        s += VP[q, a, b] * g[p, b]
                    f_int[i, a] -= s

    variant = f"{COMPILED_SOURCE} {dim} {law} {updated}"
    return CompiledOnce(kinematics_stress, variant), CompiledOnce(forces, variant)
