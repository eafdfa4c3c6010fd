"""Surface tractions and prescribed displacements given as expressions of position, on
Timoshenko & Goodier's cantilever (runs/cantilever.toml, [R §9.1]) and a plate in tension;
a prescribed velocity released after a duration, on the rod of runs/rod_pulse.toml
([R §9.2])."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parsph.analytic import driven_rod_velocity, timoshenko_cantilever
from physics import block_2d, run_until, scene_from, simulation

TENSION = """
[groups.left]
box = { lower = [-1.0, -1.0], upper = [0.05, 1.0] }
[groups.corner]
nearest = [0.0, 0.0]
[groups.right]
box = { lower = [0.95, -1.0], upper = [2.0, 1.0] }
[[bc]]
type = "fixed"
group = "left"
components = [0]
[[bc]]
type = "fixed"
group = "corner"
components = [1]
[[tractions]]
group = "right"
value = [2.0e4, 0.0]
ramp = 0.01
"""


def test_a_uniform_traction_stretches_a_plate_uniformly():
    """A 1 x 0.6 plate (10 x 6 particles, 1 m thick) held at x = 0 (x only) and pulled at
    x = 1 by 2e4 Pa: each of the 6 edge particles takes 0.1 m^2 of the face, so the load is
    1.2e4 N, and at rest the constraints react with -1.2e4 N. Away from the ends the plate
    is in uniaxial stress, strain 2e4 (1 - nu^2) / E along x in plane strain: measured 0.94
    to 0.98 of it in the middle columns. The end columns strain less (0.51-0.69): the
    particles sit half a spacing inside the faces, the clamp holds the first column, and a
    uniform stress is not what collocation gives its edge particles for a share of the
    traction (tests/test_nodal_methods.py)."""
    sim = simulation(block_2d(extra="damping = 30.0") + TENSION, ["time.end=2.0"])
    run_until(sim, 2.0, every=100000)
    right = sim.group_index("right")
    assert np.sum(sim.conditions.external_force(sim.state, sim.t)[right, 0]) == pytest.approx(1.2e4, rel=1e-12)
    assert np.sum(sim.conditions.reaction(sim.state)[:, 0]) == pytest.approx(-1.2e4, rel=1e-9)
    assert np.abs(sim.quantity("velocity")).max() < 1e-9
    strain = (sim.quantity("deformation_gradient")[:, 0, 0] - 1.0) / (2e4 * (1 - 0.3 ** 2) / 1e6)
    middle = np.abs(sim.quantity("reference_position")[:, 0] - 0.5) < 0.3
    assert 0.93 < strain[middle].min() and strain[middle].max() < 1.0


def test_cantilever_clamp_takes_the_exact_displacement():
    """The clamp's particles (two columns) sit exactly at the solution's displacement at rest."""
    sim = simulation("cantilever", ["time.end=0.2"])
    run_until(sim, 0.2, every=10000)
    clamp, tip = sim.group_index("clamp"), sim.group_index("tip")
    assert len(clamp) == 2 * len(tip) == 16  # two columns clamped
    exact, _ = timoshenko_cantilever(sim.quantity("reference_position", clamp), 48.0, 12.0, 3e7, 0.3, 1000.0)
    u = sim.quantity("displacement", clamp)
    assert np.array_equal(u, exact) or np.abs(u - exact).max() < 1e-18


@pytest.mark.parametrize("n", [3, 8, 16])
def test_cantilever_end_load_has_the_force_and_moment_of_the_exact_one(n):
    """The end load P = 1000 N at x = L = 48, carried to the last column (x = L - h/2, h =
    12 / n) as the exact traction on the section through it: its forces total (0, P) and
    their moment about the clamp, sum x f_y - y f_x, is P L, to round-off (the shear alone
    there would give P (L - h/2) and make the tip about 3h/(4L) too stiff)."""
    sim = simulation("cantilever", [f"parameters.n={n}"])
    tip = sim.group_index("tip")
    force = np.zeros((sim.state.n_owned, 2))
    sim.conditions.tractions.add(force, 1.0)
    assert np.array_equal(np.flatnonzero(np.any(force != 0.0, axis=1)), tip)
    assert np.sum(force[tip, 0]) == pytest.approx(0.0, abs=1e-12 * 1000.0)
    assert np.sum(force[tip, 1]) == pytest.approx(1000.0, rel=1e-13)
    x, y = sim.quantity("reference_position", tip).T
    assert np.allclose(x, 48.0 - 6.0 / n, rtol=1e-14, atol=0.0)
    assert np.sum(x * force[tip, 1] - y * force[tip, 0]) == pytest.approx(1000.0 * 48.0, rel=1e-13)


# L2 error of the displacement, energy-norm error (tools/bench_cantilever.py), n = 4 and 8
CANTILEVER = {"tlsph": ((0.1007, 0.2636), (0.02993, 0.09093)),
              "kbm": ((0.1781, 0.1739), (0.04644, 0.05324))}


@pytest.mark.parametrize("method", CANTILEVER)
def test_cantilever_converges_towards_timoshenko_goodier(method):
    """At rest after dynamic relaxation (kinetic energy below 1e-10 of the strain energy),
    against the exact solution with the load at the true end, at 4 and 8 particles across
    the depth: the measured errors; halving the spacing shrinks both errors and the tip
    deflection's at least by half, and the tip's keeps its sign (tlsph, alpha = 50: L2 and
    energy rates 1.75 and 1.54, tip -10.5 % then -3.1 %; KBM 1.94 and 1.71, +18.9 % then
    +4.9 %)."""
    import sys
    from pathlib import Path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from bench_cantilever import run

    coarse, fine = run(method, 4), run(method, 8)
    for row, (l2, energy) in zip((coarse, fine), CANTILEVER[method]):
        assert row["relaxed"]
        assert row["l2"] == pytest.approx(l2, rel=0.05)
        assert row["energy"] == pytest.approx(energy, rel=0.05)
    assert fine["l2"] < 0.5 * coarse["l2"] and fine["energy"] < 0.5 * coarse["energy"]
    assert abs(fine["tip"]) < 0.5 * abs(coarse["tip"]) and fine["tip"] * coarse["tip"] > 0


def test_a_velocity_pulse_drives_the_rod_end_then_releases_it():
    """runs/rod_pulse.toml at 1 mm spacing (60 x 5 particles), driven at 0.5 m/s (linear: the
    scene's 50 m/s strains the Saint Venant-Kirchhoff rod by 1 %) for T = 5.8 us. While the
    drive acts the end column moves at exactly 0.5 m/s; after, nothing holds it: no entry is
    constrained, and with no force from outside the total momentum stays what the drive gave
    to round-off (measured 2e-13 relative), within 3 % of the exact pulse's rho H c T V
    (measured 2.7 %; 0.6 % at 0.5 mm). The end is at rest again once the pulse has left
    (measured 2.3 % and 1.9 % of V). Before and after the reflection at the free end, at 0.75
    and 1.5 L/c, the velocity matches the exact one (parsph.analytic.driven_rod_velocity,
    from the driven column at x = dx/2 to the face at L) to an error of eq. 75 of 0.14 and
    0.115 measured: a 30-spacing rectangular pulse whose two fronts are ramps w spacings wide
    has the error sqrt(w / 180), so the bound 0.15 allows fronts spread over 4 spacings."""
    speed, duration, length, height, density = 0.5, 5.8e-6, 0.06, 0.005, 7800.0
    c = math.sqrt(2.1e11 / density)
    # at half the default step: the pulse ends inside a step, and the end's velocity after
    # the release grows with the step (3.7 % of V at the default)
    sim = simulation("rod_pulse", ["parameters.dx=1e-3", f"parameters.pulse_speed={speed}",
                                    "time.cfl=0.2"])  # about the step the figures were measured at
    left = sim.group_index("left")
    x0 = sim.quantity("reference_position", left)[:, 0].max()
    assert len(left) == 5 and x0 == sim.quantity("reference_position")[:, 0].min() == 5e-4
    momentum = []
    while sim.t < duration:
        sim.step()
        if sim.t < duration:
            assert sim.conditions.bcs.active_items(sim.t) == (0,) and np.all(sim.quantity("velocity", left)[:, 0] == speed)
    for end in (0.75 * length / c, 1.5 * length / c):
        while sim.t < end:
            sim.step()
            momentum.append(np.sum(sim.quantity("mass") * sim.quantity("velocity")[:, 0]))
        assert sim.conditions.bcs.active_items(sim.t) == () and not sim.conditions.bcs.mask.any()
        assert np.abs(sim.quantity("velocity", left)).max() < 0.03 * speed
        exact = driven_rod_velocity(sim.quantity("reference_position")[:, 0] - x0, sim.t, length - x0, c, speed,
                                    duration)
        error = np.linalg.norm(sim.quantity("velocity") - np.column_stack([exact, 0 * exact])) / np.linalg.norm(exact)
        assert error < 0.15, (sim.t, error)
    assert np.ptp(momentum) < 1e-12 * momentum[0]
    assert momentum[0] == pytest.approx(density * height * c * duration * speed, rel=0.03)


def test_scenes_from_before_the_new_keys_restart():
    """A checkpoint's scene from before tractions, expressions, formulation.integration and
    bc.duration existed (those keys absent) is the same scene as today's resolution of it."""
    from parsph.io.checkpoint import differing_keys

    new = scene_from(block_2d() + TENSION.replace("[[tractions]]", "[[ignored]]").split("[[ignored]]")[0]).as_dict()
    old = {k: v for k, v in new.items() if k != "tractions"}
    old["bc"] = [{k: v for k, v in bc.items() if k != "expression"} for bc in new["bc"]]
    assert "integration" not in new["formulation"] and not {"expression", "duration"} & set(new["bc"][0])
    assert differing_keys(old, new) == []


@pytest.mark.mpi
def test_pulse_with_efg_restarted_after_the_release_continues_bit_for_bit(tmp_path):
    """runs/rod_pulse.toml at 1 mm with EFG (the drive collocated through the MLS functions,
    parsph.collocation): 200 steps on 1 rank against 150 on 2 ranks (the drive released at
    step 100), checkpointed and continued on 3 ranks: every history series, the external
    work and energies included, and the final state bit for bit."""
    from conftest import RUNS, assert_identical_outputs, parsph

    common = ["--quiet", "--set", "parameters.dx=1e-3", "--set", 'formulation.type="efg"']
    straight, split = tmp_path / "straight", tmp_path / "split"
    for out, ranks, extra in ((straight, 1, ["--set", "time.max_steps=200"]),
                              (split, 2, ["--set", "time.max_steps=150", "--set", "output.checkpoint_every=150"]),
                              (split, 3, ["--set", "time.max_steps=200", "--restart", "latest"])):
        proc = parsph(["run", RUNS / "rod_pulse.toml", "--out", out, *common, *extra], ranks=ranks)
        assert proc.returncode == 0, proc.stderr
    assert_identical_outputs(straight, split)
