"""Neighbour pairs in a configuration, as CSR rows sorted by the neighbours' global ids.

Particles i and j are neighbours when |X_j - X_i| < (h_i + h_j) / 2: the pair's kernel
support is the mean of the two particles' supports, so the relation and every pair
quantity are symmetric in i and j. Rows are sorted by global id so that every sum over a
row runs in an order that does not depend on how particles are numbered on a rank.
An Eulerian kernel keeps lists found with a skin beyond the supports (candidates) and picks
the neighbours from them at each step (within_support) until a particle has moved half the
skin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import cKDTree


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
    tree = cKDTree(positions)
    pairs = tree.query_pairs(r=float(support.max()) + skin, output_type="ndarray").astype(np.int64)
    i, j = pairs[:, 0], pairs[:, 1]
    sep = positions[j] - positions[i]
    dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
    keep = dist < 0.5 * (support[i] + support[j]) + skin
    i, j = i[keep], j[keep]
    i, j = np.concatenate([i, j]), np.concatenate([j, i])
    mine = i < rows
    i, j = i[mine], j[mine]
    order = np.lexsort((gid[j], i))
    i, j = i[order], j[order]
    ptr = np.zeros(rows + 1, np.int64)
    np.cumsum(np.bincount(i, minlength=rows), out=ptr[1:])
    return Pairs(ptr, j)


def within_support(candidates: Pairs, positions: np.ndarray, support: np.ndarray) -> tuple:
    """(the pairs of `candidates` (lists found with a skin) closer than the mean of their
    supports at `positions`, which candidates they are): what find_pairs would find now, in
    the same order, as long as no particle has moved half the skin since the candidates
    were found."""
    keep = np.empty(len(candidates.idx), np.bool_)
    ptr = np.empty(candidates.rows + 1, np.int64)
    _within(candidates.ptr, candidates.idx, positions, support, keep, ptr)
    return Pairs(ptr, candidates.idx[keep]), keep


@njit(cache=True)
def _within(ptr, idx, positions, support, keep, out_ptr):
    dim = positions.shape[1]
    out_ptr[0] = 0
    for i in range(len(ptr) - 1):
        count = 0
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            s = 0.0
            for a in range(dim):
                d = positions[j, a] - positions[i, a]
                s += d * d
            keep[p] = math.sqrt(s) < 0.5 * (support[i] + support[j])
            count += keep[p]
        out_ptr[i + 1] = out_ptr[i] + count


def within_bodies(pairs: Pairs, body: np.ndarray) -> Pairs:
    """`pairs` without the pairs of particles of different bodies (`body`: each local
    particle's body index): bodies interact only through contact, not through kernels."""
    rows = pairs.row_of_pair()
    keep = body[rows] == body[pairs.idx]
    ptr = np.zeros(pairs.rows + 1, np.int64)
    np.cumsum(np.bincount(rows[keep], minlength=pairs.rows), out=ptr[1:])
    return Pairs(ptr, pairs.idx[keep])
