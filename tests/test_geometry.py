import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from parsph.geometry import (
    box,
    cylinder,
    disk,
    random_box,
    random_patch,
    ring,
    select,
    support_for_neighbours,
    support_from_spacing,
    union,
)
from parsph.geometry.voronoi import _cells


@pytest.fixture(scope="module")
def patch():
    return random_patch([0.0, 0.0], [1.0, 1.0], 444, seed=3)


# --- lattice.box ---------------------------------------------------------------

@pytest.mark.parametrize("n", [1, 2, 5])
def test_box_cell_counts_and_volume(n):
    pos, vol = box([0.0, 0.0], [3.0, 8.0], 1.0 / n)
    assert pos.shape == (3 * n * 8 * n, 2) and vol.shape == (pos.shape[0],)
    assert pos.dtype == np.float64 and vol.dtype == np.float64
    assert np.allclose(vol, 1.0 / n**2, rtol=1e-12)
    assert vol.sum() == pytest.approx(24.0, rel=1e-12)
    assert np.all((pos > 0.0) & (pos < [3.0, 8.0]))


@pytest.mark.parametrize("n", [1, 2, 5])
def test_box_node_counts_and_volume(n):
    pos, vol = box([0.0, 0.0], [3.0, 8.0], 1.0 / n, placement="node")
    assert pos.shape == ((3 * n + 1) * (8 * n + 1), 2)
    assert vol.sum() == pytest.approx(24.0, rel=1e-12)


