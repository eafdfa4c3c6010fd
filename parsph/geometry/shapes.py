"""Curved particle bodies (cylinder, ring, disk) whose volumes sum to the exact body
volume, and a union of bodies that drops coincident particles."""

import math

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from .lattice import _nonnegative, _positive, _ravel_first_fastest, _vector


def cylinder(base_center, radius, length, spacing, axis=2):
    """3D cylinder from a cell-centred cubic lattice; returns (positions, volumes).

    In each cross-section the lattice points sit at base_center + (i, j)·spacing, so the
    cylinder axis passes through a lattice column, and those with distance < radius from
    the axis are kept. Axial layers sit at base + (k + 0.5)·length/n_layers with
    n_layers = max(1, round(length/spacing)). All volumes are equal and sum to π r² L.
    """
    c = _vector(base_center, "base_center", "cylinder", dim=3)
    r = _positive(radius, "radius", "cylinder")
    length = _positive(length, "length", "cylinder")
    h = _positive(spacing, "spacing", "cylinder")
    if isinstance(axis, bool) or not isinstance(axis, (int, np.integer)) or axis not in (0, 1, 2):
        raise ValueError(f"cylinder: axis must be 0, 1 or 2, got {axis!r}")
    m = math.ceil(r / h)
    offsets = np.arange(-m, m + 1) * h
    u, v = _ravel_first_fastest([offsets, offsets])
    inside = np.hypot(u, v) < r * (1.0 - 1e-12)
    u, v = u[inside], v[inside]
    n_layers = max(1, round(length / h))
    w = (np.arange(n_layers) + 0.5) * (length / n_layers)
    plane = [k for k in range(3) if k != axis]
    positions = np.empty((u.size * n_layers, 3))
    positions[:, plane[0]] = np.tile(u, n_layers)
    positions[:, plane[1]] = np.tile(v, n_layers)
    positions[:, axis] = np.repeat(w, u.size)
    positions += c
    volumes = np.full(positions.shape[0], math.pi * r * r * length / positions.shape[0])
    return positions, volumes


def _concentric(center, r_in, r_out, h):
    """Particles on concentric circles covering the annulus r_in <= r <= r_out."""
    n_r = max(1, round((r_out - r_in) / h))
    dr = (r_out - r_in) / n_r
    pos, vol = [], []
    for k in range(n_r):
        rk = r_in + (k + 0.5) * dr
        n_t = max(3, round(2.0 * math.pi * rk / h))
        dt = 2.0 * math.pi / n_t
        theta = np.arange(n_t) * dt
        pos.append(center + rk * np.column_stack((np.cos(theta), np.sin(theta))))
        vol.append(np.full(n_t, rk * dr * dt))
    return np.concatenate(pos), np.concatenate(vol)


def ring(center, inner_radius, outer_radius, spacing):
    """2D annulus on concentric circles; returns (positions, volumes).

    round((r_out - r_in)/spacing) layers (at least 1) at radii r_in + (k + 0.5)·Δr, each
    with round(2π r_k/spacing) (at least 3) particles evenly spaced in angle and volume
    r_k Δr Δθ, so the volumes sum to π (r_out² - r_in²).
    """
    c = _vector(center, "center", "ring", dim=2)
    r_in = _nonnegative(inner_radius, "inner_radius", "ring")
    r_out = _positive(outer_radius, "outer_radius", "ring")
    if r_in >= r_out:
        raise ValueError(f"ring: inner_radius={r_in!r} must be < outer_radius={r_out!r}")
    return _concentric(c, r_in, r_out, _positive(spacing, "spacing", "ring"))


def disk(center, radius, spacing):
    """2D disk: the concentric construction of :func:`ring` with inner radius 0."""
    c = _vector(center, "center", "disk", dim=2)
    r = _positive(radius, "radius", "disk")
    return _concentric(c, 0.0, r, _positive(spacing, "spacing", "disk"))


def union(*parts, tol):
    """Concatenate (positions, volumes) parts, dropping (with its volume) every particle
    closer than ``tol`` to an earlier kept particle; returns (positions, volumes)."""
    if not parts:
        raise ValueError("union: parts must contain at least one (positions, volumes) pair")
    tol = _nonnegative(tol, "tol", "union")
    pos_list, vol_list = [], []
    for i, part in enumerate(parts):
        try:
            p, v = part
        except (TypeError, ValueError):
            raise ValueError(f"union: parts[{i}] must be a (positions, volumes) pair") from None
        p = np.asarray(p, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        if p.ndim != 2 or v.shape != (p.shape[0],):
            raise ValueError(f"union: parts[{i}] must be positions (n, D) and volumes (n,), "
                             f"got shapes {p.shape} and {v.shape}")
        if pos_list and p.shape[1] != pos_list[0].shape[1]:
            raise ValueError(f"union: parts[{i}] has dimension {p.shape[1]}, "
                             f"expected {pos_list[0].shape[1]} like parts[0]")
        pos_list.append(p)
        vol_list.append(v)
    positions = np.concatenate(pos_list)
    volumes = np.concatenate(vol_list)
    n = positions.shape[0]
    keep = np.ones(n, dtype=bool)
    if tol > 0.0 and n > 1:
        pairs = cKDTree(positions).query_pairs(tol, output_type="ndarray")
        dist = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
        pairs = pairs[dist < tol]
        lo, hi = pairs.min(axis=1), pairs.max(axis=1)
        later = csr_matrix((np.ones(lo.size, dtype=bool), (lo, hi)), shape=(n, n))
        for i in np.unique(lo):
            if keep[i]:
                keep[later.indices[later.indptr[i]:later.indptr[i + 1]]] = False
    return positions[keep], volumes[keep]
