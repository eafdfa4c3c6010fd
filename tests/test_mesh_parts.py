"""Mesh parts (geometry.mesh_parts): a particle per element at its centroid with its exact
volume, the mesh's sets as groups, the same particles on any number of ranks, and bad
meshes refused by name."""

from __future__ import annotations

import filecmp
import itertools
import math
import re
import tomllib

import meshio
import numpy as np
import pytest
from mpi4py import MPI

from conftest import ROOT, parsph, parsph_batch, run_on_ranks
from parsph import config
from parsph.build import build_bodies
from parsph.errors import InputError
from parsph.geometry import lattice
from parsph.geometry.mesh_parts import MeshPart
from physics import soft_solid

# (VTK / meshio node order) each element type as tetrahedra of its nodes, for exact moments
TETS = {"tetra": [[0, 1, 2, 3]], "pyramid": [[0, 1, 2, 4], [0, 2, 3, 4]],
        "wedge": [[0, 1, 2, 3], [1, 2, 3, 4], [2, 3, 4, 5]],
        "hexahedron": [[0, 1, 3, 4], [1, 2, 3, 6], [1, 3, 4, 6], [1, 4, 5, 6], [3, 4, 6, 7]],
        "triangle": [[0, 1, 2]], "quad": [[0, 1, 2], [0, 2, 3]]}


def simplex_moments(v: np.ndarray):
    """Exact volume, first moment and second moment about the origin of the simplex of
    vertices v (D + 1, D): V, V c, V / ((D+1)(D+2)) (sum v v^T + s s^T)."""
    d = v.shape[1]
    volume = abs(np.linalg.det(v[1:] - v[0])) / math.factorial(d)
    s = v.sum(axis=0)
    return volume, volume * s / (d + 1), volume / ((d + 1) * (d + 2)) * (v.T @ v + np.outer(s, s))


def element_moments(points, cell_type, nodes):
    """Exact (volume, first moment, second moment) of one element with planar faces, from its
    tetrahedra (triangles)."""
    parts = [simplex_moments(points[np.asarray(nodes)[t]]) for t in TETS[cell_type]]
    return tuple(sum(p[k] for p in parts) for k in range(3))


def oriented(points, cell_type, cells):
    """The cells with their nodes reordered (a mirror of the element's node order) where the
    element's signed volume is negative."""
    mirror = {"tetra": [0, 2, 1, 3], "pyramid": [0, 3, 2, 1, 4], "wedge": [0, 2, 1, 3, 5, 4],
              "hexahedron": [0, 3, 2, 1, 4, 7, 6, 5], "triangle": [0, 2, 1], "quad": [0, 3, 2, 1]}[cell_type]
    out = []
    for c in cells:
        t = points[np.asarray(c)[TETS[cell_type][0]]]
        out.append(list(c) if np.linalg.det(t[1:] - t[0]) > 0 else [c[k] for k in mirror])
    return np.array(out)


def grid(shape, lower, upper):
    """Nodes of a structured grid (x fastest) and the node index function."""
    axes = [np.linspace(lo, hi, n + 1) for lo, hi, n in zip(lower, upper, shape)]
    mesh = np.meshgrid(*axes, indexing="ij")
    points = np.column_stack([m.ravel(order="F") for m in mesh])
    dims = [n + 1 for n in shape]

    def node(*index):
        return int(np.ravel_multi_index(index, dims, order="F"))
    return points, node


def box_cells(kind, shape, lower, upper):
    """A box [lower, upper] divided into shape cells, each cell as one hexahedron, 6 tetrahedra,
    2 wedges or 6 pyramids (an apex node at its centre)."""
    points, node = grid(shape, lower, upper)
    points = list(points)
    cells = []
    for k, j, i in itertools.product(*(range(n) for n in shape[::-1])):  # x fastest
        h = [node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
             node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1), node(i, j + 1, k + 1)]
        if kind == "hexahedron":
            cells.append(h)
        elif kind == "tetra":  # Kuhn's six around the diagonal 0-6
            for a, b in ((1, 2), (2, 3), (3, 7), (7, 4), (4, 5), (5, 1)):
                cells.append([h[0], h[a], h[b], h[6]])
        elif kind == "wedge":
            cells += [[h[0], h[1], h[2], h[4], h[5], h[6]], [h[0], h[2], h[3], h[4], h[6], h[7]]]
        else:
            points.append(np.mean([points[n] for n in h], axis=0))
            apex = len(points) - 1
            for face in ([0, 1, 2, 3], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]):
                cells.append([h[f] for f in face] + [apex])
    points = np.array(points)
    return points, oriented(points, kind, cells)


