"""Solid parts filled by a clipped lattice (geometry.solids, geometry.fill): volume,
centroid and second moments against exact values, transforms, booleans, bad input.

The volumes are scaled to the exact volume, so the sum matches to rounding. The centroid
and the central second moments M = sum V (x - c)(x - c)^T (the inertia tensor is
tr(M) 1 - M) carry the lattice's staircase error at the boundary, O(h): the centroid must lie within h / 2 of
the exact one and the moments within (h / L) |M| (L the solid's size: volume^(1/D), or
given); halving h shrinks the error (the worst case here uses 0.85 of the moments' bound,
a quarter disc, and 0.25 of the centroid's).
"""

import math
import re

import numpy as np
import pytest

from parsph import config
from parsph.errors import InputError
from parsph.geometry import fill
from physics import soft_solid

TOL_CENTROID = 0.5  # centroid error < TOL_CENTROID h
TOL_MOMENTS = 1.0  # second moments' error < TOL_MOMENTS (h / L) |M|


def moments(X, V):
    """(volume, centroid, central second moments) of particles or of exact pieces."""
    vol = V.sum()
    c = (V[:, None] * X).sum(axis=0) / vol
    d = X - c
    return vol, c, np.einsum("i,ij,ik->jk", V, d, d)


def combine(pieces):
    """Exact (volume, centroid, central M) of signed pieces (V, c, central M)."""
    vol = sum(v for v, _, _ in pieces)
    c = sum(v * np.asarray(ci) for v, ci, _ in pieces) / vol
    M = sum(Mi + v * np.outer(ci - c, ci - c) for v, ci, Mi in pieces)
    return vol, c, M


def rectangle(lo, hi):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    size = hi - lo
    v = np.prod(size)
    return v, (lo + hi) / 2, np.diag(v * size ** 2 / 12)


def disc(c, r):
    v = math.pi * r * r
    return v, np.asarray(c, float), np.eye(2) * v * r * r / 4


def check(part, exact, dim=2, size=None, rel=1e-12):
    """Fill `part` and compare with `exact` (V, c, M); returns the errors (centroid,
    moments) relative to h and to h / L |M|. The volume is exact to `rel` (3D booleans:
    manifold3d's volume of the children's meshes)."""
    g = fill(part, "part", dim)
    X, V = g.rows(0, g.count)
    vol, c, M = moments(X, V)
    ev, ec, eM = exact
    assert vol == pytest.approx(ev, rel=rel)
    assert g.count * part["spacing"] ** dim == pytest.approx(ev, rel=0.05)  # the lattice volume, roughly
    h = part["spacing"]
    size = size or ev ** (1.0 / dim)
    dc = np.abs(c - ec).max() / h
    dM = np.abs(M - eM).max() / (np.abs(eM).max() * h / size)
    assert dc < TOL_CENTROID and dM < TOL_MOMENTS, (dc, dM)
    return dc, dM


PLATE = {"shape": "difference", "spacing": 0.002,
         "parts": [{"shape": "polygon", "vertices": [[0, 0], [0.1, 0], [0.1, 0.05], [0, 0.05]]},
                   {"shape": "circle", "center": [0.05, 0.025], "radius": 0.01}]}


def plate_exact():
    v, c, M = disc([0.05, 0.025], 0.01)
    return combine([rectangle([0, 0], [0.1, 0.05]), (-v, c, -M)])


def test_plate_with_a_hole_by_difference():
    check(PLATE, plate_exact())


def test_plate_with_a_hole_by_polygon_holes_converges():
    square = [[0.02, 0.01], [0.03, 0.01], [0.03, 0.03], [0.02, 0.03]]
    part = {"shape": "polygon", "vertices": [[0, 0], [0.1, 0], [0.1, 0.05], [0, 0.05]], "holes": [square]}
    v, c, M = rectangle([0.02, 0.01], [0.03, 0.03])
    exact = combine([rectangle([0, 0], [0.1, 0.05]), (-v, c, -M)])
    coarse = check(dict(part, spacing=0.004), exact)
    fine = check(dict(part, spacing=0.0011), exact)
    assert max(fine) * 0.0011 < max(coarse) * 0.004  # errors relative to h: the absolute ones shrink


