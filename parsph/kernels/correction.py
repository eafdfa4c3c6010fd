"""Corrected kernel gradients in a reference configuration [G eq. 13-15], [V eq. 8].

For each pair (i, j) with X_ij = X_j - X_i and the pair support h_ij = (h_i + h_j)/2:

    w_ij = dW/dr(|X_ij|, h_ij) X_ij / |X_ij|            (kernel gradient, [G eq. 9])
    L_i  = sum_j V_j w_ij (x) X_ij                       (correction matrix, [G eq. 15])
    g_ij = V_j L_i^-1 w_ij                               (corrected gradient times volume)

so that sum_j X_ij (x) g_ij = I exactly [G eq. 16] and grad u(X_i) = sum_j (u_j - u_i) (x) g_ij
is exact for linear fields. A singular or ill-conditioned L_i is reported with the particle's
global id and position instead of being turned into NaNs.

What is stored is gw_ij = V_j w_ij per pair and L_i^-1 per row, g_ij = L_i^-1 gw_ij: w is
antisymmetric, so the reverse gradient is g_ji = -(V_i / V_j) L_j^-1 gw_ij, and the pair
loops apply L^-1 per particle rather than per pair (formulations.tlsph).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.kernels.functions import KERNEL_NAMES, curvature, evaluate, value_and_slope
from parsph.materials.elastic import det, inverse, right_cauchy_green, symmetric_extremes
from parsph.neighbors import without
from parsph.relations import BLOCK_PAIRS, Relation, row_blocks

# L_i with a larger condition number is refused: the corrected gradient would amplify
# round-off by that factor.
MAX_CONDITION = 1e6


@dataclass
class ReferencePairs:
    """Per-pair reference data (CSR, aligned with `pairs.idx`); dx, w and h are None where
    reference_pairs handed them to its caller a block at a time."""

    pairs: Relation
    dx: np.ndarray | None  # (npairs, d) X_j - X_i
    w: np.ndarray | None  # (npairs,) W(|X_ij|, h_ij)
    h: np.ndarray | None  # (npairs,) pair support h_ij = (h_i + h_j) / 2
    gw: np.ndarray  # (npairs, d) V_j w_ij: the corrected gradient g_ij = L_i^-1 gw_ij
    gw_sum: np.ndarray  # (rows, d) sum_j gw_ij
    Linv: np.ndarray  # (rows, d, d) L_i^-1 (-I for a plain row)
    condition: np.ndarray  # (rows,) condition number of L_i
    bad: np.ndarray  # rows whose L_i is singular or ill-conditioned (`tolerant`: not raised)
    nearest: np.ndarray  # (rows,) each row's nearest neighbour distance (inf without one)


@njit(cache=True)
def _correction_matrices(ptr, idx, dx, dwdr, dist, volume, dim, L):
    for i in range(len(ptr) - 1):
        for a in range(dim):
            for b in range(dim):
                L[i, a, b] = 0.0
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            c = volume[j] * dwdr[p] / dist[p]
            for a in range(dim):
                for b in range(dim):
                    L[i, a, b] += c * dx[p, a] * dx[p, b]


@njit(cache=True)
def _weighted_gradients(ptr, idx, dx, dwdr, dist, volume, dim, gw, gw_sum):
    """gw_ij = V_j w_ij and the row sums, with the same c_ij = V_j (dW/dr / r) as L_i."""
    for i in range(len(ptr) - 1):
        for a in range(dim):
            gw_sum[i, a] = 0.0
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            c = volume[j] * dwdr[p] / dist[p]
            for a in range(dim):
                gw[p, a] = c * dx[p, a]
                gw_sum[i, a] += gw[p, a]


def reverse_index(pairs: Relation) -> np.ndarray:
    """For each pair p = (i, j), the index of the pair (j, i) in j's row, or -1 if j has no
    row (32-bit)."""
    rev = np.empty(len(pairs.idx), np.int32)
    _reverse_index(pairs.ptr, pairs.idx, pairs.n_rows, rev)
    return rev


@njit(cache=True, _nrt=False)
def _gather_rows(values, rev, out):
    """out[p] = values[rev[p]], NaN where rev[p] < 0."""
    for p in range(len(rev)):
        q = rev[p]
        for a in range(values.shape[1]):
            out[p, a] = values[q, a] if q >= 0 else np.nan


@njit(cache=True, _nrt=False)
def _condition_numbers(L, check, out, M):
    """The 2-norm condition number of each matrix L[i] (dim x dim) with check[i], from the
    extreme eigenvalues of L^T L (materials.elastic.symmetric_extremes; inf for a singular
    one). M: 3x3 scratch."""
    dim = L.shape[1]
    for i in range(len(L)):
        if not check[i]:
            continue
        for a in range(dim):
            for b in range(dim):
                s = 0.0
                for k in range(dim):
                    s += L[i, k, a] * L[i, k, b]
                M[a, b] = s
        small, large = symmetric_extremes(M, dim)
        out[i] = math.sqrt(large / small) if small > 0.0 else np.inf


@njit(cache=True)
def _reverse_index(ptr, idx, rows, rev):
    """rev[p] for every pair of the rows: a scan of the neighbour's row, no temporaries."""
    for i in range(rows):
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            rev[p] = -1
            if j < rows:
                for q in range(ptr[j], ptr[j + 1]):
                    if idx[q] == i:
                        rev[p] = q
                        break


