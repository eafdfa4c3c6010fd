"""Helpers for in-process physics tests: build a Simulation from a scene file or text."""

from __future__ import annotations

import dataclasses

import numpy as np
from mpi4py import MPI

from parsph import config
from parsph.api import build, load_scene
from parsph.simulation import Simulation

from conftest import RUNS


def scene_from(name_or_text: str, overrides=()) -> dict:
    """Resolved scene from runs/NAME.toml or from TOML text, with `--set`-style overrides."""
    return load_scene(name_or_text if "\n" in name_or_text else RUNS / f"{name_or_text}.toml", overrides)


def typed(name: str, **keys):
    """The typed scene section `name` ("time", "balance", ...) or entry of the array of
    tables `name` ("walls", "tools", "tractions", ...) with `keys`, the others at their
    defaults (config.SECTION_TYPES, config.ENTRY_TYPES)."""
    return (config.SECTION_TYPES.get(name) or config.ENTRY_TYPES[name]).of(keys)


def simulation(name_or_text: str, overrides=(), comm=MPI.COMM_SELF) -> Simulation:
    return build(scene_from(name_or_text, overrides), comm)


def run_until(sim: Simulation, end: float, every: int = 1, probe=None) -> dict:
    """Step to `end`; returns arrays of diagnostics (and `probe(sim)`) every `every` steps
    and at the end."""
    rows = [dict(sim.diagnostics(), probe=probe(sim) if probe else None)]
    while sim.t < end * (1 - 1e-12):
        sim.step()
        if sim.step_count % every == 0 or sim.t >= end * (1 - 1e-12):
            rows.append(dict(sim.diagnostics(), probe=probe(sim) if probe else None))
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def energy_gradient(sim: Simulation, energy, i: int, eps: float) -> np.ndarray:
    """Central differences of energy() with respect to particle i's displacement."""
    out = np.zeros(sim.state.dim)
    for a in range(sim.state.dim):
        sim.state.u[i, a] += eps
        up = energy()
        sim.state.u[i, a] -= 2 * eps
        down = energy()
        sim.state.u[i, a] += eps
        out[a] = (up - down) / (2 * eps)
    return out


def elastic_constants(model: str) -> str:
    """The [material] lines of a law's constants (small-strain moduli of about 1e6 Pa)."""
    return {"neo_hookean_nearly_incompressible": "shear_modulus = 4.0e5\nbulk_modulus = 2.0e6",
            "mooney_rivlin": "c1 = 3.5e5\nc2 = 5.0e4\nlambda = 1.0e6",
            "tait_fluid": "tait_b = 4.704e5\ntait_gamma = 7.0"}.get(
        model, "youngs_modulus = 1.0e6\npoisson_ratio = 0.3")


def soft_solid(support: float) -> str:
    """The kernel and material tables of a soft elastic solid (scene text): Wendland C2 with
    `support`, Saint Venant-Kirchhoff, 1000 kg/m^3, E = 1 MPa, nu = 0.3."""
    return f"""[kernel]
type = "wendland_c2"
support = {support}
[material]
model = "saint_venant_kirchhoff"
density = 1000.0
youngs_modulus = 1.0e6
poisson_ratio = 0.3
"""


def block_2d(model="saint_venant_kirchhoff", hourglass=0.0, form="variational", extra=""):
    """A small free 2D block scene (text), 10 x 6 particles."""
    elastic = elastic_constants(model)
    return f"""
[scene]
name = "block"
dimension = 2
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [1.0, 0.6]
spacing = 0.1
[kernel]
type = "wendland_c2"
support = 2.5
[material]
model = "{model}"
density = 1000.0
{elastic}
[formulation]
hourglass = {hourglass}
hourglass_form = "{form}"
[time]
end = 1.0
{extra}
"""


# the arrays a run never changes after its points are set up (or, for the updated
# reference, changes only with a refresh of every field)
CONSTANT = {"X", "measure", "volume", "mass", "support", "groups", "gid", "Xr", "Fr", "measure_r", "volume_r",
            "weight", "body", "owner"}


def poison_undeclared(sim) -> None:
    """Wrap every stage of `sim`: the ghost rows of the changing arrays of every point set
    that it neither declares to read nor writes ("NAME" of the particles, "SET.NAME" of
    another set), nor share memory with those, hold other values (1.5 x + 1) while it runs:
    a stage that reads one at neighbours without declaring it computes other forces. (NaN
    would hide in the kernels' comparisons, which are false for it.)"""
    changing = []
    for points in sim.state.point_sets():
        n = points.n_owned
        prefix = "" if points.name == "particles" else points.name + "."
        changing += [(prefix + k, a, n) for k, a in points.arrays.items() if k not in CONSTANT
                     and isinstance(a, np.ndarray) and a.dtype.kind == "f" and len(a) > n]
    arrays = {name: a for name, a, _ in changing}

    def wrap(stage):
        kept = [arrays[k] for k in stage.reads + stage.writes if k in arrays]
        hidden = [(a, n) for k, a, n in changing if not any(np.shares_memory(a, b) for b in kept)]

        def run():
            saved = [a[n:].copy() for a, n in hidden]
            for a, n in hidden:
                a[n:] = 1.5 * a[n:] + 1.0
            try:
                stage.run()
            finally:
                for (a, n), value in zip(hidden, saved):
                    a[n:] = value
        return dataclasses.replace(stage, run=run)

    for b in sim.state.bodies:
        b.stages = [wrap(stage) for stage in b.stages]