def test_circle_area_is_exact_and_union_of_overlapping_rectangles():
    check({"shape": "circle", "center": [1.0, 2.0], "radius": 0.5, "spacing": 0.02}, disc([1.0, 2.0], 0.5))
    ell = {"shape": "union", "spacing": 0.05,
           "parts": [{"shape": "polygon", "vertices": [[0, 0], [2, 0], [2, 1], [0, 1]]},
                     {"shape": "polygon", "vertices": [[0, 0], [1, 0], [1, 2], [0, 2]]}]}
    v, c, M = rectangle([0, 0], [1, 1])  # the overlap, counted twice by the two rectangles
    check(ell, combine([rectangle([0, 0], [2, 1]), rectangle([0, 0], [1, 2]), (-v, c, -M)]))


def test_intersection_of_a_square_and_a_circle_is_a_quarter_disc():
    r = 1.0
    part = {"shape": "intersection", "spacing": 0.02,
            "parts": [{"shape": "polygon", "vertices": [[0, 0], [2, 0], [2, 2], [0, 2]]},
                      {"shape": "circle", "center": [0, 0], "radius": r}]}
    v = math.pi * r * r / 4
    c = np.full(2, 4 * r / (3 * math.pi))
    about_origin = np.array([[math.pi * r ** 4 / 16, r ** 4 / 8], [r ** 4 / 8, math.pi * r ** 4 / 16]])
    check(part, (v, c, about_origin - v * np.outer(c, c)))


def test_transforms_move_volume_centroid_and_moments():
    A_scale, mirror = np.diag([2.0, 0.5]), np.diag([-1.0, 1.0])
    a = math.radians(30.0)
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    A, t = R @ mirror @ A_scale, np.array([0.3, -0.2])
    v, c, M = plate_exact()
    moved = dict(PLATE, scale=[2.0, 0.5], mirror=0, rotate=30.0, translate=t.tolist())
    check(moved, (v * abs(np.linalg.det(A)), A @ c + t, A @ M @ A.T * abs(np.linalg.det(A))), size=0.1)


def test_a_rectangle_polygon_gives_the_box_lattice():
    from parsph.geometry import box
    g = fill({"shape": "polygon", "vertices": [[0, 0], [0.1, 0], [0.1, 0.05], [0, 0.05]], "spacing": 0.01},
             "part", 2)
    X, V = g.rows(0, g.count)
    Xb, Vb = box([0, 0], [0.1, 0.05], 0.01)
    assert np.allclose(X, Xb, rtol=0, atol=1e-15) and np.allclose(V, Vb, rtol=1e-14)


