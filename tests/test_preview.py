"""`parsph preview`: the particles as a run builds them, written before any step, the same on
any rank count; the obstacles' surfaces; the picture; the summary; bad input and the output
directory as `parsph run` treats them."""

from __future__ import annotations

from types import SimpleNamespace

import h5py
import meshio
import numpy as np
import pytest

from conftest import RUNS, parsph, parsph_batch
from parsph import preview
from parsph.walls import Tool
from physics import typed

SCENES = {"punch": 2, "tensile_failure": 3}  # a 2D scene with a tool, a 3D one of five parts with groups
RANKS = [pytest.param(1, id="1rank"), pytest.param(2, id="2ranks", marks=pytest.mark.mpi)]


def run_preview(out, scene, ranks=1, *args, env=None):
    proc = parsph(["preview", RUNS / f"{scene}.toml", "--out", out, *args], ranks=ranks, env=env)
    assert proc.returncode == 0, proc.stderr
    return proc


def particles(out) -> dict:
    with h5py.File(out / "particles.h5", "r") as f:
        return {name: f["step_00000000"][name][()] for name in f["step_00000000"]}


def area(triangles) -> float:
    edges = np.pad(triangles[:, 1:] - triangles[:, :1], ((0, 0), (0, 0), (0, 3 - triangles.shape[2])))
    return 0.5 * np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1).sum()


def summary(proc) -> list:
    """The summary's lines of bodies and groups (not the rank count or the directory)."""
    return [line for line in proc.stdout.splitlines() if line.startswith(("  body", "  group", "  obstacles"))]


@pytest.mark.mpi
@pytest.mark.parametrize(("scene", "serial_hdf5"), [("punch", False), ("tensile_failure", False), ("punch", True)])
def test_the_same_files_on_one_and_two_ranks(scene, serial_hdf5, tmp_path):
    one = run_preview(tmp_path / "1", scene)
    two = run_preview(tmp_path / "2", scene, 2, env={"PARSPH_SERIAL_HDF5": "1"} if serial_hdf5 else None)
    a, b = particles(tmp_path / "1"), particles(tmp_path / "2")
    assert sorted(a) == sorted(b) and {"position", "body", "volume", "mass", "support", "gid", "rank"} <= set(a)
    assert np.array_equal(a["gid"], np.arange(len(a["gid"])))  # global-id order
    for name in a:
        if name != "rank":
            assert np.array_equal(a[name], b[name]) and a[name].dtype == b[name].dtype, name
    assert set(b["rank"]) == {0, 1} and set(a["rank"]) == {0}
    assert (tmp_path / "1" / "particles.xdmf").read_text() == (tmp_path / "2" / "particles.xdmf").read_text()
    assert summary(one) == summary(two) and summary(one)
    if scene == "punch":  # the tool
        tools = [meshio.read(tmp_path / n / "obstacles.xdmf") for n in ("1", "2")]
        assert np.array_equal(tools[0].points, tools[1].points) and len(tools[0].cells[0].data) == 64
    for n in ("1", "2"):
        assert (tmp_path / n / "particles.png").stat().st_size > 1000


@pytest.mark.parametrize("scene", SCENES)
def test_what_is_written_is_what_a_run_starts_from(scene, tmp_path):
    """Volumes and masses row for row as the run's snapshot has them (summing to the run's);
    the XDMF reads back with meshio; `parsph plot` and the summary read the same file."""
    proc = run_preview(tmp_path / "preview", scene)
    run = parsph(["run", RUNS / f"{scene}.toml", "--out", tmp_path / "run", "--quiet", "--set", "time.max_steps=1",
                  "--set", 'output.snapshot_fields=["position", "volume", "mass", "body"]'])
    assert run.returncode == 0, run.stderr
    with h5py.File(tmp_path / "run" / "snapshots.h5", "r") as f:
        ran = {name: f["step_00000001"][name][()] for name in ("volume", "mass", "body", "gid")}
    shown = particles(tmp_path / "preview")
    for name in ran:
        assert np.array_equal(shown[name], ran[name]), name
    assert shown["volume"].sum() == ran["volume"].sum()
    if scene == "tensile_failure":  # five boxes: 5375 mm^3; groups from the scene's boxes
        assert shown["volume"].sum() == pytest.approx(5.375e-6, rel=1e-12)
        assert "volume 5.375e-06 m^3" in proc.stdout and "group 'held'" in proc.stdout
        assert shown["group_held"].dtype == np.uint8 and 0 < shown["group_held"].sum() < len(shown["gid"])
    mesh = meshio.read(tmp_path / "preview" / "particles.xdmf")
    assert np.array_equal(mesh.points[:, :SCENES[scene]], shown["position"][:, :SCENES[scene]])
    assert np.array_equal(mesh.point_data["volume"], shown["volume"])
    assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == len(shown["gid"])


