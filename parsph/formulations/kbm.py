"""Krongauz-Belytschko corrected gradients with stress points, Lagrangian kernel [R §4.3,
§5.2; eq. 26-32, 63-65; implementation forms: DATA_SHEET §A].

Integration points q are the particles and the stress points (parsph.geometry.stress_points,
a point set of their own: no mass, no degrees of freedom). At each q, from the particles J
whose kernel covers it (|X_q - X_J| < h_J, the particle itself included):

    Shepard functions    W^S_J(X) = W_J(X) / S(X),  S = sum_K W_K               [R eq. 28]
    their gradients      grad W^S_J = (grad W_J - W^S_J grad S) / S
    correction           A(X_q) = sum_K (X_K - X_q) (x) grad W^S_K(X_q)          [R eq. 30]
    trial gradients      G_J(X_q) = A^-T grad W^S_J(X_q)                        [R eq. 31]
    deformation          F_q = I + sum_J (u_J - u_b) (x) G_J(X_q)                [R eq. 32]

(u_b: the particle itself, or a stress point's first neighbour; sum_J G_J = 0, so it only
makes a rigid translation exact in floating point). The stress comes from the body's
material law at every integration point. Forces are Petrov-Galerkin with the Shepard
functions as test functions [R eq. 64]:

    f_I = - sum_q w_q P(X_q) grad W^S_I(X_q)

over the integration points in particle I's support, w_q the Voronoi volume of q among
particles and stress points together [R eq. 65]; particle masses come from the particles'
own volumes (DATA_SHEET §A: not given by [R]). sum_I grad W^S_I = 0 at every q: linear
momentum is conserved. The sums run over particles then stress points, each in global-id
order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.fields import Field, register
from parsph.formulations.base import Stage, source_hash
from parsph.formulations.reference import PairOptions
from parsph.kernels.correction import MAX_CONDITION
from parsph.kernels.functions import evaluate
from parsph.materials import elastic, update
from parsph.materials.elastic import det
from parsph.relations import within_support

SET = "stress_points"

register(
    Field("weight", "scalar", owner="kbm", doc="quadrature weight among particles and stress points [m^3]"),
    Field("gid", "id", points=SET, doc="global id"),
    Field("X", "point", points=SET, doc="reference position [m]"),
    Field("volume", "scalar", points=SET, doc="quadrature weight among particles and stress points [m^3]"),
    Field("body", "id", points=SET, doc="index of the body"),
)


def _shepard(relation, x_rows, x_cols, support, kernel):
    """Per pair of `relation` (row q, column J): W_J(X_q) and grad W_J(X_q); per row: S, grad S."""
    dim = x_rows.shape[1]
    row, j = relation.row_of_pair(), relation.idx
    sep = x_rows[row] - x_cols[j]
    dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
    w, dwdr, _ = evaluate(kernel, dist, support[j], dim)
    scale = np.divide(dwdr, dist, out=np.zeros_like(dist), where=dist > 0)
    grad = scale[:, None] * sep
    n = len(relation.ptr) - 1
    S = np.bincount(row, w, n)
    dS = np.stack([np.bincount(row, grad[:, a], n) for a in range(dim)], axis=1)
    return w, grad, S, dS


def trial_gradients(relation, x_rows, x_cols, support, kernel, gid_rows, active, what):
    """(G per pair, S, grad S per row) of `relation` from integration points to particles;
    raises InputError naming the first `active` point whose A is singular or
    ill-conditioned (the other rows are left with A = I)."""
    dim = x_rows.shape[1]
    n = len(relation.ptr) - 1
    row, j = relation.row_of_pair(), relation.idx
    w, grad, S, dS = _shepard(relation, x_rows, x_cols, support, kernel)
    counts = np.diff(relation.ptr)
    if n and not (S > 0)[active].all():
        first = int(np.flatnonzero(~(S > 0) & active)[0])
        where = ", ".join(f"{c:.6g}" for c in x_rows[first])
        raise InputError(f"{what} {int(gid_rows[first])} at ({where}) lies in no particle's kernel support; "
                         "increase kernel.support")
    S[~active] = 1.0
    gws = (grad - (w / S[row])[:, None] * dS[row]) / S[row][:, None]
    A = np.zeros((n, dim, dim))
    np.add.at(A, row, np.einsum("pa,pb->pab", x_cols[j] - x_rows[row], gws))
    A[~active] = np.eye(dim)
    condition = np.linalg.cond(A) if n else np.zeros(0)
    bad = ~(condition < MAX_CONDITION)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        where = ", ".join(f"{c:.6g}" for c in x_rows[first])
        raise InputError(
            f"correction matrix A of {what} {int(gid_rows[first])} at ({where}) is singular or ill-conditioned "
            f"(condition number {condition[first]:.3g}, {int(counts[first])} particles in reach); "
            f"{int(bad.sum())} point(s) affected. Increase kernel.support")
    Ainv = np.linalg.inv(A) if n else A
    G = np.einsum("pba,pb->pa", Ainv[row], gws)
    return np.ascontiguousarray(G), S, dS


def shepard_gradients(relation, x_rows, x_cols, S, dS, support, kernel):
    """grad W^S_I(X_q) per pair of `relation` from particles I to integration points q."""
    dim = x_rows.shape[1]
    row, q = relation.row_of_pair(), relation.idx
    sep = x_cols[q] - x_rows[row]  # X_q - X_I
    dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
    w, dwdr, _ = evaluate(kernel, dist, support[row], dim)
    scale = np.divide(dwdr, dist, out=np.zeros_like(dist), where=dist > 0)
    grad = scale[:, None] * sep
    return np.ascontiguousarray((grad - (w / S[q])[:, None] * dS[q]) / S[q][:, None])


class StressPointFormulation:
    """One body's KBM formulation: its relations, compiled stages and strain energy."""

    type = "kbm"
    updated = False  # what the loop asks of every formulation: no updated reference,
    eta = 0.0  # no Hessian stabilisation, no hourglass control
    hourglass_form = 0
    weighted_hessian = True
    update_every = update_strain = 0

    def __init__(self, options: dict, dim: int, law: int):
        self.kinematics_stress, self.forces = compile_stages(dim, law)

    @property
    def pair_options(self) -> PairOptions:
        """The nodal pair data every particle has (nearest spacing for the time step, disorder)."""
        return PairOptions(corrected=True, hourglass_form=0, alpha=0.0)

    def stages(self, sim, body) -> list:
        ref = sim.stress_point_data  # built by the loop for every kbm body (build_reference)
        sp = sim.stress_points.arrays
        part = sim.particles.arrays
        lo, hi = body.lo, body.hi
        slo, shi = body.stress_rows

        def kinematics_stress():
            c = body.constants.values
            bad = self.kinematics_stress(lo, hi, ref.p_ptr, ref.p_idx, ref.p_G, ref.p_base, sim.d, part["weight"],
                                         c, sim.no_state, sim.F, sim.VP, sim.J, sim.psi)
            if bad >= 0:
                raise sim.unstable_particle(bad)
            bad = self.kinematics_stress(slo, shi, ref.s_ptr, ref.s_idx, ref.s_G, ref.s_base, sim.d, sp["volume"],
                                         c, sim.no_state, sp["F"], sp["VP"], sp["J"], sp["psi"])
            if bad >= 0:
                raise sim.unstable_stress_point(bad)

        def forces():
            self.forces(lo, hi, ref.f_ptr, ref.f_idx, ref.f_g, sim.VP, ref.fs_ptr, ref.fs_idx, ref.fs_g, sp["VP"],
                        sim.f_int)

        return [Stage("kinematics+stress", kinematics_stress, reads=("d",),
                      writes=("F", "VP", "J", "psi", f"{SET}.VP", f"{SET}.F", f"{SET}.J", f"{SET}.psi")),
                Stage("forces", forces, reads=("VP", f"{SET}.VP"), writes=("f_int",))]

    def strain_energy_terms(self, sim, body) -> np.ndarray:
        """w_q psi_q over the body's owned particles and stress points."""
        sp = sim.stress_points.arrays
        slo, shi = body.stress_rows
        return np.concatenate([sim.particles.arrays["weight"][body.lo:body.hi] * sim.psi[body.lo:body.hi],
                               sp["volume"][slo:shi] * sp["psi"][slo:shi]])


