"""User solids of a scene's parts: polygons, circles, spheres, cones, extrusions, closed
surface meshes and their booleans, each with an inside test, its exact volume (area in 2D)
and bounding box, after the part's transforms (scale, mirror, rotate, translate).

2D solids are shapely geometries (booleans and transforms by shapely, area exact); 3D
solids compose inside tests, and the volume of a 3D boolean is that of the children's
meshes united by manifold3d (curved children meshed finely with their exact volume).
Files are read with trimesh (STL/OBJ/PLY surfaces, DXF/SVG outlines) or numpy (CSV).
Problems are ValueErrors naming the file or key.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import shapely

CIRCLE_SEGMENTS = 1024  # sides of a circle's polygon (its area made exactly pi r^2)
AMBIGUOUS = (0.2, 0.8)  # generalised winding numbers that do not say inside or outside
AMBIGUOUS_LIMIT = 0.05  # the largest fraction of ambiguous probes a surface may give
PROBES = 32  # probe lattice per axis of a surface's ambiguity check
BOOLEANS = ("union", "difference", "intersection")
SHAPES_2D = ("polygon", "circle")
SHAPES_3D = ("sphere", "cone", "extrusion", "surface")


def _vector(value, name, dim):
    vec = np.asarray(value, dtype=np.float64)
    if vec.shape != (dim,) or not np.all(np.isfinite(vec)):
        raise ValueError(f"{name} must be {dim} finite numbers, got {value!r}")
    return vec


def _positive(value, name):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number, got {value!r}")
    return float(value)


def _readable(path):
    if not os.path.isfile(path):
        raise ValueError(f"file {path!r} not found" if not os.path.exists(path) else f"{path!r} is not a file")
    if not os.access(path, os.R_OK):
        raise ValueError(f"file {path!r} is not readable")
    return path


# ---------------------------------------------------------------- 2D: shapely geometries

def _ring(points, name):
    xy = np.asarray(points, dtype=np.float64) if isinstance(points, (list, np.ndarray)) else None
    if xy is None or xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 3 or not np.all(np.isfinite(xy)):
        raise ValueError(f"{name} must be a list of at least 3 [x, y] vertices, got {points!r}")
    return xy


def _valid(geom, what):
    """`geom` if it is a valid polygon (no self-intersection) of positive area."""
    if not shapely.is_valid(geom):
        reason = re.sub(r"\[(\S+) (\S+)\]", r" at (\1, \2)", shapely.is_valid_reason(geom)).lower()
        raise ValueError(f"{what} is not a simple polygon: {reason} (edges must not cross; holes must lie "
                         "inside the outline without touching it)")
    if not geom.area > 0.0:
        raise ValueError(f"{what} has zero area")
    return geom


def _outline_file(path):
    """The polygons of a CSV (x,y per line), DXF or SVG outline file."""
    _readable(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in (".csv", ".txt", ".xy"):
        try:
            xy = np.loadtxt(path, delimiter="," if ext == ".csv" else None, ndmin=2, comments="#")
        except ValueError as exc:
            raise ValueError(f"{path}: not a list of x,y vertices ({exc})") from None
        return shapely.Polygon(_ring(xy, path))
    if ext not in (".dxf", ".svg"):
        raise ValueError(f"{path}: unknown outline format '{ext}' (use .csv, .dxf or .svg)")
    import trimesh
    try:
        outline = trimesh.load_path(path)
        polygons = list(outline.polygons_full)
    except Exception as exc:  # noqa: BLE001 - any reader failure is the file's problem
        raise ValueError(f"{path}: cannot be read as a {ext[1:].upper()} outline ({type(exc).__name__}: {exc})") from None
    if not polygons:
        raise ValueError(f"{path}: holds no closed outline")
    return shapely.union_all(polygons)


def _polygon(part, name):
    if ("file" in part) == ("vertices" in part):
        raise ValueError(f"{name}: give either vertices or file")
    if "file" in part:
        if "holes" in part:
            raise ValueError(f"{name}.holes: a file outline brings its own holes")
        return _valid(_outline_file(part["file"]), part["file"])
    holes = part.get("holes") or []
    if not isinstance(holes, list):
        raise ValueError(f"{name}.holes must be a list of vertex lists, got {holes!r}")
    geom = shapely.Polygon(_ring(part["vertices"], f"{name}.vertices"),
                           [_ring(h, f"{name}.holes[{i}]") for i, h in enumerate(holes)])
    return _valid(geom, f"{name} (vertices, holes)")


def _circle(part, name):
    """A polygon of CIRCLE_SEGMENTS sides whose area is exactly pi r^2 (its vertices a
    little outside the circle): cut by other parts it errs by ~r^2 (2 pi / N)^3 per cut."""
    center = _vector(part["center"], f"{name}.center", 2)
    r = _positive(part["radius"], f"{name}.radius")
    n = CIRCLE_SEGMENTS
    big = r * math.sqrt(2.0 * math.pi / (n * math.sin(2.0 * math.pi / n)))
    theta = 2.0 * math.pi * np.arange(n) / n
    return shapely.Polygon(center + big * np.column_stack((np.cos(theta), np.sin(theta))))


def _affine(part, name, dim):
    """(A, t) of the part's scale, mirror, rotate and translate, applied in that order."""
    A = np.eye(dim)
    if part.get("scale") is not None:
        s = part["scale"]
        s = np.full(dim, _positive(s, f"{name}.scale")) if not isinstance(s, list) else \
            _vector(s, f"{name}.scale", dim)
        if np.any(s <= 0.0):
            raise ValueError(f"{name}.scale must be positive (use mirror to reflect), got {part['scale']!r}")
        A = np.diag(s) @ A
    if part.get("mirror") is not None:
        axes = part["mirror"] if isinstance(part["mirror"], list) else [part["mirror"]]
        if not all(isinstance(a, int) and not isinstance(a, bool) and 0 <= a < dim for a in axes):
            raise ValueError(f"{name}.mirror must be an axis (0..{dim - 1}) or a list of axes, got {part['mirror']!r}")
        m = np.ones(dim)
        for a in axes:
            m[a] = -m[a]
        A = np.diag(m) @ A
    if part.get("rotate") is not None:
        rot = part["rotate"]
        if dim == 2:
            if isinstance(rot, bool) or not isinstance(rot, (int, float)):
                raise ValueError(f"{name}.rotate must be an angle in degrees in 2D, got {rot!r}")
            c, s = math.cos(math.radians(rot)), math.sin(math.radians(rot))
            R = np.array([[c, -s], [s, c]])
        else:
            from scipy.spatial.transform import Rotation  # here: scipy takes a quarter of a second to import
            R = Rotation.from_rotvec(_vector(rot, f"{name}.rotate", 3), degrees=True).as_matrix()
        A = R @ A
    t = np.zeros(dim) if part.get("translate") is None else _vector(part["translate"], f"{name}.translate", dim)
    return A, t


