"""Exact sums of float64 values, independent of their order and of how they are split
among ranks.

Every finite double is an integer multiple of 2^-1074 (the smallest subnormal), so a sum
of doubles is an integer in those units, which a Python int holds exactly. `Exact` is such
a sum, with the non-finite terms kept apart (their float sum: inf, -inf or nan); `float()`
of it is the exact sum correctly rounded (what math.fsum returns; an exact zero is +0.0
and a finite sum beyond the float range is +-inf). `allsum` adds the sums of all ranks.

`Accumulator` gathers values in one compiled pass: each is x = M 2^(e-53) (M and e read
from its bits, |M| < 2^53), split as M = 2^26 hi + lo (|hi| <= 2^27, 0 <= lo < 2^26), and
hi and lo are added to int64 sums per exponent, which cannot overflow within 2^35 values; when the sums
are read (or that many values have been added) a compiled pass folds each column's
exponents into one two's-complement integer that becomes a Python int. It serves both
one-off sums (`sums`, `total`) and running totals.
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
def _deposit(values, counts, buckets, span, special):
    """Add `values` (1-D), counts[c] after counts[c - 1] to column c, to the int64 sums per
    exponent `buckets` (columns, EXPONENTS, 2: hi, lo), widening the column's occupied
    range `span` (columns, 2: first, last + 1), or, if not finite, to its `special`."""
    bits = values.view(np.int64)
    i = 0
    for c in range(len(counts)):
        for _ in range(counts[c]):
            x = values[i]
            field = bits[i]
            i += 1
            if x == 0.0:
                continue
            if not math.isfinite(x):
                special[c] += x
                continue
            # x = m 2^(b - 1126) from its bits: m the significand (with the implicit bit of a
            # normal number), b the biased exponent + 51 (52 for a subnormal)
            biased = (field >> 52) & 2047
            m = field & 4503599627370495
            if biased > 0:
                m += 4503599627370496
            b = max(biased, 1) + 51
            if field < 0:
                m = -m
            buckets[c, b, 0] += m >> 26
            buckets[c, b, 1] += m & 67108863
            span[c, 0] = min(span[c, 0], b)
            span[c, 1] = max(span[c, 1], b + 1)


LIMBS = 70  # 32-bit limbs of a column's bucket total: |total| < 2^(53 + 35 + 2097) < 2^(32 * 69)


@njit(cache=True)
def _add_at(limbs, v, shift):
    """Add v * 2^shift to `limbs` (int64 v; 32-bit limbs held in int64 with room for the
    carries of every bucket), in pieces below 2^32 each."""
    q, r = shift >> 5, shift & 31
    low = (v & 4294967295) << r  # below 2^63
    high = (v >> 32) << r  # |high| < 2^61
    limbs[q] += low & 4294967295
    limbs[q + 1] += (low >> 32) + (high & 4294967295)
    limbs[q + 2] += high >> 32


@njit(cache=True)
def _fold(buckets, span):
    """Each column's bucket total sum_b (2^26 hi_b + lo_b) 2^b over its occupied `span` as
    little-endian two's complement bytes (columns, 4 LIMBS); the buckets are emptied."""
    out = np.zeros((buckets.shape[0], 4 * LIMBS), np.uint8)
    limbs = np.zeros(LIMBS, np.int64)
    for c in range(buckets.shape[0]):
        limbs[:] = 0
        for b in range(span[c, 0], span[c, 1]):
            _add_at(limbs, buckets[c, b, 0], b + 26)
            _add_at(limbs, buckets[c, b, 1], b)
            buckets[c, b, 0] = buckets[c, b, 1] = 0
        span[c, 0], span[c, 1] = EXPONENTS, 0
        for i in range(LIMBS - 1):  # carries: limbs 0 .. LIMBS-2 in [0, 2^32), the top one 0 or -1
            carry = limbs[i] >> 32
            limbs[i] -= carry << 32
            limbs[i + 1] += carry
        for i in range(LIMBS):
            for j in range(4):
                out[c, 4 * i + j] = (limbs[i] >> (8 * j)) & 255
    return out


