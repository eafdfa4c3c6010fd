"""Rigid obstacles from surface files ([[surfaces]], parsph.surfaces): a flat STL pressing a
block as the same [[walls]] plane does, frictionless sliding that keeps the tangential
momentum and Coulomb friction that takes it, the work of a moving and of a turning surface
in the energy balance (their force times velocity, torque times angular velocity), the
punch as an outline against the punch as a tool, the same answer on 1 and 3 ranks, and bad
surface files refused naming the file."""

from __future__ import annotations

import re
import sys

import numpy as np
import pytest
import trimesh

from parsph import preview
from parsph.io import read_history
from physics import run_until, simulation, soft_solid

from conftest import ROOT, RUNS, assert_identical_outputs, assert_runs_by_ranks, assert_same_on_ranks, parsph_batch

sys.path.insert(0, str(ROOT / "tools"))
import measure  # noqa: E402

BLOCK = """
[scene]
name = "surface_block"
dimension = 3
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0, 0.0]
upper = [0.4, 0.4, 0.3]
spacing = 0.1
""" + soft_solid(2.2) + """[formulation]
hourglass = 20.0
[time]
end = 1.0
[output]
history_every = 1
"""


def plane_stl(path) -> str:
    """A square of side 4 m in z = 0 (two triangles) facing +z, written as STL."""
    V = np.array([[-2.0, -2.0, 0.0], [2.0, -2.0, 0.0], [2.0, 2.0, 0.0], [-2.0, 2.0, 0.0]])
    trimesh.Trimesh(V, [[0, 1, 2], [0, 2, 3]], process=False).export(path)
    return str(path)


def surface(file: str, extra: str = "") -> str:
    return f'[[surfaces]]\nfile = "{file}"\n{extra}\n'


@pytest.fixture
def plane(tmp_path):
    return plane_stl(tmp_path / "plane.stl")


def test_a_flat_stl_presses_a_block_as_the_same_wall_plane(plane):
    """A plane rising at 1 m/s from 3 cm below the block's lowest particles: as a two-triangle
    STL and as a [[walls]] plane, the same force history and the same particles, to
    round-off (the STL's closest points are the plane's feet); as an OBJ of the same
    triangles with shared vertices, the STL's exactly."""
    wall = simulation(BLOCK + '[[walls]]\npoint = [0.0, 0.0, 0.02]\nnormal = [0.0, 0.0, 1.0]\nvelocity = [0.0, 0.0, 1.0]\n')
    stl = simulation(BLOCK + surface(plane, "translate = [0.0, 0.0, 0.02]\nvelocity = [0.0, 0.0, 1.0]"))
    a, b = run_until(wall, 0.06), run_until(stl, 0.06)
    assert len(a["time"]) == len(b["time"])
    assert np.abs(a["wall0_force_z"]).max() > 10.0  # pressed
    assert np.allclose(b["surface0_force_z"], a["wall0_force_z"], rtol=1e-9, atol=1e-9 * np.abs(a["wall0_force_z"]).max())
    assert np.abs(b["surface0_force_x"]).max() < 1e-9 * np.abs(a["wall0_force_z"]).max()
    (name, drawn), = preview.obstacle_surfaces(stl.scene, stl.state.X, stl.t)  # the plane where it is
    assert name == "surface0" and np.allclose(drawn[..., 2], 0.02 + stl.t, rtol=0, atol=1e-15)
    obj = plane.replace(".stl", ".obj")  # the same triangles with shared vertices
    trimesh.load(plane, process=False).export(obj)
    assert np.array_equal(run_until(simulation(BLOCK + surface(obj, "translate = [0.0, 0.0, 0.02]\n"
                                                               "velocity = [0.0, 0.0, 1.0]")), 0.06)["surface0_force_z"],
                          b["surface0_force_z"])
    rows = wall.group_index("all")
    assert np.allclose(stl.quantity("position", rows), wall.quantity("position", rows), rtol=0, atol=1e-12)
    assert stl.quantity("position", rows)[:, 2].min() >= 0.02 + stl.t - 1e-12  # none left inside

