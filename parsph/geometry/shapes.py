"""Curved particle bodies (cylinder, ring, disk) whose volumes sum to the exact body
volume, and a union of bodies that drops coincident particles."""

import math

import numpy as np

from parsph.cells import kdtree

from .lattice import _check_count, _nonnegative, _positive, _ravel_first_fastest, _vector


class Cylinder:
    """3D cylinder from a cell-centred cubic lattice, generated in blocks of rows.

    In each cross-section the lattice points sit at base_center + (i, j)·spacing, so the
    cylinder axis passes through a lattice column, and those with distance < radius from
    the axis are kept. Axial layers sit at base + (k + 0.5)·length/n_layers with
    n_layers = max(1, round(length/spacing)), ordered layer by layer. All volumes are
    equal and sum to π r² L.
    """

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, base_center, radius, length, spacing, axis=2):
        self.center = _vector(base_center, "base_center", "cylinder", dim=3)
        r = _positive(radius, "radius", "cylinder")
        length = _positive(length, "length", "cylinder")
        h = _positive(spacing, "spacing", "cylinder")
        if isinstance(axis, bool) or not isinstance(axis, (int, np.integer)) or axis not in (0, 1, 2):
            raise ValueError(f"cylinder: axis must be 0, 1 or 2, got {axis!r}")
        what = f"radius {r:g} and length {length:g} at spacing {h:g}"
        _check_count("cylinder", max(r, length) / h, what)
        _check_count("cylinder", max(1.0, math.pi * (r / h) ** 2) * max(1.0, length / h), what)
        m = math.ceil(r / h)
        offsets = np.arange(-m, m + 1) * h
        u, v = _ravel_first_fastest([offsets, offsets])
        inside = np.hypot(u, v) < r * (1.0 - 1e-12)
        self.u, self.v = u[inside], v[inside]
        n_layers = max(1, round(length / h))
        self.w = (np.arange(n_layers) + 0.5) * (length / n_layers)
        self.axis = axis
        self.count = self.u.size * n_layers
        self.volume = math.pi * r * r * length / self.count

    def rows(self, start: int, stop: int):
        layer, j = np.divmod(np.arange(start, stop), self.u.size)
        plane = [k for k in range(3) if k != self.axis]
        positions = np.empty((stop - start, 3))
        positions[:, plane[0]] = self.u[j]
        positions[:, plane[1]] = self.v[j]
        positions[:, self.axis] = self.w[layer]
        positions += self.center
        return positions, np.full(stop - start, self.volume)


class Concentric:
    """2D particles on concentric circles covering the annulus r_in <= r <= r_out, in
    blocks of rows: round((r_out - r_in)/spacing) layers (at least 1) at radii r_in +
    (k + 0.5)·Δr, each with round(2π r_k/spacing) (at least 3) particles evenly spaced in
    angle and volume r_k Δr Δθ, so the volumes sum to π (r_out² - r_in²). `func` names the
    shape in error messages."""

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, center, r_in, r_out, h, func):
        self.center = center
        what = f"radii {r_in:g} to {r_out:g} at spacing {h:g}"
        _check_count(func, r_out / h, what)
        _check_count(func, max(3.0 * (r_out - r_in) / h, math.pi * ((r_out / h) ** 2 - (r_in / h) ** 2)),
                     what)
        n_r = max(1, round((r_out - r_in) / h))
        dr = (r_out - r_in) / n_r
        self.radius = r_in + (np.arange(n_r) + 0.5) * dr
        per_layer = np.maximum(3, np.round(2.0 * math.pi * self.radius / h)).astype(np.int64)
        self.dtheta = 2.0 * math.pi / per_layer
        self.volume = self.radius * dr * self.dtheta
        self.first = np.concatenate([[0], np.cumsum(per_layer)])
        self.count = int(self.first[-1])

    def rows(self, start: int, stop: int):
        index = np.arange(start, stop)
        layer = np.searchsorted(self.first, index, side="right") - 1
        theta = (index - self.first[layer]) * self.dtheta[layer]
        rk = self.radius[layer][:, None]
        positions = self.center + rk * np.column_stack((np.cos(theta), np.sin(theta)))
        return positions, self.volume[layer].copy()


class Ring(Concentric):
    """2D annulus on concentric circles."""

    def __init__(self, center, inner_radius, outer_radius, spacing):
        c = _vector(center, "center", "ring", dim=2)
        r_in = _nonnegative(inner_radius, "inner_radius", "ring")
        r_out = _positive(outer_radius, "outer_radius", "ring")
        if r_in >= r_out:
            raise ValueError(f"ring: inner_radius={r_in!r} must be < outer_radius={r_out!r}")
        super().__init__(c, r_in, r_out, _positive(spacing, "spacing", "ring"), "ring")


