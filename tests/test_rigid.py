"""Rigid bodies made of particles (parsph.rigid): free flight and spin as Newton and Euler
say, a spinning rigid disk striking an elastic block (rigidity, momenta, energy; with
friction, the angular momentum its couples change, converging with the spacing), a rigid
disk thrown at a wall (a plastic impact of the body whole, booked in the balance), a rigid
body held by [[bc]], and bodies held in part refused."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

from parsph import readouts
from parsph.errors import InputError
from physics import run_until, simulation

from conftest import (CEILING, assert_identical_outputs, assert_runs_by_ranks, assert_same_on_ranks,
                      kill_processes_mentioning, mpiexec, parsph, wait_for)

DISK = """
[scene]
name = "rigid_disk"
dimension = 2
[kernel]
type = "wendland_c2"
support = 2.2
[formulation]
type = "tlsph"
[[bodies]]
name = "block"
[[bodies.parts]]
shape = "box"
lower = [0.0, 0.0]
upper = [0.02, 0.01]
spacing = 1.0e-3
[bodies.material]
model = "neo_hookean"
density = 1100.0
youngs_modulus = 1.0e7
poisson_ratio = 0.3
[[bodies]]
name = "disk"
rigid = true
[[bodies.parts]]
shape = "disk"
center = [0.01, 0.0161]
radius = 0.005
spacing = 1.0e-3
[bodies.material]
model = "neo_hookean"
density = 7800.0
youngs_modulus = 2.0e11
poisson_ratio = 0.3
[[contact]]
bodies = ["block", "disk"]
[groups.disk]
sphere = { center = [0.01, 0.0161], radius = 0.0055 }
[[initial]]
type = "velocity"
group = "disk"
value = [1.0, -5.0]
[[initial]]
type = "angular_velocity"
group = "disk"
omega = [300.0]
center = [0.01, 0.0161]
[time]
end = 4.0e-3
"""


def disk_particles(sim) -> np.ndarray:
    body = sim.state.bodies[1]
    return np.arange(body.lo, body.hi)


def test_a_free_rigid_body_falls_and_spins_as_newton_and_euler_say():
    """The disk alone under gravity (the block far away): its particles stay a rigid copy of
    the disk turned by omega t about a centre that falls as c0 + v0 t + g t^2 / 2 (the
    step is exact for a constant force and a constant spin), to round-off."""
    gravity = np.array([0.0, -9.81])
    text = DISK.replace("0.0161", "0.1161").replace("[time]", "[loads]\nbody_acceleration = [0.0, -9.81]\n[time]")
    sim = simulation(text)
    rows = disk_particles(sim)
    X = sim.quantity("reference_position", rows)
    centre0 = sim.conditions.rigid_bodies[0].centre0
    while sim.t < 2e-3:
        sim.step()
    t = sim.t
    c, s = np.cos(300.0 * t), np.sin(300.0 * t)
    turned = (X - centre0) @ np.array([[c, -s], [s, c]]).T
    expected = centre0 + np.array([1.0, -5.0]) * t + 0.5 * gravity * t * t + turned
    assert np.allclose(sim.quantity("position", rows), expected, rtol=0, atol=1e-12)
    assert np.allclose(sim.quantity("velocity", rows), np.array([1.0, -5.0]) + gravity * t
                       + 300.0 * np.stack([-turned[:, 1], turned[:, 0]], axis=1), rtol=0, atol=1e-9)
    assert np.allclose(sim.quantity("J", rows), 1.0)  # F is the rotation: no strain, no stress but round-off
    assert readouts.von_mises(sim, rows).max() < 1e-13 * 2.0e11


def test_a_spinning_rigid_disk_strikes_an_elastic_block_and_stays_rigid():
    """The disk (spinning at 300 rad/s) hits the block and bounces: every distance between
    its particles unchanged to round-off, linear momentum to round-off, angular momentum
    to 1e-4 and the total energy to 1e-3 of the kinetic energy at impact."""
    sim = simulation(DISK)
    rows = disk_particles(sim)
    x0 = sim.quantity("position", rows)
    h = run_until(sim, 4e-3, every=10)
    x = sim.quantity("position", rows)
    distances = [np.linalg.norm(p[:, None] - p[None], axis=2) for p in (x0, x)]
    assert np.abs(distances[1] - distances[0]).max() < 1e-15
    assert np.abs(h["contact_force_y.block.disk"]).max() > 0  # they touched
    assert h["kinetic_energy.disk"][-1] < 0.9 * h["kinetic_energy.disk"][0]  # the block took some
    impact = h["kinetic_energy"][0]
    for a in "xy":
        assert np.abs(h[f"momentum_{a}"] - h[f"momentum_{a}"][0]).max() < 1e-13 * abs(h["momentum_y"][0])
    assert np.abs(h["angular_momentum"] - h["angular_momentum"][0]).max() < 1e-4 * abs(h["angular_momentum"][0])
    assert np.abs(h["total_energy"] - h["total_energy"][0]).max() < 1e-3 * impact


def test_the_history_gives_the_force_and_torque_the_rigid_body_takes():
    """The disk striking the block, a row at every step: the force on the disk is minus the
    disk's force on the block, and its angular momentum about its centre changes by the
    torque in the history integrated over the steps (each step's kicks: the trapezoidal
    rule), to round-off."""
    sim = simulation(DISK)
    body = sim.conditions.rigid_bodies[0]
    spin = body.inertia0[0, 0] * body.omega[0]
    h = run_until(sim, 1e-3)
    assert np.abs(h["rigid_torque.disk"]).max() > 0
    assert np.allclose(h["rigid_force_y.disk"], -h["contact_force_y.block.disk"], rtol=1e-12, atol=0)
    torque = h["rigid_torque.disk"]
    impulse = np.sum(np.diff(h["time"]) * 0.5 * (torque[1:] + torque[:-1]))
    change = body.inertia0[0, 0] * body.omega[0] - spin
    assert change == pytest.approx(impulse, rel=1e-9)


def friction_impact(spacing: float, friction: float) -> tuple:
    """The disk, not spinning, grazing the block at (20, -5) m/s with `friction` at `spacing`,
    to 4 ms: (the change of the total angular momentum, the friction impulse on the disk)."""
    text = DISK.replace("spacing = 1.0e-3", f"spacing = {spacing}").replace(
        'bodies = ["block", "disk"]', f'bodies = ["block", "disk"]\nfriction = {friction}').replace(
        "omega = [300.0]", "omega = [0.0]").replace("value = [1.0, -5.0]", "value = [20.0, -5.0]")
    sim = simulation(text)
    disk = sim.state.bodies[1]
    start, impulse = sim.diagnostics()["angular_momentum"], np.zeros(2)
    while sim.t < 4e-3:
        dt = sim.step()
        impulse += dt * sim.interactions.contact.dissipation[disk.lo:disk.hi].sum(axis=0)  # its kicks: the same each step
    return sim.diagnostics()["angular_momentum"] - start, np.linalg.norm(impulse)


def test_friction_changes_the_angular_momentum_by_couples_that_vanish_with_the_spacing():
    """A free oblique impact with friction 0.3 (the disk slides along the block): a pair's
    friction forces are equal and opposite but a contact distance apart, so each pair adds
    the couple r_ij x f; the total angular momentum changes by the friction impulse times a
    lever below the contact distance (measured 0.90 and 0.44 of a spacing of 1 and 0.5 mm,
    while the impulse is the same to 2 %), so the change halves with the spacing: first
    order, as the contact's own offset of the surfaces. Without friction it is round-off."""
    (coarse, impulse_coarse), (fine, impulse_fine) = (friction_impact(s, 0.3) for s in (1.0e-3, 0.5e-3))
    assert impulse_fine == pytest.approx(impulse_coarse, rel=0.05)  # sliding: mu times the normal impulse
    assert abs(coarse) < 1.0e-3 * impulse_coarse and abs(fine) < 0.5e-3 * impulse_fine
    assert 0.4 < fine / coarse < 0.6
    frictionless, _ = friction_impact(1.0e-3, 0.0)
    assert abs(frictionless) < 1e-10 * abs(coarse)