def test_box_1d_order_and_first_axis_fastest():
    pos, vol = box([-1.0], [1.0], 0.5)
    assert pos.shape == (4, 1)
    assert np.allclose(pos[:, 0], [-0.75, -0.25, 0.25, 0.75])
    assert np.allclose(vol, 0.5)
    pos, _ = box([0.0, 0.0, 0.0], [3.0, 2.0, 2.0], 1.0)
    assert np.allclose(pos[:4], [[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [2.5, 0.5, 0.5], [0.5, 1.5, 0.5]])


def test_box_node_lumping_3d():
    lo, hi, h = np.array([0.0, -1.0, 2.0]), np.array([2.0, 1.0, 3.0]), 0.25
    pos, vol = box(lo, hi, h, placement="node")
    assert vol.sum() == pytest.approx(np.prod(hi - lo), rel=1e-12)
    on_boundary = (np.isclose(pos, lo) | np.isclose(pos, hi)).sum(axis=1)
    assert np.allclose(vol, h**3 * 0.5**on_boundary, rtol=1e-12)
    assert np.count_nonzero(on_boundary == 3) == 8                       # corners: 1/8
    assert np.count_nonzero(on_boundary == 2) == 4 * (7 + 7 + 3)        # edges: 1/4
    assert pos.min(axis=0) == pytest.approx(lo) and pos.max(axis=0) == pytest.approx(hi)


def test_box_node_lumping_2d_half_and_quarter():
    pos, vol = box([0.0, 0.0], [1.0, 1.0], 0.5, placement="node")
    assert np.allclose(vol.reshape(3, 3), [[1 / 16, 1 / 8, 1 / 16], [1 / 8, 1 / 4, 1 / 8],
                                           [1 / 16, 1 / 8, 1 / 16]])


def test_box_actual_spacing_within_tolerance():
    pos, vol = box([0.0], [1.0], 0.1 * (1 + 1e-8))
    assert len(pos) == 10 and vol.sum() == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("args, kwargs, word", [
    (([0, 0], [1, 1], 0.0), {}, "spacing"),
    (([0, 0], [1, 1], -0.1), {}, "spacing"),
    (([0, 1], [1, 1], 0.1), {}, "lower"),
    (([0, 0], [1, 1, 1], 0.1), {}, "upper"),
    (([0, 0], [1, 1], 0.3), {}, "multiple"),
    (([0], [1], 0.1), {"placement": "vertex"}, "placement"),
    (([0, 0, 0, 0], [1, 1, 1, 1], 0.1), {}, "lower"),
])
def test_box_bad_input(args, kwargs, word):
    with pytest.raises(ValueError, match=word):
        box(*args, **kwargs)


# --- shapes ----------------------------------------------------------------------

@pytest.mark.parametrize("axis", [0, 1, 2])
def test_cylinder(axis):
    base = np.array([1.0, 2.0, 3.0])
    r, length, h = 0.5, 2.0, 0.1
    pos, vol = cylinder(base, r, length, h, axis=axis)
    assert vol.sum() == pytest.approx(math.pi * r * r * length, rel=1e-12)
    assert np.allclose(vol, vol[0])
    rel = pos - base
    radial = np.linalg.norm(np.delete(rel, axis, axis=1), axis=1)
    assert np.all(radial < r)
    assert np.all((rel[:, axis] > 0) & (rel[:, axis] < length))
    layers = np.unique(np.round(rel[:, axis], 12))
    assert np.allclose(layers, (np.arange(20) + 0.5) * h)
    assert np.any(radial < 1e-12)                   # the axis passes through a column
    gauss = sum(i * i + j * j < 25 for i in range(-5, 6) for j in range(-5, 6))
    assert len(pos) == 20 * gauss                   # lattice points strictly inside r = 5 h
    assert np.allclose(np.delete(rel, axis, axis=1).mean(axis=0), 0.0, atol=1e-12)


def test_ring_and_disk():
    c = np.array([0.3, -0.2])
    pos, vol = ring(c, 1.0, 2.0, 0.1)
    assert vol.sum() == pytest.approx(math.pi * (4.0 - 1.0), rel=1e-12)
    radius = np.linalg.norm(pos - c, axis=1)
    assert np.all((radius > 1.0) & (radius < 2.0))
    assert np.allclose(np.unique(np.round(radius, 12)), 1.0 + (np.arange(10) + 0.5) * 0.1)
    assert np.allclose((vol[:, None] * pos).sum(0) / vol.sum(), c, atol=1e-12)
    pos, vol = disk(c, 1.0, 0.05)
    assert vol.sum() == pytest.approx(math.pi, rel=1e-12)
    radius = np.linalg.norm(pos - c, axis=1)
    assert radius.min() == pytest.approx(0.025) and radius.max() < 1.0
    assert len(pos) == pytest.approx(math.pi / 0.05**2, rel=0.05)


@pytest.mark.parametrize("func, args, word", [
    (ring, ([0, 0], 2.0, 1.0, 0.1), "inner_radius"),
    (ring, ([0, 0], 1.0, 1.0, 0.1), "inner_radius"),
    (ring, ([0, 0], -1.0, 1.0, 0.1), "inner_radius"),
    (ring, ([0, 0], 0.5, 1.0, 0.0), "spacing"),
    (ring, ([0, 0, 0], 0.5, 1.0, 0.1), "center"),
    (disk, ([0, 0], 0.0, 0.1), "radius"),
    (cylinder, ([0, 0, 0], 1.0, -1.0, 0.1), "length"),
    (cylinder, ([0, 0], 1.0, 1.0, 0.1), "base_center"),
    (cylinder, ([0, 0, 0], 1.0, 1.0, 0.1, 3), "axis"),
])
def test_shapes_bad_input(func, args, word):
    with pytest.raises(ValueError, match=word):
        func(*args)


def test_union_drops_coincident_later_points():
    a = box([0.0, 0.0], [1.0, 1.0], 0.25, placement="node")
    b = box([1.0, 0.0], [2.0, 1.0], 0.25, placement="node")
    pos, vol = union(a, b, tol=1e-6)
    assert len(pos) == 25 + 25 - 5
    assert np.array_equal(pos[:25], a[0]) and np.array_equal(vol[:25], a[1])
    assert len(cKDTree(pos).query_pairs(1e-6)) == 0
    # closer than tol to any earlier point is dropped, exactly tol apart is kept (the rule
    # does not depend on the order points are visited in, so ranks can apply it apart)
    line = (np.array([[0.0], [0.4], [0.8], [1.3]]), np.ones(4))
    pos, vol = union(line, tol=0.5)
    assert np.allclose(pos[:, 0], [0.0, 1.3])
    pos, _ = union(line, tol=0.0)
    assert len(pos) == 4
    with pytest.raises(ValueError, match="tol"):
        union(a, tol=-1.0)
    with pytest.raises(ValueError, match="dimension"):
        union(a, (np.zeros((1, 3)), np.ones(1)), tol=0.1)


# --- voronoi -----------------------------------------------------------------------

@pytest.mark.parametrize("dim", [2, 3])
def test_cells_of_regular_points_are_lattice_cells(dim):
    lo, hi = np.zeros(dim), np.array([2.0, 1.0, 1.0][:dim])
    points, volumes = box(lo, hi, 0.5)
    centroids, cell_volumes = _cells(points, lo, hi)
    assert np.allclose(centroids, points, atol=1e-12)
    assert np.allclose(cell_volumes, volumes, rtol=1e-12)


def test_random_patch_properties(patch):
    pos, vol = patch
    assert pos.shape == (444, 2) and vol.shape == (444,)
    assert vol.sum() == pytest.approx(1.0, rel=1e-12)
    assert np.all((pos > 0.0) & (pos < 1.0)) and np.all(vol > 0.0)
    dist, _ = cKDTree(pos).query(pos, k=2)
    assert dist[:, 1].min() > 0.3 * math.sqrt(1.0 / 444)
    assert np.std(vol) > 0.02 * np.mean(vol)                 # irregular, not a lattice


def test_random_patch_reproducible_per_seed(patch):
    pos, vol = random_patch([0.0, 0.0], [1.0, 1.0], 444, seed=3)
    assert np.array_equal(pos, patch[0]) and np.array_equal(vol, patch[1])
    other, _ = random_patch([0.0, 0.0], [1.0, 1.0], 444, seed=4, lloyd_iterations=2)
    assert not np.allclose(other, pos)


def test_random_patch_lloyd_improves_spacing():
    lo, hi, n = [-1.0, 2.0], [1.0, 3.0], 100
    raw, vol = random_patch(lo, hi, n, seed=0, lloyd_iterations=0)
    relaxed, _ = random_patch(lo, hi, n, seed=0, lloyd_iterations=20)
    assert vol.sum() == pytest.approx(2.0, rel=1e-12)
    gap = [cKDTree(p).query(p, k=2)[0][:, 1].min() for p in (raw, relaxed)]
    assert gap[1] > gap[0]


def test_random_box_3d():
    lo, hi = np.array([0.0, 0.0, -1.0]), np.array([1.0, 2.0, 1.0])
    pos, vol = random_box(lo, hi, 80, seed=1, lloyd_iterations=5)
    assert pos.shape == (80, 3)
    assert vol.sum() == pytest.approx(4.0, rel=1e-12)
    assert np.all((pos > lo) & (pos < hi))


@pytest.mark.parametrize("kwargs, word", [
    ({"count": 0}, "count"),
    ({"count": 2.5}, "count"),
    ({"count": 10, "lloyd_iterations": -1}, "lloyd_iterations"),
    ({"count": 10, "upper": [0.0, 1.0]}, "lower"),
    ({"count": 10, "upper": [1.0, 1.0, 1.0], "lower": [0.0, 0.0, 0.0]}, "2 components"),
])
def test_random_patch_bad_input(kwargs, word):
    args = {"lower": [0.0, 0.0], "upper": [1.0, 1.0]} | kwargs
    with pytest.raises(ValueError, match=word):
        random_patch(**args)


# --- smoothing ---------------------------------------------------------------------

def test_support_for_neighbours_on_patch(patch):
    pos, _ = patch
    h = support_for_neighbours(pos, 12)
    assert h.shape == (444,) and np.all(h > 0)
    dist = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=2)
    neighbours = (dist < h[:, None]).sum(axis=1) - 1
    assert np.all(np.abs(neighbours - 12) <= 2)