class Region:
    """A 2D solid: a shapely (multi)polygon."""

    dim = 2

    def __init__(self, geom):
        self.geom = geom
        shapely.prepare(geom)
        self.volume = float(geom.area)
        b = geom.bounds
        self.bounds = (np.array(b[:2]), np.array(b[2:]))

    def inside(self, P):
        return shapely.contains_xy(self.geom, P[:, 0], P[:, 1])


def _given(part):
    """The part's keys that are given (a resolved part holds None for the absent ones)."""
    return {k: v for k, v in part.items() if v is not None}


def _geometry_2d(part, name):
    part = _given(part)
    shape = part["shape"]
    if shape in BOOLEANS:
        geoms = [_geometry_2d(p, f"{name}.parts[{i}]") for i, p in enumerate(_children(part, name))]
        if shape == "union":
            geom = shapely.union_all(geoms)
        elif shape == "intersection":
            geom = shapely.intersection_all(geoms)
        else:
            geom = shapely.difference(geoms[0], shapely.union_all(geoms[1:]))
    elif shape == "polygon":
        geom = _polygon(part, name)
    elif shape == "circle":
        geom = _circle(part, name)
    else:
        raise ValueError(f"{name}: shape '{shape}' is not a 2D solid (use {', '.join(SHAPES_2D + BOOLEANS)})")
    A, t = _affine(part, name, 2)
    if not np.array_equal(A, np.eye(2)) or np.any(t):
        geom = shapely.affinity.affine_transform(geom, [*A.ravel(), *t])
    if geom.is_empty or not geom.area > 0.0:
        raise ValueError(f"{name}: the {shape} is empty (zero area)")
    return geom


