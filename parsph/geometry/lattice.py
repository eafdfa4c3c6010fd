"""Square/cubic particle lattices filling an axis-aligned box, with cell-centred or
node placement; node placement lumps boundary volumes as in Rabczuk et al. (2004) §6."""

import math

import numpy as np

MAX_PARTICLES = 2**31  # the most particles one part may have


def _check_count(func, estimate, what):
    """Refuse a part of `estimate` particles (a number, possibly inf) above MAX_PARTICLES."""
    if not estimate <= MAX_PARTICLES:
        about = f" (about {estimate:.3g})" if math.isfinite(estimate) else ""
        raise ValueError(f"{func}: {what} give more than 2^31 particles{about}; "
                         f"use a larger spacing or a smaller body")


def _vector(value, name, func, dim=None):
    """Return ``value`` as a finite float64 vector of length 1-3 (or exactly ``dim``)."""
    try:
        vec = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{func}: {name} must be a sequence of numbers, got {value!r}") from None
    if vec.ndim != 1:
        raise ValueError(f"{func}: {name} must be a 1D sequence of coordinates, got shape {vec.shape}")
    if dim is None and not 1 <= vec.size <= 3:
        raise ValueError(f"{func}: {name} must have 1, 2 or 3 components, got {vec.size}")
    if dim is not None and vec.size != dim:
        raise ValueError(f"{func}: {name} must have {dim} components (dimension {dim}), got {vec.size}")
    if not np.all(np.isfinite(vec)):
        raise ValueError(f"{func}: {name} must be finite, got {value!r}")
    return vec


def _positive(value, name, func):
    """Return ``value`` as a float, requiring it to be finite and > 0."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{func}: {name} must be a number, got {value!r}") from None
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f"{func}: {name} must be a positive finite number, got {value!r}")
    return x


def _nonnegative(value, name, func):
    """Return ``value`` as a float, requiring it to be finite and >= 0."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{func}: {name} must be a number, got {value!r}") from None
    if not (math.isfinite(x) and x >= 0.0):
        raise ValueError(f"{func}: {name} must be a finite number >= 0, got {value!r}")
    return x


def _bounds(lower, upper, func):
    """Validate a box given by its corners; return (lower, upper) float64 vectors."""
    lo = _vector(lower, "lower", func)
    hi = _vector(upper, "upper", func)
    if lo.size != hi.size:
        raise ValueError(f"{func}: lower and upper must have the same length, got {lo.size} and {hi.size}")
    bad = np.flatnonzero(lo >= hi)
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"{func}: lower must be < upper on every axis, axis {k} has "
                         f"lower={lo[k]!r} >= upper={hi[k]!r}")
    return lo, hi


def _ravel_first_fastest(arrays):
    """Tensor-product of 1D arrays flattened with the first axis varying fastest."""
    grids = np.meshgrid(*arrays, indexing="ij")
    return [g.ravel(order="F") for g in grids]


class Box:
    """Lattice filling the box [lower, upper], generated in blocks of rows.

    The number of cells per axis is round(length/spacing); the resulting spacing must
    match ``spacing`` to 1e-6 relative. ``placement="cell"`` puts one particle at each
    cell centre; ``placement="node"`` puts particles on the count+1 nodes per axis and
    halves the volume once per axis on which a node lies on the boundary, so the total
    is the box volume. Particles are ordered with the x index varying fastest; `rows(start,
    stop)` returns (positions, volumes) of particles start..stop-1 of that order.
    """

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, lower, upper, spacing, placement="cell"):
        lo, hi = _bounds(lower, upper, "box")
        h0 = _positive(spacing, "spacing", "box")
        if placement not in ("cell", "node"):
            raise ValueError(f"box: placement must be 'cell' or 'node', got {placement!r}")
        lengths = [float(b) - float(a) for a, b in zip(lo, hi)]
        what = f"lengths {', '.join(f'{x:g}' for x in lengths)} at spacing {h0:g}"
        self.lower, self.upper = [float(a) for a in lo], [float(b) for b in hi]
        counts = []
        for k, length in enumerate(lengths):
            _check_count("box", length / h0, what)
            count = round(length / h0)
            if count < 1:
                raise ValueError(f"box: the box length {length:g} on axis {k} is shorter than "
                                 f"half the spacing {h0:g}: no particle fits")
            if abs(length / count - h0) > 1e-6 * h0:
                raise ValueError(f"box: the box length {length:g} on axis {k} is not a multiple of "
                                 f"spacing={h0:g} (to 1e-6 relative)")
            counts.append(count)
        _check_count("box", math.prod(c + (placement == "node") for c in counts), what)
        self.coords, self.weights = [], []
        for k, (length, count) in enumerate(zip(lengths, counts)):
            h = length / count
            if placement == "cell":
                self.coords.append(lo[k] + (np.arange(count) + 0.5) * h)
                self.weights.append(np.full(count, h))
            else:
                x = lo[k] + np.arange(count + 1) * h
                x[-1] = hi[k]
                w = np.full(count + 1, h)
                w[[0, -1]] = 0.5 * h
                self.coords.append(x)
                self.weights.append(w)
        self.shape = tuple(len(c) for c in self.coords)
        self.count = math.prod(self.shape)

    def rows(self, start: int, stop: int):
        return tensor_rows(self.coords, self.weights, start, stop)


def tensor_rows(coords: list, weights: list, start: int, stop: int):
    """Rows start..stop-1 (first axis fastest) of the tensor product of per-axis points
    `coords` with per-axis weights `weights`: (positions, products of the weights)."""
    index = np.unravel_index(np.arange(start, stop), tuple(len(c) for c in coords), order="F")
    positions = np.column_stack([c[i] for c, i in zip(coords, index)])
    volumes = np.prod(np.column_stack([w[i] for w, i in zip(weights, index)]), axis=1)
    return positions, volumes


def box(lower, upper, spacing, placement="cell"):
    """All particles of :class:`Box`; returns (positions (n, D), volumes (n,))."""
    lattice = Box(lower, upper, spacing, placement)
    return lattice.rows(0, lattice.count)
