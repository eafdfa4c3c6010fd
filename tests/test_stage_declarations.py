"""The stages' declarations against their code: each stage declares the fields it reads at
neighbours (formulations.base.Stage.reads), and the loop refreshes only those. Here every
other field that changes in a run has other values in its ghost rows while the stage runs
(physics.poison_undeclared): a stage that reads one of them at neighbours without
declaring it changes the forces, which must stay the same bit for bit. On one rank the
ghost rows are the mirror images of the symmetric punch; on two, the cantilever's halo
(every formulation, tests/mpi/declarations_check.py)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from conftest import CEILING, ROOT, mpiexec
from physics import RUNS, poison_undeclared, simulation

# the punch of a J2 material as soft as its rubber
J2_PUNCH = (RUNS / "punch.toml").read_text().replace(
    'model = "neo_hookean_nearly_incompressible"', 'model = "j2_plasticity"').replace(
    "shear_modulus = 0.3571e6\nbulk_modulus = 1.67e6",
    "youngs_modulus = 1.0e6\npoisson_ratio = 0.4\nyield_stress = 2.0e4\nhardening_modulus = 1.0e5")


@pytest.mark.parametrize("scene, overrides", [
    ("punch", []),
    ("punch", ["formulation.hourglass_form='paper'"]),
    ("punch_ul", []),
    ("punch", ["formulation.viscosity=1.0", "formulation.viscosity_beta=2.0"]),
    (J2_PUNCH, []),
    (J2_PUNCH, ["formulation.hourglass_form='paper'", "formulation.plastic_hourglass='viscous'"]),
    (J2_PUNCH, ["material.jc_d1=0.5"]),
    ("punch", ["material.failure_strain=0.05"]),
], ids=["tlsph", "paper", "ulsph", "viscosity", "j2", "machdyn", "jc_failure", "damage"])
def test_no_stage_reads_an_undeclared_field_at_neighbours(scene, overrides):
    sim = simulation(scene, ["parameters.spacing=1e-3", *overrides])
    assert sim.state.particles.decomp.n_rows > sim.state.n_owned  # mirror images: ghost rows to change
    for _ in range(40):  # deformed under the punch, some particles yielded
        sim.step()
    if "j2" in scene:
        assert sim.quantity("plastic_strain").max() > 0.0
    sim.compute_forces()
    force = sim.quantity("force")
    assert np.isfinite(force).all() and np.abs(force).max() > 0.0
    poison_undeclared(sim)
    sim.compute_forces()
    assert np.array_equal(sim.quantity("force"), force)


@pytest.mark.mpi
def test_no_stage_of_any_formulation_reads_an_undeclared_field_across_ranks():
    script = ROOT / "tests" / "mpi" / "declarations_check.py"
    proc = subprocess.run([mpiexec(), "-n", "2", sys.executable, str(script)],
                          capture_output=True, text=True, timeout=CEILING, cwd=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "OK" in proc.stdout