@dataclass
class StressPointData:
    """The relations of the kbm bodies (CSR, local rows) and their per-pair coefficients."""

    p_ptr: np.ndarray  # owned particles -> particles: trial gradients G_J(X_q)
    p_idx: np.ndarray
    p_G: np.ndarray
    p_base: np.ndarray  # the row whose displacement is subtracted (the particle itself)
    s_ptr: np.ndarray  # owned stress points -> particles: G_J(X_q)
    s_idx: np.ndarray
    s_G: np.ndarray
    s_base: np.ndarray  # a stress point's first particle
    f_ptr: np.ndarray  # owned particles -> particles (owned and ghosts): grad W^S_I(X_q)
    f_idx: np.ndarray
    f_g: np.ndarray
    fs_ptr: np.ndarray  # owned particles -> stress points (owned and ghosts): grad W^S_I(X_q)
    fs_idx: np.ndarray
    fs_g: np.ndarray


def build_reference(sim, kernel: str) -> StressPointData:
    """The relations and coefficients of `sim`'s kbm bodies in the reference configuration
    (once: the kernel is Lagrangian). Refreshes the Shepard sums of the ghost rows."""
    parts, sps = sim.particles, sim.stress_points
    P, Sp = parts.arrays, sps.arrays
    n, ns = parts.n_owned, sps.n_owned
    X, support, gid, body = P["X"], P["support"], P["gid"], sim.body
    kbm = np.array([b.formulation.type == "kbm" for b in sim.bodies])
    group = np.where(kbm[body], body, -1)  # the particles of other bodies take no part
    col_group = np.where(kbm[body], body, -2)
    rel_p = within_support("particles", "particles", X[:n], X, gid, support, "cols", group[:n], col_group)
    rel_s = within_support(SET, "particles", Sp["X"][:ns], X, gid, support, "cols", Sp["body"][:ns], col_group)
    p_G, P["shepard"][:n], P["shepard_grad"][:n] = trial_gradients(
        rel_p, X[:n], X, support, kernel, gid, group[:n] >= 0, "particle")
    s_G, Sp["shepard"][:ns], Sp["shepard_grad"][:ns] = trial_gradients(
        rel_s, Sp["X"][:ns], X, support, kernel, Sp["gid"], np.ones(ns, bool), "stress point")
    parts.refresh("shepard", "shepard_grad")
    sps.refresh("shepard", "shepard_grad")
    rows = len(P["shepard"])
    f_p = within_support("particles", "particles", X[:n], X[:rows], gid[:rows], support, "rows", group[:n],
                         col_group[:rows])
    f_s = within_support("particles", SET, X[:n], Sp["X"], Sp["gid"], support, "rows", group[:n], Sp["body"])
    return StressPointData(
        p_ptr=rel_p.ptr, p_idx=rel_p.idx, p_G=p_G, p_base=np.arange(n, dtype=np.int64),
        s_ptr=rel_s.ptr, s_idx=rel_s.idx, s_G=s_G,
        s_base=rel_s.idx[rel_s.ptr[:-1]] if ns else np.zeros(0, np.int64),  # every row has a particle
        f_ptr=f_p.ptr, f_idx=f_p.idx,
        f_g=shepard_gradients(f_p, X[:n], X, P["shepard"], P["shepard_grad"], support, kernel),
        fs_ptr=f_s.ptr, fs_idx=f_s.idx,
        fs_g=shepard_gradients(f_s, X[:n], Sp["X"], Sp["shepard"], Sp["shepard_grad"], support, kernel))


