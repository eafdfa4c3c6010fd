"""Relations: neighbour graphs from the points of one set to the points of another (or the
same) set, as CSR rows with the columns sorted by global id, so that every sum over a row
runs in the same order on any number of ranks.

A relation is built by its formulation in a configuration (the reference positions for a
Lagrangian kernel) whenever the loop rebuilds the topology: at set-up and at each update of
the reference. Which points are related is decided by the support of the column point
(`radius="cols"`: the kernel of point J evaluated at the row point, |X_q - X_J| < h_J) or
of the row point (`radius="rows"`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsph.neighbors import kdtree


@dataclass
class Relation:
    """Rows: points 0..len(ptr)-2 of set `rows`; `idx`: local rows of set `cols`."""

    rows: str
    cols: str
    ptr: np.ndarray  # int64 (rows + 1,)
    idx: np.ndarray  # int64 (pairs,)

    def row_of_pair(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.ptr) - 1, dtype=np.int64), np.diff(self.ptr))


def find_relation(rows: str, cols: str, x_rows: np.ndarray, x_cols: np.ndarray, gid_cols: np.ndarray,
                   support: np.ndarray, radius: str, group_rows: np.ndarray, group_cols: np.ndarray) -> Relation:
    """The relation from the points at `x_rows` to the points at `x_cols` within the kernel
    support (`support` of the columns or of the rows, as `radius` says), between points of
    the same group (body); rows ordered by the columns' global ids. A point and itself (the
    same position) are related."""
    n = len(x_rows)
    reach = float(support.max()) if len(support) else 0.0
    if n == 0 or len(x_cols) == 0:
        return Relation(rows, cols, np.zeros(n + 1, np.int64), np.zeros(0, np.int64))
    near = kdtree(x_rows).sparse_distance_matrix(kdtree(x_cols), reach, output_type="ndarray")
    i, j = near["i"].astype(np.int64), near["j"].astype(np.int64)
    sep = x_cols[j] - x_rows[i]
    dist = np.sqrt(np.einsum("pa,pa->p", sep, sep))
    h = support[j] if radius == "cols" else support[i]
    keep = (dist < h) & (group_rows[i] == group_cols[j])
    i, j = i[keep], j[keep]
    order = np.lexsort((gid_cols[j], i))
    ptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(i, minlength=n), out=ptr[1:])
    return Relation(rows, cols, ptr, j[order])
