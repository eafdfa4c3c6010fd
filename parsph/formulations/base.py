"""What a formulation gives the simulation loop: the fields it carries per particle and the
stages of a force evaluation, each declaring the fields it reads at neighbours and the ones
it writes on owned points.

The loop (simulation.Simulation.compute_forces) runs the stages of all bodies phase by
phase; before a phase it refreshes the ghost values of every field the phase reads at
neighbours that was written since its last refresh (by a stage, or by the integrator for
the displacement). No refresh is placed by hand.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Callable


def source_hash(*paths: str) -> str:
    """Hash of the source files compiled stages are made from. Numba keys a cached closure
    by its own bytecode and captured values only, not by the functions it inlines; a stage
    that captures this hash misses stale cache entries after any change to these files (or
    while a process still runs old code) instead of loading them."""
    digest = hashlib.sha256()
    for path in paths:
        with open(path, "rb") as fh:
            digest.update(fh.read())
    return digest.hexdigest()


@dataclass(frozen=True)
class Stage:
    """One compiled pass over a body's owned particles."""

    name: str  # label of its time in the per-stage report
    run: Callable[[], None]
    reads: tuple = ()  # fields read at neighbours: their ghost values must be current
    writes: tuple = ()  # fields written on owned particles (ghost values become stale)
