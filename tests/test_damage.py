"""Tensile damage [G eq. 45-46] (materials/damage.py, `material.failure_strain`): the
degraded stress in principal axes, the growth law, and a notched strip pulled to failure:
it breaks across the notch, the energy balance (with the damage work) closes,
and the run is the same bit for bit on 1 and 3 ranks and across a restart."""

from __future__ import annotations

import math
import re

import h5py
import numpy as np
import pytest

from conftest import assert_identical_outputs, assert_it_happened, parsph, parsph_batch
from parsph.diagnostics import global_diagnostics
from parsph.materials import damage
from physics import simulation


def degraded(P: np.ndarray, F: np.ndarray, D: float) -> tuple:
    """(P after degrade, the trial row) at one point with damage D."""
    state = damage.initial_state(1)
    state[0, damage.DAMAGE] = D
    trial = state.copy()
    P = P.copy()
    damage.degrade(P, np.ascontiguousarray(F), F.shape[0], state, trial, 0, np.empty((7, 3, 3)))
    return P, trial[0]


def cauchy(P, F):
    return P @ F.T / np.linalg.det(F)


def test_positive_principal_stresses_are_scaled_negative_ones_kept():
    """A Cauchy stress with principal values (+3, -2, +1) in rotated axes: with D = 0.25
    they become (2.25, -2, 0.75) in the same axes; with D = 1 only the compression is left."""
    rng = np.random.default_rng(3)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    F = np.eye(3) + 0.05 * rng.standard_normal((3, 3))
    sigma = Q @ np.diag([3.0, -2.0, 1.0]) @ Q.T
    P = np.linalg.det(F) * sigma @ np.linalg.inv(F).T
    for D, expected in ((0.0, [3.0, -2.0, 1.0]), (0.25, [2.25, -2.0, 0.75]), (1.0, [0.0, -2.0, 0.0])):
        out, trial = degraded(P, F, D)
        np.testing.assert_allclose(cauchy(out, F), Q @ np.diag(expected) @ Q.T, atol=1e-12)
        assert trial[damage.DAMAGE] == D
    strain = 0.5 * math.log(np.linalg.eigvalsh(F.T @ F).max())
    assert trial[damage.STRAIN] == pytest.approx(strain, rel=1e-12)


def test_damage_grows_at_the_front_speed_only_beyond_the_failure_strain_and_never_heals():
    """D^(1/3) = 0.4 c0 t / h while the strain exceeds the threshold, capped at 1; no growth
    below it, and what has grown stays."""
    c0, h, dt = 2000.0, 1e-3, 1e-8
    state = damage.initial_state(3)
    state[:, damage.STRAIN] = [0.09, 0.07, 0.09]
    for _ in range(100):
        damage.grow(state, 0.08, c0, np.full(3, h), dt)
    assert state[0, damage.DAMAGE] == pytest.approx((0.4 * c0 * 100 * dt / h) ** 3, rel=1e-12)
    assert state[1, damage.DAMAGE] == 0.0
    state[0, damage.STRAIN] = 0.0  # unloaded: stays
    before = state[0, damage.DAMAGE]
    damage.grow(state, 0.08, c0, np.full(3, h), dt)
    assert state[0, damage.DAMAGE] == before
    for _ in range(2000):
        damage.grow(state, 0.08, c0, np.full(3, h), dt)
    assert state[2, damage.DAMAGE] == 1.0


STRIP = """
[scene]
name = "notched_strip"
dimension = 2
[parameters]
s = 5.0e-4
[geometry]
thickness = 1.0e-3
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [10.0e-3, 6.0e-3]
spacing = "= s"
[[geometry.parts]]
shape = "box"
lower = [14.0e-3, 0.0]
upper = [24.0e-3, 6.0e-3]
spacing = "= s"
[[geometry.parts]]
shape = "box"
lower = [10.0e-3, 1.0e-3]
upper = [14.0e-3, 5.0e-3]
spacing = "= s"
[kernel]
support = 2.0
[material]
model = "saint_venant_kirchhoff"
density = 2700.0
youngs_modulus = 10.0e9
poisson_ratio = 0.3
failure_strain = 0.03
[formulation]
type = "tlsph"
hourglass = 50.0
hourglass_form = "paper"
[time]
end = 1.3e-5
[groups.held]
box = { lower = [-1.0, -1.0], upper = [1.0e-3, 1.0] }
[groups.pulled]
box = { lower = [23.0e-3, -1.0], upper = [1.0, 1.0] }
[[bc]]
type = "fixed"
group = "held"
[[bc]]
type = "velocity"
group = "pulled"
value = [50.0, 0.0]
ramp = 2.0e-6
[[probes]]
name = "force"
group = "pulled"
quantity = "reaction"
component = 0
reduce = "sum"
[output]
history_interval = 1.0e-6
snapshot_interval = 1.0e-5
snapshot_fields = ["position", "velocity", "damage"]
"""