def test_support_for_neighbours_lattice_and_errors():
    pos, _ = box([0.0], [1.0], 0.1)
    h = support_for_neighbours(pos, 2)
    assert h[5] == pytest.approx(0.15) and h[0] == pytest.approx(0.25)
    with pytest.raises(ValueError, match="target"):
        support_for_neighbours(pos, 0)
    with pytest.raises(ValueError, match="target"):
        support_for_neighbours(pos[:3], 2)
    with pytest.raises(ValueError, match="positions"):
        support_for_neighbours(np.zeros(5), 2)


def test_support_from_spacing():
    assert np.allclose(support_from_spacing([0.25, 1.0], 2.0, 2), [1.0, 2.0])
    assert np.allclose(support_from_spacing([0.001], 1.5, 3), [0.15])
    with pytest.raises(ValueError, match="factor"):
        support_from_spacing([1.0], 0.0, 2)
    with pytest.raises(ValueError, match="dim"):
        support_from_spacing([1.0], 1.0, 4)
    with pytest.raises(ValueError, match="volumes"):
        support_from_spacing([1.0, -1.0], 1.0, 2)


# --- groups ------------------------------------------------------------------------

@pytest.fixture
def grid():
    return box([0.0, 0.0], [4.0, 3.0], 1.0, placement="node")      # 5 x 4 nodes


