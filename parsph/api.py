"""The Python interface for scripts and notebooks: a scene loaded (from a file, TOML text
or a dict, with `--set`-style overrides), its simulation built on one rank or on a
communicator's ranks, stepped, and its state read as named arrays. A run's output files
are read back with parsph.io.read_history and parsph.io.read_snapshots.

    from parsph.api import load_scene, build
    sim = build(load_scene("runs/bar1d.toml", ["time.end=1e-4"]))
    while sim.t < 1e-4:
        sim.step()
    sim.diagnostics()["kinetic_energy"], sim.quantity("velocity", sim.group_index("all"))
"""

from __future__ import annotations

import copy
import os
import tomllib

from mpi4py import MPI

from parsph import config
from parsph.build import build_local
from parsph.errors import InputError
from parsph.simulation import Simulation


def load_scene(source, overrides=()) -> config.Scene:
    """The resolved (validated, defaults filled in, typed: config.Scene) scene of `source`: the path of a scene
    file, TOML text (anything with a line break) or a raw scene dict (left unchanged), with
    each override "key.path=value" applied first, as `parsph run --set` does."""
    if isinstance(source, dict):
        raw = copy.deepcopy(source)
    elif isinstance(source, str) and "\n" in source:
        try:
            raw = tomllib.loads(source)
        except ValueError as exc:
            raise InputError(f"the scene text is not valid TOML: {exc}") from None
    else:
        return config.load(os.fspath(source), list(overrides))
    for text in overrides:
        config.apply_override(raw, *config.parse_override(text))
    return config.validate(raw)


def build(scene: config.Scene | dict, comm=MPI.COMM_SELF) -> Simulation:
    """The simulation of a resolved scene (load_scene) on the ranks of `comm` (collective),
    at t = 0 with its initial conditions applied and its first forces evaluated. A scene
    table is validated as a scene file is (a resolved scene passes unchanged)."""
    if isinstance(scene, dict):
        scene = config.validate(scene)
    elif not isinstance(scene, config.Scene):
        raise InputError(f"build takes a scene (load_scene's), got {type(scene).__name__}: load it first")
    return Simulation(scene, build_local(scene, comm), comm)
