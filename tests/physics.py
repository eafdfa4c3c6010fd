"""Helpers for in-process physics tests: build a Simulation from a scene file or text."""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsph.api import build, load_scene
from parsph.simulation import Simulation

from conftest import RUNS


def scene_from(name_or_text: str, overrides=()) -> dict:
    """Resolved scene from runs/NAME.toml or from TOML text, with `--set`-style overrides."""
    return load_scene(name_or_text if "\n" in name_or_text else RUNS / f"{name_or_text}.toml", overrides)


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
    out = np.zeros(sim.dim)
    for a in range(sim.dim):
        sim.u[i, a] += eps
        up = energy()
        sim.u[i, a] -= 2 * eps
        down = energy()
        sim.u[i, a] += eps
        out[a] = (up - down) / (2 * eps)
    return out


def elastic_constants(model: str) -> str:
    """The [material] lines of a law's constants (small-strain moduli of about 1e6 Pa)."""
    return {"neo_hookean_nearly_incompressible": "shear_modulus = 4.0e5\nbulk_modulus = 2.0e6",
            "mooney_rivlin": "c1 = 3.5e5\nc2 = 5.0e4\nlambda = 1.0e6",
            "tait_fluid": "tait_b = 4.704e5\ntait_gamma = 7.0"}.get(
        model, "youngs_modulus = 1.0e6\npoisson_ratio = 0.3")


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
