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
from dataclasses import dataclass

import numpy as np
from numba import njit


@dataclass
class Pairs:
    """CSR neighbour lists for rows 0..len(ptr)-2; `idx` are local particle indices."""

    ptr: np.ndarray  # int64 (rows + 1,)
    idx: np.ndarray  # int64 (pairs,)

    @property
    def rows(self) -> int:
        return len(self.ptr) - 1

    def counts(self) -> np.ndarray:
        return np.diff(self.ptr)

    def row_of_pair(self) -> np.ndarray:
        return np.repeat(np.arange(self.rows, dtype=np.int64), self.counts())


def find_pairs(positions: np.ndarray, support: np.ndarray, gid: np.ndarray, rows: int,
               skin: float = 0.0) -> Pairs:
    """Neighbours of particles 0..rows-1 among all given particles: closer than the mean of
    their supports plus `skin` (a length: the lists of an Eulerian kernel are kept while the
    particles move less than half of it; the kernel is zero beyond the support).

    positions (n, d), support h (n,), gid (n,) int64. A particle is not its own neighbour.
    """
    n = len(positions)
    if n == 0 or rows == 0:
        return Pairs(np.zeros(rows + 1, np.int64), np.zeros(0, np.int64))
    i, j = close_pairs(positions, float(support.max()) + skin)
    ptr = np.zeros(rows + 1, np.int64)
    _row_counts(i, j, positions, support, skin, rows, ptr)
    np.cumsum(ptr, out=ptr)
    idx = np.empty(ptr[-1], np.int64)
    _fill_rows(i, j, positions, support, gid, skin, ptr, ptr[:-1].copy(), idx)
    return Pairs(ptr, idx)


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


def kdtree(points: np.ndarray):
    """scipy's k-d tree of `points`, imported on first use: the neighbour search of a run on
    one rank needs none, and scipy.spatial takes a tenth of a second to import."""
    from scipy.spatial import cKDTree

    return cKDTree(points)