WALL = DISK.replace("center = [0.01, 0.0161]", "center = [0.0, 0.0055]").replace(
    "sphere = { center = [0.01, 0.0161], radius = 0.0055 }", "sphere = { center = [0.0, 0.0055], radius = 0.0055 }"
).replace("lower = [0.0, 0.0]\nupper = [0.02, 0.01]", "lower = [0.05, 0.05]\nupper = [0.07, 0.06]") + """
[[walls]]
group = "disk"
point = [0.0, 0.0]
normal = [0.0, 1.0]
"""


@pytest.mark.parametrize("velocity, spin, gravity", [((0.0, -50.0), 0.0, 0.0), ((30.0, -50.0), 3000.0, 0.0),
                                                      ((30.0, -50.0), 0.0, 1.0e5)])
def test_a_free_rigid_disk_meets_a_wall_as_a_rigid_body_plastically_and_the_balance_books_it(velocity, spin,
                                                                                              gravity):
    """The steel disk (765.8 J at 50 m/s) thrown at a frictionless wall plane (the block far
    away): it meets the wall's perfectly plastic law as one body, in the step it reaches
    the wall: head-on it stops there (its kinetic energy, the wall's work to round-off);
    thrown obliquely it keeps its tangential velocity (spinning, the lattice's corners
    strike off its centre and it hops on); under gravity it rests on the wall, which then
    carries its weight. No particle ends inside the wall, the body stays rigid, and the
    total energy is constant to round-off."""
    text = WALL.replace("value = [1.0, -5.0]", f"value = [{velocity[0]}, {velocity[1]}]").replace(
        "omega = [300.0]", f"omega = [{spin}]")
    if gravity:
        text += f"[loads]\nbody_acceleration = [0.0, {-gravity}]\n"
    sim = simulation(text)
    body, rows = sim.conditions.rigid_bodies[0], disk_particles(sim)
    x0 = sim.quantity("position", rows)
    h = run_until(sim, 2e-4, every=5)
    impact = h["kinetic_energy"][0]
    x = sim.quantity("position", rows)
    distances = [np.linalg.norm(p[:, None] - p[None], axis=2) for p in (x0, x)]
    assert np.abs(distances[1] - distances[0]).max() < 1e-15
    assert x[:, 1].min() >= 0.0
    assert np.abs(h["total_energy"] - h["total_energy"][0]).max() < 1e-12 * impact
    assert body.V[0] == pytest.approx(velocity[0], rel=1e-14, abs=1e-14)  # frictionless: normal impulses
    if gravity:
        weight = body.mass * gravity
        assert h["wall0_force_y"][-1] == pytest.approx(weight, rel=1e-12)
        assert body.V[1] == pytest.approx(-0.5 * sim.step_dt * gravity, rel=1e-9)  # on the wall, half a kick
    elif not spin:
        assert abs(body.V[1]) < 1e-12 * abs(velocity[1]) and h["kinetic_energy"][-1] < 1e-24 * impact
        assert h["external_work"][-1] == pytest.approx(-impact, rel=1e-12)


