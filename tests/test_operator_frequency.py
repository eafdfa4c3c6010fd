"""The stable step from each body's discrete force operator (parsph.operator_frequency,
stability.StableStep.calibrate): the power iteration finds the largest eigenvalue of the
dense M^-1 K assembled column by column from the same forces, the factor is the same bit for
bit on any number of ranks, the measurement leaves the state as it was, the chosen step
stays below the operator's leapfrog limit 2 / omega_max, and bad operators give clear errors."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from conftest import CEILING, ROOT, mpiexec
from parsph import operator_frequency
from parsph.errors import ParsphError
from physics import simulation


def dense_largest(sim) -> float:
    """The largest real eigenvalue of M^-1 K, K assembled column by column by finite
    differences of the bodies' internal force (the perturbation of the power iteration's
    size), and the state restored."""
    state = sim.state
    n, dim = state.n_owned, state.dim
    u0 = state.u[:n].copy()
    f0 = sim.internal_force()
    eps = operator_frequency.DELTA * state.bodies[0].relation.ref.min_spacing[:n].min()
    K = np.empty((n * dim, n * dim))
    for col in range(n * dim):
        state.u[:n] = u0
        state.u[col // dim, col % dim] += eps
        K[:, col] = -(sim.internal_force() - f0).ravel() / eps
    state.u[:n] = u0
    sim.compute_forces()
    mass = np.repeat(state.mass[:n], dim)
    return float(np.max(np.linalg.eigvals(K / mass[:, None]).real))


@pytest.mark.parametrize("scene, overrides, tolerance", [
    ("bar1d", [], 1e-6),  # 1D, total-Lagrangian
    ("bar1d_ul", [], 1e-5),  # updated reference with Hessian stabilisation
    ("patch_random", [], 3e-3),  # 2D disordered, the variational hourglass form
])
def test_power_iteration_finds_the_dense_operators_largest_eigenvalue(scene, overrides, tolerance):
    sim = simulation(scene, overrides)
    dense = dense_largest(sim)
    power = operator_frequency.largest_frequencies(sim.state, sim.internal_force, iterations=200)[0]
    sim.compute_forces()
    assert power == pytest.approx(dense, rel=tolerance)
    assert power <= dense * (1 + tolerance)  # a Rayleigh quotient of a symmetric operator: from below


def test_the_bars_highest_mode_is_below_the_lattice_estimate_and_the_step_below_its_limit():
    """Corrected SPH's central-difference gradient decouples odd and even particles of the
    1D bar: its highest frequency is about 0.64 of 2 c / l. The factor brings the estimate to
    the operator's, and the chosen step (time.cfl times it) is below leapfrog's limit
    2 / omega_max and within 1.5 of it."""
    sim = simulation("bar1d")
    body = sim.state.bodies[0]
    omega = np.sqrt(dense_largest(sim))
    length = body.relation.ref.min_spacing[:sim.state.n_owned].min()
    assert omega / (2 * body.constants.wave_speed / length) == pytest.approx(0.64, abs=0.01)
    assert body.step_factor == pytest.approx(omega / (2 * body.constants.wave_speed / length), rel=1e-3)
    limit = 2.0 / omega
    assert limit / 1.5 < sim.dt < limit
    assert sim.dt == pytest.approx(sim.scene.time.cfl * limit, rel=1e-3)


@pytest.mark.parametrize("scene, overrides", [
    ("taylor_impact", ["parameters.width=2.8e-3", "parameters.length=1.19e-2"]),  # plastic, paper hourglass
    ("bar1d_ul", []),  # updated reference, Hessian stabilisation
    ("two_blocks", []),  # two bodies, two formulations
])
def test_measuring_leaves_the_state_as_it_was(scene, overrides):
    """The power iteration writes the arrays the stages write; the forces evaluated again at the
    run's own displacement give the state of an evaluation that never saw it, bit for bit."""
    sim = simulation(scene, overrides)
    state = sim.state

    def snapshot():
        arrays = {k: v.copy() for k, v in state.particles.arrays.items()}
        arrays.update({k: getattr(state, k).copy() for k in ("u", "f_int", "force", "acc")})
        if state.hourglass:
            arrays.update(f_hg=state.f_hg.copy(), omega_hg2=state.omega_hg2.copy())
        return arrays, {k: [[x.to_json() for x in acc.sums()] for acc in v] for k, v in sim.ledger.totals.items()}

    before = snapshot()
    factors = [b.step_factor for b in state.bodies]
    squared = operator_frequency.largest_frequencies(state, sim.internal_force)
    sim.compute_forces()
    after = snapshot()
    assert sorted(before[0]) == sorted(after[0])
    for name, values in before[0].items():
        assert np.array_equal(values, after[0][name], equal_nan=True), name
    assert before[1] == after[1]
    sim.stable.calibrate(state, squared)
    assert [b.step_factor for b in state.bodies] == factors  # the same measurement