def test_frictionless_sliding_keeps_the_tangential_momentum_and_friction_takes_it(plane):
    """The block thrown at (2, 0, -1) m/s onto a plane at rest: frictionless, the plane's
    forces are normal and the momentum along it is kept to round-off; with friction 0.3 the
    plane's tangential force opposes the sliding and is at most 0.3 times its normal force
    at every step (Coulomb), and the block slows down."""
    throw = '[[initial]]\ntype = "velocity"\nvalue = [2.0, 0.0, -1.0]\n'
    free = simulation(BLOCK + throw + surface(plane, "translate = [0.0, 0.0, 0.03]"))
    h = run_until(free, 0.1)
    assert np.abs(h["surface0_force_z"]).max() > 100.0  # it struck
    assert np.abs(h["momentum_x"] - h["momentum_x"][0]).max() < 1e-12 * h["momentum_x"][0]
    rough = simulation(BLOCK + throw + surface(plane, "translate = [0.0, 0.0, 0.03]\nfriction = 0.3"))
    h = run_until(rough, 0.1)
    fx, fz = h["surface0_force_x"], h["surface0_force_z"]
    assert fx.min() < -10.0 and fx.max() <= 0.0
    assert np.all(np.abs(fx) <= 0.3 * np.abs(fz) * (1 + 1e-12))
    assert h["momentum_x"][-1] < 0.95 * h["momentum_x"][0]


def test_a_rotated_plane_faces_where_its_rotation_turns_its_normal(plane):
    """The plane (normal +z) rotated by the rotation vector [0, 90, 0] degrees (a quarter
    turn about y: its normal turns to +x) and moved to x = -0.03: its triangles lie in
    that plane, and it stops the block thrown at it along -x (a force along +x)."""
    throw = '[[initial]]\ntype = "velocity"\nvalue = [-1.0, 0.0, 0.0]\n'
    sim = simulation(BLOCK + throw + surface(plane, "rotate = [0.0, 90.0, 0.0]\ntranslate = [-0.03, 0.0, 0.0]"))
    assert np.allclose(sim.walls.items[0].triangles(0.0)[..., 0], -0.03, rtol=0, atol=1e-15)
    h = run_until(sim, 0.15)  # it reaches the plane at 80 ms
    assert h["surface0_force_x"].max() > 10.0 and h["surface0_force_x"].min() >= 0.0
    assert sim.quantity("position", sim.group_index("all"))[:, 0].min() >= -0.03


def step_with_impulses(sim, end: float, power) -> tuple:
    """Step `sim` to `end`; returns (history of diagonstics each step, the sum over the steps
    of power(sim, row) times the time the step's impulse stands for, (dt_(n-1) + dt_n) / 2)."""
    rows, work, last = [sim.diagnostics()], 0.0, 0.0
    while sim.t < end * (1 - 1e-12):
        dt = sim.step()
        rows.append(sim.diagnostics())
        work += power(sim, rows[-1]) * 0.5 * (last + dt)
        last = dt
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}, work


def pressed(plane: str, cfl: float) -> tuple:
    """The plane, touching the block's lowest particles at t = 0, rising at a velocity ramped
    as an expression of t (0 to 1 m/s over 20 ms) to 60 ms at `cfl`: (history, the sum over
    the steps of its force times its velocity)."""
    sim = simulation(BLOCK + surface(plane, 'translate = [0.0, 0.0, 0.05]\n'
                                     'velocity_expression = ["0", "0", "minimum(t / 0.02, 1.0)"]'), [f"time.cfl={cfl}"])
    return step_with_impulses(sim, 0.06, lambda s, row: row["surface0_force_z"] * min(s.t / 0.02, 1.0))


def test_a_moving_surface_does_its_force_times_velocity_as_work_in_the_balance(plane):
    """The balance's external work (the rising plane's alone) tends to the sum of its force
    times its velocity over the steps at first order in the step (what the plastic contact
    loses in a step, as the tool's: measured 6.9 % of it at cfl 0.6, 3.6 % at 0.3), and the
    total energy is conserved to the integration's error (second order: 0.36 %, 0.09 %)."""
    gaps, drifts = [], []
    for cfl in (0.6, 0.3):
        h, work = pressed(plane, cfl)
        assert work > 10.0
        gaps.append((work - h["external_work"][-1]) / work)
        drifts.append(np.abs(h["total_energy"] - h["total_energy"][0]).max() / work)
    assert 0.0 < gaps[0] < 0.1 and 0.4 < gaps[1] / gaps[0] < 0.65
    assert drifts[0] < 0.01 and drifts[1] < 0.35 * drifts[0]


ROTOR = """
[scene]
name = "surface_rotor"
dimension = 2
[[geometry.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [1.0, 0.6]
spacing = 0.1
""" + soft_solid(2.2) + """[formulation]
hourglass = 20.0
[time]
end = 1.0
[groups.bottom]
extreme = { axis = 1, side = "min" }
[[bc]]
type = "fixed"
group = "bottom"
"""