def test_a_rigid_body_held_by_a_condition_moves_as_it_says_and_a_part_cannot_be_held():
    """A [[bc]] holding the whole disk moves it with the prescribed velocity and no spin;
    one holding part of it, or some components, is refused naming the condition, and a
    rigid body without particles naming its part."""
    held = DISK + '[[bc]]\ntype = "velocity"\ngroup = "disk"\nvalue = [0.0, -2.0]\n'
    sim = simulation(held)
    rows = disk_particles(sim)
    assert not sim.conditions.rigid_bodies
    while sim.t < 1e-3:
        sim.step()
    assert np.allclose(sim.quantity("displacement", rows), [0.0, -2.0 * sim.t], rtol=1e-12, atol=0)
    part = DISK + ('[groups.half]\nbox = { lower = [0.0, 0.0161], upper = [0.02, 0.03] }\n'
                   '[[bc]]\ntype = "fixed"\ngroup = "half"\n')
    with pytest.raises(InputError, match=r"bc\[0\] holds part of rigid body 'disk'"):
        simulation(part)
    some = DISK + '[[bc]]\ntype = "fixed"\ngroup = "disk"\ncomponents = [1]\n'
    with pytest.raises(InputError, match=r"bc\[0\] holds part of rigid body 'disk'"):
        simulation(some)
    empty = DISK.replace('shape = "disk"\ncenter = [0.01, 0.0161]\nradius = 0.005',
                         'shape = "box"\nlower = [0.01, 0.016]\nupper = [0.0101, 0.0161]')
    with pytest.raises(InputError, match=r"bodies\[1\]\.parts\[0\]: box: .* no particle fits"):
        simulation(empty)


