"""The Taylor bar of [G §4.5] (runs/taylor_impact.toml) through its first 8 us, the bulk of
the impact: plastic work takes the kinetic energy and the balance kinetic + strain + plastic
+ hourglass = initial + external work (the wall's contact work) closes; hourglass control
with the yield stress as a yielded particle's modulus keeps the particles ordered where the
unstabilised run does not [G Fig. 9]; with E in the hourglass force instead, plastic flow is
held back."""

from __future__ import annotations

import numpy as np
import pytest

from parsph.diagnostics import global_diagnostics
from physics import simulation

END = 8e-6


def impact(*overrides) -> tuple:
    """(diagnostics at t = 0, at END, the simulation) of the base-resolution bar."""
    sim = simulation("taylor_impact", [f"time.end={END}", *overrides])
    start = global_diagnostics(sim)
    while sim.t < END:
        sim.step(END)
    return start, global_diagnostics(sim), sim


@pytest.fixture(scope="module")
def stabilised():
    return impact()


def test_energy_balance_closes_and_plastic_work_takes_the_kinetic_energy(stabilised):
    start, end, sim = stabilised
    initial = start["kinetic_energy"]
    assert end["total_energy"] == pytest.approx(initial, rel=1e-3)
    assert end["plastic_work"] > 0.7 * initial
    assert end["kinetic_energy"] < 0.25 * initial
    # the wall takes the kinetic energy of the particles it stops: at least the bottom row's
    rows = 67
    assert -end["external_work"] > initial / rows
    strain = sim.quantity("plastic_strain", np.arange(sim.n_owned))
    assert strain.min() >= 0.0 and strain.max() > 0.5
    bottom = sim.X[: sim.n_owned, 1] < 1e-3  # the foot has flowed, the top barely (the reflected
    top = sim.X[: sim.n_owned, 1] > 20e-3  # elastic precursor)
    assert strain[bottom].min() > 0.25 and strain[top].max() < 0.01


def test_hourglass_control_keeps_the_particles_ordered(stabilised):
    """[G Fig. 9]: alpha = 50 with the yield-stress switch against alpha = 0."""
    _, end, _ = stabilised
    _, unstabilised, _ = impact("formulation.hourglass=0")
    # both balances close (at the default step: 3e-4 with hourglass control, 1e-3 without)
    assert unstabilised["total_energy"] == pytest.approx(end["total_energy"], rel=2e-3)
    assert unstabilised["disorder"] > 2.5 * end["disorder"]
    assert unstabilised["disorder_max"] > 4 * end["disorder_max"]


def test_youngs_modulus_in_the_hourglass_force_holds_plastic_flow_back(stabilised):
    """Without the switch the hourglass springs (alpha E) resist the non-affine part of the
    flow: the foot spreads less and the largest plastic strain is smaller. ([G] reports no
    plastic flow at all and an elastic rebound; see the README.)"""
    _, end, sim = stabilised
    _, stiff, stiff_sim = impact("formulation.plastic_hourglass=false")
    assert stiff["total_energy"] == pytest.approx(end["total_energy"], rel=1e-3)
    width = [float(np.max(s.X[: s.n_owned, 0] + s.u[: s.n_owned, 0])) for s in (sim, stiff_sim)]
    assert width[1] < 0.85 * width[0]
    strain = [s.quantity("plastic_strain", np.arange(s.n_owned)).max() for s in (sim, stiff_sim)]
    assert strain[1] < 0.6 * strain[0]