def test_a_turning_surface_does_its_torque_times_angular_velocity_as_work(tmp_path):
    """A bar (a closed outline, 1.2 m x 4 cm) hinged at its end, lying on the block held at
    its base, turns down at an angular velocity ramped as an expression of t (0 to -2 rad/s
    over 20 ms): its torque about the hinge presses (negative), the balance's external work
    is the sum over the steps of torque times angular velocity, to the contact's loss
    (measured 0.96 % at cfl 0.6), the total energy is conserved, and the bar's outline at
    the end is turned by the integral of the angular velocity."""
    bar = tmp_path / "bar.csv"
    np.savetxt(bar, [[0.0, 0.55], [1.2, 0.55], [1.2, 0.59], [0.0, 0.59]], delimiter=",")
    sim = simulation(ROTOR + surface(bar, 'center = [0.0, 0.57]\n'
                                     'angular_velocity_expression = ["-2 * minimum(t / 0.02, 1.0)"]'), ["time.cfl=0.3"])
    h, work = step_with_impulses(sim, 0.06, lambda s, row: -2.0 * min(s.t / 0.02, 1.0) * row["surface0_torque_z"])
    torque = h["surface0_torque_z"]
    assert torque.min() < -1e4 and torque.max() <= 0.0
    assert work > 1e3
    assert h["external_work"][-1] == pytest.approx(work, rel=0.02)
    assert np.abs(h["total_energy"] - h["total_energy"][0]).max() < 0.01 * work
    a = -2.0 * (sim.t - 0.01)  # the ramp's integral
    corner = np.array([0.0, 0.57]) + np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) @ [1.2, -0.02]
    drawn = sim.walls.items[0].triangles(sim.t).reshape(-1, 2)
    assert np.linalg.norm(drawn - corner, axis=1).min() < 1e-12


def test_the_punch_as_an_outline_presses_as_the_punch_as_a_tool():
    """The first tenth of the punch's stroke at a spacing of 1 mm: the force of the outline
    (runs/punch_stl.toml) is that of the tool (runs/punch.toml) within 2 % at every step
    where it exceeds a tenth of its last value, and at the end (tools/measure.py
    punch_stl; the whole stroke at 0.5 mm: 0.07 %, the figures in the README)."""
    coarse = ["parameters.spacing=1e-3", "time.end=5e-4"]
    surface_run = run_until(simulation("punch_stl", coarse), 5e-4)
    tool_run = run_until(simulation("punch", coarse), 5e-4)
    times, fa, fb, worst, end = measure.stroke_difference(surface_run, tool_run)
    assert len(times) > 20 and abs(fb[-1]) > 100.0
    assert worst < 0.02 and end < 0.02


SPHERE_SCENE = BLOCK.replace("spacing = 0.1", "spacing = 0.05") + """
[[surfaces]]
file = "sphere.stl"
translate = [0.17, 0.21, 0.425]
velocity = [0.0, 0.0, -1.0]
angular_velocity = [0.0, 2.0, 5.0]
friction = 0.2
"""


@pytest.mark.mpi
def test_a_3d_surface_gives_the_same_answer_on_1_and_3_ranks(tmp_path):
    """An icosphere (320 triangles, radius 15 cm), touching the block at t = 0, pressed
    off-centre into it at 1 m/s, spinning, with friction: each rank holds only the
    triangles near its particles, and the particles, the surface's force and torque are
    the same, bit for bit, on 1 and 3 ranks."""
    trimesh.creation.icosphere(subdivisions=2, radius=0.15).export(tmp_path / "sphere.stl")
    scene = tmp_path / "sphere.toml"
    scene.write_text(SPHERE_SCENE)
    assert_same_on_ranks(scene, ["--set", "time.max_steps=40"], tmp_path, ranks=(1, 3))
    h = read_history(tmp_path / "ranks_1")
    assert h["surface0_force_z"].min() < -100.0 and np.abs(h["surface0_torque_z"]).max() > 1.0  # pressed, spinning


BAD = {
    "missing": (None, r"surfaces\[0\]\.file = '.*absent\.stl': file not found"),
    "unreadable": (b"ply\nformat nonsense\n", r"surfaces\[0\]\.file = '.*bad\.ply': cannot be read"),
    "empty": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", r"surfaces\[0\]\.file = '.*bad\.obj': not a surface"),
    "degenerate": (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 4\nf 1 2 3\n",
                   r"surfaces\[0\]\.file = '.*bad\.obj': triangle 1 is degenerate"),
    "flipped": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 3 4\n",
                r"surfaces\[0\]\.file = '.*bad\.obj': its triangles are not consistently oriented"),
    "group": (None, r"surfaces\[0\]\.group names group 'tool', which is not defined"),
}


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", (1, 2))
def test_a_bad_surface_is_refused_naming_the_file(ranks, tmp_path, plane):
    """A missing file, one no reader understands, one without triangles, one with a
    triangle of zero area, one with a triangle turned against its neighbour, and an unknown
    group: exit 2 on every rank with a message naming the key and the file, no traceback.
    The cases run one after another in one MPI job (conftest.parsph_batch)."""
    commands = []
    for case, (content, _) in sorted(BAD.items()):
        folder = tmp_path / case
        folder.mkdir()
        name = {"missing": "absent.stl", "unreadable": "bad.ply", "group": plane}.get(case, "bad.obj")
        if content is not None:
            (folder / name).write_bytes(content)
        scene = folder / "scene.toml"
        scene.write_text(BLOCK + surface(name, 'group = "tool"' if case == "group" else ""))
        commands.append(["run", scene, "--out", folder / "out", "--quiet"])
    failures = []
    for (case, (_, message)), proc in zip(sorted(BAD.items()), parsph_batch(commands, ranks, tmp_path / "batch")):
        try:
            assert proc.returncode == 2, proc.stderr
            assert re.search(message, proc.stderr), proc.stderr
            assert "Traceback" not in proc.stderr
        except AssertionError as exc:
            failures.append(f"{case}: {exc}")
    assert not failures, "\n\n".join(failures)


