"""Rigid frictionless tools (walls.Tool): contact geometry, impulse balance, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from parsph.walls import Walls
from physics import block_2d, simulation


def test_tool_puts_particles_on_its_rounded_surface_and_keeps_their_tangential_velocity():
    """A box 2 x 1 with edges rounded to 0.25, moving down at 1 m/s, at t = 0.5 s: a particle
    just inside the bottom face goes to the face, one inside the rounded lower-left edge goes
    radially onto the arc; each keeps its tangential velocity and takes the tool's normal
    velocity; a particle outside is left alone."""
    spec = {"group": "all", "lower": [0.0, 0.0], "upper": [2.0, 1.0], "radius": 0.25, "velocity": [0.0, -1.0]}
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
    edge rounded: the tool's force integrated over the steps equals the block's change of
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
    impulse = np.zeros(2)
    while sim.t < 0.05:
        dt = sim.step()
        d = sim.diagnostics()
        impulse += dt * np.array([d["tool0_force_x"], d["tool0_force_y"]])
    assert impulse[1] < -0.5 * start[1]  # a real collision
    assert impulse[0] < 0.0  # the rounded edge pushed it back sideways too
    assert np.allclose(momentum() - start, impulse, rtol=1e-10, atol=1e-12 * np.abs(start).max())


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
