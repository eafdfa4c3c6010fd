"""Per-particle kernel support radii: from a target neighbour count (Ganzenmüller 2015
§4.1, ~12 neighbours) or from the particle volume."""

import operator

import numpy as np

from parsph.cells import kdtree

from .lattice import _positive


def _positions(positions, func):
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 2 or not 1 <= pos.shape[1] <= 3:
        raise ValueError(f"{func}: positions must have shape (n, D) with D in 1..3, got {pos.shape}")
    if not np.all(np.isfinite(pos)):
        raise ValueError(f"{func}: positions must be finite")
    return pos


def support_for_neighbours(positions, target, others=None, reach=np.inf):
    """Support radius h_i = (d_target + d_{target+1})/2, d_k being the distance from
    particle i to its k-th nearest other particle, so that ``target`` other particles
    lie within h_i (unless distances tie). ``others`` are further points that count as
    neighbours (another rank's particles); a particle with fewer than target + 1 others
    within ``reach`` gets an infinite radius."""
    pos = _positions(positions, "support_for_neighbours")
    try:
        target = operator.index(target)
    except TypeError:
        raise ValueError(f"support_for_neighbours: target must be an integer, got {target!r}") from None
    if target < 1:
        raise ValueError(f"support_for_neighbours: target must be >= 1, got {target}")
    if others is None and pos.shape[0] < target + 2:
        raise ValueError(f"support_for_neighbours: target={target} needs at least {target + 2} "
                         f"positions, got {pos.shape[0]}")
    points = pos if others is None else np.concatenate([pos, others])
    dist, _ = kdtree(points).query(pos, k=target + 2, distance_upper_bound=reach)
    return 0.5 * (dist[:, target] + dist[:, target + 1])


def support_from_spacing(volumes, factor, dim):
    """Support radius h_i = factor · volumes_i^(1/dim)."""
    vol = np.asarray(volumes, dtype=np.float64)
    if vol.ndim != 1 or not np.all(np.isfinite(vol) & (vol > 0.0)):
        raise ValueError("support_from_spacing: volumes must be a 1D array of positive finite numbers")
    factor = _positive(factor, "factor", "support_from_spacing")
    if dim not in (1, 2, 3) or isinstance(dim, bool):
        raise ValueError(f"support_from_spacing: dim must be 1, 2 or 3, got {dim!r}")
    return factor * vol ** (1.0 / dim)