def test_notched_strip_breaks_across_the_notch_and_the_energy_balance_closes():
    sim = simulation(STRIP)
    peak = 0.0
    while sim.t < 1.3e-5:  # the crack has crossed the neck
        sim.step(1.3e-5)
        peak = max(peak, float(sim.conditions.reaction(sim.state)[sim.group_index("pulled"), 0].sum()))
    d = global_diagnostics(sim)
    assert abs(d["total_energy"]) < 1e-3 * d["external_work"]  # the balance closes
    assert d["damage_work"] > 0  # the work the failed particles took, now dissipated
    n = sim.state.n_owned
    D = sim.quantity("damage", np.arange(n))
    failed = D == 1.0
    X = sim.state.X[:n]
    assert np.all(np.abs(X[failed, 0] - 12e-3) < 4.5e-3)  # at the neck (10-14 mm) and its corners
    neck_rows = np.unique(X[(X[:, 1] > 1e-3) & (X[:, 1] < 5e-3), 1])
    assert np.isin(neck_rows, X[failed, 1]).all()  # the crack crosses every row of the neck
    force = float(sim.conditions.reaction(sim.state)[sim.group_index("pulled"), 0].sum())
    assert peak > 0 and abs(force) < 0.2 * peak  # no longer carries the load


def pair_components(sim) -> np.ndarray:
    """The connected components of the owned particles' pair graph (one rank): a label each."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n, ref = sim.state.n_owned, sim.topology.relations[0].ref
    graph = csr_matrix((np.ones(len(ref.idx)), ref.idx, ref.ptr), shape=(n, n))
    return connected_components(graph, directed=False)[1]


@pytest.mark.parametrize("breaking", [False, True])
def test_with_pair_breaking_the_crack_opens_and_the_strip_comes_apart(breaking):
    """The notched strip to 25 us with material.break_pairs: its failed particles have no
    pairs, the intact ones form two bodies, one held and one pulled, which have moved apart
    by more than a spacing at the crack; the balance (the strain energy released by the
    broken pairs counted as damage work) closes to 1 % of the external work. Without it the
    strip stays one piece, glued by its failed particles."""
    text = STRIP.replace("end = 1.3e-5", "end = 2.5e-5")
    if breaking:
        text = text.replace("failure_strain = 0.03", "failure_strain = 0.03\nbreak_pairs = true")
    sim = simulation(text)
    worst = 0.0
    while sim.t < 2.5e-5:
        sim.step(2.5e-5)
        d = global_diagnostics(sim)
        worst = max(worst, abs(d["total_energy"]) / d["external_work"]) if sim.step_count > 20 else 0.0
    n = sim.state.n_owned
    failed = sim.quantity("damage", np.arange(n)) == 1.0
    label = pair_components(sim)
    intact = np.unique(label[~failed])
    held, pulled = label[sim.group_index("held")], label[sim.group_index("pulled")]
    if not breaking:
        assert len(intact) == 1
        return
    assert failed.sum() > 10 and not np.isin(np.flatnonzero(failed), sim.topology.relations[0].ref.idx).any()
    assert np.all(np.diff(sim.topology.relations[0].ref.ptr)[failed] == 0)
    assert len(intact) == 2 and len(np.unique(held)) == len(np.unique(pulled)) == 1 and held[0] != pulled[0]
    x = sim.state.X[:n] + sim.state.u[:n]
    a, b = x[label == held[0]], x[label == pulled[0]]
    gap = np.sqrt(((a[:, None] - b[None]) ** 2).sum(axis=2)).min()
    assert gap > 1.5 * 0.5e-3  # the spacing s
    assert worst < 0.01


@pytest.mark.parametrize("self_contact", [False, True])
def test_with_self_contact_the_faces_of_a_crack_push_apart_instead_of_passing_through(self_contact):
    """The notched strip as a body with break_pairs, broken in two (20 us), then its pulled
    end driven back at 50 m/s for 30 us: with self-contact the crack's faces meet and hold
    (no two particles of the two pieces closer than 0.6 of a spacing); without it the pieces
    pass into each other."""
    text = STRIP.replace("[[geometry.parts]]", "[[bodies.parts]]", 1).replace(
        "[[bodies.parts]]", '[[bodies]]\nname = "strip"\n[[bodies.parts]]', 1).replace(
        "[[geometry.parts]]", "[[bodies.parts]]").replace("[material]", "[bodies.material]").replace(
        "failure_strain = 0.03", "failure_strain = 0.03\nbreak_pairs = true").replace("end = 1.3e-5", "end = 5.0e-5")
    if self_contact:
        text += '[[contact]]\nbodies = ["strip", "strip"]\nself_contact = true\n'
    sim = simulation(text)
    while sim.t < 2.0e-5:
        sim.step(2.0e-5)
    label = pair_components(sim)
    n = sim.state.n_owned
    held, pulled = label[sim.group_index("held")][0], label[sim.group_index("pulled")][0]
    assert held != pulled  # broken in two
    for c in sim.conditions.bcs.items:
        if c.kind == "velocity":
            c.value = -c.value
    closest = np.inf
    while sim.t < 5.0e-5:
        sim.step(5.0e-5)
        x = sim.state.X[:n] + sim.state.u[:n]
        a, b = x[label == held], x[label == pulled]
        closest = min(closest, np.sqrt(((a[:, None] - b[None]) ** 2).sum(axis=2)).min())
    if self_contact:
        assert closest > 0.6 * 0.5e-3
        assert global_diagnostics(sim)["contact_energy"] >= 0.0
    else:
        assert closest < 0.3 * 0.5e-3


@pytest.mark.mpi
def test_damage_is_the_same_on_three_ranks_and_across_a_restart(tmp_path):
    """One rank straight through against two ranks to the history row at about 3/4 of the
    run (the crack growing) and three after the restart: the same bit for bit; with the
    failed particles' pairs broken too."""
    path = tmp_path / "strip.toml"
    path.write_text(STRIP)
    broken = tmp_path / "broken.toml"
    broken.write_text(STRIP.replace("failure_strain = 0.03", "failure_strain = 0.03\nbreak_pairs = true"))
    same_across_ranks_and_restart([(scene, tmp_path / scene.stem, ()) for scene in (path, broken)])