def _children(part, name):
    parts = part.get("parts")
    if not isinstance(parts, list) or not parts or not all(isinstance(p, dict) and "shape" in p for p in parts):
        raise ValueError(f"{name}.parts must be a non-empty list of tables with a shape, got {parts!r}")
    if part["shape"] != "union" and len(parts) < 2:
        raise ValueError(f"{name}: a {part['shape']} needs at least 2 parts")
    return parts


# ---------------------------------------------------------------- 3D solids

class Sphere:
    """A ball."""

    def __init__(self, center, radius):
        self.center, self.radius = center, radius
        self.volume = 4.0 / 3.0 * math.pi * radius ** 3
        self.bounds = (center - radius, center + radius)

    def inside(self, P):
        return np.einsum("ij,ij->i", P - self.center, P - self.center) < self.radius ** 2

    def mesh(self):
        import trimesh
        m = trimesh.creation.icosphere(subdivisions=6, radius=1.0)
        m.apply_scale(self.radius * (4.0 / 3.0 * math.pi / m.volume) ** (1.0 / 3.0))  # the exact volume
        m.apply_translation(self.center)
        return m


class Cone:
    """A frustum of a cone: radius r0 at base_center, r1 at base_center + length · axis."""

    def __init__(self, base, axis, length, r0, r1):
        self.base, self.axis, self.length, self.r0, self.r1 = base, axis, length, r0, r1
        self.volume = math.pi * length * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0
        top = base + length * axis
        rim = np.sqrt(np.maximum(0.0, 1.0 - axis ** 2))  # extent of a unit circle normal to axis
        self.bounds = (np.minimum(base - r0 * rim, top - r1 * rim), np.maximum(base + r0 * rim, top + r1 * rim))

    def inside(self, P):
        d = P - self.base
        s = d @ self.axis
        radial = np.einsum("ij,ij->i", d, d) - s * s
        r = self.r0 + (self.r1 - self.r0) * s / self.length
        return (s > 0.0) & (s < self.length) & (radial < r * r)

    def mesh(self):
        import trimesh
        n = CIRCLE_SEGMENTS
        m = trimesh.creation.revolve([[0.0, 0.0], [self.r0, 0.0], [self.r1, self.length], [0.0, self.length]],
                                     sections=n)
        factor = math.sqrt(2.0 * math.pi / (n * math.sin(2.0 * math.pi / n)))  # the n-gon's area made pi r^2
        m.apply_transform(np.diag([factor, factor, 1.0, 1.0]))
        from scipy.spatial.transform import Rotation  # here: scipy takes a quarter of a second to import
        z = np.array([0.0, 0.0, 1.0])
        R = Rotation.align_vectors([self.axis], [z])[0].as_matrix()
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, self.base
        m.apply_transform(T)
        return m


class Extrusion:
    """A 2D region extruded along z from z0 over length."""

    def __init__(self, region, z0, length):
        self.region, self.z0, self.length = region, z0, length
        self.volume = region.volume * length
        lo, hi = region.bounds
        self.bounds = (np.append(lo, z0), np.append(hi, z0 + length))

    def inside(self, P):
        inz = (P[:, 2] > self.z0) & (P[:, 2] < self.z0 + self.length)
        out = np.zeros(len(P), dtype=bool)
        out[inz] = self.region.inside(P[inz, :2])
        return out

    def mesh(self):
        import trimesh
        geoms = getattr(self.region.geom, "geoms", [self.region.geom])
        m = trimesh.util.concatenate([trimesh.creation.extrude_polygon(g, self.length) for g in geoms])
        m.apply_translation([0.0, 0.0, self.z0])
        return m