def exact_box(lower, upper):
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    volume, c = np.prod(hi - lo), 0.5 * (lo + hi)
    return volume, volume * c, volume * (np.outer(c, c) + np.diag((hi - lo) ** 2 / 12.0))


def check_moments(part, points, cell_type, cells, exact):
    """The particles are the elements' exact centroids and volumes; their sums and the
    elements' own second moments add up to the exact body's."""
    x, v = part.rows(0, part.count)
    assert part.count == len(cells)
    second = np.einsum("n,ni,nj->ij", v, x, x)
    for n, c in enumerate(cells):
        volume, first, inertia = element_moments(points, cell_type, c)
        assert v[n] == pytest.approx(volume, rel=1e-12)
        assert x[n] == pytest.approx(first / volume, rel=1e-12, abs=1e-12)
        second += inertia - np.outer(first, first) / volume  # the element's own, about its centroid
    volume, first, inertia = exact
    assert v.sum() == pytest.approx(volume, rel=1e-12)
    assert v @ x == pytest.approx(first, rel=1e-12)
    assert second == pytest.approx(inertia, rel=1e-12)


@pytest.mark.parametrize("kind", ["hexahedron", "tetra", "wedge", "pyramid"])
def test_a_box_of_elements_has_the_box_volume_centroid_and_inertia(kind, tmp_path):
    lower, upper = [0.5, -1.0, 2.0], [2.5, 0.5, 3.0]
    points, cells = box_cells(kind, (4, 3, 2), lower, upper)
    meshio.write(tmp_path / "box.vtu", meshio.Mesh(points, [(kind, cells)]))
    part = MeshPart(str(tmp_path / "box.vtu"), dimension=3)
    check_moments(part, points, kind, cells, exact_box(lower, upper))
    assert part.spacing == pytest.approx((3.0 / part.count) ** (1 / 3))


def test_a_distorted_hexahedron_has_the_trilinear_volume_and_centroid(tmp_path):
    """The unit cube with its corner (1, 1, 1) raised by d: the top face is z = 1 + d x y, so
    V = 1 + d/4, and the centroid is that of the region below it."""
    d = 0.6
    points = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1 + d], [0, 1, 1]],
                      float)
    meshio.write(tmp_path / "hex.msh", meshio.Mesh(points, [("hexahedron", [list(range(8))])]), file_format="gmsh22")
    x, v = MeshPart(str(tmp_path / "hex.msh"), dimension=3).rows(0, 1)
    volume = 1 + d / 4
    assert v[0] == pytest.approx(volume, rel=1e-14)
    assert x[0] == pytest.approx(np.array([0.5 + d / 6, 0.5 + d / 6, (1 + d / 2 + d * d / 9) / 2]) / volume, rel=1e-14)


def annulus(n_sides, r_in, r_out, layers, triangles):
    """The region between two regular n-gons (circumradii r_in, r_out) as quads, or triangles."""
    radii = np.linspace(r_in, r_out, layers + 1)
    theta = 2 * np.pi * np.arange(n_sides) / n_sides
    points = np.array([[r * np.cos(t), r * np.sin(t)] for r in radii for t in theta])
    cells = []
    for layer, k in itertools.product(range(layers), range(n_sides)):
        a, b = layer * n_sides + k, layer * n_sides + (k + 1) % n_sides
        q = [a, b, b + n_sides, a + n_sides]
        cells += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] if triangles else [q]
    kind = "triangle" if triangles else "quad"
    return points, kind, oriented(points, kind, cells)


@pytest.mark.parametrize("triangles", [False, True])
def test_a_polygonal_annulus_has_its_exact_area_centroid_and_inertia(triangles, tmp_path):
    n, r_in, r_out = 24, 0.3, 1.0
    points, kind, cells = annulus(n, r_in, r_out, 3, triangles)
    centre = np.array([0.2, -0.1])
    # written in the plane z = 0 (3 coordinates), placed by translate
    meshio.write(tmp_path / "ring.msh", meshio.Mesh(np.column_stack([points, np.zeros(len(points))]),
                                                    [("line", [[0, 1]]), (kind, cells)]), file_format="gmsh22")
    part = MeshPart(str(tmp_path / "ring.msh"), translate=centre, dimension=2)
    area = 0.5 * n * math.sin(2 * math.pi / n) * (r_out ** 2 - r_in ** 2)
    polar = n / 12 * math.sin(2 * math.pi / n) * (2 + math.cos(2 * math.pi / n)) * (r_out ** 4 - r_in ** 4)
    exact = (area, area * centre, area * np.outer(centre, centre) + 0.5 * polar * np.eye(2))
    check_moments(part, points + centre, kind, cells, exact)


