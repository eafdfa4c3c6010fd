"""Rigid frictionless tools (walls.Tool): contact geometry, impulse balance, the force on a
shortened last step, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from parsph.walls import Walls
from physics import block_2d, simulation, typed


def test_tool_puts_particles_on_its_rounded_surface_and_keeps_their_tangential_velocity():
    """A box 2 x 1 with edges rounded to 0.25, moving down at 1 m/s, at t = 0.5 s: a particle
    just inside the bottom face goes to the face, one inside the rounded lower-left edge goes
    radially onto the arc; each keeps its tangential velocity and takes the tool's normal
    velocity; a particle outside is left alone."""
    spec = typed("tools", group="all", lower=[0.0, 0.0], upper=[2.0, 1.0], radius=0.25, velocity=[0.0, -1.0])
    walls = Walls([], [spec], 2)
    walls.select({"all": np.ones(3, bool)})
    center = np.array([0.25, -0.25])  # the arc's centre at t = 0.5
    direction = np.array([-1.0, -2.0]) / np.sqrt(5.0)
    X = np.array([[1.0, -0.45], center + 0.2 * direction, [1.0, -0.6]])
    u = np.zeros_like(X)
    v = np.array([[0.3, 0.0], [0.5, 0.5], [0.0, 2.0]])
    mass = np.array([1.0, 2.0, 1.0])
    dt = 1e-3
    walls.enforce(X, u, v, mass, 0.5, dt)
    x = X + u
    assert np.allclose(x[0], [1.0, -0.5]) and np.allclose(v[0], [0.3, -1.0])
    assert np.allclose(x[1], center + 0.25 * direction)
    tangent = np.array([-direction[1], direction[0]])
    assert v[1] @ tangent == pytest.approx(np.array([0.5, 0.5]) @ tangent)
    assert (v[1] - [0.0, -1.0]) @ direction == pytest.approx(0.0, abs=1e-14)
    assert np.all(u[2] == 0.0) and np.all(v[2] == [0.0, 2.0])
    momentum_change = mass[:2, None] * (v[:2] - [[0.3, 0.0], [0.5, 0.5]])
    assert np.allclose(walls.force[0] * dt, momentum_change.sum(axis=0))
    assert walls.names == ["tool0"]


def test_tool_force_is_the_momentum_it_gives_the_body():
    """A free block thrown up and sideways into a resting tool that covers part of its top,
    edge rounded: the tool's force integrated over the steps, each row over the time its
    impulse stands for ((dt_(n-1) + dt_n) / 2: parsph.walls), equals the block's change of
    momentum in both components (no other external force), and the block bounced."""
    tool = """
[[tools]]
lower = [0.5, 0.58]
upper = [2.0, 1.0]
radius = 0.2
[[initial]]
type = "velocity"
value = [0.3, 1.0]
"""
    sim = simulation(block_2d(extra=tool))

    def momentum():
        return (sim.quantity("mass")[:, None] * sim.quantity("velocity")).sum(axis=0)

    start = momentum()
    impulse, before = np.zeros(2), 0.0
    while sim.t < 0.05:
        dt = sim.step()
        d = sim.diagnostics()
        impulse += 0.5 * (before + dt) * np.array([d["tool0_force_x"], d["tool0_force_y"]])
        before = dt
    assert impulse[1] < -0.5 * start[1]  # a real collision
    assert impulse[0] < 0.0  # the rounded edge pushed it back sideways too
    assert np.allclose(momentum() - start, impulse, rtol=1e-10, atol=1e-12 * np.abs(start).max())


def test_a_tools_force_on_the_shortened_last_step_is_the_force_of_the_steps_before():
    """runs/punch.toml at 1 mm (30 x 10 particles) ended at 1 ms, and at 1 ms moved by
    0.02 to 0.1 %: the last step is cut to 0.29 to 0.41 of the one before. The tool's force
    in the last row is its impulse over the time it stands for (parsph.walls): within 10 %
    of the row before (the force rises or falls by up to 4 % a step at this spacing) and
    the same to 0.1 % whatever the cut. (The impulse over the short step alone made it
    1.7 to 2.2 times the force.)"""
    last = []
    for end in (1.0e-3, 1.0002e-3, 1.0005e-3, 1.001e-3):
        sim = simulation("punch", ["parameters.spacing=1e-3", f"time.end={end}", "time.cfl=0.3"])
        forces, steps = [], []
        while sim.t < end:
            steps.append(sim.step(end))
            forces.append(sim.diagnostics()["tool0_force_y"])
        assert sim.t == end and steps[-1] < 0.5 * steps[-2]
        assert forces[-1] == pytest.approx(forces[-2], rel=0.1)
        last.append(forces[-1])
    assert np.allclose(last, last[0], rtol=1e-3, atol=0)


@pytest.mark.parametrize("extra, message", [
    ('[[tools]]\nlower = [0.0, 0.0]\nupper = [1.0, 0.0]', "upper must exceed lower"),
    ('[[tools]]\nlower = [0.0, 0.0]\nupper = [1.0, 0.5]\nradius = 0.3', "tools[0].radius = 0.3 exceeds half"),
    ('[[tools]]\nlower = [0.0, 0.0]\nupper = [1.0, 0.5]\nradius = -0.1', "tools[0].radius must be >= 0"),
    ('[[tools]]\nlower = [0.0, 0.0]\nupper = [1.0, 0.5]\nspeed = 1.0', "speed"),
    ('[[tools]]\nlower = [0.0, 0.0, 0.0]\nupper = [1.0, 0.5]', "tools[0].lower must have 2 components"),
])
def test_bad_tool_settings_are_refused(extra, message):
    from parsph.errors import InputError

    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        simulation(block_2d(extra="\n" + extra + "\n"))
