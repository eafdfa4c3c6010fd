"""Irregular but well-spaced particle sets from Lloyd-relaxed Voronoi tessellations of a
box, standing in for the 444-particle random patch of Ganzenmüller (2015) §4.1."""

import itertools
import math
import operator

import numpy as np

from .lattice import MAX_PARTICLES, _bounds


def _cells(points, lo, hi):
    """Centroids and volumes of the Voronoi cells of ``points`` clipped to [lo, hi].

    Mirroring the points across every face of the box makes each face a Voronoi
    boundary, so the cells of the original points are exactly the clipped cells. Each
    cell is split into simplices joining its generator to its (fan-triangulated) ridges;
    scipy lists the vertices of a 3D ridge in cyclic order.
    """
    n, dim = points.shape
    mirrored = [points]
    for k in range(dim):
        for face in (lo[k], hi[k]):
            m = points.copy()
            m[:, k] = 2.0 * face - m[:, k]
            mirrored.append(m)
    from scipy.spatial import Voronoi  # here: scipy.spatial takes 0.1 s to import

    vor = Voronoi(np.concatenate(mirrored))
    owners = vor.ridge_points
    used = np.flatnonzero((owners < n).any(axis=1))
    ridges = [vor.ridge_vertices[r] for r in used]
    sizes = np.fromiter(map(len, ridges), dtype=np.intp, count=len(ridges))
    flat = np.fromiter(itertools.chain.from_iterable(ridges), dtype=np.intp, count=sizes.sum())
    starts = np.cumsum(sizes) - sizes
    if dim == 2:
        faces = flat.reshape(-1, 2)
        face_ridge = used
    else:
        fans = sizes - 2
        first = np.repeat(starts, fans)
        k = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans) + 1
        faces = flat[np.column_stack((first, first + k, first + k + 1))]
        face_ridge = np.repeat(used, fans)
    centroid_sum = np.zeros((n, dim))
    volumes = np.zeros(n)
    for side in (0, 1):
        gen = owners[face_ridge, side]
        own = gen < n
        g = points[gen[own]]
        verts = vor.vertices[faces[own]]                     # (f, dim, dim)
        vol = np.abs(np.linalg.det(verts - g[:, None, :])) / math.factorial(dim)
        volumes += np.bincount(gen[own], weights=vol, minlength=n)
        moment = vol[:, None] * (g + verts.sum(axis=1)) / (dim + 1)
        for k in range(dim):
            centroid_sum[:, k] += np.bincount(gen[own], weights=moment[:, k], minlength=n)
    return centroid_sum / volumes[:, None], volumes


def random_box(lower, upper, count, seed=0, lloyd_iterations=20):
    """Random particles in the 2D or 3D box [lower, upper]; returns (positions, volumes).

    ``count`` points drawn with numpy.random.default_rng(seed) are moved to the centroids
    of their clipped Voronoi cells ``lloyd_iterations`` times (Lloyd relaxation). The
    particles are the centroids of the final cells and their volumes the cell volumes,
    which sum to the box volume.
    """
    lo, hi = _bounds(lower, upper, "random_box")
    if lo.size not in (2, 3):
        raise ValueError(f"random_box: lower/upper must be 2D or 3D, got dimension {lo.size}")
    try:
        count = operator.index(count)
        lloyd_iterations = operator.index(lloyd_iterations)
    except TypeError:
        raise ValueError(f"random_box: count and lloyd_iterations must be integers, "
                         f"got {count!r} and {lloyd_iterations!r}") from None
    if count < 1:
        raise ValueError(f"random_box: count must be >= 1, got {count}")
    if lloyd_iterations < 0:
        raise ValueError(f"random_box: lloyd_iterations must be >= 0, got {lloyd_iterations}")
    points = lo + (hi - lo) * np.random.default_rng(seed).random((count, lo.size))
    for _ in range(lloyd_iterations):
        points, _ = _cells(points, lo, hi)
    positions, volumes = _cells(points, lo, hi)
    total = float(np.prod(hi - lo))
    if abs(volumes.sum() - total) > 1e-12 * total:
        raise RuntimeError(f"random_box: cell volumes sum to {volumes.sum()!r}, "
                           f"not the box volume {total!r}")
    return positions, volumes


def random_patch(lower, upper, count, seed=0, lloyd_iterations=20):
    """2D random patch (Ganzenmüller 2015 §4.1): :func:`random_box` restricted to 2D."""
    if np.size(lower) != 2 or np.size(upper) != 2:
        raise ValueError(f"random_patch: lower and upper must have 2 components, "
                         f"got {lower!r} and {upper!r}")
    return random_box(lower, upper, count, seed, lloyd_iterations)


class RandomPatch:
    """:func:`random_patch` as a part generator. The Lloyd relaxation needs all points at
    once, so the set exists only whole (`blockwise` is False): one rank builds it and hands
    out the blocks."""

    blockwise = False

    def __init__(self, lower, upper, count, seed=0, lloyd_iterations=20):
        try:
            self.count = operator.index(count)
        except TypeError:
            raise ValueError(f"random_box: count must be an integer, got {count!r}") from None
        if self.count > MAX_PARTICLES:
            raise ValueError(f"random_patch: count = {self.count} is more than 2^31 particles")
        self.args = (lower, upper, count, seed, lloyd_iterations)
        self._whole = None

    def rows(self, start: int, stop: int):
        if self._whole is None:
            self._whole = random_patch(*self.args)
        positions, volumes = self._whole
        return positions[start:stop], volumes[start:stop]
