"""Packing of a filled solid's boundary layer: the lattice's particles near the boundary
relaxed by a short-range repulsion and kept inside, at half a spacing from the surface, so
the boundary is smooth at the spacing instead of a staircase. The count and the volumes do
not change; the particles deeper than BAND spacings stay on the lattice.

The boundary is the solid's (shapely's in 2D; in 3D libigl's distance to the solid's mesh),
the side the solid's inside test. The computation takes the particles of the layer in
global-id order and is the same on every rank.
"""

from __future__ import annotations

import numpy as np
import shapely

BAND = 3.0  # particles within BAND spacings of the boundary move
NEIGHBOURS = 4.0  # those within NEIGHBOURS spacings take part (the deeper ones fixed)
STEP = 0.2  # repulsion step, in spacings per unit push
LIMIT = 5_000_000  # the most particles of a boundary layer (held whole by every rank)


def boundary(solid):
    """The function P -> (signed distance, negative inside; closest boundary points) of a
    solid."""
    if solid.dim == 2:
        edge = solid.geom.boundary
        shapely.prepare(edge)

        def distance(P):
            C = shapely.get_coordinates(shapely.shortest_line(edge, shapely.points(P))).reshape(-1, 2, 2)[:, 0]
            d = np.linalg.norm(P - C, axis=1)
            return np.where(solid.inside(P), -d, d), C
        return distance
    import igl
    mesh = solid.mesh()
    V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    tree = igl.AABB()
    tree.init(V, F)

    def distance(P):
        P = np.ascontiguousarray(P, dtype=np.float64)
        squared, _, C = tree.squared_distance(V, F, P)
        d = np.sqrt(squared)
        return np.where(solid.inside(P), -d, d), C
    return distance


def relax(X: np.ndarray, mobile: np.ndarray, h: float, distance, iterations: int) -> np.ndarray:
    """The positions X after `iterations` steps: each mobile particle pushed by its
    neighbours closer than h (weight 1 - r/h, at most h/4 a step), then any closer than h/2
    to the boundary or outside put h/2 inside it, on the line to its closest point."""
    from scipy.spatial import cKDTree  # here: scipy.spatial takes a tenth of a second to import
    X = X.copy()
    moving = np.flatnonzero(mobile)
    for _ in range(iterations):
        pairs = cKDTree(X).query_pairs(h, output_type="ndarray")
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        d = X[pairs[:, 0]] - X[pairs[:, 1]]
        r = np.linalg.norm(d, axis=1)
        f = ((1.0 - r / h) / np.maximum(r, 1e-12 * h))[:, None] * d
        push = np.zeros_like(X)
        np.add.at(push, pairs[:, 0], f)
        np.add.at(push, pairs[:, 1], -f)
        step = STEP * h * push[moving]
        size = np.linalg.norm(step, axis=1)
        step *= np.minimum(1.0, 0.25 * h / np.maximum(size, 1e-300))[:, None]
        X[moving] += step
        s, C = distance(X[moving])
        out = np.flatnonzero((s > -0.5 * h) & (np.abs(s) > 1e-9 * h))
        inward = (C[out] - X[moving[out]]) / s[out][:, None]
        X[moving[out]] = C[out] + 0.5 * h * inward
    return X
