"""Particle group selection (boundary-condition and output sets) from the dict specs of a
TOML scene file."""

from collections.abc import Mapping

import numpy as np

from .lattice import _nonnegative, _vector

SELECTORS = ("all", "box", "sphere", "halfspace", "nearest", "extreme")


def _fields(value, name, required, optional=()):
    """Check that the sub-table ``name`` has exactly the required (and optional) keys."""
    if not isinstance(value, Mapping):
        raise ValueError(f"select: {name} must be a table with keys {list(required)}, got {value!r}")
    missing = [k for k in required if k not in value]
    unknown = [k for k in value if k not in required and k not in optional]
    if missing or unknown:
        raise ValueError(f"select: {name} needs keys {list(required)}"
                         + (f" (optional {list(optional)})" if optional else "")
                         + f", got {sorted(value)}")


def _reduce(value, how, comm):
    """`how` of `value` over all ranks (the value itself without a communicator)."""
    return value if comm is None else how(comm.allgather(value))


def _kth(values, k, comm):
    """The k-th smallest (from 0) of all ranks' values, by bisection on the value."""
    lo = _reduce(float(values.min()) if len(values) else np.inf, min, comm)
    hi = _reduce(float(values.max()) if len(values) else -np.inf, max, comm)

    def count(v):
        return _reduce(int(np.count_nonzero(values <= v)), sum, comm)

    if count(lo) > k:
        return lo
    while True:  # count(<= lo) <= k < count(<= hi): the answer lies in (lo, hi]
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            return hi
        if count(mid) > k:
            hi = mid
        else:
            lo = mid


def _median(values, n, comm):
    """np.median of all ranks' values (n of them)."""
    if comm is None:
        return float(np.median(values))
    if n % 2:
        return _kth(values, n // 2, comm)
    return (_kth(values, n // 2 - 1, comm) + _kth(values, n // 2, comm)) / 2


def select(spec, positions, volumes=None, ids=None, comm=None):
    """Boolean mask (n,) of the particles matched by ``spec``.

    ``spec`` holds exactly one selector key, plus an optional ``"invert": bool``:
    ``{"all": true}``, ``{"box": {"lower", "upper"}}`` (closed), ``{"sphere": {"center",
    "radius"}}``, ``{"halfspace": {"point", "normal"}}`` ((X - point)·normal >= 0),
    ``{"nearest": point}`` (lowest index on ties) or ``{"extreme": {"axis", "side":
    "min"|"max", "tolerance"}}`` (coordinate ``axis`` within ``tolerance`` of its min/max).
    Comparisons allow 1e-12 × the coordinate scale. For ``extreme`` the tolerance may be
    omitted when ``volumes`` is given; it then defaults to half the median particle size
    volumes^(1/D). An empty selection is returned as such.

    With a communicator ``comm`` each rank passes its own particles (global ids ``ids``,
    which order the ``nearest`` ties) and the selection is that of the whole set.
    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 2 or not 1 <= pos.shape[1] <= 3:
        raise ValueError(f"select: positions must have shape (n, D) with D in 1..3, got {pos.shape}")
    n, dim = pos.shape
    if not isinstance(spec, Mapping):
        raise ValueError(f"select: spec must be a table with one of the keys {list(SELECTORS)}, got {spec!r}")
    keys = [k for k in spec if k != "invert"]
    if len(keys) != 1 or keys[0] not in SELECTORS:
        raise ValueError(f"select: spec must have exactly one of the keys {list(SELECTORS)} "
                         f"(plus optional 'invert'), got {sorted(spec)}")
    invert = spec.get("invert", False)
    if not isinstance(invert, bool):
        raise ValueError(f"select: invert must be true or false, got {invert!r}")
    key, value = keys[0], spec[keys[0]]
    ids = np.arange(n) if ids is None else np.asarray(ids)
    scale = _reduce(float(np.abs(pos).max()) if n else 0.0, max, comm)
    tol = 1e-12 * (scale if scale > 0.0 else 1.0)

    if key == "all":
        if value is not True:
            raise ValueError(f"select: all must be true, got {value!r}")
        mask = np.ones(n, dtype=bool)
    elif key == "box":
        _fields(value, "box", ("lower", "upper"))
        lo = _vector(value["lower"], "box.lower", "select", dim)
        hi = _vector(value["upper"], "box.upper", "select", dim)
        if np.any(lo > hi):
            raise ValueError(f"select: box.lower {lo.tolist()} must be <= box.upper {hi.tolist()}")
        mask = np.all((pos >= lo - tol) & (pos <= hi + tol), axis=1)
    elif key == "sphere":
        _fields(value, "sphere", ("center", "radius"))
        c = _vector(value["center"], "sphere.center", "select", dim)
        r = _nonnegative(value["radius"], "sphere.radius", "select")
        mask = np.linalg.norm(pos - c, axis=1) <= r + tol
    elif key == "halfspace":
        _fields(value, "halfspace", ("point", "normal"))
        p = _vector(value["point"], "halfspace.point", "select", dim)
        normal = _vector(value["normal"], "halfspace.normal", "select", dim)
        length = np.linalg.norm(normal)
        if length == 0.0:
            raise ValueError("select: halfspace.normal must be non-zero")
        mask = (pos - p) @ (normal / length) >= -tol
    elif key == "nearest":
        p = _vector(value, "nearest", "select", dim)
        dist = np.linalg.norm(pos - p, axis=1)
        i = int(np.lexsort((ids, dist))[0]) if n else -1
        best = _reduce((float(dist[i]), int(ids[i])) if n else (np.inf, -1), min, comm)
        mask = ids == best[1]
    else:
        _fields(value, "extreme", ("axis", "side"), ("tolerance",))
        axis, side = value["axis"], value["side"]
        if isinstance(axis, bool) or not isinstance(axis, (int, np.integer)) or not 0 <= axis < dim:
            raise ValueError(f"select: extreme.axis must be an integer in 0..{dim - 1}, got {axis!r}")
        if side not in ("min", "max"):
            raise ValueError(f"select: extreme.side must be 'min' or 'max', got {side!r}")
        if "tolerance" in value:
            t = _nonnegative(value["tolerance"], "extreme.tolerance", "select")
        elif volumes is not None:
            vol = np.asarray(volumes, dtype=np.float64)
            if vol.shape != (n,):
                raise ValueError(f"select: volumes must have shape ({n},), got {vol.shape}")
            total = _reduce(n, sum, comm)
            t = 0.5 * _median(vol, total, comm) ** (1.0 / dim) if total else 0.0
        else:
            raise ValueError("select: extreme.tolerance is required when volumes are not given")
        x = pos[:, axis]
        if side == "min":
            mask = x <= _reduce(float(x.min()) if n else np.inf, min, comm) + t + tol
        else:
            mask = x >= _reduce(float(x.max()) if n else -np.inf, max, comm) - t - tol
    return ~mask if invert else mask
