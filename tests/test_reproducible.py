"""The same history bit for bit on any number of ranks (exact sums, parsph.exact_sum), the
last step landing on time.end, and blow-up messages that name the problem."""

from __future__ import annotations

import math
import random
import re
from fractions import Fraction

import numpy as np
import pytest

from conftest import BAR, parsph
from physics import block_2d, simulation

from parsph.exact_sum import Accumulator, Exact, allsum, sums, total
from parsph.io import read_history, read_snapshots


# ---- exact sums
def exact_reference(values) -> float:
    """The correctly rounded sum (math.fsum, or exact rationals where fsum overflows)."""
    values = np.ravel(values).tolist()
    try:
        return math.fsum(values)
    except OverflowError:
        return float(sum(map(Fraction, values), Fraction(0)))


def nasty(rng, n):
    """Values over the whole exponent range, subnormals, zeros and near-cancelling pairs."""
    x = rng.standard_normal(n) * 2.0 ** rng.integers(-1090, 1000, n).astype(float)
    x[rng.random(n) < 0.1] = 0.0
    pairs = -x[: n // 3] * (1.0 + 2.0 ** -52 * rng.integers(-3, 4, n // 3))
    out = np.concatenate([x, pairs, [5e-324, -1e-320, 2.2250738585072014e-308]])
    rng.shuffle(out)
    return out


@pytest.mark.parametrize("values", [
    [], [0.0, -0.0], [1e16, 1.0, -1e16], [1.0, 1e100, 1.0, -1e100], [5e-324] * 7,
    [2.2250738585072014e-308, -2.225073858507201e-308], [1e308, 1e308, -1e308],
    [1.0, 2.0 ** -53], [1.0, 2.0 ** -53, 2.0 ** -105], [0.1] * 10,
])
def test_exact_sum_is_the_correctly_rounded_sum(values):
    assert float(total(np.array(values, float))) == exact_reference(values)


def test_exact_sum_on_random_data_over_the_whole_exponent_range():
    rng = np.random.default_rng(1)
    for _ in range(100):
        x = nasty(rng, int(rng.integers(0, 400)))
        assert float(total(x)) == exact_reference(x)
    x = rng.standard_normal(10 ** 6) * np.exp(rng.uniform(-40.0, 40.0, 10 ** 6))
    assert float(total(x)) == math.fsum(x.tolist())
    columns = rng.standard_normal((1000, 3)) * [1.0, 1e-300, 1e300]
    assert [float(s) for s in sums(columns)] == [math.fsum(c) for c in columns.T.tolist()]
    assert [float(s) for s in sums(np.zeros((0, 3)))] == [0.0, 0.0, 0.0]


def test_exact_sum_does_not_depend_on_order_or_partition():
    rng = np.random.default_rng(2)
    x = nasty(rng, 3000)
    whole = total(x)
    for _ in range(20):
        perm = rng.permutation(x)
        cuts = np.sort(rng.integers(0, len(x), rng.integers(0, 6)))
        parts = [total(p) for p in np.split(perm, cuts)]
        random.Random(0).shuffle(parts)
        summed = sum(parts[1:], parts[0])
        assert summed.units == whole.units and float(summed) == float(whole)
    acc = Accumulator()
    for p in np.array_split(x, 7):
        acc.add(p)
    assert acc.sums()[0].units == whole.units


def test_exact_sum_keeps_non_finite_values_and_overflow():
    assert math.isnan(float(total(np.array([1.0, np.nan]))))
    assert math.isnan(float(total(np.array([np.inf, 1.0, -np.inf]))))
    assert float(total(np.array([np.inf, 1.0, 1e308]))) == math.inf
    assert float(total(np.array([-np.inf, 2.0]))) == -math.inf
    assert float(total(np.array([1.7e308, 1.7e308]))) == math.inf  # beyond the float range
    assert float(total(np.array([-1.7e308, -1.7e308]))) == -math.inf
    split = total(np.array([np.inf, 1.0])) + total(np.array([-np.inf]))  # on two ranks
    assert math.isnan(float(split))


def test_exact_sum_survives_json_and_a_single_rank_allsum():
    from mpi4py import MPI

    rng = np.random.default_rng(3)
    s = total(nasty(rng, 500))
    for value in (s, -s, Exact(0, math.inf), Exact(0, -math.inf)):
        back = Exact.from_json(value.to_json())
        assert back.units == value.units and float(back) == float(value)
    assert math.isnan(float(Exact.from_json(Exact(0, math.nan).to_json())))
    assert allsum(MPI.COMM_SELF, [s])[0].units == s.units


# ---- the same history on 1 and 3 ranks
# 24 x 8 particles, updated reference every 7 steps (ownership re-decided at each update),
# a tool pressing on the top, a wall on the left, the bottom driven up (reactions: external
# work) under gravity; probes reduced by sum and mean.
SCENE = """
[scene]
name = "reproducible"
dimension = 2
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [0.06, 0.02]
spacing = 2.5e-3
[kernel]
type = "wendland_c2"
support = 2.2
[material]
model = "neo_hookean"
density = 1100.0
youngs_modulus = 1.0e6
poisson_ratio = 0.3
[formulation]
type = "ulsph"
update_every = 7
hourglass = 50.0
hourglass_form = "FORM"
hessian = ETA
[time]
end = 1.0
[loads]
body_acceleration = [0.0, -2000.0]
[groups.bottom]
box = { lower = [-1.0, -1.0], upper = [1.0, 1.5e-3] }
[[bc]]
type = "velocity"
group = "bottom"
value = [0.0, 0.5]
ramp = 1.0e-3
components = [1]
[[initial]]
type = "velocity"
value = [-1.0, 0.0]
[[walls]]
point = [1.1e-3, 0.0]
normal = [1.0, 0.0]
[[tools]]
lower = [0.02, 0.0186]
upper = [0.04, 0.03]
radius = 2.0e-3
velocity = [0.0, -1.0]
[[probes]]
name = "reaction_sum"
group = "bottom"
quantity = "reaction"
component = 1
reduce = "sum"
[[probes]]
name = "speed_mean"
group = "all"
quantity = "velocity"
reduce = "mean"
[[probes]]
name = "J_mean"
group = "all"
quantity = "J"
[[probes]]
name = "disorder_sum"
group = "all"
quantity = "disorder"
reduce = "sum"
[output]
history_interval = 0.0
history_every = 1
snapshot_fields = ["position", "velocity", "J"]
"""
VARIANTS = {"paper": SCENE.replace("FORM", "paper").replace("ETA", "0.0"),
            "variational_hessian": SCENE.replace("FORM", "variational").replace("ETA", "0.3")}


def run_scene(tmp_path, name, text, ranks, *extra):
    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    out = tmp_path / f"{name}_r{ranks}"
    proc = parsph(["run", scene, "--out", out, "--quiet", *extra], ranks=ranks)
    assert proc.returncode == 0, proc.stderr
    return out


def history(out) -> dict:
    return read_history(out)


def final_state(out) -> dict:
    return read_snapshots(out, ("position", "velocity", "J"), which=-1)[0].fields


def assert_same_run(a, b):
    ha, hb = history(a), history(b)
    assert sorted(ha) == sorted(hb)
    for name in ha:
        assert np.array_equal(ha[name], hb[name]), f"history '{name}' differs"
    sa, sb = final_state(a), final_state(b)
    for name in sa:
        assert np.array_equal(sa[name], sb[name]), f"final {name} differs"
    return ha


@pytest.mark.mpi
def test_history_is_the_same_bit_for_bit_on_1_and_3_ranks(tmp_path):
    """The variational hourglass form with Hessian stabilisation (the paper form, with its
    step-by-step work total, is compared across rank counts through a restart below)."""
    variant = "variational_hessian"
    runs = [run_scene(tmp_path, variant, VARIANTS[variant], n, "--set", "time.max_steps=84")
            for n in (1, 3)]
    h = assert_same_run(*runs)
    assert h["reference_updates"][-1] == 12
    assert np.abs(h["tool0_force_y"]).max() > 0 and np.abs(h["wall0_force_x"]).max() > 0  # contact
    assert np.abs(h["external_work"]).max() > 0 and np.abs(h["hourglass_energy"]).max() > 0


@pytest.mark.mpi
def test_restart_on_other_rank_counts_continues_every_history_series_bit_for_bit(tmp_path):
    """The paper hourglass form (work absorbed step by step): straight on 2 ranks; split: 1
    rank to a checkpoint between updates (step 45), 3 ranks on."""
    text = VARIANTS["paper"]
    straight = run_scene(tmp_path, "straight", text, 2, "--set", "time.max_steps=90")
    split = run_scene(tmp_path, "split", text, 1, "--set", "time.max_steps=45",
                      "--set", "output.checkpoint_every=45")
    scene = tmp_path / "split.toml"
    proc = parsph(["run", scene, "--out", split, "--quiet", "--set", "time.max_steps=90",
                   "--restart", "latest"], ranks=3)
    assert proc.returncode == 0, proc.stderr
    h = assert_same_run(straight, split)
    assert np.array_equal(h["step"], np.arange(91))
    assert np.abs(h["tool0_force_y"]).max() > 0 and np.abs(h["hourglass_energy"]).max() > 0


# ---- the last step
def test_last_step_lands_exactly_on_the_end_time():
    sim = simulation(BAR)
    assert sim.dt > 1e-9
    assert sim.step(1e-9) == 1e-9
    assert sim.t == 1e-9 and sim.step_count == 1
    sim = simulation(BAR)
    end = 10.5 * sim.dt
    while sim.t < end * (1 - 1e-12):
        sim.step(end)
    assert sim.t == end and sim.step_count == 11


def test_a_step_within_a_relative_1e_12_of_the_end_lands_on_it():
    sim = simulation(BAR)
    end = sim.dt * (1.0 + 1e-13)
    sim.step(end)
    assert sim.t == end and sim.step_count == 1


# ---- blow-up messages
def run_failing(tmp_path, text, ranks=1, *extra):
    scene = tmp_path / "scene.toml"
    scene.write_text(text)
    proc = parsph(["run", scene, "--out", tmp_path / "out", "--quiet", *extra], ranks=ranks)
    err = proc.stderr
    assert proc.returncode == 1, f"exit code {proc.returncode}\n{err}"
    assert "Traceback" not in err and ".." not in err, err
    assert err.count("parsph: error") == 1, err
    return err


def test_blow_up_with_a_fixed_step_advises_reducing_time_dt(tmp_path):
    """The bar of runs/bar1d.toml (neo-Hookean) with time.dt 1.5 times its CFL step (1.27 times
    its force operator's limit 2 / omega_max, 7.9e-6 s)."""
    text = BAR.replace("saint_venant_kirchhoff", "neo_hookean").replace("cfl = 0.5", "dt = 1.0e-5")
    err = run_failing(tmp_path, text, 1, "--set", "time.max_steps=1000")
    assert re.search(r"particle \d+ at \(.*\) is inverted", err), err
    assert "reduce time.dt = 1e-05 s" in err and "reduce time.cfl" not in err, err
    step = float(re.search(r"the CFL step, time.cfl times the stable step, was (\S+) s at step 0", err)[1])
    assert 6e-6 < step < 7.5e-6, err


# the upper part of a 10 x 12 block flattened in y onto y = 0.3 (J = 1e-9 > 0: not inverted,
# but no stable step) deep inside, compressed less near y = 0.3
FLATTENED = block_2d(model="neo_hookean", hourglass=50.0).replace("upper = [1.0, 0.6]",
                                                                  "upper = [1.0, 1.2]") + """
[groups.squashed]
box = { lower = [-1.0, 0.3], upper = [2.0, 2.0] }
[[initial]]
type = "displacement_gradient"
group = "squashed"
gradient = [[0.0, 0.0], [0.0, -0.999999999]]
center = [0.0, 0.3]
"""


@pytest.mark.parametrize("ranks", [1, pytest.param(3, marks=pytest.mark.mpi)])
def test_collapsed_time_step_names_the_particle(tmp_path, ranks):
    """The message names a flattened particle (the lowest id with a zero step), the same on
    any rank count."""
    from parsph.errors import ParsphError

    err = run_failing(tmp_path, FLATTENED, ranks)
    with pytest.raises(ParsphError) as single:
        simulation(FLATTENED)
    assert f"parsph: error: {single.value}\n" in err
    found = re.search(r"the stable time step collapsed to zero at step 0, t = 0: particle (\d+) at "
                      r"\(([^)]*)\) is flattened", err)
    assert found, err
    x = [float(c) for c in found[2].split(",")]
    assert abs(x[1] - 0.3) < 1e-8, err  # in the flattened part
    assert "reduce time.cfl" in err


def test_failed_reference_update_message_has_no_double_period(tmp_path):
    """The bar updated every step with its tip thrown outwards at 1e5 m/s: after the first
    step the tip has no neighbours in the new reference."""
    text = (BAR.replace('type = "tlsph"', 'type = "ulsph"\nupdate_every = 1')
            .replace('group = "right_quarter"\nvalue = [5.0]', 'group = "B"\nvalue = [1.0e5]'))
    err = run_failing(tmp_path, text, 1, "--set", "time.max_steps=5")
    assert re.search(r"reference update 1 at step 1, .* failed: .*particle 39 .*\. The particles are too "
                     "disordered", err), err
