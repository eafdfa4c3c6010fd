"""Ties (parsph.ties): two bars bonded end to end carry a wave as one bar while the tie holds,
break when the traction reaches the strength and separate; the quadratic failure criterion
of one pair; the energy balance and momentum; the same bits on 1, 2 and 3 ranks and across a
restart after the break; bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from parsph.errors import InputError
from parsph.io import read_history
from parsph.ties import _tie
from physics import run_until, simulation

from conftest import RUNS, assert_identical_outputs, assert_runs_by_ranks, parsph

SCENE = (RUNS / "bonded_bars.toml").read_text()
WAVE_SPEED = math.sqrt(200.0e9 / 7850.0)
L, AREA, SPEED, STRENGTH = 0.05, 1.0e-4, 1.0, 60.0e6
SIGMA = 7850.0 * WAVE_SPEED * SPEED  # the first wave's stress, 39.6 MPa: 2 SIGMA after reflection


def one_bar(text: str) -> str:
    """The same scene with the two bars as one bar of length 2L, without the tie."""
    start, end = text.index("[[bodies]]"), text.index("[groups.held]")
    return text[:start] + """[[bodies]]
name = "bar"
[[bodies.parts]]
shape = "box"
lower = [0.0]
upper = ["= 2 * L"]
spacing = "= spacing"
[bodies.material]
model = "saint_venant_kirchhoff"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0