def test_select_all_and_invert(grid):
    pos, _ = grid
    assert select({"all": True}, pos).all()
    assert not select({"all": True, "invert": True}, pos).any()


def test_select_box(grid):
    pos, _ = grid
    mask = select({"box": {"lower": [1.0, 0.0], "upper": [2.0, 1.0]}}, pos)
    assert np.array_equal(np.flatnonzero(mask), [1, 2, 6, 7])
    inv = select({"box": {"lower": [1.0, 0.0], "upper": [2.0, 1.0]}, "invert": True}, pos)
    assert np.array_equal(inv, ~mask)


def test_select_sphere(grid):
    pos, _ = grid
    mask = select({"sphere": {"center": [2.0, 1.0], "radius": 1.0}}, pos)
    assert np.array_equal(np.flatnonzero(mask), [2, 6, 7, 8, 12])
    line, _ = box([0.0], [1.0], 0.1)
    assert select({"sphere": {"center": [0.5], "radius": 0.2}}, line).sum() == 4


def test_select_halfspace(grid):
    pos, _ = grid
    mask = select({"halfspace": {"point": [0.0, 2.0], "normal": [0.0, 5.0]}}, pos)
    assert np.array_equal(mask, pos[:, 1] >= 2.0) and mask.sum() == 10
    diag = select({"halfspace": {"point": [0.0, 0.0], "normal": [1.0, -1.0]}}, pos)
    assert np.array_equal(diag, pos[:, 0] >= pos[:, 1])


def test_select_nearest(grid):
    pos, _ = grid
    assert np.flatnonzero(select({"nearest": [2.9, 1.2]}, pos)).tolist() == [8]
    assert np.flatnonzero(select({"nearest": [2.5, 1.5]}, pos)).tolist() == [7]   # 4-way tie


def test_select_extreme(grid):
    pos, vol = grid
    top = select({"extreme": {"axis": 1, "side": "max", "tolerance": 0.1}}, pos)
    assert np.array_equal(np.flatnonzero(top), [15, 16, 17, 18, 19])
    left = select({"extreme": {"axis": 0, "side": "min", "tolerance": 1.0}}, pos)
    assert np.array_equal(left, pos[:, 0] <= 1.0)
    assert np.array_equal(select({"extreme": {"axis": 1, "side": "max"}}, pos, vol), top)


def test_select_empty_is_not_an_error(grid):
    pos, _ = grid
    assert not select({"sphere": {"center": [10.0, 10.0], "radius": 0.5}}, pos).any()


@pytest.mark.parametrize("spec, word", [
    ({}, "exactly one of"),
    ({"all": True, "box": {"lower": [0, 0], "upper": [1, 1]}}, "exactly one of"),
    ({"ball": {"center": [0, 0], "radius": 1}}, "halfspace"),
    ({"box": {"lower": [0, 0, 0], "upper": [1, 1, 1]}}, "box.lower must have 2 components"),
    ({"nearest": [1.0]}, "nearest must have 2 components"),
    ({"sphere": {"centre": [0, 0], "radius": 1}}, "sphere needs keys"),
    ({"sphere": {"center": [0, 0], "radius": -1}}, "sphere.radius"),
    ({"halfspace": {"point": [0, 0], "normal": [0, 0]}}, "halfspace.normal"),
    ({"extreme": {"axis": 2, "side": "max", "tolerance": 0}}, "extreme.axis"),
    ({"extreme": {"axis": 0, "side": "top", "tolerance": 0}}, "extreme.side"),
    ({"extreme": {"axis": 0, "side": "max"}}, "extreme.tolerance"),
    ({"all": True, "invert": "yes"}, "invert"),
])
def test_select_bad_spec(grid, spec, word):
    with pytest.raises(ValueError, match=word):
        select(spec, grid[0])