class Disk(Concentric):
    """2D disk: the concentric construction with inner radius 0."""

    def __init__(self, center, radius, spacing):
        c = _vector(center, "center", "disk", dim=2)
        r = _positive(radius, "radius", "disk")
        super().__init__(c, 0.0, r, _positive(spacing, "spacing", "disk"), "disk")


def _all(generator):
    return generator.rows(0, generator.count)


def cylinder(base_center, radius, length, spacing, axis=2):
    """All particles of :class:`Cylinder`; returns (positions, volumes)."""
    return _all(Cylinder(base_center, radius, length, spacing, axis))


def ring(center, inner_radius, outer_radius, spacing):
    """All particles of :class:`Ring`; returns (positions, volumes)."""
    return _all(Ring(center, inner_radius, outer_radius, spacing))


def disk(center, radius, spacing):
    """All particles of :class:`Disk`; returns (positions, volumes)."""
    return _all(Disk(center, radius, spacing))


def close_pairs(positions, others, reach):
    """Index arrays (i, j) and distances of the pairs of a point i of `positions` and a point
    j of `others` closer than `reach`."""
    if reach > 0.0 and len(positions) and len(others):
        near = kdtree(positions).sparse_distance_matrix(kdtree(others), reach, output_type="ndarray")
        near = near[near["v"] < reach]
        return near["i"], near["j"], near["v"]
    return np.zeros(0, np.intp), np.zeros(0, np.intp), np.zeros(0)


def shadowed(positions, index, others, other_index, tol):
    """Mask of the points of `positions` (global indices `index`) closer than `tol` to a
    point of `others` with a smaller index: the particles a union of parts drops."""
    dropped = np.zeros(len(positions), dtype=bool)
    i, j, _ = close_pairs(positions, others, tol)
    dropped[i[other_index[j] < index[i]]] = True
    return dropped


def union(*parts, tol):
    """Concatenate (positions, volumes) parts, dropping (with its volume) every particle
    closer than ``tol`` to an earlier particle; returns (positions, volumes)."""
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
    index = np.arange(len(positions))
    keep = ~shadowed(positions, index, positions, index, tol)
    return positions[keep], volumes[keep]


class PolarRing:
    """2D annulus as a polar lattice, for the stress points of KBM on a ring [R §9.5-9.6]:
    `radial` rows of particles at radii evenly spaced from r_in to r_out (on both surfaces),
    each of `angular` particles evenly spaced in angle; a particle's volume is its annular
    sector, radii halfway to the next rows (clipped at the surfaces) and angles halfway to
    its neighbours, so the volumes sum to π (r_out² - r_in²). Row after row, counter-clockwise
    from the +x axis."""

    blockwise = True

    def __init__(self, center, inner_radius, outer_radius, radial, angular):
        self.center = _vector(center, "center", "polar_ring", dim=2)
        r_in = _positive(inner_radius, "inner_radius", "polar_ring")
        r_out = _positive(outer_radius, "outer_radius", "polar_ring")
        if r_in >= r_out:
            raise ValueError(f"polar_ring: inner_radius={r_in!r} must be < outer_radius={r_out!r}")
        if int(radial) < 2 or int(angular) < 3:
            raise ValueError(f"polar_ring: needs radial >= 2 and angular >= 3, got {radial}, {angular}")
        _check_count("polar_ring", float(radial) * float(angular), f"{radial} x {angular} particles")
        self.shape = (int(radial), int(angular))
        self.radius = np.linspace(r_in, r_out, self.shape[0])
        self.dtheta = 2.0 * math.pi / self.shape[1]
        edges = np.concatenate([[r_in], 0.5 * (self.radius[1:] + self.radius[:-1]), [r_out]])
        self.volume = 0.5 * (edges[1:] ** 2 - edges[:-1] ** 2) * self.dtheta
        self.count = self.shape[0] * self.shape[1]
        self.spacing = max(self.radius[1] - self.radius[0], r_out * self.dtheta)  # the coarser direction

    def rows(self, start: int, stop: int):
        row, column = np.divmod(np.arange(start, stop), self.shape[1])
        theta = column * self.dtheta
        positions = self.center + self.radius[row][:, None] * np.column_stack((np.cos(theta), np.sin(theta)))
        return positions, self.volume[row].copy()
