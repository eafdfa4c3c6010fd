"""Corrected kernel gradients in a reference configuration [G eq. 13-15], [V eq. 8].

For each pair (i, j) with X_ij = X_j - X_i and the pair support h_ij = (h_i + h_j)/2:

    w_ij = dW/dr(|X_ij|, h_ij) X_ij / |X_ij|            (kernel gradient, [G eq. 9])
    L_i  = sum_j V_j w_ij (x) X_ij                       (correction matrix, [G eq. 15])
    g_ij = V_j L_i^-1 w_ij                               (corrected gradient times volume)

so that sum_j X_ij (x) g_ij = I exactly [G eq. 16] and grad u(X_i) = sum_j (u_j - u_i) (x) g_ij
is exact for linear fields. A singular or ill-conditioned L_i is reported with the particle's
global id and position instead of being turned into NaNs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.kernels.functions import evaluate
from parsph.materials.elastic import symmetric_extremes
from parsph.neighbors import Pairs

# L_i with a larger condition number is refused: the corrected gradient would amplify
# round-off by that factor.
MAX_CONDITION = 1e6


@dataclass
class ReferencePairs:
    """Per-pair reference data (CSR, aligned with `pairs.idx`)."""

    pairs: Pairs
    dx: np.ndarray  # (npairs, d) X_j - X_i
    w: np.ndarray  # (npairs,) W(|X_ij|, h_ij)
    h: np.ndarray  # (npairs,) pair support h_ij = (h_i + h_j) / 2
    g: np.ndarray  # (npairs, d) V_j L_i^-1 w_ij
    g_rev: np.ndarray  # (npairs, d) g_ji: the same pair seen from j
    g_sum: np.ndarray  # (rows, d) sum_j g_ij
    condition: np.ndarray  # (rows,) condition number of L_i
    rev: np.ndarray  # (npairs,) index of the pair (j, i), -1 if j has no row
    bad: np.ndarray  # rows whose L_i is singular or ill-conditioned (`tolerant`: not raised)


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
def _corrected_gradients(ptr, idx, dx, dwdr, dist, volume, Linv, dim, g, g_sum):
    for i in range(len(ptr) - 1):
        for a in range(dim):
            g_sum[i, a] = 0.0
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            c = volume[j] * dwdr[p] / dist[p]
            for a in range(dim):
                s = 0.0
                for b in range(dim):
                    s += Linv[i, a, b] * dx[p, b]
                g[p, a] = c * s
                g_sum[i, a] += g[p, a]


def reverse_index(pairs: Pairs) -> np.ndarray:
    """For each pair p = (i, j), the index of the pair (j, i) in j's row, or -1 if j has no
    row."""
    rev = np.empty(len(pairs.idx), np.int64)
    _reverse_index(pairs.ptr, pairs.idx, pairs.rows, rev)
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
        out = np.empty_like(values)
        _gather_rows(values, rev, out)
        return out
    out = values[np.maximum(rev, 0)]
    out[rev < 0] = np.nan
    return out


def reference_pairs(
    positions: np.ndarray, volume: np.ndarray, support: np.ndarray, gid: np.ndarray,
    pairs: Pairs, kernel: str, corrected: np.ndarray | None = None, rev: np.ndarray | None = None,
    detached: np.ndarray | None = None, tolerant: bool = False,
) -> ReferencePairs:
    """Kernel values and corrected gradients for every row of `pairs` in `positions`. Rows
    with `corrected` False get the plain SPH gradient g_ij = -V_j w_ij = V_j grad_i W_ij
    (L_i^-1 replaced by -I: [R eq. 21-25]), which needs no invertible L_i; so do the rows
    of `detached` particles (no pairs). `rev`: the pairs' reverse_index, if known.
    `tolerant`: singular or ill-conditioned rows are listed in `bad` (with L_i^-1 = -I)
    instead of raising."""
    dim = positions.shape[1]
    rows = pairs.rows
    row = pairs.row_of_pair()
    dx = positions[pairs.idx] - positions[row]
    dist = np.sqrt(np.einsum("pa,pa->p", dx, dx))
    if len(dist) and not np.isfinite(dist).all():
        p = int(np.flatnonzero(~np.isfinite(dist))[0])
        raise InputError(f"particles {int(gid[row[p]])} and {int(gid[pairs.idx[p]])} have no finite distance "
                         f"(a position is not a number)")
    if len(dist) and not dist.min() > 0.0:
        p = int(np.argmin(dist))
        where = ", ".join(f"{c:.6g}" for c in positions[row[p]])
        raise InputError(f"particles {int(gid[row[p]])} and {int(gid[pairs.idx[p]])} coincide at ({where})")
    h_pair = 0.5 * (support[row] + support[pairs.idx])
    w, dwdr, _ = evaluate(kernel, dist, h_pair, dim)
    L = np.empty((rows, dim, dim))
    _correction_matrices(pairs.ptr, pairs.idx, dx, dwdr, dist, volume, dim, L)
    counts = pairs.counts()
    condition = np.full(rows, np.inf)
    ok = counts > 0
    plain = np.zeros(rows, bool) if corrected is None else ~corrected
    if detached is not None:
        plain |= detached[:rows]
    ok &= ~plain
    condition[plain] = 1.0
    _condition_numbers(L, ok, condition, np.empty((3, 3)))
    bad = ~(condition < MAX_CONDITION)
    if tolerant:
        plain |= bad
    elif bad.any():
        first = int(np.flatnonzero(bad)[0])
        where = ", ".join(f"{c:.6g}" for c in positions[first])
        raise InputError(
            f"correction matrix L of particle {int(gid[first])} at ({where}) is singular or "
            f"ill-conditioned (condition number {condition[first]:.3g}, {int(counts[first])} neighbours); "
            f"{int(bad.sum())} particle(s) affected. Increase kernel.support or kernel.neighbours, "
            "or check for isolated or collinear particles."
        )
    L[plain] = -np.eye(dim)
    Linv = np.linalg.inv(L) if rows else L
    g = np.empty_like(dx)
    g_sum = np.empty((rows, dim))
    _corrected_gradients(pairs.ptr, pairs.idx, dx, dwdr, dist, volume, Linv, dim, g, g_sum)
    rev = reverse_index(pairs) if rev is None else rev
    g_rev = reverse_values(g, rev)
    return ReferencePairs(pairs=pairs, dx=dx, w=w, h=h_pair, g=g, g_rev=g_rev, g_sum=g_sum, condition=condition,
                          rev=rev, bad=np.flatnonzero(bad))
