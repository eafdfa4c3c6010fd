"""Stress points of a box lattice or a polar ring [R §5.2] and the quadrature weights of
particles and stress points together.

[R] intersperses stress points between the particles without saying where;
the counts it prints fit one stress point at the centre of each cell of the particle
lattice, which is the rule used here: a box of n_1 x ... x n_d particles has
(n_1 - 1) x ... x (n_d - 1) stress points. The quadrature weights are the volumes of the
Voronoi cells of particles and stress points together, clipped to the box [R eq. 65]: in
the interior Δ^d / 2 each on a square lattice. A point's cell depends only on the points
within about one spacing, so the weights are those of the matching point in a box of at
most 7 particles per axis (the first and last three along each axis as they are, every
other point as the middle one); the weights of any block of rows are computed without the
rest of the lattice.
"""

from __future__ import annotations

import math

import numpy as np

from .lattice import Box
from .shapes import PolarRing
from .voronoi import _cells

MARGIN = 3  # lattice rows at each end of an axis whose cells differ from the interior's


def _small_index(i: np.ndarray, n: int, m: int) -> np.ndarray:
    """Index in a row of m points standing for index i in a row of n (m = n if n <= 2 MARGIN + 1)."""
    if n == m:
        return i
    return np.where(i < MARGIN, i, np.where(i >= n - MARGIN, i - (n - m), MARGIN))


def _volumes(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Volumes of the Voronoi cells of `points` clipped to the box [lo, hi]."""
    if points.shape[1] > 1:
        return _cells(points, lo, hi)[1]
    x = points[:, 0]
    order = np.argsort(x)
    edges = np.concatenate([[lo[0]], 0.5 * (x[order][1:] + x[order][:-1]), [hi[0]]])
    out = np.empty(len(x))
    out[order] = np.diff(edges)
    return out


class BoxStressPoints:
    """The stress points of a box lattice (parsph.geometry.lattice.Box), with `count` and
    `rows(start, stop)` -> (positions, quadrature weights) like a part generator, and the
    particles' quadrature weights `particle_weights(index)` (index: lattice rows)."""

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, box: Box, scale: float = 1.0):
        """`scale`: factor from the lattice's d-dimensional measure to volume (the
        thickness in 2D, the cross-section in 1D)."""
        self.box = box
        self.scale = scale
        self.shape = tuple(n - 1 for n in box.shape)
        self.count = math.prod(self.shape) if min(self.shape) > 0 else 0
        self.small = tuple(min(n, 2 * MARGIN + 1) for n in box.shape)
        # a lattice of the first `small` points per axis, with the same distances to the faces
        small_coords = [c[:m] for c, m in zip(box.coords, self.small)]
        lo = np.array(box.lower, float)
        hi = np.array([c[m - 1] + (u - c[-1]) for c, m, u in zip(box.coords, self.small, box.upper)])
        particles = np.column_stack([x.ravel(order="F") for x in np.meshgrid(*small_coords, indexing="ij")])
        centres = [0.5 * (c[1:] + c[:-1]) for c in small_coords]
        stress = np.column_stack([x.ravel(order="F") for x in np.meshgrid(*centres, indexing="ij")])
        volumes = _volumes(np.concatenate([particles, stress]), lo, hi) if self.count else \
            np.zeros(len(particles) + len(stress))
        self._particle_volume = volumes[: len(particles)].reshape(self.small, order="F")
        self._stress_volume = volumes[len(particles):].reshape(tuple(m - 1 for m in self.small), order="F")
        self._centres = [0.5 * (c[1:] + c[:-1]) for c in box.coords]

    def rows(self, start: int, stop: int):
        index = np.unravel_index(np.arange(start, stop), self.shape, order="F")
        positions = np.column_stack([c[i] for c, i in zip(self._centres, index)])
        small = tuple(_small_index(i, n, m - 1) for i, n, m in zip(index, self.shape, self.small))
        return positions, self.scale * self._stress_volume[small]

    def particle_weights(self, index: np.ndarray) -> np.ndarray:
        rows = np.unravel_index(index, self.box.shape, order="F")
        small = tuple(_small_index(i, n, m) for i, n, m in zip(rows, self.box.shape, self.small))
        return self.scale * self._particle_volume[small]


class PolarStressPoints:
    """The stress points of a polar lattice (parsph.geometry.shapes.PolarRing): one at the
    centre of every polar cell, (radial - 1) x angular, row after row. Weights split each
    cell as Voronoi cells split a square one: half to its stress point, an eighth to each
    corner particle; they sum to the annulus' area. Same interface as BoxStressPoints."""

    blockwise = True

    def __init__(self, ring, scale: float = 1.0):
        self.ring, self.scale = ring, scale
        radial, angular = ring.shape
        self.shape = (radial - 1, angular)
        self.count = self.shape[0] * self.shape[1]
        r = ring.radius
        self._cell = 0.5 * (r[1:] ** 2 - r[:-1] ** 2) * ring.dtheta  # area of the cells of each row
        self._middle = 0.5 * (r[1:] + r[:-1])

    def rows(self, start: int, stop: int):
        row, column = np.divmod(np.arange(start, stop), self.shape[1])
        theta = (column + 0.5) * self.ring.dtheta
        positions = self.ring.center + self._middle[row][:, None] * np.column_stack((np.cos(theta), np.sin(theta)))
        return positions, self.scale * 0.5 * self._cell[row]

    def particle_weights(self, index: np.ndarray) -> np.ndarray:
        row = np.asarray(index) // self.ring.shape[1]
        cells = np.concatenate([[0.0], self._cell, [0.0]])  # the cells below and above each row
        return self.scale * 0.25 * (cells[row] + cells[row + 1])


def stress_points_of(lattice, scale: float = 1.0):
    """The stress points of a part's lattice: a box (cell placement) or a polar ring."""
    return PolarStressPoints(lattice, scale) if isinstance(lattice, PolarRing) else BoxStressPoints(lattice, scale)
