"""Solid parts filled by a clipped lattice (geometry.solids, geometry.fill): volume,
centroid and second moments against exact values, transforms, booleans, bad input.

The volumes are scaled to the exact volume, so the sum matches to rounding. The centroid
and the central second moments M = sum V (x - c)(x - c)^T (the inertia tensor is
tr(M) 1 - M) carry the lattice's staircase error at the boundary, O(h): the tolerance is
TOL * h / L (L the solid's size), and halving h must shrink the error.
"""

import math

import numpy as np
import pytest

from parsph import config
from parsph.errors import InputError
from parsph.geometry import fill

TOL = 1.0  # centroid error < TOL h; second moments' error < TOL (h / L) |M|


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


def check(part, exact, dim=2, size=None):
    """Fill `part` and compare with `exact` (V, c, M); returns the errors (centroid,
    moments) relative to h and to h / L |M|."""
    g = fill(part, "part", dim)
    X, V = g.rows(0, g.count)
    vol, c, M = moments(X, V)
    ev, ec, eM = exact
    assert vol == pytest.approx(ev, rel=1e-12)
    assert g.count * part["spacing"] ** dim == pytest.approx(ev, rel=0.05)  # the lattice volume, roughly
    h = part["spacing"]
    size = size or ev ** (1.0 / dim)
    dc = np.abs(c - ec).max() / h
    dM = np.abs(M - eM).max() / (np.abs(eM).max() * h / size)
    assert dc < TOL and dM < TOL, (dc, dM)
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


def test_outline_file_csv_and_dxf_relative_to_the_scene(tmp_path):
    import trimesh
    square = np.array([[0, 0], [0.1, 0], [0.1, 0.05], [0, 0.05]])
    np.savetxt(tmp_path / "plate.csv", square, delimiter=",")
    path = trimesh.load_path(np.vstack([square, square[:1]]))
    (tmp_path / "plate.dxf").write_text(trimesh.path.exchange.dxf.export_dxf(path))
    for name in ("plate.csv", "plate.dxf"):
        scene = tmp_path / "s.toml"
        scene.write_text(SCENE_2D.format(part=f'shape = "polygon"\nfile = "{name}"\nspacing = 0.005'))
        part = config.load(str(scene))["geometry"]["parts"][0]
        assert part["file"] == str(tmp_path / name)
        check(part, rectangle([0, 0], [0.1, 0.05]))


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