def test_scale_and_translate_place_the_elements(tmp_path):
    points, cells = box_cells("hexahedron", (2, 2, 2), [0, 0, 0], [10, 20, 30])
    meshio.write(tmp_path / "mm.inp", meshio.Mesh(points, [("hexahedron", cells)]))
    part = MeshPart(str(tmp_path / "mm.inp"), scale=1e-3, translate=[1.0, 0.0, -1.0], dimension=3)
    x, v = part.rows(0, part.count)
    assert v.sum() == pytest.approx(6e-6, rel=1e-12)
    assert v @ x / v.sum() == pytest.approx([1.005, 0.01, -0.985], rel=1e-12)
    assert part.rows(3, 5)[0] == pytest.approx(x[3:5])


SCENE = """
[scene]
name = "mesh"
dimension = 3
[geometry]
[[geometry.parts]]
shape = "mesh"
file = "{file}"
{extra}
""" + soft_solid(2.0) + """[formulation]
type = "tlsph"
[time]
end = 1.0
max_steps = 20
[output]
snapshot_fields = ["position", "velocity", "J"]
"""


def scene_file(tmp_path, file, groups: dict, extra="", name="scene.toml"):
    text = SCENE.format(file=file, extra=extra) + "".join(
        f"[groups.{g}]\n{spec}\n" for g, spec in groups.items())
    path = tmp_path / name
    path.write_text(text)
    return path


def groups_of(path) -> dict:
    """{group: sorted particle gids} of the scene file `path`, built on one rank."""
    scene = config.load(str(path))
    owned, _ = build_bodies(scene, MPI.COMM_SELF)
    names = sorted(scene.groups)
    return {name: np.sort(owned["gid"][owned["groups"][:, k] == 1]) for k, name in enumerate(names)}


def bar_mesh():
    """A bar of 6 x 2 x 2 unit hexahedra (x fastest: element e at x index e % 6), its end
    faces as quads, and the element and node index sets the tests name."""
    points, cells = box_cells("hexahedron", (6, 2, 2), [0, 0, 0], [6, 2, 2])
    left = np.flatnonzero(points[:, 0] == 0.0)
    faces = [c[[0, 3, 7, 4]] for c in cells if points[c[0], 0] == 0.0]  # the faces on x = 0
    return points, cells, np.array(faces), left



def test_mirror_and_rotate_move_volume_centroid_and_inertia(tmp_path):
    """A tetrahedral box mirrored in y and turned by a rotation vector, as a solid part is:
    volume, first and second moments are the box's mapped by A = R M (the mirrored elements
    keep positive volumes)."""
    from scipy.spatial.transform import Rotation
    lower, upper = [0.5, -1.0, 2.0], [2.5, 0.5, 3.0]
    points, cells = box_cells("tetra", (4, 3, 2), lower, upper)
    meshio.write(tmp_path / "box.vtu", meshio.Mesh(points, [("tetra", cells)]))
    part = MeshPart(str(tmp_path / "box.vtu"), scale=2.0, translate=[1.0, 2.0, 3.0], dimension=3, mirror=1,
                    rotate=[0.0, 30.0, 45.0])
    A = Rotation.from_rotvec([0.0, 30.0, 45.0], degrees=True).as_matrix() @ np.diag([1.0, -1.0, 1.0]) * 2.0
    t = np.array([1.0, 2.0, 3.0])
    volume, first, inertia = exact_box(lower, upper)
    x, v = part.rows(0, part.count)
    assert (v > 0).all() and v.sum() == pytest.approx(8.0 * volume, rel=1e-12)
    assert v @ x / v.sum() == pytest.approx(A @ (first / volume) + t, rel=1e-12)
    y = (x - t) @ np.linalg.inv(A).T  # back in the file's frame: the centroids, exactly placed
    x0, v0 = MeshPart(str(tmp_path / "box.vtu"), dimension=3).rows(0, part.count)
    assert y == pytest.approx(x0, abs=1e-12) and v == pytest.approx(8.0 * v0, rel=1e-12)