def _folded(buckets, span) -> list:
    """_fold's column totals as Python ints (in 2^-1126 units); the buckets are emptied."""
    return [int.from_bytes(f.tobytes(), "little", signed=True) for f in _fold(buckets, span)]


class Accumulator:
    """Running exact sums of `columns` columns of values."""

    def __init__(self, columns: int = 1):
        self.buckets = np.zeros((columns, EXPONENTS, 2), np.int64)
        self.span = np.tile(np.array([EXPONENTS, 0], np.int64), (columns, 1))
        self.special = np.zeros(columns)
        self.units = [0] * columns  # in 2^-1126 = 2^-1074 / 2^52: every shift is >= 0
        self.pending = 0  # values per column in the int64 sums

    def add(self, values: np.ndarray) -> None:
        """Add the rows of `values` (n, columns), or of a 1-D array to a single column
        (at most LIMIT rows a call)."""
        values = np.asarray(values, dtype=np.float64).reshape(-1, len(self.units))
        if self.pending + len(values) > LIMIT:
            self._collect()
        _deposit(values.T.ravel(), np.full(values.shape[1], len(values)), self.buckets, self.span, self.special)
        self.pending += len(values)

    def _collect(self) -> None:
        """Move the int64 sums into the Python ints."""
        for c, units in enumerate(_folded(self.buckets, self.span)):
            self.units[c] += units
        self.pending = 0

    def sums(self) -> list:
        """The exact sums so far, one per column."""
        self._collect()
        return [Exact(u >> 52, float(s)) for u, s in zip(self.units, self.special)]  # exact shift

    def set(self, sums: list) -> None:
        """Make the sums so far `sums` (Exact, one per column)."""
        self.buckets[:] = 0
        self.span[:] = [EXPONENTS, 0]
        self.pending = 0
        self.units = [s.units << 52 for s in sums]
        self.special[:] = [s.special for s in sums]


class _Scratch:
    """Empty buckets for one-off sums, kept between calls (each fold empties what it used)."""

    buckets = np.zeros((0, EXPONENTS, 2), np.int64)
    span = np.zeros((0, 2), np.int64)

    @classmethod
    def take(cls, columns: int) -> tuple:
        if len(cls.buckets) < columns:
            cls.buckets = np.zeros((columns, EXPONENTS, 2), np.int64)
            cls.span = np.tile(np.array([EXPONENTS, 0], np.int64), (columns, 1))
        return cls.buckets[:columns], cls.span[:columns], np.zeros(columns)


def totals(items: list) -> list:
    """Exact sums of `items`: an Exact stays as it is, an array becomes the exact sum of its
    elements, except a 2-D array (n, k): the k exact sums of its columns (in its place); the
    arrays in one fold."""
    columns = [column for x in items if not isinstance(x, Exact)
               for column in (np.asarray(x, dtype=np.float64).T if np.ndim(x) == 2 else [np.ravel(x)])]
    buckets, span, special = _Scratch.take(len(columns))
    if columns:
        _deposit(np.concatenate(columns), np.array([len(c) for c in columns], np.int64), buckets, span, special)
    found = iter([Exact(units >> 52, float(s)) for units, s in zip(_folded(buckets, span), special)])  # exact shift
    out = []
    for x in items:
        if isinstance(x, Exact):
            out.append(x)
        else:
            out.extend(next(found) for _ in range(np.shape(x)[1] if np.ndim(x) == 2 else 1))
    return out


def sums(values: np.ndarray) -> list:
    """Exact sums of the columns of `values` (n, k), or of a 1-D array (one sum)."""
    return totals([values])


def total(values: np.ndarray) -> Exact:
    """Exact sum of all elements of `values`."""
    return totals([np.ravel(values)])[0]


def allsum(comm, parts: list) -> list:
    """Exact sums over the ranks of `comm` of each rank's list of Exact `parts`
    (collective; the same on every rank, whatever the rank count)."""
    if comm.size == 1:
        return list(parts)
    gathered = comm.allgather([(p.units, p.special) for p in parts])
    return [Exact(sum(u for u, _ in column), sum(s for _, s in column)) for column in zip(*gathered)]
