"""Rings for KBM [R §9.5-9.6]: the polar lattice and its stress points (counts, weights that
sum to the annulus), time profiles of tractions, and the rubber ring of runs/rubber_ring.toml
staying rotationally symmetric with the Lagrangian kernel."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parsph import readouts
from parsph.bc import Tractions
from parsph.geometry import PolarRing
from parsph.geometry.stress_points import stress_points_of
from physics import run_until, simulation, typed


def test_polar_ring_counts_and_weights_sum_to_the_annulus():
    ring = PolarRing([0.1, -0.2], 0.05, 0.125, 9, 60)
    stress = stress_points_of(ring, 2.0)
    assert (ring.count, stress.count) == (540, 480)  # [R §9.6]
    X, volume = ring.rows(0, ring.count)
    area = math.pi * (0.125 ** 2 - 0.05 ** 2)
    assert volume.sum() == pytest.approx(area, rel=1e-13)
    radius = np.hypot(*(X - [0.1, -0.2]).T)
    assert radius.min() == pytest.approx(0.05) and radius.max() == pytest.approx(0.125)
    Y, weight = stress.rows(0, stress.count)
    total = weight.sum() + stress.particle_weights(np.arange(ring.count)).sum()
    assert total == pytest.approx(2.0 * area, rel=1e-13)
    inner = np.hypot(*(Y - [0.1, -0.2]).T)
    assert inner.min() > 0.05 and inner.max() < 0.125  # between the rows


def test_traction_duration_and_decay():
    spec = typed("tractions", group="all", value=[2.0, 0.0], ramp=0.0, duration=1.0, decay=0.5, area=3.0)
    loads = Tractions([spec], {"all": np.ones(2, bool)}, np.zeros((2, 2)), np.arange(2), np.ones(2), 1.0, {})
    force = np.zeros((2, 2))
    loads.add(force, 0.25)
    np.testing.assert_allclose(force[:, 0], 6.0 * math.exp(-0.5))
    force[:] = 0.0
    loads.add(force, 1.0)
    assert not force.any()


def test_rubber_ring_stays_rotationally_symmetric_with_the_lagrangian_kernel():
    """[R §9.6]: KBM, Lagrangian kernel, during the pulse: every particle of a row at the
    same radius, the hoop stress at mid-radius the same all round."""
    sim = simulation("rubber_ring", ["time.end=1.5e-5"])
    run_until(sim, 1.5e-5)
    x, X = sim.quantity("position"), sim.quantity("reference_position")
    row = np.round(np.hypot(*X.T) / 0.009375).astype(int)  # radial rows 0.009375 m apart
    for k in np.unique(row):
        r = np.hypot(*x[row == k].T)
        assert np.ptp(r) < 1e-12 * r.mean()
    assert np.hypot(*x[row == row.min()].T).mean() > 0.0501  # the inner surface has moved out
    mid = np.flatnonzero(row == row.min() + 4)
    theta = np.arctan2(x[mid, 1], x[mid, 0])
    t = np.column_stack([-np.sin(theta), np.cos(theta)])
    hoop = np.einsum("na,nab,nb->n", t, readouts.cauchy_stress(sim, mid), t)
    assert np.ptp(hoop) < 1e-9 * np.abs(hoop).max()