def reverse_values(values: np.ndarray, rev: np.ndarray) -> np.ndarray:
    """values of the reverse pairs (reverse_index), NaN where j has no row."""
    if values.ndim == 2:
        out = np.empty((len(rev), values.shape[1]))
        _gather_rows(values, rev, out)
        return out
    out = values[np.maximum(rev, 0)]
    out[rev < 0] = np.nan
    return out


def reference_pairs(
    positions: np.ndarray, volume: np.ndarray, support: np.ndarray, gid: np.ndarray,
    pairs: Relation, kernel: str, corrected: np.ndarray | None = None,
    detached: np.ndarray | None = None, tolerant: bool = False, each_block=None,
) -> ReferencePairs:
    """Kernel values, weighted kernel gradients gw_ij and inverse correction matrices for every
    row of `pairs` in `positions`. Rows with `corrected` False get the plain SPH gradient
    g_ij = -V_j w_ij = V_j grad_i W_ij (L_i^-1 replaced by -I: [R eq. 21-25]), which needs
    no invertible L_i; so do the rows of `detached` particles (no pairs).
    `tolerant`: singular or ill-conditioned rows are listed in `bad` (with L_i^-1 = -I)
    instead of raising.
    The rows are taken in blocks of about BLOCK_PAIRS pairs, so that the per-pair
    temporaries (separations, distances, pair supports, kernel values and slopes) are held
    for one block at a time (each value is the same as from one pass over all pairs). Given
    `each_block`, it is called as each_block(r0, r1, p0, p1, dx, w, h) with each block's
    rows r0..r1-1, pairs p0..p1-1 and their temporaries, which are then not kept (dx, w and
    h of the result are None); without it they are kept for all pairs, in one block."""
    dim = positions.shape[1]
    rows, ptr, idx = pairs.n_rows, pairs.ptr, pairs.idx
    npairs = len(idx)
    counts = pairs.counts()
    plain = np.zeros(rows, bool) if corrected is None else ~corrected
    if detached is not None:
        plain |= detached[:rows]
    condition = np.full(rows, np.inf)
    condition[plain] = 1.0
    gw = np.empty((npairs, dim))
    gw_sum = np.empty((rows, dim))
    Linv = np.empty((rows, dim, dim))
    nearest = np.full(rows, np.inf)
    kept = None
    for r0, r1 in row_blocks(ptr, BLOCK_PAIRS) if each_block is not None else [(0, rows)]:
        p0, p1 = int(ptr[r0]), int(ptr[r1])
        block_ptr, block_idx = ptr[r0:r1 + 1] - p0, idx[p0:p1]
        row = np.repeat(np.arange(r0, r1, dtype=np.int64), counts[r0:r1])
        dx = positions[block_idx] - positions[row]
        dist = np.sqrt(np.einsum("pa,pa->p", dx, dx))
        if len(dist) and not np.isfinite(dist).all():
            p = int(np.flatnonzero(~np.isfinite(dist))[0])
            raise InputError(f"particles {int(gid[row[p]])} and {int(gid[block_idx[p]])} have no finite distance "
                             f"(a position is not a number)")
        if len(dist) and not dist.min() > 0.0:
            p = int(np.argmin(dist))
            where = ", ".join(f"{c:.6g}" for c in positions[row[p]])
            raise InputError(f"particles {int(gid[row[p]])} and {int(gid[block_idx[p]])} coincide at ({where})")
        h_pair = 0.5 * (support[row] + support[block_idx])
        del row  # the per-pair temporaries go as soon as they are used: they set the peak memory
        w, dwdr = evaluate(kernel, dist, h_pair, dim)[:2]
        L = np.empty((r1 - r0, dim, dim))
        _correction_matrices(block_ptr, block_idx, dx, dwdr, dist, volume, dim, L)
        ok = (counts[r0:r1] > 0) & ~plain[r0:r1]
        _condition_numbers(L, ok, condition[r0:r1], np.empty((3, 3)))
        # a singular row takes the plain gradient here; unless `tolerant` the rows are then refused
        L[plain[r0:r1] | ~(condition[r0:r1] < MAX_CONDITION)] = -np.eye(dim)
        if r1 > r0:
            Linv[r0:r1] = np.linalg.inv(L)
        _weighted_gradients(block_ptr, block_idx, dx, dwdr, dist, volume, dim, gw[p0:p1], gw_sum[r0:r1])
        has = counts[r0:r1] > 0
        if has.any():
            nearest[r0:r1][has] = np.minimum.reduceat(dist, block_ptr[:-1][has])
        del dist, dwdr
        if each_block is None:
            kept = dx, w, h_pair
        else:
            each_block(r0, r1, p0, p1, dx, w, h_pair)
    bad = ~(condition < MAX_CONDITION)
    if bad.any() and not tolerant:
        first = int(np.flatnonzero(bad)[0])
        where = ", ".join(f"{c:.6g}" for c in positions[first])
        raise InputError(
            f"correction matrix L of particle {int(gid[first])} at ({where}) is singular or "
            f"ill-conditioned (condition number {condition[first]:.3g}, {int(counts[first])} neighbours); "
            f"{int(bad.sum())} particle(s) affected. Increase kernel.support or kernel.neighbours, "
            "or check for isolated or collinear particles."
        )
    dx, w, h_pair = kept if kept is not None else (None, None, None)
    return ReferencePairs(pairs=pairs, dx=dx, w=w, h=h_pair, gw=gw, gw_sum=gw_sum, Linv=Linv, condition=condition,
                          bad=np.flatnonzero(bad), nearest=nearest)