@pytest.mark.parametrize(("extra", "message"), [
    ('[[bc]]\ntype = "displacement"\ngroup = "disk"\nexpression = ["0.1 * (x - 0.01)", "0"]\nramp = 1e-4\n',
     r"bc\[0\] gives the particles of rigid body 'disk' different values"),
    ('[[bc]]\ntype = "velocity"\ngroup = "disk"\nexpression = ["100 * (x - 0.01)", "0"]\n',
     r"bc\[0\] gives the particles of rigid body 'disk' different values"),
    ('[[initial]]\ntype = "displacement_gradient"\ngroup = "disk"\ngradient = [[0.1, 0.0], [0.0, 0.0]]\n',
     r"an \[\[initial\]\] displacement moves the particles of rigid body 'disk'"),
    ('[[initial]]\ntype = "displacement_field"\ngroup = "disk"\nexpression = ["1e-4", "0"]\n'
     '[[bc]]\ntype = "velocity"\ngroup = "disk"\nvalue = [0.0, -2.0]\n', None),
    ('[[initial]]\ntype = "displacement_field"\ngroup = "disk"\nexpression = ["1e-4 * x", "0"]\n'
     '[[bc]]\ntype = "velocity"\ngroup = "disk"\nvalue = [0.0, -2.0]\n',
     r"an \[\[initial\]\] displacement moves the particles of rigid body 'disk'"),
], ids=["bc-displacement-field", "bc-velocity-field", "initial-stretch", "initial-shift-held", "initial-stretch-held"])
def test_conditions_that_would_deform_a_rigid_body_are_refused(extra, message):
    """A [[bc]] with an expression of position (a stretch), or an initial displacement of a
    free rigid body or an uneven one of a held body, is refused; a held body shifted evenly
    moves on rigidly."""
    if message is None:
        sim = simulation(DISK + extra)
        sim.step()
        u = sim.quantity("displacement", disk_particles(sim))
        assert np.ptp(u, axis=0).max() == 0.0 and u[0, 0] == 1e-4
        return
    with pytest.raises(InputError, match=message):
        simulation(DISK + extra)


