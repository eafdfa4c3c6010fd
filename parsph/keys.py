"""Scene keys as the modules that own them declare them: type, default, value check and
meaning (parsph.config validates the scene against them; plug-ins such as the material laws
bring their own; parsph.keyref prints them as the reference of the scene keys)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

REQUIRED = object()


@dataclass(frozen=True)
class Key:
    """One scene key: its type, default (or REQUIRED), an optional value check and its
    meaning (`doc`; a unit in brackets, "[m/s]", as the reference shows it)."""

    kind: str  # "int" | "float" | "str" | "bool" | "vector" | "matrix" | "intlist" | "strlist" | "table"
    default: Any = None
    check: Callable[[Any], str | None] | None = None
    doc: str = ""


class Check:
    """A value check that says what it allows: check(v) is None or the problem ("must be
    > 0"); str(check) is what it allows ("> 0"), for the reference."""

    def __init__(self, allows: str, test: Callable[[Any], bool]):
        self.allows = allows
        self.test = test

    def __call__(self, v) -> str | None:
        return None if self.test(v) else f"must be {self.allows}"

    def __str__(self) -> str:
        return self.allows


def describe(check) -> str:
    """What a key's check allows: a Check's own words, else the first paragraph of the
    check function's docstring ("" without a check)."""
    if check is None:
        return ""
    if isinstance(check, Check):
        return str(check)
    return " ".join((check.__doc__ or "").strip().split("\n\n")[0].split())


positive = Check("> 0", lambda v: v > 0)
non_negative = Check(">= 0", lambda v: v >= 0)


def greater_than(lo) -> Check:
    return Check(f"> {lo}", lambda v: v > lo)


def one_of(*choices) -> Check:
    return Check(f"one of {', '.join(map(repr, choices))}", lambda v: v in choices)


def in_range(lo, hi, lo_open=False, hi_open=False) -> Check:
    return Check(f"in {'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}",
                 lambda v: (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi))
