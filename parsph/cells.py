"""Spatial search: every pair of points within a distance, by a compiled search over cells
(scipy's k-d tree for clouds too wide for a cell table)."""

from __future__ import annotations

import numpy as np
from numba import njit


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
