"""`parsph preview`: the particles as a run builds them, written before any step, the same on
any rank count; the obstacles' surfaces; the picture; the summary; bad input and the output
directory as `parsph run` treats them."""

from __future__ import annotations

from types import SimpleNamespace

import h5py
import meshio
import numpy as np
import pytest

from conftest import RUNS, parsph_batch
from parsph import preview
from parsph.walls import Tool
from physics import typed

SCENES = {"punch": 2, "tensile_failure": 3}  # a 2D scene with a tool, a 3D one of five parts with groups
RANKS = [pytest.param(1, id="1rank"), pytest.param(2, id="2ranks", marks=pytest.mark.mpi)]


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
def test_the_same_files_on_one_and_two_ranks(tmp_path):
    """Each scene's preview on two ranks (and punch's with serial HDF5 too) against its
    preview on one. The previews on one rank count (and environment) go one after another
    in one MPI job (conftest.parsph_batch): three jobs instead of six."""
    def previews(ranks, scenes, folder, env=None):
        procs = parsph_batch([["preview", RUNS / f"{scene}.toml", "--out", tmp_path / folder / scene]
                              for scene in scenes], ranks, tmp_path / f"batch_{folder}", env=env)
        for proc in procs:
            assert proc.returncode == 0, proc.stderr
        return dict(zip(scenes, procs))

    ones = previews(1, SCENES, "1")
    cases = [(scene, "2", proc) for scene, proc in previews(2, SCENES, "2").items()]
    cases += [("punch", "2_serial", previews(2, ["punch"], "2_serial", env={"PARSPH_SERIAL_HDF5": "1"})["punch"])]
    for scene, folder, two in cases:
        one_dir, two_dir = tmp_path / "1" / scene, tmp_path / folder / scene
        a, b = particles(one_dir), particles(two_dir)
        assert sorted(a) == sorted(b) and {"position", "body", "volume", "mass", "support", "gid", "rank"} <= set(a)
        assert np.array_equal(a["gid"], np.arange(len(a["gid"])))  # global-id order
        for name in a:
            if name != "rank":
                assert np.array_equal(a[name], b[name]) and a[name].dtype == b[name].dtype, (folder, scene, name)
        assert set(b["rank"]) == {0, 1} and set(a["rank"]) == {0}
        assert (one_dir / "particles.xdmf").read_text() == (two_dir / "particles.xdmf").read_text()
        assert summary(ones[scene]) == summary(two) and summary(ones[scene])
        if scene == "punch":  # the tool
            tools = [meshio.read(d / "obstacles.xdmf") for d in (one_dir, two_dir)]
            assert np.array_equal(tools[0].points, tools[1].points) and len(tools[0].cells[0].data) == 64
        for d in (one_dir, two_dir):
            assert (d / "particles.png").stat().st_size > 1000


def test_what_is_written_is_what_a_run_starts_from(tmp_path):
    """Volumes and masses row for row as the run's snapshot has them (summing to the run's);
    the XDMF reads back with meshio; `parsph plot` and the summary read the same file. Each
    scene's preview and one-step run go one after another in one process
    (conftest.parsph_batch)."""
    commands = []
    for scene in SCENES:
        commands += [["preview", RUNS / f"{scene}.toml", "--out", tmp_path / scene / "preview"],
                     ["run", RUNS / f"{scene}.toml", "--out", tmp_path / scene / "run", "--quiet",
                      "--set", "time.max_steps=1",
                      "--set", 'output.snapshot_fields=["position", "volume", "mass", "body"]']]
    procs = parsph_batch(commands, 1, tmp_path / "batch")
    for k, scene in enumerate(SCENES):
        proc, run = procs[2 * k: 2 * k + 2]
        assert proc.returncode == 0, proc.stderr
        assert run.returncode == 0, run.stderr
        with h5py.File(tmp_path / scene / "run" / "snapshots.h5", "r") as f:
            ran = {name: f["step_00000001"][name][()] for name in ("volume", "mass", "body", "gid")}
        shown = particles(tmp_path / scene / "preview")
        for name in ran:
            assert np.array_equal(shown[name], ran[name]), (scene, name)
        assert shown["volume"].sum() == ran["volume"].sum()
        if scene == "tensile_failure":  # five boxes: 5375 mm^3; groups from the scene's boxes
            assert shown["volume"].sum() == pytest.approx(5.375e-6, rel=1e-12)
            assert "volume 5.375e-06 m^3" in proc.stdout and "group 'held'" in proc.stdout
            assert shown["group_held"].dtype == np.uint8 and 0 < shown["group_held"].sum() < len(shown["gid"])
        mesh = meshio.read(tmp_path / scene / "preview" / "particles.xdmf")
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