""" + text[end:]


def face_series(sim) -> tuple:
    """(displacement of the left bar's last particle, the tie force on the left bar, broken ties)."""
    i = sim.group_index("left_face") if "left_face" in sim.state.groups else np.zeros(0, int)
    ties = sim.interactions.ties
    left = sim.state.bodies[0]
    force = float(ties.entry_force[0, left.lo:left.hi].sum()) if ties is not None else 0.0
    broken = int(np.count_nonzero(ties.broken)) if ties is not None else 0
    return float(sim.state.u[i, 0].sum()), force, broken


def test_bonded_bars_below_the_strength_carry_the_wave_as_one_bar():
    """Strength above 2 sigma: the tie never breaks, and the face's displacement follows the
    one bar's at the same point (interpolated to the tied run's times: the tie's spring
    shortens the step) to 1 % of its largest value through the first wave, its
    reflection at the held end and its return (t up to 4L/c); the tie carries sigma A, then
    2 sigma A: on average over L/c and 0.5 L/c behind the fronts to 2 %, the discrete bar's
    ripple behind a front within 8 %."""
    end = 4.0 * L / WAVE_SPEED
    strong = SCENE.replace("normal_strength = 60.0e6", "normal_strength = 1.0e9")
    tied = run_until(simulation(strong, ["time.end=4e-5"]), end, probe=face_series)
    bar = run_until(simulation(one_bar(strong), ["time.end=4e-5"]), end, probe=face_series)
    u_tied = np.array([p[0] for p in tied["probe"]])
    u_bar = np.array([p[0] for p in bar["probe"]])
    force = np.array([p[1] for p in tied["probe"]])
    assert all(p[2] == 0 for p in tied["probe"])
    along = np.interp(tied["time"], bar["time"], u_bar)  # the tie's spring shortens the step: other times
    assert np.abs(u_tied - along).max() < 0.01 * np.abs(u_bar).max()
    t = tied["time"]
    first = (t > 1.5 * L / WAVE_SPEED) & (t < 2.5 * L / WAVE_SPEED)
    second = t > 3.5 * L / WAVE_SPEED
    for window, stress in ((first, SIGMA), (second, 2.0 * SIGMA)):  # the tie pulls the left bar right: F > 0
        assert abs(force[window].mean() / (stress * AREA) - 1.0) < 0.02
        assert np.abs(force[window] / (stress * AREA) - 1.0).max() < 0.08  # the discrete bar's ripple


def test_the_tie_breaks_when_the_reflected_wave_brings_its_strength_and_the_bars_separate():
    """Strength between sigma and 2 sigma: the tie holds the first wave and breaks when the
    reflected front reaches it, at 3L/c to 1 %, having carried the strength times the tied
    area to 3 % (its largest force); then the faces part at the relative speed 4V the release
    waves give them (to 5 %), and the tie's energy
    has gone to the released energy, the total energy constant to 1e-3 of the work put in and
    the momentum that the forces between particles leave at round-off."""
    sim = simulation(SCENE)
    rows = run_until(sim, 4.5e-5, probe=face_series)
    force = np.array([p[1] for p in rows["probe"]])
    broken = np.array([p[2] for p in rows["probe"]])
    t = rows["time"]
    at = int(np.argmax(broken > 0))
    assert broken[-1] == 2 and at > 0  # the one tie, on both of its particles
    assert abs(t[at] / (3.0 * L / WAVE_SPEED) - 1.0) < 0.01
    assert abs(force[:at].max() / (STRENGTH * AREA) - 1.0) < 0.03
    assert (force[at:] == 0.0).all()
    gap = (sim.state.X[sim.group_index("right_face"), 0] + sim.state.u[sim.group_index("right_face"), 0]
           - sim.state.X[sim.group_index("left_face"), 0] - sim.state.u[sim.group_index("left_face"), 0])
    # released, the faces part at 2V each (the left from stress 2 sigma at rest, the right from sigma
    # at V) until the release waves return, 2L/c later
    assert abs((gap[0] - 5.0e-4) / (4.0 * SPEED * (t[-1] - t[at])) - 1.0) < 0.05
    released = rows["tie_released"]
    assert released[-1] > 0.5 * rows["tie_energy"][at - 1] and rows["tie_energy"][-1] == 0.0
    drift = rows["total_energy"] - rows["total_energy"][0]
    assert np.abs(drift).max() < 1.0e-3 * rows["external_work"][-1]
    assert np.abs(rows["momentum_defect_x"]).max() < 1.0e-12 * np.abs(rows["momentum_x"]).max()


def strip(text: str) -> str:
    """The bonded bars as 2D strips 4 mm high (plane strain, nu = 0: the same waves), held and
    pulled along their end columns, the face probes at mid-height."""
    for old, new in (("dimension = 1", "dimension = 2"),
                     ("area = 1.0e-4   # cross-section [m^2]", "thickness = 1.0e-2"),
                     ("speed = 1.0\n", "speed = 1.0\nH = 4.0e-3\n"),
                     ('lower = [0.0]\nupper = ["= L"]', 'lower = [0.0, 0.0]\nupper = ["= L", "= H"]'),
                     ('lower = ["= L"]\nupper = ["= 2 * L"]', 'lower = ["= L", 0.0]\nupper = ["= 2 * L", "= H"]'),
                     ('nearest = [0.0]', 'box = { lower = [-1.0, -1.0], upper = ["= spacing / 2", 1.0] }'),
                     ('nearest = ["= 2 * L"]', 'box = { lower = ["= 2 * L - spacing / 2", -1.0], upper = [1.0, 1.0] }'),
                     ('nearest = ["= L - spacing / 2"]', 'nearest = ["= L - spacing / 2", "= H / 2 - spacing / 2"]'),
                     ('nearest = ["= L + spacing / 2"]', 'nearest = ["= L + spacing / 2", "= H / 2 - spacing / 2"]'),
                     ('value = ["= speed"]', 'value = ["= speed", 0.0]')):
        assert old in text
        text = text.replace(old, new)
    return text


def test_bonded_strips_in_2d_carry_the_wave_and_break_together_at_the_strength():
    """The same in 2D (4 particles across the face, each tied to the one facing it): the tie
    forces carry sigma times the face area to 1 % on average behind the first front, have no
    lateral resultant (below 1e-9 of it), and every tie breaks in one step, at 3L/c to 1 %,
    having carried the strength times the face area to 3 %; the total energy stays constant
    to 1e-3 of the work put in."""
    sim = simulation(strip(SCENE), ["parameters.spacing=1e-3", "time.cfl=0.3"])
    face = 4.0e-3 * 1.0e-2

    def probe(sim):
        left = sim.state.bodies[0]
        pull = sim.interactions.ties.entry_force[0, left.lo:left.hi].sum(axis=0)
        return pull[0], pull[1], int(np.count_nonzero(sim.interactions.ties.broken))

    rows = run_until(sim, 4.0e-5, probe=probe)
    pull, lateral, broken = (np.array([p[k] for p in rows["probe"]]) for k in range(3))
    t = rows["time"]
    assert len(sim.interactions.ties.broken) == 8  # 4 pairs, each on both of its particles
    first = (t > 1.5 * L / WAVE_SPEED) & (t < 2.5 * L / WAVE_SPEED)
    assert abs(pull[first].mean() / (SIGMA * face) - 1.0) < 0.01
    assert np.abs(lateral).max() < 1.0e-9 * np.abs(pull).max()
    at = int(np.argmax(broken > 0))
    assert broken[at] == 8 and abs(t[at] / (3.0 * L / WAVE_SPEED) - 1.0) < 0.01
    assert abs(pull[:at].max() / (STRENGTH * face) - 1.0) < 0.03
    drift = rows["total_energy"] - rows["total_energy"][0]
    assert np.abs(drift).max() < 1.0e-3 * rows["external_work"][-1]


def test_with_contact_the_tie_breaks_alike_and_both_springs_bound_the_step():
    """bonded_bars with [[contact]] between the bars as well (it carries nothing in tension):
    the tie breaks at 3L/c to 1 %, the stable step's bound is the sum of both interactions'
    springs (at the start, tied), and the total energy stays constant to 1e-3 of the work put in."""
    text = SCENE.replace("[[ties]]", '[[contact]]\nbodies = ["left", "right"]\n\n[[ties]]')
    sim = simulation(text)
    assert [i.name for i in sim.interactions] == ["contact", "ties"]
    assert (sim.interactions.omega2 == sim.interactions.contact.omega2 + sim.interactions.ties.omega2).all() and sim.interactions.ties.omega2.max() > 0
    rows = run_until(sim, 3.5e-5, probe=face_series)
    broken = np.array([p[2] for p in rows["probe"]])
    assert abs(rows["time"][np.argmax(broken > 0)] / (3.0 * L / WAVE_SPEED) - 1.0) < 0.01
    drift = rows["total_energy"] - rows["total_energy"][0]
    assert np.abs(drift).max() < 1.0e-3 * rows["external_work"][-1]


def test_the_ties_dashpots_work_is_booked():
    """With damping 0.5 the dashpots take energy (tie_work > 0), the tie still breaks near 3L/c
    and the total energy, with the tie work, stays constant to 1e-3 of the work put in."""
    sim = simulation(SCENE.replace("shear_strength = 60.0e6", "shear_strength = 60.0e6\ndamping = 0.5"))
    rows = run_until(sim, 3.5e-5, probe=face_series)
    assert rows["tie_work"][-1] > 0.05 * rows["tie_energy"].max()  # 16 % of it
    assert np.array([p[2] for p in rows["probe"]])[-1] == 2
    drift = rows["total_energy"] - rows["total_energy"][0]
    assert np.abs(drift).max() < 1.0e-3 * rows["external_work"][-1]


@pytest.mark.parametrize("opening, sliding, breaks", [(0.59, 0.0, False), (0.61, 0.0, True), (-5.0, 0.0, False),
                                                      (0.0, 0.79, False), (0.0, 0.81, True),
                                                      (0.4, 0.55, False), (0.45, 0.6, True)])
def test_one_pair_fails_by_the_quadratic_criterion(opening, sliding, breaks):
    """A 2D pair, normal along y, k_n = 1e11 Pa/m and k_t = 0.5e11 Pa/m, N = 60 MPa and
    S = 40 MPa: the pair breaks exactly when (max(sigma_n, 0) / N)^2 + (tau / S)^2 >= 1
    (openings and slidings in mm: sigma_n = k_n s, tau = k_t |w_t|; compression never breaks
    it); its force is A t, equal and opposite on the two particles; a broken pair releases
    its energy (the last evaluation at the same state: no step's correction)."""
    u = np.array([[0.0, 0.0], [sliding * 1e-3, opening * 1e-3]])
    rows = {}
    for i in range(2):
        out = dict(force=np.zeros((2, 2)), dissipation=np.zeros((0, 2)), energy=np.zeros(2), omega2=np.zeros(2),
                   released=np.zeros(2), entry_force=np.zeros((1, 2, 2)))
        other = 1 - i
        ptr = np.array([0, 1, 1]) if i == 0 else np.array([0, 0, 1])
        _tie(2, ptr, np.array([other]), np.array([i == 0]), u, np.zeros((2, 2)), np.array([[0.0, 1.0]]),
             np.array([2.0e-4]), np.array([1.0e11]), np.array([0.5e11]), np.array([[60.0e6, 40.0e6]]),
             np.array([1.0]), np.array([0.0]), np.array([0]), np.ones(2), np.zeros(1, np.bool_),
             (u[1] - u[0])[None, :].copy(), out["force"], out["dissipation"], out["energy"], out["omega2"],
             out["released"], out["entry_force"])
        rows[i] = out
    sigma, tau = 1.0e11 * opening * 1e-3, 0.5e11 * sliding * 1e-3
    assert ((max(sigma, 0.0) / 60e6) ** 2 + (tau / 40e6) ** 2 >= 1.0) == breaks
    energy = 0.5 * 2.0e-4 * (1.0e11 * (opening * 1e-3) ** 2 + 0.5e11 * (sliding * 1e-3) ** 2)
    if breaks:
        assert (rows[0]["force"] == 0.0).all() and (rows[1]["force"] == 0.0).all()
        assert rows[0]["released"][0] + rows[1]["released"][1] == pytest.approx(energy, rel=1e-14)
    else:
        expected = 2.0e-4 * np.array([tau if sliding else 0.0, sigma])
        assert rows[0]["force"][0] == pytest.approx(expected, rel=1e-14)
        assert (rows[1]["force"][1] == -rows[0]["force"][0]).all()
        assert rows[0]["energy"][0] + rows[1]["energy"][1] == pytest.approx(energy, rel=1e-14)


@pytest.mark.mpi
def test_ties_are_the_same_on_1_2_and_3_ranks_and_across_a_restart_after_the_break(tmp_path):
    """bonded_bars at 1 mm spacing (on 2 ranks the tie joins two ranks' particles): the same
    history and final state bit for bit on 1, 2 and 3 ranks, and a run checkpointed on 2
    ranks after the tie broke, restarted on 3, continues exactly; the tie did break."""
    # time.cfl 0.42: the scene's 0.5 step before the step followed the force operator (the
    # checkpoint at step 400 falls after the break)
    coarse = ["--set", "parameters.spacing=1e-3", "--set", "time.end=4e-5", "--set", "time.cfl=0.42"]
    scene = RUNS / "bonded_bars.toml"
    bars, split = tmp_path / "bars", tmp_path / "split"
    # three MPI jobs (conftest.parsph_by_ranks): one rank; two ranks straight and stopped;
    # three ranks straight and restarted
    assert_runs_by_ranks([(n, ["run", scene, "--out", bars / f"ranks_{n}", "--quiet", *coarse]) for n in (1, 2)]
                         + [(2, ["run", scene, "--out", split, "--quiet", *coarse, "--set", "time.max_steps=400",
                                 "--set", "output.checkpoint_every=400"])], tmp_path / "batch")
    assert read_history(split)["tie_released"][-1] > 0.0  # the checkpoint has the tie broken
    assert_runs_by_ranks([(3, ["run", scene, "--out", bars / "ranks_3", "--quiet", *coarse]),
                          (3, ["run", scene, "--out", split, "--quiet", *coarse, "--restart", "latest"])],
                         tmp_path / "batch_restart")
    for other in (bars / "ranks_2", bars / "ranks_3", split):
        assert_identical_outputs(bars / "ranks_1", other)
    history = read_history(bars / "ranks_1")
    assert history["ties_broken.left.right"][-1] == 1.0 and history["tie_energy"][-1] == 0.0
    assert history["tie_force_x.left.right"].max() > 0.9 * STRENGTH * AREA  # it carried its strength


@pytest.mark.parametrize("tie, message", [
    ('bodies = ["left", "rigth"]', "ties[0].bodies names body 'rigth', which is not defined"),
    ('bodies = ["left", "left"]', "ties[0].bodies: body 'left' is tied to itself"),
    ('bodies = ["left"]', "ties[0].bodies must name two bodies"),
    ('normal_strength = -1.0', "ties[0].normal_strength must be > 0"),
    ('shear_strength = 0.0', "ties[0].shear_strength must be > 0"),
    ('damping = 2.0', "ties[0].damping must be in [0.0, 1.0]"),
    ('strenght = 1.0', "unknown key 'ties[0].strenght'"),
])
def test_bad_ties_are_refused(tie, message):
    given = {line.split(" = ")[0]: line for line in tie.split("\n")}
    keys = {"bodies": 'bodies = ["left", "right"]', "normal_strength": "normal_strength = 60.0e6",
            "shear_strength": "shear_strength = 60.0e6"}
    block = "\n".join({**keys, **given}.values())
    text = SCENE.replace('[[ties]]\nbodies = ["left", "right"]\nnormal_strength = 60.0e6\nshear_strength = 60.0e6',
                         "[[ties]]\n" + block)
    assert text != SCENE
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        simulation(text)


def test_a_distance_beyond_the_halo_exits_2_naming_the_key(tmp_path):
    """The ghosts reach the largest kernel support (1.5 spacings here): a tie distance of 2
    spacings could miss partners on another rank, and is refused with exit code 2."""
    scene = tmp_path / "far.toml"
    scene.write_text(SCENE.replace("shear_strength = 60.0e6", "shear_strength = 60.0e6\ndistance = 1.0e-3"))
    proc = parsph(["run", scene, "--out", tmp_path / "out", "--quiet"])
    assert proc.returncode == 2 and "ties[0].distance = 0.001 m exceeds the halo's reach" in proc.stderr
