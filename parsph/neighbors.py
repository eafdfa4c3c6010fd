"""Neighbour pairs in a configuration, as CSR rows sorted by the neighbours' global ids.

Particles i and j are neighbours when |X_j - X_i| < (h_i + h_j) / 2: the pair's kernel
support is the mean of the two particles' supports, so the relation and every pair
quantity are symmetric in i and j. Rows are sorted by global id so that every sum over a
row runs in an order that does not depend on how particles are numbered on a rank.
An Eulerian kernel keeps lists found with a skin beyond the supports (candidates) and picks
the neighbours from them at each step (kernels.correction.KeptPairs) until a particle has
moved half the skin.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.cells import close_pairs
from parsph.relations import Relation


def find_pairs(positions: np.ndarray, support: np.ndarray, gid: np.ndarray, rows: int,
               skin: float = 0.0) -> Relation:
    """Neighbours of particles 0..rows-1 among all given particles: closer than the mean of
    their supports plus `skin` (a length: the lists of an Eulerian kernel are kept while the
    particles move less than half of it; the kernel is zero beyond the support).

    positions (n, d), support h (n,), gid (n,) int64. A particle is not its own neighbour.
    """
    n = len(positions)
    if n == 0 or rows == 0:
        return Relation(np.zeros(rows + 1, np.int64), np.zeros(0, np.int64))
    i, j = close_pairs(positions, float(support.max()) + skin)
    ptr = np.zeros(rows + 1, np.int64)
    _row_counts(i, j, positions, support, skin, rows, ptr)
    np.cumsum(ptr, out=ptr)
    idx = np.empty(ptr[-1], np.int64)
    _fill_rows(i, j, positions, support, gid, skin, ptr, ptr[:-1].copy(), idx)
    return Relation(ptr, idx)


@njit(cache=True, inline="always")
def _close(i, j, positions, support, skin):
    """|x_j - x_i| < (h_i + h_j) / 2 + skin."""
    s = 0.0
    for a in range(positions.shape[1]):
        e = positions[j, a] - positions[i, a]
        s += e * e
    return math.sqrt(s) < 0.5 * (support[i] + support[j]) + skin


@njit(cache=True, _nrt=False)
def _row_counts(i, j, positions, support, skin, rows, counts):
    """counts[1 + r] += 1 for each end r < rows of a close pair (i, j)."""
    for p in range(len(i)):
        if _close(i[p], j[p], positions, support, skin):
            if i[p] < rows:
                counts[1 + i[p]] += 1
            if j[p] < rows:
                counts[1 + j[p]] += 1


@njit(cache=True, _nrt=False)
def _fill_rows(i, j, positions, support, gid, skin, ptr, at, idx):
    """The close pairs into the rows of the CSR (ptr; at: each row's next slot), then each
    row sorted by the neighbours' global ids (insertion sort: rows are short)."""
    rows = len(ptr) - 1
    for p in range(len(i)):
        if _close(i[p], j[p], positions, support, skin):
            if i[p] < rows:
                idx[at[i[p]]] = j[p]
                at[i[p]] += 1
            if j[p] < rows:
                idx[at[j[p]]] = i[p]
                at[j[p]] += 1
    for r in range(rows):
        for p in range(ptr[r] + 1, ptr[r + 1]):
            k = idx[p]
            key = gid[k]
            q = p - 1
            while q >= ptr[r] and gid[idx[q]] > key:
                idx[q + 1] = idx[q]
                q -= 1
            idx[q + 1] = k


def within_bodies(pairs: Relation, body: np.ndarray) -> Relation:
    """`pairs` without the pairs of particles of different bodies (`body`: each local
    particle's body index): bodies interact only through contact, not through kernels."""
    rows = pairs.row_of_pair()
    return _kept(pairs, rows, body[rows] == body[pairs.idx])


def without(pairs: Relation, detached: np.ndarray, gid: np.ndarray, cut: np.ndarray) -> Relation:
    """`pairs` without the pairs of which an end is `detached` (a bool per local particle:
    failed particles that have lost their pairs, materials.damage) and without the pairs
    `cut` (pair_keys of their global ids: crossing)."""
    rows = pairs.row_of_pair()
    keep = ~(detached[rows] | detached[pairs.idx])
    if len(cut):
        keep &= ~np.isin(pair_keys(gid[rows], gid[pairs.idx]), cut)
    return _kept(pairs, rows, keep)


def pair_keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """One int64 per pair of global ids (below 2^31), the same for (a, b) and (b, a)."""
    return (np.minimum(a, b) << 32) | np.maximum(a, b)


def crossing(pairs: Relation, X: np.ndarray, gid: np.ndarray, spacing: np.ndarray, failed: np.ndarray) -> np.ndarray:
    """The pair_keys of the pairs (a, b) of neighbours of a failed particle k (rows `failed`
    of `pairs`, searched in the reference X) whose reference segment passes within half
    k's spacing of X_k: the crack through k cuts them, as it cuts k's own pairs (the
    visibility criterion of meshfree fracture). Sorted, unique."""
    keys = [np.zeros(0, np.int64)]
    for k in failed:
        near = pairs.idx[pairs.ptr[k]:pairs.ptr[k + 1]]
        a, b = np.triu_indices(len(near), 1)
        A, B = X[near[a]], X[near[b]]
        seg = B - A
        t = np.clip(np.einsum("pa,pa->p", X[k] - A, seg) / np.einsum("pa,pa->p", seg, seg), 0.0, 1.0)
        off = A + t[:, None] * seg - X[k]
        hit = np.einsum("pa,pa->p", off, off) < (0.5 * spacing[k]) ** 2
        keys.append(pair_keys(gid[near[a][hit]], gid[near[b][hit]]))
    return np.unique(np.concatenate(keys))


def _kept(pairs: Relation, rows: np.ndarray, keep: np.ndarray) -> Relation:
    ptr = np.zeros(pairs.n_rows + 1, np.int64)
    np.cumsum(np.bincount(rows[keep], minlength=pairs.n_rows), out=ptr[1:])
    return Relation(ptr, pairs.idx[keep])
