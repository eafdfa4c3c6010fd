"""Relations: neighbour graphs from the points of one set to the points of another (or the
same) set, as CSR rows with the columns sorted by global id, so that every sum over a row
runs in the same order on any number of ranks.

A relation is built by its formulation in a configuration (the reference positions for a
Lagrangian kernel) whenever the loop rebuilds the topology: at set-up and at each update of
the reference. Which points are related is decided by the support of the column point
(`radius="cols"`: the kernel of point J evaluated at the row point, |X_q - X_J| < h_J) or
of the row point (`radius="rows"`). An Eulerian kernel searches with a skin and keeps the
lists (KeptRelation) until a point has moved half the skin, picking the related points
from them at each step; a Skin holds that rule for every relation kept so (the Eulerian
kernel's, contact's).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from numba import njit

from parsph.cells import close_pairs

BLOCK_PAIRS = 1 << 18  # about the pairs whose temporaries a set-up pass holds at once (row_blocks)


@dataclass
class Relation:
    """CSR rows: points 0..n_rows-1 of set `rows`, each related to the points `idx` (local
    rows of set `cols`) in global-id order: particle neighbours (neighbors.find_pairs),
    Galerkin trial and test relations (find_relation)."""

    ptr: np.ndarray  # int64 (n_rows + 1,)
    idx: np.ndarray  # int64 (pairs,)
    rows: str = "particles"
    cols: str = "particles"

    @property
    def n_rows(self) -> int:
        return len(self.ptr) - 1

    def counts(self) -> np.ndarray:
        return np.diff(self.ptr)

    def row_of_pair(self) -> np.ndarray:
        return np.repeat(np.arange(self.n_rows, dtype=np.int64), self.counts())


def row_blocks(ptr: np.ndarray, pairs: int) -> list:
    """(r0, r1) blocks of the CSR rows `ptr`, in order, of about `pairs` pairs each (a row is
    never split): what a pass whose per-pair temporaries set the peak memory takes at a time."""
    rows = len(ptr) - 1
    cuts = np.unique(np.searchsorted(ptr, np.arange(pairs, int(ptr[-1]), pairs), side="right") - 1)
    cuts = [0] + [int(c) for c in cuts if 0 < c < rows] + [rows]
    return list(zip(cuts[:-1], cuts[1:]))


def find_relation(rows: str, cols: str, x_rows: np.ndarray, x_cols: np.ndarray, gid_cols: np.ndarray,
                  support: np.ndarray, radius: str, group_rows: np.ndarray, group_cols: np.ndarray,
                  skin: float = 0.0) -> Relation:
    """The relation from the points at `x_rows` to the points at `x_cols` within the kernel
    support (`support` of the columns or of the rows, as `radius` says) plus `skin`, between
    points of the same group (body); rows ordered by the columns' global ids. A point and
    itself (the same position) are related."""
    n = len(x_rows)
    reach = (float(support.max()) if len(support) else 0.0) + skin
    if n == 0 or len(x_cols) == 0:
        return Relation(np.zeros(n + 1, np.int64), np.zeros(0, np.int64), rows, cols)
    # one cloud of both sets; only pairs across them (a row point first)
    side = np.concatenate([np.zeros(n, np.int64), np.ones(len(x_cols), np.int64)])
    a, b = close_pairs(np.concatenate([x_rows, x_cols]), reach, side, np.array([[False, True], [True, False]]))
    i, j = np.where(a < n, a, b), np.where(a < n, b, a) - n
    sep = x_cols[j] - x_rows[i]
    dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
    h = support[j] if radius == "cols" else support[i]
    keep = (dist < h + skin) & (group_rows[i] == group_cols[j])
    i, j = i[keep], j[keep]
    order = np.lexsort((gid_cols[j], i))
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(i, minlength=n), out=ptr[1:])
    return Relation(ptr, j[order], rows, cols)


class Skin:
    """The rebuild rule of lists searched in the current configuration with a skin of
    `length` beyond their reach: searched again after `every` steps (updates) at most, or
    sooner once a point has moved half the skin since the last search, on any rank."""

    def __init__(self, length: float, comm, every: float = math.inf):
        self.length, self.every, self.comm = length, every, comm
        self.at = None  # the points' positions at the last search (None: a search is due)
        self.since = 0  # steps since it
        self.searches = 0

    def due(self, x: np.ndarray, rows: np.ndarray | None = None) -> bool:
        """Whether the lists must be searched again, the points (rows of) x having moved
        (collective)."""
        if self.at is None or self.since >= self.every:
            return True
        rows = np.arange(len(x)) if rows is None else rows
        moved = math.sqrt(_largest_move(x, rows, self.at)) if len(rows) else 0.0
        return self.comm.allreduce(moved, op=MPI.MAX) > 0.5 * self.length

    def searched(self, x: np.ndarray, rows: np.ndarray | None = None) -> None:
        """The lists were searched with the points at (rows of) x."""
        self.at = (x if rows is None else x[rows]).copy()
        self.since = 0
        self.searches += 1

    def stepped(self) -> None:
        self.since += 1

    def forget(self) -> None:
        """The lists no longer hold (their points changed): search at the next check."""
        self.at = None


@njit(cache=True, _nrt=False)
def _largest_move(x, rows, before):
    """max_k |x[rows[k]] - before[k]|^2."""
    largest = 0.0
    for k in range(len(rows)):
        d2 = 0.0
        for a in range(x.shape[1]):
            e = x[rows[k], a] - before[k, a]
            d2 += e * e
        largest = max(largest, d2)
    return largest


class KeptRelation:
    """A relation searched with a skin (find_relation) and kept: `current` picks the pairs
    within the support at given positions, in the same order, as find_relation without the
    skin would find them, while no point has moved half the skin since the search."""

    def __init__(self, candidates: Relation, radius: str):
        self.candidates = candidates
        self.by_cols = radius == "cols"
        self.ptr = np.zeros(len(candidates.ptr), np.int64)
        self.idx = np.empty(len(candidates.idx), np.int64)

    def current(self, x_rows: np.ndarray, x_cols: np.ndarray, support: np.ndarray) -> Relation:
        c = self.candidates
        _compile_within(x_rows.shape[1])(c.ptr, c.idx, x_rows, x_cols, support, self.by_cols, self.ptr, self.idx)
        return Relation(self.ptr, self.idx[: self.ptr[-1]], c.rows, c.cols)


@functools.lru_cache(maxsize=None)
def _compile_within(dim: int):
    """The filter of KeptRelation.current, compiled for dimension `dim`."""
    @njit(cache=True, _nrt=False)
    def _within_support(cptr, cidx, x_rows, x_cols, support, by_cols, ptr, idx):
        k = 0
        for i in range(len(cptr) - 1):
            for p in range(cptr[i], cptr[i + 1]):
                j = cidx[p]
                r2 = 0.0
                for a in range(dim):
                    e = x_cols[j, a] - x_rows[i, a]
                    r2 += e * e
                if math.sqrt(r2) < (support[j] if by_cols else support[i]):
                    idx[k] = j
                    k += 1
            ptr[i + 1] = k

    return _within_support