@pytest.mark.parametrize("scene, overrides", [
    ("punch_ul", ["parameters.spacing=1e-3", "formulation.update_every=10"]),  # updated, a tool's motion limit
    ("taylor_impact", ["parameters.width=2.8e-3", "parameters.length=1.19e-2"]),  # plastic, against a wall
])
def test_measuring_during_a_run_leaves_the_state_as_it_was(scene, overrides):
    """The measurement every operator_frequency.EVERY steps runs the stages again at the run's
    own u: every array, the forces, the motion's step limits and the ledger as they were."""
    sim = simulation(scene, overrides)
    for _ in range(25):
        sim.step()
    state = sim.state

    def snapshot():
        arrays = {k: v.copy() for k, v in state.particles.arrays.items()}
        arrays.update({k: np.copy(getattr(state, k)) for k in
                       ("u", "v", "f_int", "force", "acc", "internal_force", "step_limit", "omega_hg2")})
        return arrays, {k: [[x.to_json() for x in acc.sums()] for acc in v] for k, v in sim.ledger.totals.items()}

    before = snapshot()
    sim._measure_operator()
    after = snapshot()
    for name, values in before[0].items():
        assert np.array_equal(values, after[0][name], equal_nan=True), name
    assert before[1] == after[1]
    assert sim.stable.measured == sim.step_count


def test_a_body_without_stiffness_or_with_forces_that_are_not_finite_is_an_error():
    sim = simulation("bar1d")
    state = sim.state
    n = state.n_owned
    u = state.u[:n].copy()
    with pytest.raises(ParsphError, match="force operator is singular"):
        operator_frequency.largest_frequencies(state, lambda: np.zeros((n, state.dim)))
    with pytest.raises(ParsphError, match="not finite"):
        operator_frequency.largest_frequencies(state, lambda: np.where(state.u[:n] != 0.0, np.nan, 0.0))
    assert np.array_equal(state.u[:n], u)  # restored after the error


@pytest.mark.mpi
@pytest.mark.parametrize("scene, overrides", [
    ("patch_random", []),
    ("two_blocks", []),
    ("rings", ["parameters.spacing=4e-3"]),
    ("bar1d", ["geometry.parts.0.spacing=0.5"]),  # 3 particles: a rank owns none
])
def test_the_factor_is_the_same_on_every_rank_count(scene, overrides):
    script = ROOT / "tests" / "mpi" / "step_factor_check.py"
    printed = []
    for ranks in (1, 3, 4) if "spacing=0.5" in " ".join(overrides) else (1, 3):
        proc = subprocess.run([mpiexec(), "-n", str(ranks), sys.executable, str(script), scene, *overrides],
                              capture_output=True, text=True, timeout=CEILING, cwd=ROOT)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        printed.append(proc.stdout.strip())
    assert len(set(printed)) == 1, printed
