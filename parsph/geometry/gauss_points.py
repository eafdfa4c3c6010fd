"""Gauss points of background cells over a box lattice, for EFG with cell integration
[R §5.3, eq. 66-69].

[R] uses quadtree cells with n_Q x n_Q Gauss points, n_Q = sqrt(m) + 2 for m particles in
a cell, and leaves cell size and rounding open. Here the cells tile the box
(particles set back half a spacing from the faces, so the box is the union of the
particles' cells) two lattice cells wide along each axis, the last one one cell wide when
a count is odd; a cell with k_a particles along axis a gets k_a + 2 Gauss-Legendre points
along it, which is sqrt(m) + 2 for [R]'s square cells (4 x 4 points for 2 x 2 particles).
Weights are the Gauss weights times the cell's half-widths (det J), times the thickness in
2D (cross-section in 1D).
"""

from __future__ import annotations

import math

import numpy as np

from .lattice import Box, tensor_rows


class BoxGaussPoints:
    """Gauss points of the background cells of a box lattice, as a part generator:
    `count`, `rows(start, stop)` -> (positions, weights)."""

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, box: Box, scale: float = 1.0):
        self.scale = scale
        axes = []  # per axis: (coordinates, weights) of its Gauss points, in order
        for lo, hi, n in zip(box.lower, box.upper, box.shape):
            width = (hi - lo) / n
            x, w = [], []
            for first in range(0, n, 2):
                k = min(2, n - first)
                a, b = lo + first * width, lo + (first + k) * width
                xi, wi = np.polynomial.legendre.leggauss(k + 2)
                x.append(0.5 * (a + b) + 0.5 * (b - a) * xi)
                w.append(0.5 * (b - a) * wi)
            axes.append((np.concatenate(x), np.concatenate(w)))
        self.coords = [a[0] for a in axes]
        self.weights = [a[1] for a in axes]
        self.shape = tuple(len(c) for c in self.coords)
        self.count = math.prod(self.shape)

    def rows(self, start: int, stop: int):
        positions, weights = tensor_rows(self.coords, self.weights, start, stop)
        return positions, self.scale * weights