def test_gmsh_physical_groups_select_their_elements_and_face_groups_the_elements_on_them(tmp_path):
    points, cells, faces, _ = bar_mesh()
    physical = np.where(np.arange(len(cells)) % 6 < 3, 1, 2)  # x < 3: group 1
    mesh = meshio.Mesh(points, [("quad", faces), ("hexahedron", cells)],
                       cell_data={"gmsh:physical": [np.full(len(faces), 5), physical],
                                  "gmsh:geometrical": [np.full(len(faces), 5), physical]},
                       field_data={"near": np.array([1, 3]), "far": np.array([2, 3]), "end": np.array([5, 2])})
    meshio.write(tmp_path / "bar.msh", mesh, file_format="gmsh22")
    got = groups_of(scene_file(tmp_path, "bar.msh", {"near": 'mesh_set = "near"', "far": 'mesh_set = "far"',
                                                     "end": 'mesh_set = "end"', "tag": 'mesh_set = "gmsh:physical=2"',
                                                     "not_end": 'mesh_set = "end"\ninvert = true'}))
    e = np.arange(len(cells))
    assert np.array_equal(got["near"], e[e % 6 < 3]) and np.array_equal(got["far"], e[e % 6 >= 3])
    assert np.array_equal(got["tag"], got["far"])
    assert np.array_equal(got["end"], e[e % 6 == 0])  # the face group's elements
    assert np.array_equal(got["not_end"], e[e % 6 != 0])


GMSH41 = """$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n2\n3 1 "left"\n3 2 "right"\n$EndPhysicalNames
$Entities\n0 0 0 2\n1 0 0 0 1 1 1 1 1 0\n2 1 0 0 2 1 1 1 2 0\n$EndEntities
$Nodes\n1 12 1 12\n3 1 0 12\n""" + "".join(f"{n}\n" for n in range(1, 13)) + """0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1
1 0 1\n1 1 1\n0 1 1\n2 0 0\n2 1 0\n2 0 1\n2 1 1\n$EndNodes
$Elements\n2 2 1 2\n3 1 5 1\n1 1 2 3 4 5 6 7 8\n3 2 5 1\n2 2 9 10 3 6 11 12 7\n$EndElements\n"""


def test_gmsh_4_physical_volumes_are_sets(tmp_path):
    """Two unit cubes, each a volume entity of its own physical group, as Gmsh 4.1 writes them."""
    (tmp_path / "two.msh").write_text(GMSH41)
    part = MeshPart(str(tmp_path / "two.msh"), dimension=3)
    assert {"left", "right"} <= set(part.set_names())
    assert part.set_mask("left").tolist() == [True, False] and part.set_mask("right").tolist() == [False, True]
    assert part.rows(0, 2)[1] == pytest.approx([1.0, 1.0], rel=1e-14)


def test_abaqus_element_and_node_sets_select_their_elements(tmp_path):
    points, cells, _, left = bar_mesh()
    e = np.arange(len(cells))
    corner = [int(np.flatnonzero((points == [6, 2, 2]).all(axis=1))[0])]
    mesh = meshio.Mesh(points, [("hexahedron", cells)], cell_sets={"middle": [e[(e % 6 == 2) | (e % 6 == 3)]]},
                       point_sets={"left": left, "corner": np.array(corner)})
    meshio.write(tmp_path / "bar.inp", mesh)
    got = groups_of(scene_file(tmp_path, "bar.inp", {"middle": 'mesh_set = "middle"', "left": 'mesh_set = "left"',
                                                     "corner": 'mesh_set = "corner"'}))
    assert np.array_equal(got["middle"], e[(e % 6 == 2) | (e % 6 == 3)])
    assert np.array_equal(got["left"], e[e % 6 == 0])  # the elements touching the nodes on x = 0
    assert np.array_equal(got["corner"], [len(cells) - 1])


def test_cells_take_only_a_sets_elements_and_vtk_tags_are_sets(tmp_path):
    points, cells, _, _ = bar_mesh()
    e = np.arange(len(cells))
    mesh = meshio.Mesh(points, [("hexahedron", cells)], cell_data={"CellEntityIds": [np.where(e % 6 < 2, 7, 8)]})
    meshio.write(tmp_path / "bar.vtu", mesh)
    path = scene_file(tmp_path, "bar.vtu", {"first": 'mesh_set = "CellEntityIds=7"'}, 'cells = ["CellEntityIds=8"]')
    scene = config.load(str(path))
    owned, _ = build_bodies(scene, MPI.COMM_SELF)
    assert len(owned["gid"]) == 16 and owned["X"][:, 0].min() == pytest.approx(2.5, rel=1e-14)  # x index 2..5
    assert owned["volume"].sum() == pytest.approx(16.0, rel=1e-14)
    assert not owned["groups"][:, sorted(scene.groups).index("first")].any()