def test_a_2d_outline_reads_the_same_from_csv_and_dxf_turned_counter_clockwise(tmp_path):
    """The punch's outline (tools/punch_tool_outline.py) as a CSV, as the same CSV listed
    clockwise and as a DXF polyline (trimesh): the same closed outline, counter-clockwise
    (the outside on the segments' right: igl's pseudo-normal sign), so that a point inside
    the punch is inside."""
    import igl
    from trimesh.path.entities import Line

    import punch_tool_outline
    from parsph.surfaces import read

    V = punch_tool_outline.outline(8)
    np.savetxt(tmp_path / "ccw.csv", V, delimiter=",")
    np.savetxt(tmp_path / "cw.csv", V[::-1], delimiter=",")
    trimesh.path.Path2D(entities=[Line(np.r_[np.arange(len(V)), 0])], vertices=V).export(str(tmp_path / "tool.dxf"))
    outlines = [read(str(tmp_path / name), "file", 2) for name in ("ccw.csv", "cw.csv", "tool.dxf")]
    for W, F in outlines:
        assert len(F) == len(V) and np.array_equal(np.sort(F[:, 1] - F[:, 0]) % len(V), np.ones(len(V)))
        segments = W[F]
        assert np.abs(np.sort(segments.reshape(len(F), -1), axis=0)
                      - np.sort(V[np.c_[np.arange(len(V)), (np.arange(len(V)) + 1) % len(V)]].reshape(len(V), -1),
                                axis=0)).max() < 1e-12
        S = igl.signed_distance(np.array([[0.0, 0.01], [0.0, -0.001]]), W, F, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)[0]
        assert S[0] == pytest.approx(-0.01) and S[1] == pytest.approx(0.001)


def test_no_particle_moves_more_than_a_quarter_of_the_margin_in_a_step(plane):
    """The block skimming at 300 m/s over the plane (whose margin is 0.28 m: a twentieth of
    its diagonal) would move 0.36 m in a stable step; a step lets it move a quarter of the
    margin, no more, and the block alone keeps its own step."""
    fast = BLOCK + '[[initial]]\ntype = "velocity"\nvalue = [300.0, 0.0, 0.0]\n'
    sim = simulation(fast + surface(plane, "translate = [0.0, 0.0, -0.03]"))
    margin = sim.walls.items[0].margin
    assert margin == pytest.approx(0.05 * np.hypot(4.0, 4.0))
    free = simulation(fast)
    for s in (sim, free):
        s.step()
    assert sim.stable.dt * 300.0 <= 0.25 * margin * (1 + 1e-12)
    assert free.stable.dt * 300.0 > margin


@pytest.mark.mpi
def test_a_run_with_a_surface_restarts_bit_for_bit(tmp_path):
    """punch_stl at a spacing of 1 mm: a checkpoint at step 20, restarted on 2 ranks, ends
    at step 40 as the run straight through on one (every history row: the surface's force
    and torque included)."""
    common = ["--quiet", "--set", "parameters.spacing=1e-3", "--set", "output.history_every=1",
              "--set", "output.history_interval=0.0"]
    straight, split = tmp_path / "straight", tmp_path / "split"
    scene = RUNS / "punch_stl.toml"
    # the straight and the stopped run in one job (conftest.parsph_by_ranks), then the restart
    assert_runs_by_ranks([(1, ["run", scene, "--out", straight, *common, "--set", "time.max_steps=40"]),
                          (1, ["run", scene, "--out", split, *common, "--set", "time.max_steps=20",
                               "--set", "output.checkpoint_every=20"])], tmp_path / "batch")
    assert_runs_by_ranks([(2, ["run", scene, "--out", split, *common, "--set", "time.max_steps=40",
                               "--restart", "latest"])], tmp_path / "batch_restart")
    assert_identical_outputs(straight, split)
    assert np.abs(read_history(split)["surface0_torque_z"]).max() > 0.0