class KeptPairs:
    """The per-pair reference data of an updated reference (an Eulerian kernel, rebuilt at
    every step from lists kept between searches, found with a skin; updated-Lagrangian
    SPH, at each update), by compiled passes (`rebuild`) into arrays allocated once per
    search: the pairs of the owned rows closer than the mean of their supports (as
    neighbors.find_pairs would find them now, in the same order), kernel values, the
    weighted gradients gw_ij = V_j (dW/dr / r) X_ij with their row sums and the inverse of
    L_i in closed form (the rows of the ghosts are summed for L only), the nearest
    neighbour distance; and with `hessian` (eta, weighted) the stabilisation of
    formulations.reference (q, gh, their reverses, q's row sums and the stiffening) from
    the corrected Hessians' row sums Hc_ij 1 = V_j (H_ij 1 - w_ij As_i X_ij),
    As_i = (sum_b C_i[:, b, :]) D_i^-1 (kernels.hessian), h_i = (l_i, ..., l_i)."""

    def __init__(self, candidates: Relation, dim: int, kernel: str, hessian: tuple | None = None,
                 detached: np.ndarray | None = None):
        self.candidates = candidates
        self.detached = detached  # rows without pairs (failed: materials.damage), as `without` left them
        self.options = (dim, kernel, hessian)
        size, rows = len(candidates.idx), candidates.n_rows
        self.kind = KERNEL_NAMES.index(kernel)
        self.eta, weighted = hessian if hessian else (0.0, True)
        self.passes = _compile_kept(dim, self.eta > 0, weighted)
        self.ptr = np.zeros(rows + 1, np.int64)
        self.idx = np.empty(size, np.int32)
        self.dx, self.gw = np.empty((size, dim)), np.empty((size, dim))
        self.w, self.h, self.slope = np.empty(size), np.empty(size), np.empty(size)
        self.gw_sum = np.empty((rows, dim))
        self.Linv = np.empty((rows, dim, dim))
        stabilised = size if self.eta > 0 else 0
        self.Hs, self.q, self.q_rev = (np.empty((stabilised, dim)) for _ in range(3))
        self.gh, self.gh_rev = np.empty(stabilised), np.empty(stabilised)
        self.As = np.empty((rows if self.eta > 0 else 0, dim, dim))
        self.q_sum = np.empty((rows if self.eta > 0 else 0, dim))
        self.report = np.zeros(3)
        self.singular = np.zeros(rows, np.bool_)  # rows whose L_i the last rebuild found singular
        self.scratch = (np.empty((dim, dim)), np.empty((3, 3)), np.empty((dim, dim)), np.empty((dim, dim)))

    def without(self, detached: np.ndarray, gid: np.ndarray, cut: np.ndarray) -> KeptPairs:
        """These lists without the pairs of `detached` rows and the pairs `cut`
        (neighbors.without: the filters formulations.reference.build applies to a search),
        in new arrays."""
        dim, kernel, hessian = self.options
        return KeptPairs(without(self.candidates, detached, gid, cut), dim, kernel, hessian,
                         detached[: self.candidates.n_rows].copy())

    def rebuild(self, positions: np.ndarray, volume: np.ndarray, support: np.ndarray, gid: np.ndarray,
                plain: np.ndarray, n_owned: int, min_spacing: np.ndarray, stiffening: np.ndarray,
                tolerant: bool = False) -> tuple:
        """Rebuild at `positions` (rows with `plain` take the plain SPH gradient, as in
        reference_pairs, and so do the `detached` rows); the nearest neighbour distance of
        the owned rows into `min_spacing`, the stabilisation's stiffening into `stiffening`.
        Returns the number of pairs of the owned rows and the owned rows with a singular
        L_i (with `tolerant`, given the plain gradient as reference_pairs gives them);
        raises InputError on a position that is not a number, coinciding particles or a
        singular L_i (unless `tolerant`) or Hessian correction."""
        cand = self.candidates
        kept_rows, kept_gradients = self.passes
        if self.detached is not None:
            plain = plain | self.detached
        code = kept_rows(cand.ptr, cand.idx, positions, volume, support, self.kind, plain, n_owned, self.ptr,
                         self.idx, self.dx, self.w, self.h, self.slope, self.Hs, self.Linv, self.As, min_spacing,
                         *self.scratch, self.report, self.singular)
        bad = np.zeros(0, np.int64)
        if code == _SINGULAR and tolerant:
            bad = np.flatnonzero(self.singular[:n_owned])
            code = kept_rows(cand.ptr, cand.idx, positions, volume, support, self.kind, plain | self.singular,
                             n_owned, self.ptr, self.idx, self.dx, self.w, self.h, self.slope, self.Hs, self.Linv,
                             self.As, min_spacing, *self.scratch, self.report, self.singular)
        if code == _FINE:
            kept_gradients(n_owned, self.ptr, self.idx, self.dx, self.w, self.slope, volume, support, self.Linv,
                           self.Hs, self.As, self.eta, self.gw, self.gw_sum, self.q, self.q_rev,
                           self.q_sum, self.gh, self.gh_rev, stiffening)
            return int(self.ptr[n_owned]), bad
        a, b, value = int(self.report[0]), int(self.report[1]), self.report[2]
        if code == _NOT_A_NUMBER:
            raise InputError(f"particles {int(gid[a])} and {int(gid[b])} have no finite distance "
                             "(a position is not a number)")
        where = ", ".join(f"{c:.6g}" for c in positions[a])
        if code == _COINCIDE:
            raise InputError(f"particles {int(gid[a])} and {int(gid[b])} coincide at ({where})")
        if code == _HESSIAN:
            raise InputError(f"the Hessian correction of particle {int(gid[a])} is singular (its neighbours are "
                             "collinear); increase kernel.support")
        raise InputError(
            f"correction matrix L of particle {int(gid[a])} at ({where}) is singular or ill-conditioned "
            f"(condition number {value:.3g}); {b} particle(s) affected. Increase kernel.support or "
            "kernel.neighbours, or check for isolated or collinear particles.")


