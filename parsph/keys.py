"""Scene keys as the modules that own them declare them: type, default and value check
(parsph.config validates the scene against them; plug-ins such as the material laws bring
their own)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

REQUIRED = object()


@dataclass(frozen=True)
class Key:
    """One scene key: its type, default (or REQUIRED) and an optional value check."""

    kind: str  # "int" | "float" | "str" | "bool" | "vector" | "matrix" | "intlist" | "strlist" | "table"
    default: Any = None
    check: Callable[[Any], str | None] | None = None
    doc: str = ""


def positive(v):
    return None if v > 0 else "must be > 0"


def non_negative(v):
    return None if v >= 0 else "must be >= 0"


def greater_than(lo):
    def check(v):
        return None if v > lo else f"must be > {lo}"

    return check


def one_of(*choices):
    def check(v):
        return None if v in choices else f"must be one of {', '.join(map(repr, choices))}"

    return check


def in_range(lo, hi, lo_open=False, hi_open=False):
    def check(v):
        ok_lo = v > lo if lo_open else v >= lo
        ok_hi = v < hi if hi_open else v <= hi
        if ok_lo and ok_hi:
            return None
        return f"must be in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"

    return check