@pytest.mark.mpi
def test_rigid_body_is_the_same_on_1_and_3_ranks_and_across_a_restart(tmp_path):
    """The spinning disk striking the block (touching from step ~60): the same history and
    final state on 1 and 3 ranks, and checkpointed at step 150 on 2 ranks, restarted on 3,
    the same again (the rigid body's centre, orientation and velocities carried)."""
    scene = tmp_path / "rigid_disk.toml"
    scene.write_text(DISK + "[output]\nhistory_every = 5\n")
    steps = ["--set", "time.max_steps=300"]
    split = tmp_path / "split"
    # three MPI jobs (conftest.parsph_by_ranks): one rank; two ranks; three ranks straight and restarted
    assert_runs_by_ranks([(1, ["run", scene, "--out", tmp_path / "ranks_1", "--quiet", *steps]),
                          (2, ["run", scene, "--out", split, "--quiet", "--set", "time.max_steps=150", "--set",
                               "output.checkpoint_every=150"])], tmp_path / "batch")
    assert_runs_by_ranks([(3, ["run", scene, "--out", tmp_path / "ranks_3", "--quiet", *steps]),
                          (3, ["run", scene, "--out", split, "--quiet", *steps, "--restart", "latest"])],
                         tmp_path / "batch_restart")
    assert_identical_outputs(tmp_path / "ranks_1", tmp_path / "ranks_3")
    assert_identical_outputs(tmp_path / "ranks_1", split)


@pytest.mark.mpi
def test_a_rigid_body_meets_a_wall_the_same_on_1_and_2_ranks(tmp_path):
    """A rigid plate instead of the disk (10 x 4 particles), thrown spinning at the wall
    under gravity: it lands on a corner, rocks and settles flat, touching the wall with
    particles of both ranks (the block small and far away, the ranks' cut runs through the
    plate); the same history and final state on 1 and 2 ranks (every rank solves for the
    contacts of all, in the order of their reference positions)."""
    scene = tmp_path / "rigid_wall.toml"
    scene.write_text(WALL.replace('shape = "disk"\ncenter = [0.0, 0.0055]\nradius = 0.005',
                                  'shape = "box"\nlower = [-0.005, 0.0005]\nupper = [0.005, 0.0045]').replace(
        "radius = 0.0055 }", "radius = 0.008 }").replace("upper = [0.07, 0.06]", "upper = [0.053, 0.053]").replace(
        "value = [1.0, -5.0]", "value = [3.0, -20.0]").replace("omega = [300.0]", "omega = [1000.0]")
        + "[loads]\nbody_acceleration = [0.0, -1.0e5]\n[output]\nhistory_every = 5\n")
    assert_same_on_ranks(scene, ["--set", "time.max_steps=150"], tmp_path, ranks=(1, 2))


@pytest.mark.mpi
def test_a_run_killed_mid_contact_continues_from_its_checkpoint_as_if_never_stopped(tmp_path):
    """The spinning disk on the block on 2 ranks, checkpointed every 150 steps and killed
    (SIGKILL, every process) soon after its first checkpoint, while the disk presses into
    the block; `--restart latest` on 2 ranks to step 600 equals the uninterrupted run."""
    scene = tmp_path / "rigid_disk.toml"
    scene.write_text(DISK + "[output]\nhistory_every = 5\n")
    straight, killed = tmp_path / "straight", tmp_path / "killed"
    proc = parsph(["run", scene, "--out", straight, "--quiet", "--set", "time.max_steps=600"])
    assert proc.returncode == 0, proc.stderr
    cmd = [mpiexec(), "-n", "2", sys.executable, "-m", "parsph", "run", str(scene), "--out", str(killed), "--quiet",
           "--set", "time.max_steps=100000", "--set", "time.end=1.0", "--set", "output.checkpoint_every=150"]
    job = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    wait_for(lambda: list((killed / "checkpoints").glob("step_*.h5")), poll=0.05)
    time.sleep(np.random.default_rng().uniform(0.0, 0.2))
    assert len(kill_processes_mentioning(str(killed))) >= 2, job.communicate()
    job.wait(timeout=CEILING)
    proc = parsph(["run", scene, "--out", killed, "--quiet", "--set", "time.max_steps=600", "--set", "time.end=1.0",
                   "--restart", "latest"], ranks=2)
    assert proc.returncode == 0, proc.stderr
    assert_identical_outputs(straight, killed)