def test_rows_in_blocks_equal_the_whole():
    g = fill(dict(PLATE, spacing=0.001), "part", 2)
    X, _ = g.rows(0, g.count)
    cuts = [0, 7, 1000, 1001, g.count // 2, g.count]
    assert np.array_equal(np.concatenate([g.rows(a, b)[0] for a, b in zip(cuts, cuts[1:])]), X)


def test_outline_files_csv_dxf_svg_relative_to_the_scene(tmp_path):
    """A CSV outline; DXF and SVG outlines with a hole (their units as written)."""
    import shapely
    import trimesh
    square = np.array([[0, 0], [0.1, 0], [0.1, 0.05], [0, 0.05]])
    np.savetxt(tmp_path / "plate.csv", square, delimiter=",")
    plate = shapely.Polygon(square * 1000, [[(40, 15), (60, 15), (60, 35), (40, 35)]])  # in mm
    (tmp_path / "plate.dxf").write_text(trimesh.path.exchange.dxf.export_dxf(trimesh.load_path(plate)))
    (tmp_path / "plate.svg").write_text('<svg xmlns="http://www.w3.org/2000/svg"><path d="M 0 0 L 100 0 L 100 50 '
                                        'L 0 50 Z M 40 15 L 60 15 L 60 35 L 40 35 Z"/></svg>')
    v, c, M = rectangle([0.04, 0.015], [0.06, 0.035])
    holed = combine([rectangle([0, 0], [0.1, 0.05]), (-v, c, -M)])
    for name, exact in (("plate.csv", rectangle([0, 0], [0.1, 0.05])), ("plate.dxf", holed), ("plate.svg", holed)):
        scene = tmp_path / "s.toml"
        scale = "" if name.endswith("csv") else "\nscale = 0.001"
        scene.write_text(SCENE_2D.format(part=f'shape = "polygon"\nfile = "{name}"\nspacing = 0.0025{scale}'))
        part = config.load(str(scene)).geometry.parts[0]
        assert part["file"] == str(tmp_path / name)
        check(part, exact)


SCENE_2D = """[scene]
name = "s"
dimension = 2
[[geometry.parts]]
{part}
[material]
model = "saint_venant_kirchhoff"
density = 1.0
youngs_modulus = 1.0
poisson_ratio = 0.3
[time]
end = 1.0
"""


@pytest.mark.parametrize("part, message", [
    ({"shape": "polygon", "vertices": [[0, 0], [1, 1], [1, 0], [0, 1]], "spacing": 0.1}, "self-intersection"),
    ({"shape": "polygon", "file": "/nonexistent/outline.csv", "spacing": 0.1}, "not found"),
    ({"shape": "circle", "center": [0, 0], "radius": 1.0, "spacing": 1e-6}, r"more than 2\^31; .* units"),
    ({"shape": "difference", "spacing": 0.1,
      "parts": [{"shape": "circle", "center": [0, 0], "radius": 1.0},
                {"shape": "circle", "center": [0, 0], "radius": 2.0}]}, "empty"),
])
def test_bad_2d_solids_are_refused(part, message):
    with pytest.raises(ValueError, match=message):
        fill(part, "part", 2)


def test_scene_keys_of_solids_are_checked(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(SCENE_2D.format(part='shape = "polygon"\nvertices = [[0, 0], [1, 0], [0, 1]]'))
    with pytest.raises(InputError, match=r"geometry.parts\[0\].spacing"):
        config.load(str(scene))
    scene.write_text(SCENE_2D.format(part='shape = "union"\nspacing = 0.1\nparts = [{shape = "box", lower = [0, 0], '
                                          'upper = [1, 1], spacing = 0.1}]'))
    with pytest.raises(InputError, match=r"parts\[0\].shape must be one of polygon"):
        config.load(str(scene))


# --- 3D ----------------------------------------------------------------------------

def ball(c, r):
    v = 4.0 / 3.0 * math.pi * r ** 3
    return v, np.asarray(c, float), np.eye(3) * v * r * r / 5


def frustum(base, axis, length, r0, r1):
    """Exact moments of a frustum by quadrature along its axis."""
    from scipy.integrate import quad
    rho = lambda s: r0 + (r1 - r0) * s / length  # noqa: E731
    v = quad(lambda s: math.pi * rho(s) ** 2, 0, length, epsabs=0, epsrel=1e-13)[0]
    s0 = quad(lambda s: math.pi * rho(s) ** 2 * s, 0, length, epsabs=0, epsrel=1e-13)[0] / v
    axial = quad(lambda s: math.pi * rho(s) ** 2 * (s - s0) ** 2, 0, length, epsabs=0, epsrel=1e-13)[0]
    radial = quad(lambda s: math.pi * rho(s) ** 4 / 4, 0, length, epsabs=0, epsrel=1e-13)[0]
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    return v, np.asarray(base, float) + s0 * a, radial * (np.eye(3) - np.outer(a, a)) + axial * np.outer(a, a)


def mesh_exact(mesh):
    """A closed mesh's exact (volume, centroid, central second moments)."""
    inertia = mesh.moment_inertia  # about the centroid, density 1
    return mesh.volume, mesh.center_mass, np.trace(inertia) / 2 * np.eye(3) - inertia


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    import trimesh
    folder = tmp_path_factory.mktemp("meshes")
    ico = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    ico.export(folder / "ico.stl")
    box = trimesh.creation.box(extents=[2.0, 2.0, 2.0])
    box.apply_translation([0.0, 0.0, 1.0])  # z in 0..2
    box.export(folder / "box.stl")
    small = ico.copy()  # one triangle missing: a small hole
    small.update_faces(np.arange(len(ico.faces)) != 5)
    small.export(folder / "hole.stl")
    cup = ico.copy()  # the top cut away: no inside
    cup.update_faces(ico.triangles_center[:, 2] < 0.3)
    cup.export(folder / "cup.stl")
    inverted = ico.copy()
    inverted.invert()
    inverted.export(folder / "inverted.stl")
    trimesh.Trimesh(np.vstack([ico.vertices, [[3, 0, 0], [4, 0, 0], [5, 0, 0]]]),
                    np.vstack([ico.faces, [[642, 643, 644]]]), process=False).export(folder / "degenerate.stl")
    (folder / "garbage.stl").write_text("not a mesh\n")
    millimetres = ico.copy()
    millimetres.apply_scale(1000.0)
    millimetres.export(folder / "mm.stl")
    # as written: an STL holds single-precision vertices
    return {"folder": folder, "ico": trimesh.load_mesh(folder / "ico.stl"), "box": trimesh.load_mesh(folder / "box.stl")}


def test_sphere_cone_frustum():
    check({"shape": "sphere", "center": [0.1, 0.2, 0.3], "radius": 1.0, "spacing": 0.1}, ball([0.1, 0.2, 0.3], 1.0), 3)
    check({"shape": "cone", "base_center": [0, 0, 0], "axis": [1, 1, 0], "length": 2.0, "radius": 0.5,
           "spacing": 0.05}, frustum([0, 0, 0], [1, 1, 0], 2.0, 0.5, 0.0), 3)
    check({"shape": "cone", "base_center": [0, 0, 1], "length": 2.0, "radius": 0.5, "top_radius": 0.25,
           "spacing": 0.05}, frustum([0, 0, 1], [0, 0, 1], 2.0, 0.5, 0.25), 3)


def test_extrusion_of_a_polygon_with_a_hole():
    part = {"shape": "extrusion", "vertices": [[0, 0], [1, 0], [1, 1], [0, 1]],
            "holes": [[[0.2, 0.2], [0.4, 0.2], [0.4, 0.6], [0.2, 0.6]]], "z0": -0.5, "length": 0.5, "spacing": 0.025}
    v, c, M = combine([rectangle([0, 0], [1, 1]), tuple(-x if i != 1 else x for i, x in
                                                          enumerate(rectangle([0.2, 0.2], [0.4, 0.6])))])
    length = 0.5
    M3 = np.zeros((3, 3))
    M3[:2, :2], M3[2, 2] = M * length, v * length ** 3 / 12
    check(part, (v * length, np.append(c, -0.25), M3), 3)


def test_surface_meshes(meshes):
    check({"shape": "surface", "file": str(meshes["folder"] / "ico.stl"), "spacing": 0.05},
          mesh_exact(meshes["ico"]), 3)
    check({"shape": "surface", "file": str(meshes["folder"] / "box.stl"), "spacing": 0.1},
          mesh_exact(meshes["box"]), 3)


def test_3d_booleans(meshes):
    hollow = {"shape": "difference", "spacing": 0.05, "parts": [
        {"shape": "sphere", "center": [0, 0, 0], "radius": 1.0}, {"shape": "sphere", "center": [0, 0, 0], "radius": 0.6}]}
    v, c, M = ball([0, 0, 0], 0.6)
    check(hollow, combine([ball([0, 0, 0], 1.0), (-v, c, -M)]), 3, rel=1e-7)
    r = 1.0  # a ball cut by the box z in 0..2: the upper hemisphere
    half = {"shape": "intersection", "spacing": 0.05, "parts": [
        {"shape": "sphere", "center": [0, 0, 0], "radius": r}, {"shape": "surface", "file": str(meshes["folder"] / "box.stl")}]}
    v, zc = 2 * math.pi * r ** 3 / 3, 3 * r / 8
    M = np.diag([v * r * r / 5, v * r * r / 5, v * r * r / 5 - v * zc * zc])
    g = fill(half, "half", 3)
    assert g.volume == pytest.approx(v, rel=1e-4)  # manifold3d's volume of the finely meshed ball's cut
    check(half, (g.volume, np.array([0, 0, zc]), M), 3)
    pair = {"shape": "union", "spacing": 0.1, "parts": [
        {"shape": "sphere", "center": [0, 0, 0], "radius": 1.0}, {"shape": "sphere", "center": [3, 0, 0], "radius": 1.0}]}
    g = fill(pair, "pair", 3)
    check(pair, combine([ball([0, 0, 0], 1.0), ball([3, 0, 0], 1.0)]), 3, size=1.6, rel=1e-7)


def test_3d_transforms_move_volume_centroid_and_moments(meshes):
    from scipy.spatial.transform import Rotation
    S, mirror = np.diag([1.0, 2.0, 0.5]), np.diag([1.0, -1.0, 1.0])
    R = Rotation.from_rotvec([0.0, 30.0, 45.0], degrees=True).as_matrix()
    A, t = R @ mirror @ S, np.array([1.0, -2.0, 0.5])
    det = abs(np.linalg.det(A))
    v, c, M = frustum([0, 0, 0], [0, 0, 1], 2.0, 0.5, 0.25)
    cone = {"shape": "cone", "base_center": [0, 0, 0], "length": 2.0, "radius": 0.5, "top_radius": 0.25,
            "spacing": 0.04, "scale": [1.0, 2.0, 0.5], "mirror": 1, "rotate": [0.0, 30.0, 45.0], "translate": t.tolist()}
    check(cone, (v * det, A @ c + t, A @ M @ A.T * det), 3, size=1.0)
    v, c, M = mesh_exact(meshes["ico"])
    ico = {"shape": "surface", "file": str(meshes["folder"] / "ico.stl"), "spacing": 0.05, "scale": 0.5,
           "mirror": [0, 2], "translate": [5.0, 0.0, 0.0]}
    check(ico, (v / 8, np.array([5.0, 0, 0]) + c * [-0.5, 0.5, -0.5], M / 32), 3)


SCENE_3D = """[scene]
name = "solid"
dimension = 3
[[geometry.parts]]
{part}
[material]
model = "saint_venant_kirchhoff"
density = 1.0
youngs_modulus = 1.0
poisson_ratio = 0.3
[time]
end = 1.0
"""


def preview_particles(out):
    import h5py
    with h5py.File(out / "particles.h5", "r") as f:
        return {name: f["step_00000000"][name][()] for name in f["step_00000000"]}


@pytest.mark.mpi
def test_a_packed_surface_scene_is_the_same_on_1_and_3_ranks(tmp_path, meshes):
    from conftest import parsph
    import shutil
    shutil.copy(meshes["folder"] / "ico.stl", tmp_path / "ico.stl")
    scene = tmp_path / "solid.toml"
    scene.write_text(SCENE_3D.format(part='shape = "surface"\nfile = "ico.stl"\nspacing = 0.05\npack = true\n'
                                          'pack_iterations = 5'))
    fields = {}
    for ranks in (1, 3):
        proc = parsph(["preview", scene, "--out", tmp_path / f"r{ranks}"], ranks=ranks)
        assert proc.returncode == 0, proc.stderr
        assert "geometry.parts[0]: " in proc.stdout and "lattice volume error" in proc.stdout
        fields[ranks] = preview_particles(tmp_path / f"r{ranks}")
    assert len(fields[1]["gid"]) > 30000  # 40 layers: 3 chunks of 16 layers, one a rank
    assert fields[1]["volume"].sum() == pytest.approx(meshes["ico"].volume, rel=1e-12)
    for name in ("position", "volume", "gid"):
        assert np.array_equal(fields[1][name], fields[3][name]), name



@pytest.mark.mpi
def test_a_run_of_a_body_filled_from_an_stl_is_the_same_on_1_and_3_ranks(tmp_path, meshes):
    """A ball filled from the STL icosphere, its lower cap held and the rest set moving:
    the particles and the whole history of 20 steps bit for bit the same on 1 and 3 ranks."""
    from conftest import run_on_ranks
    import shutil
    shutil.copy(meshes["folder"] / "ico.stl", tmp_path / "ico.stl")
    scene = tmp_path / "ball.toml"
    scene.write_text("""[scene]
name = "ball"
dimension = 3
[[geometry.parts]]
shape = "surface"
file = "ico.stl"
spacing = 0.25
""" + soft_solid(2.0) + """[formulation]
type = "tlsph"
[time]
end = 1.0
max_steps = 20
[output]
snapshot_fields = ["position", "velocity", "J"]
[groups.cap]
box = { lower = [-2.0, -2.0, -2.0], upper = [2.0, 2.0, -0.6] }
[groups.all]
all = true
[[initial]]
type = "velocity_field"
group = "all"
expression = ["y", "-x", "z"]
[[bc]]
type = "fixed"
group = "cap"
""")
    (one, h1), (three, h3) = run_on_ranks(scene, tmp_path)
    assert len(one["gid"]) > 200 and np.array_equal(one["gid"], three["gid"])
    assert h1["step"][-1] == 20 and h1["kinetic_energy"][-1] != h1["kinetic_energy"][0]  # it ran
    for field in ("position", "velocity", "J"):
        assert np.array_equal(one[field], three[field]), field
    for name, series in h1.items():
        assert np.array_equal(h3[name], series), name

BAD_SURFACES = [
    ("missing.stl", 0.1, r"file '.*missing.stl' not found"),
    ("garbage.stl", 0.1, r"garbage.stl: holds no triangles"),
    ("cup.stl", 0.1, r"cup.stl: the surface is not closed: \d+ boundary edge\(s\) \(holes\) within .* the inside "
                     r"cannot be decided"),
    ("inverted.stl", 0.1, r"inverted.stl: the surface encloses a volume of -.* normals point inwards"),
    ("degenerate.stl", 0.1, r"degenerate.stl: 1 degenerate triangle\(s\) of zero area"),
    ("mm.stl", 0.001, r"geometry.parts\[0\] \(.*mm.stl\): spacing 0.001 would fill .*a mesh in mm and a spacing in m\?"),
]


SELF_INTERSECTING = ('shape = "polygon"\nvertices = [[0, 0], [1, 1], [1, 0], [0, 1]]\nspacing = 0.1',
                     r"geometry.parts\[0\] \(vertices, holes\) is not a simple polygon: self-intersection at "
                     r"\(0.5, 0.5\)")


def bad_scenes(tmp_path, meshes):
    """[(scene path, output directory, pattern of the message)] of every bad solid."""
    cases = []
    for i, (name, spacing, message) in enumerate(BAD_SURFACES):
        scene = tmp_path / f"bad{i}.toml"
        scene.write_text(SCENE_3D.format(part=f'shape = "surface"\nfile = "{meshes["folder"] / name}"\n'
                                              f'spacing = {spacing}'))
        cases.append((str(scene), str(tmp_path / f"out{i}"), message))
    scene = tmp_path / "polygon.toml"
    scene.write_text(SCENE_2D.format(part=SELF_INTERSECTING[0]))
    return cases + [(str(scene), str(tmp_path / "out"), SELF_INTERSECTING[1])]


def test_bad_solids_exit_2_with_the_file_and_the_problem(tmp_path, meshes, capsys):
    from parsph.cli import main
    for scene, out, message in bad_scenes(tmp_path, meshes):
        assert main(["preview", scene, "--out", out]) == 2
        err = capsys.readouterr().err
        assert err.count("parsph: error:") == 1 and re.search(message, err), err


@pytest.mark.mpi
def test_bad_solids_exit_2_on_2_ranks(tmp_path, meshes):
    """Every case in one launch (the CLI's main in turn), and one as its own job."""
    import json
    import subprocess
    import sys

    from conftest import CEILING, ROOT, mpiexec, parsph
    cases = bad_scenes(tmp_path, meshes)
    (tmp_path / "cases.json").write_text(json.dumps(cases))
    proc = subprocess.run([mpiexec(), "-n", "2", sys.executable, str(ROOT / "tests" / "mpi" / "solids_check.py"),
                           str(tmp_path / "cases.json")], capture_output=True, text=True, timeout=CEILING, cwd=ROOT)
    assert proc.returncode == 0 and "OK" in proc.stdout, proc.stdout + proc.stderr
    scene, out, message = cases[2]  # the open cup
    proc = parsph(["preview", scene, "--out", out], ranks=2)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.count("parsph: error:") == 1 and re.search(message, proc.stderr), proc.stderr


def test_a_small_hole_is_survived_with_a_warning(meshes):
    warnings = []
    g = fill({"shape": "surface", "file": str(meshes["folder"] / "hole.stl"), "spacing": 0.1}, "part", 3,
             warn=warnings.append)
    assert len(warnings) == 1 and re.search(r"not closed: 3 boundary edge\(s\).*winding number", warnings[0])
    assert g.volume == pytest.approx(meshes["ico"].volume, rel=1e-12)  # the hole filled (a flat triangle)
    assert g.rows(0, g.count)[1].sum() == pytest.approx(g.volume, rel=1e-12)


@pytest.mark.parametrize("part, dim", [(PLATE, 2), ({"shape": "sphere", "center": [0, 0, 0], "radius": 1.0,
                                                     "spacing": 0.1}, 3)])
def test_packing_smooths_the_boundary_and_keeps_count_and_volumes(part, dim):
    """Packed: every particle at least h/2 inside, the outer layer's distances to the
    surface less spread than the lattice's staircase, no two particles closer than h/2."""
    from scipy.spatial import cKDTree

    from parsph.geometry.pack import boundary
    h = part["spacing"]
    lattice, packed = fill(part, "part", dim), fill(dict(part, pack=True, pack_iterations=10), "part", dim)
    X0, V0 = lattice.rows(0, lattice.count)
    X, V = packed.rows(0, packed.count)
    assert packed.count == lattice.count and np.array_equal(V, V0)
    distance = boundary(packed.solid)
    d0, d = distance(X0)[0], distance(X)[0]
    assert d.max() <= -0.5 * h * (1 - 1e-9)
    assert np.std(d[d > -h]) < 0.6 * np.std(d0[d0 > -h])
    assert cKDTree(X).query(X, k=2)[0][:, 1].min() > 0.5 * h
    assert np.array_equal(X[d0 < -4 * h], X0[d0 < -4 * h])  # the inside stays on the lattice