class Surface:
    """The inside of a triangle mesh file: generalised winding number > 1/2 (libigl's fast
    winding number), which decides the inside of a mesh with small holes too."""

    def __init__(self, path, warn):
        import trimesh
        _readable(path)
        try:
            mesh = trimesh.load_mesh(path, process=True)
        except Exception as exc:  # noqa: BLE001 - any reader failure is the file's problem
            raise ValueError(f"{path}: cannot be read as a triangle mesh ({type(exc).__name__}: {exc})") from None
        if isinstance(mesh, trimesh.Scene):
            mesh = mesh.to_mesh() if mesh.geometry else None
        if mesh is None or not len(getattr(mesh, "faces", ())):
            raise ValueError(f"{path}: holds no triangles")
        self.V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        self.F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        scale = float(np.ptp(self.V, axis=0).max())
        area = mesh.area_faces
        bad = np.flatnonzero(area <= 1e-12 * scale * scale)
        if bad.size:
            at = self.V[self.F[bad[0]]].mean(axis=0)
            raise ValueError(f"{path}: {bad.size} degenerate triangle(s) of zero area (the first near "
                             f"{_point(at)}); clean the mesh (merge or remove them) and export it again")
        self.closed = bool(mesh.is_watertight)
        if self.closed:
            volume = float(mesh.volume)
        else:
            edges = mesh.edges_sorted
            unique, counts = np.unique(edges, axis=0, return_counts=True)
            boundary = unique[counts == 1]
            lo, hi = self.V[boundary.ravel()].min(axis=0), self.V[boundary.ravel()].max(axis=0)
            fraction = self._ambiguous()
            where = (f"{path}: the surface is not closed: {len(boundary)} boundary edge(s) (holes) within "
                     f"{_point(lo)}..{_point(hi)}")
            if fraction > AMBIGUOUS_LIMIT:
                raise ValueError(f"{where}; the inside cannot be decided: {100 * fraction:.1f} % of probe points "
                                 f"have a winding number between {AMBIGUOUS[0]} and {AMBIGUOUS[1]} (at most "
                                 f"{100 * AMBIGUOUS_LIMIT:g} % allowed); close the holes")
            filled = mesh.copy()
            filled.fill_holes()
            volume = float(filled.volume) if filled.is_watertight else None
            warn(f"{where}; the inside is decided by the generalised winding number "
                 f"({100 * fraction:.2f} % ambiguous probe points), the volume "
                 + ("is that of the mesh with its holes filled" if volume is not None else
                    "is the lattice's (count x spacing^3): the holes could not be filled"))
        if volume is not None and not volume > 0.0:
            raise ValueError(f"{path}: the surface encloses a volume of {volume:.6g} "
                             + ("(its normals point inwards: flip the faces' orientation)" if volume < 0.0 else
                                "(a flat or empty surface)"))
        self.volume = volume
        self.bounds = (self.V.min(axis=0), self.V.max(axis=0))
        self.path = path
        self._mesh = mesh
        if self.closed:  # off a closed surface the winding number is constant in a ball
            self.far, self._tree = self._far, None

    def _ambiguous(self):
        """Fraction of a PROBES^3 lattice over the box whose winding number is ambiguous,
        among those not clearly outside."""
        lo, hi = self.V.min(axis=0), self.V.max(axis=0)
        axes = [lo[k] + (np.arange(PROBES) + 0.5) * (hi[k] - lo[k]) / PROBES for k in range(3)]
        P = np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])
        w = np.abs(self.winding(P))
        some = np.count_nonzero(w > AMBIGUOUS[0])
        return np.count_nonzero((w > AMBIGUOUS[0]) & (w < AMBIGUOUS[1])) / max(some, 1)

    def winding(self, P):
        import igl
        return igl.fast_winding_number(self.V, self.F, np.ascontiguousarray(P, dtype=np.float64))

    def inside(self, P):
        return self.winding(P) > 0.5

    def _far(self, P, r):
        """Points farther than r from the surface (for a closed surface, their whole ball is
        inside or outside with them)."""
        import igl
        if self._tree is None:
            self._tree = igl.AABB()
            self._tree.init(self.V, self.F)
        return self._tree.squared_distance(self.V, self.F, np.ascontiguousarray(P, dtype=np.float64))[0] > r * r

    def mesh(self):
        return self._mesh.copy()


def _point(x):
    return "(" + ", ".join(f"{v:.4g}" for v in x) + ")"


class Affine:
    """A 3D solid moved by x -> A x + t."""

    def __init__(self, solid, A, t):
        self.solid, self.A, self.t = solid, A, t
        if hasattr(solid, "path"):
            self.path = solid.path
        self.inverse = np.linalg.inv(A)
        det = abs(float(np.linalg.det(A)))
        self.volume = None if solid.volume is None else solid.volume * det
        lo, hi = solid.bounds
        corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(3, -1).T @ A.T + t
        self.bounds = (corners.min(axis=0), corners.max(axis=0))
        self.smallest = float(np.linalg.svd(A, compute_uv=False).min())
        if hasattr(solid, "far"):
            self.far = lambda P, r: solid.far(self._local(P), r / self.smallest)

    def _local(self, P):
        return (P - self.t) @ self.inverse.T

    def inside(self, P):
        return self.solid.inside(self._local(P))

    def mesh(self):
        m = self.solid.mesh()
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self.A, self.t
        m.apply_transform(T)
        return m