def test_an_unknown_set_is_refused_naming_the_file_and_its_sets(tmp_path):
    points, cells, _, left = bar_mesh()
    meshio.write(tmp_path / "bar.inp", meshio.Mesh(points, [("hexahedron", cells)], cell_sets={"A": [[0]]},
                                                   point_sets={"N": left}))
    with pytest.raises(InputError, match=r"groups\.g: mesh file .*bar\.inp has no set 'B'; its sets: A, N"):
        groups_of(scene_file(tmp_path, "bar.inp", {"g": 'mesh_set = "B"'}))


@pytest.mark.parametrize("spec, message", [
    ('mesh_set = "A"\nmesh_part = 1', "groups.g.mesh_part = 1: the scene has 1 part(s) of shape 'mesh'"),
    ('all = true\nmesh_part = 0', "groups.g.mesh_part goes with mesh_set"),
    ('mesh_set = 3', "groups.g.mesh_set must be a string"),
])
def test_mesh_set_groups_are_checked_with_the_scene(spec, message, tmp_path):
    with pytest.raises(InputError, match=re.escape(message)):
        config.load(str(scene_file(tmp_path, "bar.inp", {"g": spec})))


def test_a_mesh_set_needs_a_mesh_part():
    raw = tomllib.loads(SCENE.format(file="x", extra=""))
    raw["geometry"]["parts"] = [{"shape": "box", "lower": [0, 0, 0], "upper": [1, 1, 1], "spacing": 0.5}]
    raw["groups"] = {"g": {"mesh_set": "A"}}
    with pytest.raises(InputError, match="groups.g.mesh_set needs a part of shape 'mesh'"):
        config.validate(raw)


def test_a_count_above_the_particle_limit_is_refused(tmp_path, monkeypatch):
    points, cells, _, _ = bar_mesh()
    meshio.write(tmp_path / "bar.vtu", meshio.Mesh(points, [("hexahedron", cells)]))
    monkeypatch.setattr(lattice, "MAX_PARTICLES", 10)
    with pytest.raises(ValueError, match="bar.vtu give more than 2"):
        MeshPart(str(tmp_path / "bar.vtu"), dimension=3)


def write_bad_meshes(tmp_path) -> dict:
    """{case: (file name, a part of the message)} of meshes a scene must refuse."""
    points, cells, faces, _ = bar_mesh()
    inverted = cells.copy()
    inverted[7] = inverted[7][[0, 3, 2, 1, 4, 7, 6, 5]]
    meshio.write(tmp_path / "inverted.vtu", meshio.Mesh(points, [("hexahedron", inverted)]))
    meshio.write(tmp_path / "faces.msh", meshio.Mesh(points, [("quad", faces)]), file_format="gmsh22")
    meshio.write(tmp_path / "good.inp", meshio.Mesh(points, [("hexahedron", cells)], cell_sets={"A": [[0]]}))
    (tmp_path / "corrupt.msh").write_text("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0\n")
    return {"missing": ("absent.msh", "mesh file not found"),
            "corrupt": ("corrupt.msh", "cannot be read"),
            "inverted": ("inverted.vtu", "element 7 of cell block 0 (hexahedron"),
            "no_elements": ("faces.msh", "has no 3D elements (its cells: quad)"),
            "unknown_set": ("good.inp", "has no set 'B'; its sets: A")}


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
def test_bad_meshes_exit_2_naming_the_file(ranks, tmp_path):
    """Each case's `parsph preview`, one after another in one MPI job (conftest.parsph_batch)."""
    cases = write_bad_meshes(tmp_path)
    commands = [["preview", scene_file(tmp_path, file, {"g": 'mesh_set = "B"'} if case == "unknown_set" else {},
                                       name=f"{case}.toml"), "--out", tmp_path / f"out_{case}"]
                for case, (file, _) in cases.items()]
    for (case, (file, message)), proc in zip(cases.items(), parsph_batch(commands, ranks, tmp_path / "batch")):
        assert proc.returncode == 2, f"{case}: exit {proc.returncode}\n{proc.stderr}"
        assert "Traceback" not in proc.stderr and proc.stderr.count("parsph: error") == 1, proc.stderr
        assert file in proc.stderr and message in proc.stderr, f"{case}: {proc.stderr}"