_FINE, _NOT_A_NUMBER, _COINCIDE, _SINGULAR, _HESSIAN = 0, 1, 2, 3, 4


@njit(cache=True, inline="always")
def _symmetric(A, dim, a00, a01, a02, a11, a12, a22):
    """A (dim x dim) = the symmetric matrix of the upper entries a_ij."""
    A[0, 0] = a00
    if dim > 1:
        A[0, 1] = A[1, 0] = a01
        A[1, 1] = a11
    if dim > 2:
        A[0, 2] = A[2, 0] = a02
        A[1, 2] = A[2, 1] = a12
        A[2, 2] = a22


@njit(cache=True, inline="always")
def _row_times(M, i, a, e0, e1, e2, dim):
    """sum_b M[i, a, b] e_b over the first dim components of e."""
    t = M[i, a, 0] * e0
    if dim > 1:
        t += M[i, a, 1] * e1
    if dim > 2:
        t += M[i, a, 2] * e2
    return t


@functools.lru_cache(maxsize=None)
def _compile_kept(dim: int, hessian: bool, weighted: bool) -> tuple:
    """(_kept_rows, _kept_gradients) compiled for dimension `dim`, with or without Hessian
    stabilisation (its A term weighted by the kernel or not): constants of the machine
    code, whose branches on them are folded away."""
    @njit(cache=True, _nrt=False)
    def _kept_rows(cptr, cidx, X, volume, support, kind, plain, n_owned, ptr, idx, dx, w, hp, slope, Hs, Linv, As,
                   min_spacing, L, M, D, Dinv, report, singular):
        """KeptPairs.rebuild, first pass, row by row: the kept candidates (stored for the
        owned rows) with their kernel values and L_i, its condition number and inverse
        (and D_i, C_i summed over its middle index, As_i). report: (row, neighbour or count
        of singular rows, condition); `singular`: which rows' L_i is singular. The sums of a
        row run in scalars: stores to arrays that might alias would keep the compiler from
        holding them in registers."""
        k = 0
        first_bad, bad = -1, 0
        for i in range(len(cptr) - 1):
            owned = i < n_owned
            singular[i] = False
            l00 = l01 = l02 = l11 = l12 = l22 = 0.0
            d00 = d01 = d02 = d11 = d12 = d22 = 0.0
            c00 = c01 = c02 = c10 = c11 = c12 = c20 = c21 = c22 = 0.0
            nearest = np.inf
            count = 0
            for p in range(cptr[i], cptr[i + 1]):
                j = cidx[p]
                e0 = X[j, 0] - X[i, 0]
                e1 = X[j, 1] - X[i, 1] if dim > 1 else 0.0
                e2 = X[j, 2] - X[i, 2] if dim > 2 else 0.0
                r = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
                h = 0.5 * (support[i] + support[j])
                if not r < h:
                    if not math.isfinite(r):
                        report[0], report[1] = i, j
                        return _NOT_A_NUMBER
                    continue
                if not r > 0.0:
                    report[0], report[1] = i, j
                    return _COINCIDE
                value, dw = value_and_slope(kind, r, h, dim)
                s = dw / r
                c = volume[j] * s
                l00 += c * e0 * e0
                l01 += c * e0 * e1
                l02 += c * e0 * e2
                l11 += c * e1 * e1
                l12 += c * e1 * e2
                l22 += c * e2 * e2
                count += 1
                if hessian:  # H_ab = b e_a e_b + s delta_ab, summed over b
                    b_coef = (curvature(kind, r, h, dim) - s) / (r * r)
                    total = e0 + e1 + e2
                    h0, h1, h2 = b_coef * e0 * total + s, b_coef * e1 * total + s, b_coef * e2 * total + s
                    v = volume[j]
                    vw = v * (value if weighted else 1.0)
                    d00 += vw * e0 * e0
                    d01 += vw * e0 * e1
                    d02 += vw * e0 * e2
                    d11 += vw * e1 * e1
                    d12 += vw * e1 * e2
                    d22 += vw * e2 * e2
                    c00 += v * h0 * e0
                    c01 += v * h0 * e1
                    c02 += v * h0 * e2
                    c10 += v * h1 * e0
                    c11 += v * h1 * e1
                    c12 += v * h1 * e2
                    c20 += v * h2 * e0
                    c21 += v * h2 * e1
                    c22 += v * h2 * e2
                if owned:
                    idx[k] = j
                    dx[k, 0] = e0
                    if dim > 1:
                        dx[k, 1] = e1
                    if dim > 2:
                        dx[k, 2] = e2
                    w[k] = value
                    hp[k] = h
                    slope[k] = s
                    if hessian:
                        Hs[k, 0] = h0
                        if dim > 1:
                            Hs[k, 1] = h1
                        if dim > 2:
                            Hs[k, 2] = h2
                    nearest = min(nearest, r)
                    k += 1
            if owned:
                ptr[i + 1] = k
                min_spacing[i] = nearest
            if hessian and count:
                _symmetric(D, dim, d00, d01, d02, d11, d12, d22)
                if not abs(det(D, dim)) > 1e-300:
                    report[0] = i
                    return _HESSIAN
                inverse(D, dim, Dinv)
                for a in range(dim):
                    ca0 = c00 if a == 0 else c10 if a == 1 else c20
                    ca1 = c01 if a == 0 else c11 if a == 1 else c21
                    ca2 = c02 if a == 0 else c12 if a == 1 else c22
                    for b in range(dim):
                        t = ca0 * Dinv[0, b]
                        if dim > 1:
                            t += ca1 * Dinv[1, b]
                        if dim > 2:
                            t += ca2 * Dinv[2, b]
                        As[i, a, b] = t
            if plain[i]:
                for a in range(dim):
                    for b in range(dim):
                        Linv[i, a, b] = -1.0 if a == b else 0.0
                continue
            _symmetric(L, dim, l00, l01, l02, l11, l12, l22)
            cond = np.inf
            if count:
                right_cauchy_green(L, dim, M)  # L^T L
                small, large = symmetric_extremes(M, dim)
                if small > 0.0:
                    cond = math.sqrt(large / small)
            if not cond < MAX_CONDITION:
                if first_bad < 0:
                    first_bad, report[2] = i, cond
                bad += 1
                singular[i] = True
                continue
            inverse(L, dim, Linv[i])
        if first_bad >= 0:
            report[0], report[1] = first_bad, bad
            return _SINGULAR
        return _FINE

    @njit(cache=True, _nrt=False)
    def _kept_gradients(n_owned, ptr, idx, dx, w, slope, volume, support, Linv, Hs, As, eta, gw, gw_sum, q,
                        q_rev, q_sum, gh, gh_rev, stiffening):
        """KeptPairs.rebuild, second pass over the owned rows: gw_ij = V_j s_ij X_ij
        (s = dW/dr / r) and its row sums; with Hessian stabilisation, from the corrected
        gradients g_ij = L_i^-1 gw_ij and g_ji = V_i s_ij L_j^-1 X_ji (row j's numbers),
        q_ij = eta l_i Hc_ij 1 and gh_ij = eta l_i g_ij . 1 with their reverses, q's row sums
        and the stiffening 1 + (sum |q| + sum |gh| sum |g|) / sum |g| (formulations.reference)."""
        for i in range(n_owned):
            s0 = s1 = s2 = 0.0
            q0 = q1 = q2 = 0.0
            size_g = size_q = size_gh = 0.0
            li = 0.5 * support[i]
            for p in range(ptr[i], ptr[i + 1]):
                j = idx[p]
                e0 = dx[p, 0]
                e1 = dx[p, 1] if dim > 1 else 0.0
                e2 = dx[p, 2] if dim > 2 else 0.0
                c, b = volume[j] * slope[p], volume[i] * slope[p]
                gw[p, 0] = c * e0
                s0 += gw[p, 0]
                if dim > 1:
                    gw[p, 1] = c * e1
                    s1 += gw[p, 1]
                if dim > 2:
                    gw[p, 2] = c * e2
                    s2 += gw[p, 2]
                if hessian:
                    lj = 0.5 * support[j]
                    wt = w[p] if weighted else 1.0
                    sum_g = sum_rev = norm_g = norm_q = 0.0
                    for a in range(dim):
                        g = c * _row_times(Linv, i, a, e0, e1, e2, dim)
                        sum_g += g
                        sum_rev += b * -_row_times(Linv, j, a, e0, e1, e2, dim)
                        norm_g += g * g
                        q[p, a] = eta * li * volume[j] * (Hs[p, a] - wt * _row_times(As, i, a, e0, e1, e2, dim))
                        q_rev[p, a] = eta * lj * volume[i] * (Hs[p, a] + wt * _row_times(As, j, a, e0, e1, e2, dim))
                        norm_q += q[p, a] * q[p, a]
                    gh[p] = eta * li * sum_g
                    gh_rev[p] = eta * lj * sum_rev
                    q0 += q[p, 0]
                    if dim > 1:
                        q1 += q[p, 1]
                    if dim > 2:
                        q2 += q[p, 2]
                    size_g += math.sqrt(norm_g)
                    size_q += math.sqrt(norm_q)
                    size_gh += abs(gh[p])
            gw_sum[i, 0] = s0
            if dim > 1:
                gw_sum[i, 1] = s1
            if dim > 2:
                gw_sum[i, 2] = s2
            if hessian:
                q_sum[i, 0] = q0
                if dim > 1:
                    q_sum[i, 1] = q1
                if dim > 2:
                    q_sum[i, 2] = q2
                stiffening[i] = 1.0 + (size_q + size_gh * size_g) / size_g if size_g > 0.0 else 1.0

    return _kept_rows, _kept_gradients
