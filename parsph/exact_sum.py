"""Exact sums of float64 values, independent of their order and of how they are split
among ranks.

Every finite double is an integer multiple of 2^-1074 (the smallest subnormal), so a sum
of doubles is an integer in those units, which a Python int holds exactly. `Exact` is such
a sum, with the non-finite terms kept apart (their float sum: inf, -inf or nan); `float()`
of it is the exact sum correctly rounded (what math.fsum returns; an exact zero is +0.0
and a finite sum beyond the float range is +-inf). `allsum` adds the sums of all ranks.

`Accumulator` gathers values in one compiled pass: each is x = M 2^(e-53) (frexp,
|M| < 2^53), split as M = 2^26 hi + lo (|hi| <= 2^27, 0 <= lo < 2^26), and hi and lo are
added to int64 sums per exponent, which cannot overflow within 2^35 values; the occupied
exponents are shifted into Python ints when the sums are read (or that many values have
been added). It serves both one-off sums (`sums`, `total`) and running totals.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

EXPONENTS = 2098  # frexp exponents of finite doubles: -1073 .. 1024
LIMIT = 1 << 35  # values per column that the int64 sums take without overflow
SCALE = 1 << 1074  # 2^-1074 units per 1.0


class Exact:
    """An exact sum of doubles: `units` (int) times 2^-1074, plus `special`, the sum of
    the non-finite terms (0.0 if there were none)."""

    __slots__ = ("units", "special")

    def __init__(self, units: int = 0, special: float = 0.0):
        self.units = units
        self.special = special

    def __add__(self, other: Exact) -> Exact:
        return Exact(self.units + other.units, self.special + other.special)

    def __neg__(self) -> Exact:
        return Exact(-self.units, -self.special)

    def __sub__(self, other: Exact) -> Exact:
        return self + -other

    def __float__(self) -> float:
        if self.special:  # inf, -inf or nan
            return self.special
        try:
            return self.units / SCALE  # int / int: correctly rounded
        except OverflowError:
            return math.inf if self.units > 0 else -math.inf

    def to_json(self) -> str:
        """The sum as text: the decimal integer of units, or 'inf', '-inf', 'nan'."""
        return repr(self.special) if self.special else str(self.units)

    @classmethod
    def from_json(cls, value: str) -> Exact:
        """Inverse of to_json."""
        if value in ("inf", "-inf", "nan"):
            return cls(0, float(value))
        return cls(int(value))


@njit(cache=True)
def _deposit(values, buckets, special):
    """Add each column of `values` (n, k) to its int64 sums per exponent `buckets`
    (k, EXPONENTS, 2: hi, lo) or, if not finite, to `special` (k)."""
    for i in range(values.shape[0]):
        for c in range(values.shape[1]):
            x = values[i, c]
            if not math.isfinite(x):
                special[c] += x
                continue
            mantissa, exponent = math.frexp(x)
            m = np.int64(mantissa * 9007199254740992.0)  # 2^53 mantissa: exact
            b = exponent + 1073
            buckets[c, b, 0] += m >> 26
            buckets[c, b, 1] += m & 67108863


@njit(cache=True)
def _take(buckets):
    """Rows (column, exponent + 1073, hi sum, lo sum) of the occupied `buckets`, which
    are emptied."""
    out = np.empty((np.count_nonzero(buckets), 4), np.int64)
    k = 0
    for c in range(buckets.shape[0]):
        for b in range(buckets.shape[1]):
            if buckets[c, b, 0] != 0 or buckets[c, b, 1] != 0:
                out[k, 0], out[k, 1], out[k, 2], out[k, 3] = c, b, buckets[c, b, 0], buckets[c, b, 1]
                buckets[c, b, 0] = buckets[c, b, 1] = 0
                k += 1
    return out[:k]


class Accumulator:
    """Running exact sums of `columns` columns of values."""

    def __init__(self, columns: int = 1):
        self.buckets = np.zeros((columns, EXPONENTS, 2), np.int64)
        self.special = np.zeros(columns)
        self.units = [0] * columns  # in 2^-1126 = 2^-1074 / 2^52: every shift is >= 0
        self.pending = 0  # values per column in the int64 sums

    def add(self, values: np.ndarray) -> None:
        """Add the rows of `values` (n, columns), or of a 1-D array to a single column
        (at most LIMIT rows a call)."""
        values = np.ascontiguousarray(values, dtype=np.float64).reshape(-1, len(self.units))
        if self.pending + len(values) > LIMIT:
            self._collect()
        _deposit(values, self.buckets, self.special)
        self.pending += len(values)

    def _collect(self) -> None:
        """Move the int64 sums into the Python ints."""
        for c, b, hi, lo in _take(self.buckets).tolist():
            self.units[c] += ((hi << 26) + lo) << b
        self.pending = 0

    def sums(self) -> list:
        """The exact sums so far, one per column."""
        self._collect()
        return [Exact(u >> 52, float(s)) for u, s in zip(self.units, self.special)]  # exact shift

    def set(self, sums: list) -> None:
        """Make the sums so far `sums` (Exact, one per column)."""
        self.buckets[:] = 0
        self.pending = 0
        self.units = [s.units << 52 for s in sums]
        self.special[:] = [s.special for s in sums]


def sums(values: np.ndarray) -> list:
    """Exact sums of the columns of `values` (n, k), or of a 1-D array (one sum)."""
    values = np.asarray(values)
    acc = Accumulator(1 if values.ndim == 1 else values.shape[1])
    acc.add(values)
    return acc.sums()


def total(values: np.ndarray) -> Exact:
    """Exact sum of all elements of `values`."""
    return sums(np.ravel(values))[0]


def allsum(comm, parts: list) -> list:
    """Exact sums over the ranks of `comm` of each rank's list of Exact `parts`
    (collective; the same on every rank, whatever the rank count)."""
    if comm.size == 1:
        return list(parts)
    gathered = comm.allgather([(p.units, p.special) for p in parts])
    return [Exact(sum(u for u, _ in column), sum(s for _, s in column)) for column in zip(*gathered)]