_SOURCE_HASH = source_hash(__file__, elastic.__file__, update.__file__)


def compile_stages(dim: int, law: int):
    """(kinematics_stress, forces) for one body's dimension and material law."""
    source = _SOURCE_HASH

    @njit(cache=True)
    def kinematics_stress(lo, hi, ptr, idx, G, base, d, weight, c, state, F, VP, J, psi):
        """F, stress, w P, J and psi at integration points lo..hi-1 [R eq. 32, 63]; returns
        the first inverted point or -1."""
        source  # noqa: B018 - keys the disk cache to the source text
        return _kinematics(dim, law, lo, hi, ptr, idx, G, base, d, weight, c, state, F, VP, J, psi)

    @njit(cache=True)
    def forces(lo, hi, ptr, idx, g, VP, ptr_s, idx_s, g_s, VP_s, f_int):
        """f_I = -sum_q w_q P_q grad W^S_I(X_q) for particles lo..hi-1 [R eq. 64]."""
        source  # noqa: B018 - keys the disk cache to the source text
        for i in range(lo, hi):
            for a in range(dim):
                f_int[i, a] = 0.0
            _gather(dim, i, ptr, idx, g, VP, f_int)
            _gather(dim, i, ptr_s, idx_s, g_s, VP_s, f_int)

    return kinematics_stress, forces


@njit(cache=True, inline="always")
def _gather(dim, i, ptr, idx, g, VP, f_int):
    for p in range(ptr[i], ptr[i + 1]):
        q = idx[p]
        for a in range(dim):
            s = 0.0
            for b in range(dim):
                s += VP[q, a, b] * g[p, b]
            f_int[i, a] -= s


@njit(cache=True, inline="always")
def _kinematics(dim, law, lo, hi, ptr, idx, G, base, d, weight, c, state, F, VP, J, psi):
    P = np.empty((dim, dim))
    S = np.empty((dim, dim))
    C = np.empty((dim, dim))
    Cinv = np.empty((dim, dim))
    first_bad = -1
    for q in range(lo, hi):
        b0 = base[q]
        for a in range(dim):
            for b in range(dim):
                F[q, a, b] = 1.0 if a == b else 0.0
        for p in range(ptr[q], ptr[q + 1]):
            j = idx[p]
            for a in range(dim):
                dd = d[j, a] - d[b0, a]
                for b in range(dim):
                    F[q, a, b] += dd * G[p, b]
        e = update.update(law, F[q], dim, c, state, q, P, S, C, Cinv)
        J[q] = det(F[q], dim)
        if not (np.isfinite(e) and J[q] > 0.0) and first_bad < 0:
            first_bad = q
        psi[q] = e
        for a in range(dim):
            for b in range(dim):
                VP[q, a, b] = weight[q] * P[a, b]
    return first_bad