def test_a_mesh_in_mm_at_scale_1_is_warned_of(tmp_path):
    points, cells = box_cells("hexahedron", (2, 2, 2), [0, 0, 0], [20, 20, 40])
    meshio.write(tmp_path / "mm.vtu", meshio.Mesh(points, [("hexahedron", cells)]))
    proc = parsph(["preview", scene_file(tmp_path, "mm.vtu", {}), "--out", tmp_path / "out"])
    assert proc.returncode == 0, proc.stderr
    assert "spans 20 m at scale = 1; a mesh drawn in mm needs scale = 1e-3" in proc.stderr


@pytest.mark.mpi
def test_a_mesh_scene_is_the_same_on_1_and_3_ranks(tmp_path):
    """Tetrahedra of a bar, one end held by a node set, the other pulled by an element set:
    positions, velocities and the history are bit for bit the same on 1 and 3 ranks."""
    points, cells = box_cells("tetra", (6, 2, 2), [0, 0, 0], [0.06, 0.02, 0.02])
    centre = points[cells].mean(axis=1)
    mesh = meshio.Mesh(points, [("tetra", cells)], cell_sets={"pulled": [np.flatnonzero(centre[:, 0] > 0.05)]},
                       point_sets={"held": np.flatnonzero(points[:, 0] == 0.0)})
    meshio.write(tmp_path / "bar.inp", mesh)
    path = scene_file(tmp_path, "bar.inp", {"held": 'mesh_set = "held"', "pulled": 'mesh_set = "pulled"'})
    with open(path, "a") as fh:
        fh.write('[[bc]]\ntype = "fixed"\ngroup = "held"\n[[bc]]\ntype = "velocity"\ngroup = "pulled"\n'
                 'value = [1.0, 0.0, 0.0]\nramp = 1.0e-4\n')
    (one, h1), (three, h3) = run_on_ranks(path, tmp_path)
    assert np.array_equal(one["gid"], np.arange(len(cells))) and np.array_equal(three["gid"], one["gid"])
    for field in ("position", "velocity", "J"):
        assert np.array_equal(one[field], three[field]), field
    assert (one["velocity"][:, 0] > 0).any()
    for name, series in h1.items():
        assert np.array_equal(h3[name], series), name


def test_the_specimen_mesh_tool_writes_the_committed_file(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("specimen_mesh", ROOT / "tools" / "specimen_mesh.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    tool.main(tmp_path / "specimen.msh")
    assert filecmp.cmp(tmp_path / "specimen.msh", ROOT / "runs" / "parts" / "specimen.msh", shallow=False)
    part = MeshPart(str(tmp_path / "specimen.msh"), dimension=3)
    assert part.count == 9600
    y = np.linspace(-0.5 * tool.LENGTH, 0.5 * tool.LENGTH, tool.CELLS[1] + 1)  # the node rows
    width = tool.width(y)  # the elements' edges are straight between the rows: trapezoids
    assert part.volume.sum() == pytest.approx(tool.THICKNESS * np.sum(0.5 * (width[1:] + width[:-1]) * np.diff(y)),
                                              rel=1e-12)
    assert [int(part.set_mask(s).sum()) for s in ("grip_bottom", "gauge", "grip_top")] == [1728, 6144, 1728]


def test_the_specimen_scene_builds_its_grips_and_gauge_from_the_mesh():
    scene = config.load(str(ROOT / "runs" / "specimen_mesh.toml"))
    owned, _ = build_bodies(scene, MPI.COMM_SELF)
    names = sorted(scene.groups)
    counts = {name: int(owned["groups"][:, k].sum()) for k, name in enumerate(names)}
    assert counts == {"all": 9600, "gauge": 6144, "grip_bottom": 1728, "grip_top": 1728}
    top = owned["groups"][:, names.index("grip_top")] == 1
    assert owned["X"][top, 2].min() > 16e-3 and owned["X"][~top, 2].max() < 16e-3
    # the support: kernel.support times each particle's (element volume)^(1/3)
    assert owned["support"] == pytest.approx(2.0 * np.cbrt(owned["volume"]), rel=1e-12)
