"""Monaghan's artificial viscosity (formulations/tlsph.py `artificial_viscosity`,
`formulation.viscosity`): acts only on pairs closing in, opposes the approach, conserves
momentum; in a squeezed water drop (Tait, Eulerian kernel) it only ever absorbs energy and
the balance with it closes; in the funnel the Lagrangian kernel fails with a message naming
a particle."""

from __future__ import annotations

import numpy as np
import pytest

from parsph.diagnostics import global_diagnostics
from parsph.errors import ParsphError
from parsph.formulations.tlsph import artificial_viscosity
from physics import simulation


def pair_forces(v_j: np.ndarray) -> tuple:
    """Forces on two particles 1 mm apart on the x axis, particle 1 moving at v_j, 0 at rest;
    their heating and the steps their motion allows."""
    ptr = np.array([0, 1, 2])
    idx = np.array([1, 0])
    X = np.array([[0.0, 0.0], [1e-3, 0.0]])  # the reference positions: X_j - X_i = +-1 mm along x
    grad = np.array([[2.0, 0.0], [-2.0, 0.0]])  # g_ij along x_j - x_i (as F = I + sum (u_j - u_i) g_ij)
    Linv = np.tile(np.eye(2), (2, 1, 1))  # g_ij = L_i^-1 gw_ij: uncorrected, so g_ji = -g_ij (equal measures)
    v = np.array([[0.0, 0.0], v_j])
    mass, volume = np.array([1e-3, 2e-3]), np.array([1e-6, 1e-6])
    out, heating, limit = np.zeros((2, 2)), np.zeros(2), np.full(2, np.inf)
    artificial_viscosity(0, 2, ptr, idx, grad, Linv, np.ones(2), X, np.zeros((2, 2)), v, np.ones(2), 1000.0,
                         volume, mass, np.full(2, 2.1e-3), 50.0, 1.0, 2.0, out, heating, limit)
    return out, heating, limit


def test_closing_pairs_are_damped_heated_and_momentum_is_kept():
    """A closing pair is pushed apart along the line of centres with opposite forces; the
    power they dissipate heats the two particles alike; the pair's step is at most the time
    it takes to close at its closing speed (1 mm at 1 m/s)."""
    v = np.array([-1.0, 0.3])  # particle 1 moves towards particle 0
    closing, heating, limit = pair_forces(v)
    np.testing.assert_allclose(closing[0] + closing[1], 0.0, atol=1e-12 * np.abs(closing).max())
    assert closing[0, 0] < 0 < closing[1, 0]  # pushes them apart, along the line of centres
    assert closing[0, 1] == closing[1, 1] == 0.0
    dissipated = -(closing[1] @ v)  # the forces' power, the other particle at rest
    assert dissipated > 0.0
    assert heating == pytest.approx([0.5 * dissipated, 0.5 * dissipated], rel=1e-12)
    assert limit == pytest.approx([1e-3 / 1.0, 1e-3 / 1.0], rel=1e-12)
    forces, heating, limit = pair_forces(np.array([1.0, 0.3]))  # separating: nothing
    assert not forces.any() and not heating.any() and np.isinf(limit).all()


DROP = """
[scene]
name = "drop"
dimension = 2
[geometry]
thickness = 1.0
[[geometry.parts]]
shape = "box"
lower = [-0.025, -0.025]
upper = [0.025, 0.025]
spacing = 5.0e-3
[material]
model = "tait_fluid"
density = 1000.0
tait_b = 4.704e5
tait_gamma = 7.0
[formulation]
type = "sph"
kernel = "eulerian"
viscosity = 0.5
viscosity_beta = 1.0
[time]
end = 2.0e-3
cfl = 0.15  # leapfrog's own error, O(dt^2), is 5e-3 at the step of cfl 0.3 of the plain estimate
[[initial]]
type = "velocity_field"
expression = ["-20 * x", "-20 * y"]
"""


def test_viscous_work_grows_and_the_balance_closes():
    """A water drop squeezed by a converging initial velocity (Eulerian kernel): the
    viscosity absorbs a share of the kinetic energy (36 %), never gives any back, the
    balance kinetic + strain + viscous closes, momentum stays zero."""
    sim = simulation(DROP)
    start = global_diagnostics(sim)
    rows = []
    while sim.t < 2e-3:
        sim.step(2e-3)
        rows.append(global_diagnostics(sim))
    viscous = np.array([r["viscous_work"] for r in rows])
    initial = start["kinetic_energy"]
    assert viscous[-1] > 0.01 * initial and np.all(np.diff(viscous) >= 0)
    assert abs(rows[-1]["total_energy"] - initial) < 2e-3 * initial  # the time integration's 1.1e-3 without it
    momentum = np.array([[r["momentum_x"], r["momentum_y"]] for r in rows])
    assert np.abs(momentum).max() < 1e-12 * initial


def test_lagrangian_kernel_fails_in_the_funnel_with_a_message():
    """The particles stretch and the stable step falls below the scene's floor (a tenth of the
    first step): an error naming the particle, no NaN."""
    sim = simulation("funnel", ["formulation.kernel='lagrangian'"])
    with pytest.raises(ParsphError, match=r"the stable time step fell to .* below time.step_floor = 0.1 of the "
                                          r"first one .*: particle \d+ at \(.*\) is the most flattened"):
        while sim.t < 0.4:
            sim.step(0.4)
    assert np.isfinite(sim.quantity("displacement")).all() and np.isfinite(sim.quantity("velocity")).all()