@pytest.mark.parametrize("ranks", RANKS)
def test_bad_input_and_an_occupied_output_directory(ranks, tmp_path):
    """Bad input is refused; a directory holding a preview is refused, and kept when the
    scene given with --overwrite is bad; a good one with --overwrite replaces it. The
    command lines run one after another in two MPI jobs (conftest.parsph_batch): the first
    writes the previews `p` and `q`, the second runs into them."""
    p, q = tmp_path / "p", tmp_path / "q"
    punch = RUNS / "punch.toml"
    bad, missing, *written = parsph_batch([["preview", punch, "--out", p, "--set", "material.density=-1"],
                                           ["preview", tmp_path / "none.toml"],
                                           ["preview", punch, "--out", p], ["preview", punch, "--out", q]],
                                          ranks, tmp_path / "batch1")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and bad.stdout == ""
    assert bad.stderr.count("parsph: error: material.density must be > 0") == 1, bad.stderr
    assert missing.returncode == 2 and missing.stderr.count("scene file not found") == 1
    for proc in written:
        assert proc.returncode == 0, proc.stderr
    before = {out: (out / "particles.h5").read_bytes() for out in (p, q)}
    again, worse, better = parsph_batch([["preview", punch, "--out", p],
                                         ["preview", punch, "--out", p, "--overwrite", "--set", "kernel.support=0"],
                                         ["preview", punch, "--out", q, "--overwrite", "--set", "parameters.n=3"]],
                                        ranks, tmp_path / "batch2")
    assert again.returncode == 2 and again.stderr.count("already holds a preview") == 1
    assert worse.returncode == 2 and (p / "particles.h5").read_bytes() == before[p]  # kept: the new scene is bad
    assert better.returncode == 0, better.stderr
    assert (q / "particles.h5").read_bytes() != before[q]


def test_a_tool_is_its_rounded_box():
    """The tool's triangles lie on its surface (Tool.contact's gap 0) and cover its area."""
    spec = typed("tools", group="all", lower=[0.0, 0.0, 0.0], upper=[2.0, 1.0, 0.5], radius=0.1, velocity=[0, 0, 0])
    tool = Tool(spec)
    triangles = preview.rounded_box(tool.center, tool.core + tool.radius, tool.radius)
    gap, _ = tool.contact(triangles.reshape(-1, 3), 0.0)
    assert np.abs(gap).max() < 1e-12
    a, b, c = tool.core
    exact = 8 * (a * b + b * c + c * a) + 4 * np.pi * 0.1 * (a + b + c) + 4 * np.pi * 0.1 ** 2  # faces, edges, corners
    assert area(triangles) == pytest.approx(exact, rel=0.01)
    sharp = preview.rounded_box(tool.center, tool.core + tool.radius, 0.0)
    assert area(sharp) == pytest.approx(2 * (2 * 1 + 1 * 0.5 + 0.5 * 2), rel=1e-12)
    flat = preview.rounded_box(np.zeros(2), np.array([1.0, 0.5]), 0.0)  # 2D: the rectangle filled
    assert area(flat) == pytest.approx(2.0)


def test_a_wall_is_its_plane_within_a_box():
    lower, upper = np.zeros(3), np.ones(3)
    square = preview.plane_patch(np.array([0.0, 0.0, 0.25]), np.array([0.0, 0.0, 1.0]), lower, upper)
    assert np.allclose(square[:, :, 2], 0.25)
    assert area(square) == pytest.approx(1.0)
    normal = np.ones(3) / np.sqrt(3.0)  # through the centre: a regular hexagon
    hexagon = preview.plane_patch(np.full(3, 0.5), normal, lower, upper)
    assert len(hexagon) == 6 and np.allclose((hexagon - 0.5) @ normal, 0.0)
    assert len(preview.plane_patch(np.full(3, 5.0), normal, lower, upper)) == 0  # misses the box
    strip = preview.plane_patch(np.array([0.0, 0.5]), np.array([0.0, 1.0]), np.zeros(2), np.ones(2))
    assert np.all(strip[:, :, 1] <= 0.5) and np.ptp(strip[:, :, 0]) == 1.0  # behind the wall, across the box


def test_an_obstacle_with_triangles_gives_its_own(monkeypatch):
    """The hook other obstacles offer: a method triangles(t), asked at t = 0."""
    import parsph.walls

    class Surface:
        def triangles(self, t):
            return np.array([[[0.0, 0.0, t], [1.0, 0.0, t], [0.0, 1.0, t]]])

    class Obstacles(parsph.walls.Walls):
        def __init__(self, walls, tools, dim, *surfaces):
            super().__init__(walls, tools, dim, *surfaces)
            self.items.append(Surface())
            self.names.append("surface0")

    monkeypatch.setattr(parsph.walls, "Walls", Obstacles)
    scene = SimpleNamespace(scene=SimpleNamespace(dimension=3), walls=(), tools=(), surfaces=(), parameters={})
    (name, triangles), = preview.obstacle_surfaces(scene, np.zeros((1, 3)))
    assert name == "surface0" and np.array_equal(triangles, Surface().triangles(0.0))
