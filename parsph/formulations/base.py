"""What a formulation gives the simulation loop: the fields it carries per particle and the
stages of a force evaluation, each declaring the fields it reads at neighbours and the ones
it writes on owned points.

The loop (simulation.Simulation.compute_forces) runs the stages of all bodies phase by
phase; before a phase it refreshes the ghost values of every field the phase reads at
neighbours that was written since its last refresh (by a stage, or by the integrator for
the displacement). No refresh is placed by hand.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import tempfile
from dataclasses import dataclass
from typing import Callable


class CompiledOnce:
    """A compiled stage kernel whose first call in a process (where Numba compiles it, or
    loads it from its on-disk cache) holds an exclusive file lock named after the kernel's
    variant. Processes that need the same variant at the same time, the ranks of an MPI job
    or the workers of the test suite, then compile it once: the others wait for the lock and
    load the compiled code from the cache. Later calls go straight to the kernel."""

    def __init__(self, kernel, variant: str):
        self.kernel = kernel
        self.lock_path = os.path.join(tempfile.gettempdir(), "parsph-compile-" + hashlib.sha256(
            f"{kernel.py_func.__qualname__} {variant}".encode()).hexdigest()[:32] + ".lock")
        self.first = True

    def __call__(self, *args):
        if not self.first:
            return self.kernel(*args)
        with _locked(self.lock_path):
            out = self.kernel(*args)
        self.first = False
        return out


@contextlib.contextmanager
def _locked(path: str):
    """An exclusive flock on `path` (released however the process ends); without one (the
    folder is not writable) the block runs unlocked."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


@dataclass(frozen=True)
class Stage:
    """One compiled pass over a body's owned particles."""

    name: str  # label of its time in the per-stage report
    run: Callable[[], None]
    reads: tuple = ()  # fields read at neighbours: their ghost values must be current
    writes: tuple = ()  # fields written on owned particles (ghost values become stale)
    # a pass of the force row, which needs the state (F, stress) only: an Eulerian kernel
    # moves its reference to the current configuration before the first one
    force_row: bool = False