def same_across_ranks_and_restart(scenes) -> None:
    """For each (PATH, FOLDER, ARGS) of `scenes`: `parsph run PATH ARGS` on one rank straight
    through against two ranks to a history row at about 3/4 of the run and three after a
    restart from there: the same bit for bit. The scenes' runs on each rank count go one
    after another in one MPI job (conftest.parsph_batch): three jobs in all, whose starts
    would otherwise take most of the time."""
    ones = [folder / "one" for _, folder, _ in scenes]
    splits = [folder / "split" for _, folder, _ in scenes]
    batch = scenes[0][1].parent / f"batch_{scenes[0][1].name}"
    for proc in parsph_batch([["run", path, "--out", one, "--quiet", *args]
                              for (path, _, args), one in zip(scenes, ones)], 1, batch / "one"):
        assert proc.returncode == 0, proc.stderr
    stops = []
    for one in ones:
        with h5py.File(one / "history.h5", "r") as f:
            steps, work = f["step"][()].astype(int), f["damage_work"][()]
        at = np.argmin(np.abs(steps - 0.75 * steps[-1]))
        stops.append(steps[at])  # a row: the stopped run writes one there
        assert 0.0 < work[at] < work[-1], f"{one}: the strip must be cracking at the restart and go on after it"
    stopped = [["run", path, "--out", split, "--quiet", *args, "--set", f"time.max_steps={stop}",
                "--set", f"output.checkpoint_every={stop}"]
               for (path, _, args), split, stop in zip(scenes, splits, stops)]
    restarted = [["run", path, "--out", split, "--quiet", *args, "--restart", "latest"]
                 for (path, _, args), split in zip(scenes, splits)]
    for commands, ranks in ((stopped, 2), (restarted, 3)):
        for proc in parsph_batch(commands, ranks, batch / str(ranks)):
            assert proc.returncode == 0, proc.stderr
    for one, split in zip(ones, splits):
        assert_identical_outputs(one, split)
        assert_it_happened(one)
        with h5py.File(one / "snapshots.h5", "r") as f:
            assert f[max((k for k in f if k.startswith("step_")), key=lambda k: int(k[5:]))]["damage"][()].max() == 1.0


@pytest.mark.parametrize("ranks", [1, pytest.param(2, marks=pytest.mark.mpi)])
def test_a_body_whose_every_particle_has_failed_stops_with_a_message(ranks, tmp_path):
    """Every particle stretched beyond a failure strain of 1e-12 fails within a few
    microseconds; then no particle bounds the stable step: the run stops with exit 1 and a
    message instead of writing dt = inf, and the history holds the finite rows before."""
    path = tmp_path / "strip.toml"
    path.write_text(STRIP.replace("failure_strain = 0.03", "failure_strain = 1.0e-12")
                    .replace('[[bc]]\ntype = "fixed"\ngroup = "held"\n', "")
                    + '[[initial]]\ntype = "displacement_gradient"\ngroup = "all"\n'
                      "gradient = [[1.0e-3, 0.0], [0.0, 1.0e-3]]\n")
    proc = parsph(["run", path, "--out", tmp_path / "out", "--quiet"], ranks=ranks)
    err = proc.stderr
    assert proc.returncode == 1 and err.count("parsph: error") == 1 and "Traceback" not in err, err
    assert re.search(r"no particle sets the stable time step at step \d+, .* every particle has failed", err), err
    with h5py.File(tmp_path / "out" / "history.h5", "r") as f:
        assert len(f["dt"]) > 1 and np.isfinite(f["dt"][()]).all()