def close_pairs(x: np.ndarray, r: float, group: np.ndarray | None = None, allowed: np.ndarray | None = None) -> tuple:
    """(i, j), i < j: every pair of points of x (n, d) at most r apart, and perhaps a few
    more within a relative 1e-9 of r (callers test the distance themselves); with `group`
    (an index per point) only the pairs `allowed[group_i, group_j]` marks (the contact
    between bodies: the points of one body are not paired with each other unless
    allowed). A compiled search over cells of size r; a cloud too wide for 2^20 cells per
    dimension goes to a k-d tree."""
    finite = r > 0 and bool(np.isfinite(x).all())
    lower = x.min(axis=0) if finite else None
    cells = np.floor((x.max(axis=0) - lower) / r).astype(np.int64) + 1 if finite else None
    if not finite or cells.max() > 1 << 20:
        pairs = kdtree(x).query_pairs(r=r, output_type="ndarray").astype(np.int64)
        if group is not None:
            pairs = pairs[allowed[group[pairs[:, 0]], group[pairs[:, 1]]]]
        return pairs[:, 0], pairs[:, 1]
    if group is None:
        group, allowed = np.zeros(0, np.int64), np.ones((1, 1), np.bool_)
    key = np.zeros(len(x), np.int64)
    for a in range(x.shape[1]):  # row-major cell number
        key = key * cells[a] + np.minimum(np.floor((x[:, a] - lower[a]) / r).astype(np.int64), cells[a] - 1)
    order = np.argsort(key, kind="stable")
    sorted_keys = key[order]
    total = int(np.prod(cells))
    # each cell's first point in `order`: a table over all cells if they are not too many
    first = np.searchsorted(sorted_keys, np.arange(total + 1)) if total <= 8 * len(x) + 1024 else np.zeros(0, np.int64)
    r2 = r * r * (1.0 + 1e-9)
    counts = np.zeros(len(x), np.int64)
    empty = np.zeros(0, np.int64)
    _cell_pairs(x, r2, cells, order, sorted_keys, first, group, allowed, counts, empty, empty)
    start = np.zeros(len(x) + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    i, j = np.empty(start[-1], np.int64), np.empty(start[-1], np.int64)
    _cell_pairs(x, r2, cells, order, sorted_keys, first, group, allowed, start, i, j)
    return i, j


@njit(cache=True)
def _cell_pairs(x, r2, cells, order, sorted_keys, first, group, allowed, where, i_out, j_out):
    """Cell by cell (the points of a cell are order[s:e]), the pairs of its points with
    each other and with the points of the cells ahead of it in a half stencil (the
    neighbour cells whose offset's first non-zero component is +1: each pair of adjacent
    cells once) with |x_q - x_p|^2 <= r2 (and, if `group` is not empty, allowed[group[p],
    group[q]]), as (min, max): counted into where[s] (i_out empty), or written from
    where[s]. `first`: each cell's first position in `order` (all cells, and one past), or
    empty (then found by bisection of sorted_keys)."""
    n, dim = x.shape
    fill = len(i_out) > 0
    stride = np.ones(dim, np.int64)
    for a in range(dim - 2, -1, -1):
        stride[a] = stride[a + 1] * cells[a + 1]
    ahead = np.zeros(((3 ** dim - 1) // 2, dim), np.int64)
    count = 0
    for shift in range(3 ** dim):
        t, lead = shift, 0
        for a in range(dim):
            ahead[count, a] = t % 3 - 1
            t //= 3
            if lead == 0:
                lead = ahead[count, a]
        if lead > 0:
            count += 1
    cell = np.empty(dim, np.int64)
    s = 0
    while s < n:
        code = sorted_keys[s]
        e = s + 1
        while e < n and sorted_keys[e] == code:
            e += 1
        rest = code
        for a in range(dim - 1, -1, -1):
            cell[a] = rest % cells[a]
            rest //= cells[a]
        k = where[s] if fill else 0
        for o in range(-1, len(ahead)):  # the cell itself, then the cells ahead
            if o < 0:
                m, end = s, e
            else:
                other, inside = code, True
                for a in range(dim):
                    c = cell[a] + ahead[o, a]
                    if c < 0 or c >= cells[a]:
                        inside = False
                        break
                    other += ahead[o, a] * stride[a]
                if not inside:
                    continue
                if len(first):
                    m, end = first[other], first[other + 1]
                else:
                    m = np.searchsorted(sorted_keys, other)
                    end = np.searchsorted(sorted_keys, other + 1)
            for u in range(s, e):
                p = order[u]
                for v in range(u + 1 if o < 0 else m, end):
                    q = order[v]
                    if len(group) and not allowed[group[p], group[q]]:
                        continue
                    d2 = 0.0
                    for a in range(dim):
                        t = x[q, a] - x[p, a]
                        d2 += t * t
                    if d2 <= r2:
                        if fill:
                            i_out[k], j_out[k] = min(p, q), max(p, q)
                        k += 1
        if not fill:
            where[s] = k
        s = e


def within_bodies(pairs: Pairs, body: np.ndarray) -> Pairs:
    """`pairs` without the pairs of particles of different bodies (`body`: each local
    particle's body index): bodies interact only through contact, not through kernels."""
    rows = pairs.row_of_pair()
    return _kept(pairs, rows, body[rows] == body[pairs.idx])


def without(pairs: Pairs, detached: np.ndarray, gid: np.ndarray, cut: np.ndarray) -> Pairs:
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


def crossing(pairs: Pairs, X: np.ndarray, gid: np.ndarray, spacing: np.ndarray, failed: np.ndarray) -> np.ndarray:
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


def _kept(pairs: Pairs, rows: np.ndarray, keep: np.ndarray) -> Pairs:
    ptr = np.zeros(pairs.rows + 1, np.int64)
    np.cumsum(np.bincount(rows[keep], minlength=pairs.rows), out=ptr[1:])
    return Pairs(ptr, pairs.idx[keep])
