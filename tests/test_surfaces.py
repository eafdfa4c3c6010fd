"""Rigid obstacles from surface files ([[surfaces]], parsph.surfaces): a flat STL pressing a
block as the same [[walls]] plane does, frictionless sliding that keeps the tangential
momentum and Coulomb friction that takes it, the work of a moving and of a turning surface
in the energy balance (their force times velocity, torque times angular velocity), the
punch as an outline against the punch as a tool, the same answer on 1 and 3 ranks, and bad
surface files refused naming the file."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import trimesh

from physics import run_until, simulation

from conftest import ROOT, RUNS, assert_same_on_ranks, parsph

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
[kernel]
type = "wendland_c2"
support = 2.2
[material]
model = "saint_venant_kirchhoff"
density = 1000.0
youngs_modulus = 1.0e6
poisson_ratio = 0.3
[formulation]
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
    round-off (the STL's closest points are the plane's feet)."""
    wall = simulation(BLOCK + '[[walls]]\npoint = [0.0, 0.0, 0.02]\nnormal = [0.0, 0.0, 1.0]\nvelocity = [0.0, 0.0, 1.0]\n')
    stl = simulation(BLOCK + surface(plane, "translate = [0.0, 0.0, 0.02]\nvelocity = [0.0, 0.0, 1.0]"))
    a, b = run_until(wall, 0.06), run_until(stl, 0.06)
    assert len(a["time"]) == len(b["time"])
    assert np.abs(a["wall0_force_z"]).max() > 10.0  # pressed
    assert np.allclose(b["surface0_force_z"], a["wall0_force_z"], rtol=1e-9, atol=1e-9 * np.abs(a["wall0_force_z"]).max())
    assert np.abs(b["surface0_force_x"]).max() < 1e-9 * np.abs(a["wall0_force_z"]).max()
    rows = wall.group_index("all")
    assert np.allclose(stl.quantity("position", rows), wall.quantity("position", rows), rtol=0, atol=1e-12)
    assert stl.quantity("position", rows)[:, 2].min() >= 0.02 + stl.t - 1e-12  # none left inside