class Boolean:
    """A union, difference (the first minus the others) or intersection of 3D solids; its
    volume is manifold3d's of the children's meshes."""

    def __init__(self, kind, children, name):
        self.kind, self.children = kind, children
        los, his = np.array([c.bounds[0] for c in children]), np.array([c.bounds[1] for c in children])
        if kind == "union":
            self.bounds = (los.min(axis=0), his.max(axis=0))
        elif kind == "intersection":
            self.bounds = (los.max(axis=0), his.min(axis=0))
        else:
            self.bounds = children[0].bounds
        if np.any(self.bounds[0] >= self.bounds[1]):
            raise ValueError(f"{name}: the intersection is empty (the parts' boxes do not overlap)")
        if all(hasattr(c, "far") for c in children):
            self.far = lambda P, r: np.logical_and.reduce([c.far(P, r) for c in children])
        self.volume = float(self.mesh().volume)
        if not self.volume > 0.0:
            raise ValueError(f"{name}: the {kind} is empty (zero volume)")

    def inside(self, P):
        masks = [c.inside(P) for c in self.children]
        if self.kind == "union":
            return np.logical_or.reduce(masks)
        if self.kind == "intersection":
            return np.logical_and.reduce(masks)
        return masks[0] & ~np.logical_or.reduce(masks[1:])

    def mesh(self):
        import trimesh
        meshes = [c.mesh() for c in self.children]
        op = {"union": trimesh.boolean.union, "intersection": trimesh.boolean.intersection,
              "difference": trimesh.boolean.difference}[self.kind]
        return op(meshes, engine="manifold")


def _solid_3d(part, name, warn):
    part = _given(part)
    shape = part["shape"]
    if shape in BOOLEANS:
        solid = Boolean(shape, [_solid_3d(p, f"{name}.parts[{i}]", warn)
                                for i, p in enumerate(_children(part, name))], name)
    elif shape == "sphere":
        solid = Sphere(_vector(part["center"], f"{name}.center", 3), _positive(part["radius"], f"{name}.radius"))
    elif shape == "cone":
        axis = _vector(part.get("axis", [0.0, 0.0, 1.0]), f"{name}.axis", 3)
        if not np.linalg.norm(axis) > 0.0:
            raise ValueError(f"{name}.axis must be non-zero")
        r1 = part.get("top_radius", 0.0)
        if isinstance(r1, bool) or not isinstance(r1, (int, float)) or not r1 >= 0.0:
            raise ValueError(f"{name}.top_radius must be a number >= 0, got {r1!r}")
        solid = Cone(_vector(part["base_center"], f"{name}.base_center", 3), axis / np.linalg.norm(axis),
                     _positive(part["length"], f"{name}.length"), _positive(part["radius"], f"{name}.radius"),
                     float(r1))
    elif shape == "extrusion":
        z0 = part.get("z0", 0.0)
        if isinstance(z0, bool) or not isinstance(z0, (int, float)) or not math.isfinite(z0):
            raise ValueError(f"{name}.z0 must be a number, got {z0!r}")
        solid = Extrusion(Region(_polygon(part, name)), float(z0), _positive(part["length"], f"{name}.length"))
    elif shape == "surface":
        if not isinstance(part.get("file"), str):
            raise ValueError(f"{name}.file must name a mesh file (STL, OBJ, PLY)")
        solid = Surface(part["file"], warn)
    else:
        raise ValueError(f"{name}: shape '{shape}' is not a 3D solid (use {', '.join(SHAPES_3D + BOOLEANS)})")
    A, t = _affine(part, name, 3)
    if not np.array_equal(A, np.eye(3)) or np.any(t):
        solid = Affine(solid, A, t)
    return solid


def solid(part: dict, name: str, dim: int, warn=lambda message: None):
    """The solid of a part table (`name` in messages) in `dim` dimensions: an object with
    `dim`, `inside(P)`, `volume` (exact; None for a surface with holes that could not be
    filled), `bounds` (lower, upper) and, where whole blocks can be classified at once,
    `far(P, r)`. `warn(message)` reports problems the solid survives."""
    if dim == 2:
        return Region(_geometry_2d(part, name))
    out = _solid_3d(part, name, warn)
    out.dim = 3
    return out
