"""Rigid obstacles given by a surface file ([[surfaces]]): triangles in 3D, segments in 2D.

The file: in 3D any triangle mesh trimesh reads (STL, OBJ, PLY, ...), closed or open (an
open sheet's outside is the side its triangles' normals face); in 2D a closed outline,
either a CSV of its vertices (x, y per line, in order; the last joined to the first) or a
DXF (trimesh.load_path, curves discretised by trimesh) whose closed polylines are the
outlines. It is scaled, rotated (in degrees: counter-clockwise in 2D; in 3D by the
rotation vector, the axis times the angle) and translated, in that order, into the surface's place at t = 0; then it moves rigidly:
its centre c (default the middle of its bounding box) by the integral of `velocity`, and
it turns about c by the rotation vector that is the integral of `angular_velocity` (about
a fixed axis when the angular velocity keeps its direction); either may be given as
expressions of the time t.

Contact is that of parsph.walls (a particle found inside is put back on the surface, along
the direction to its closest point, and loses its approach, relative to the surface's
velocity at that point), with Coulomb friction: the tangential relative velocity loses at
most `friction` times the normal velocity change (a free rigid body meets it as it meets a
wall, frictionless: parsph.rigid). The signed distance is libigl's, signed by the
pseudo-normal of the closest feature (inside < 0), from the triangles of this rank's
share: those whose bounding boxes meet the particles' bounding box (in the surface's
frame) grown by the margin, chosen again when a particle leaves the box grown by half of
it. A particle is seen inside only within half the margin (a twentieth of the surface's
bounding-box diagonal) of the surface: the stable step lets no particle of its group move
by more than a quarter of the margin relative to it (Walls.limit_steps). Its closest point
is chosen among the held triangles at its distance, the nearest with ties to the lowest
triangle number of the file: a function of its position and the whole surface alone, on
any number of ranks.
"""

from __future__ import annotations

import os

import numpy as np

from parsph import expressions
from parsph.errors import InputError

MARGIN = 0.05  # of the surface's bounding-box diagonal: the reach of a rank's triangles


def read(path: str, where: str, dim: int) -> tuple:
    """(vertices, simplices) of the surface file `path` (triangles in 3D, segments of closed
    outlines in 2D, counter-clockwise: the outside on their right); InputError naming `where`
    and the file if it cannot be read or is not a surface."""
    import trimesh

    if not os.path.isfile(path):
        raise InputError(f"{where} = '{path}': file not found")
    if not os.access(path, os.R_OK):
        raise InputError(f"{where} = '{path}': file is not readable")
    try:
        if dim == 3:
            mesh = trimesh.load(path, force="mesh", process=False)
            V, F = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
        elif path.lower().endswith(".csv"):
            V, F = _outlines([np.loadtxt(path, delimiter=",", comments="#", ndmin=2)])
        else:
            V, F = _outlines([np.asarray(p)[:, :2] for p in trimesh.load_path(path).discrete])
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - any reader's failure is the file's problem
        raise InputError(f"{where} = '{path}': cannot be read as {'a triangle surface' if dim == 3 else 'an outline'} "
                         f"({type(exc).__name__}: {exc})") from None
    if F.ndim != 2 or not len(F) or V.shape[1:] != (dim,) or not np.isfinite(V).all():
        raise InputError(f"{where} = '{path}': not a surface: no {'triangles' if dim == 3 else 'segments'} "
                         f"with {dim} finite coordinates")
    edges = V[F[:, 1:]] - V[F[:, :1]]
    size = np.linalg.norm(edges[:, 0], axis=1) if dim == 2 else 0.5 * np.linalg.norm(
        np.cross(edges[:, 0], edges[:, 1]), axis=1)
    diagonal = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    bad = np.flatnonzero(size <= 1e-12 * diagonal ** (dim - 1))
    if len(bad):
        raise InputError(f"{where} = '{path}': {'triangle' if dim == 3 else 'segment'} {int(bad[0])} is degenerate "
                         f"(zero {'area' if dim == 3 else 'length'}; {len(bad)} such)")
    if dim == 3:  # shared vertices: the pseudo-normals of edges and vertices need the adjacency
        V, inverse = np.unique(V, axis=0, return_inverse=True)
        F = np.asarray(inverse).reshape(-1)[F]
        if not trimesh.Trimesh(V, F, process=False).is_winding_consistent:
            raise InputError(f"{where} = '{path}': its triangles are not consistently oriented (neighbours list "
                             "their shared edge in the same direction): which side is outside is ambiguous")
    return V, F


def _outlines(polylines: list) -> tuple:
    """The segments of closed outlines (each an (n, 2) array of vertices in order; a last
    vertex equal to the first is dropped), turned counter-clockwise."""
    V, F = [], []
    for line in polylines:
        line = np.asarray(line, float)
        if line.ndim != 2 or line.shape[1] != 2:
            raise ValueError("an outline needs two columns, x and y")
        if len(line) > 1 and np.array_equal(line[0], line[-1]):
            line = line[:-1]
        if len(line) < 3:
            continue
        x, y = line[:, 0], line[:, 1]
        if np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y) < 0.0:  # twice the signed area
            line = line[::-1]
        start = sum(len(v) for v in V)
        k = np.arange(len(line))
        V.append(line)
        F.append(start + np.column_stack([k, (k + 1) % len(line)]))
    if not V:
        return np.zeros((0, 2)), np.zeros((0, 2), np.int64)
    return np.concatenate(V), np.concatenate(F)


def _rotation(angles, dim: int) -> np.ndarray:
    """The matrix of `rotate`: [angle] in 2D, counter-clockwise; the rotation vector (the
    axis times the angle) in 3D; degrees."""
    from scipy.spatial.transform import Rotation  # here: scipy takes a quarter of a second to import
    if dim == 2:
        return Rotation.from_euler("z", angles[0], degrees=True).as_matrix()[:2, :2]
    return Rotation.from_rotvec(angles, degrees=True).as_matrix()


def _product(a: np.ndarray, M: np.ndarray) -> np.ndarray:
    """a @ M (a's rows times the matrix M), each row summed in the same order whatever the
    number of rows (a matrix product's blocking may not)."""
    out = a[:, :1] * M[0]
    for j in range(1, len(M)):
        out = out + a[:, j:j + 1] * M[j]
    return out


class _Rate:
    """A vector given as numbers or as expressions of t, and its integral from 0."""

    def __init__(self, path: str, value, texts, parameters: dict, size: int):
        self.value = np.asarray(value if value is not None else [0.0] * size, float)
        self.fields = None if texts is None else [
            expressions.Field(f"{path}[{k}]", text, parameters, 1, ("t",)) for k, text in enumerate(texts)]

    def __call__(self, t: float) -> np.ndarray:
        if self.fields is None:
            return self.value
        return np.array([float(f(np.array([[t]]), np.zeros(1, np.int64))[0]) for f in self.fields])

    def integral(self, t: float) -> np.ndarray:
        if self.fields is None:
            return self.value * t
        from scipy import integrate  # here: scipy takes a quarter of a second to import
        return np.array([integrate.quad(lambda s, k=k: self(s)[k], 0.0, t, epsabs=0.0, epsrel=1e-12, limit=200)[0]
                         for k in range(len(self.fields))])


class Surface:
    """A rigid surface with prescribed motion, the contact geometry of its held triangles."""

    def __init__(self, spec: dict, dim: int, parameters: dict, where: str):
        self.group = spec.group
        self.index = np.zeros(0, np.int64)
        self.dim = dim
        V, self.F = read(spec.file, f"{where}.file", dim)
        rotate = spec.rotate if spec.rotate is not None else [0.0] * (1 if dim == 2 else 3)
        self.V = (spec.scale * V) @ _rotation(rotate, dim).T + np.asarray(spec.translate or [0.0] * dim)
        lo, hi = self.V.min(axis=0), self.V.max(axis=0)
        self.center0 = np.asarray(spec.center, float) if spec.center is not None else 0.5 * (lo + hi)
        self.margin = MARGIN * float(np.linalg.norm(hi - lo))
        self.friction = spec.friction
        self.velocity_of = _Rate(f"{where}.velocity_expression", spec.velocity, spec.velocity_expression,
                                 parameters, dim)
        self.omega_of = _Rate(f"{where}.angular_velocity_expression", spec.angular_velocity,
                              spec.angular_velocity_expression, parameters, 1 if dim == 2 else 3)
        self.held = None  # the box (surface frame) whose points see every triangle within margin / 2
        self._pose = (None, None)

    def pose(self, t: float) -> tuple:
        """(centre, rotation matrix) at time t."""
        if self._pose[0] != t:
            from scipy.spatial.transform import Rotation  # here: scipy takes a quarter of a second to import
            theta = self.omega_of.integral(t)
            R = Rotation.from_rotvec([0.0, 0.0, theta[0]]).as_matrix()[:2, :2] if self.dim == 2 else \
                Rotation.from_rotvec(theta).as_matrix()
            self._pose = (t, (self.center0 + self.velocity_of.integral(t), R))
        return self._pose[1]

    def velocity_at(self, x: np.ndarray, t: float) -> np.ndarray:
        """The surface's velocity at the points x (rows) at time t."""
        c, _ = self.pose(t)
        r, w = x - c, self.omega_of(t)
        spin = np.column_stack([-w[0] * r[:, 1], w[0] * r[:, 0]]) if self.dim == 2 else np.cross(w, r)
        return self.velocity_of(t) + spin

    def lever(self, x: np.ndarray, t: float) -> np.ndarray:
        """x - the surface's centre at time t (the arm of its torque)."""
        return x - self.pose(t)[0]

    def _hold(self, y: np.ndarray) -> None:
        """Hold the triangles whose boxes meet the points' box grown by the margin."""
        lo, hi = y.min(axis=0) - self.margin, y.max(axis=0) + self.margin
        corners = self.V[self.F]
        meet = np.all((corners.min(axis=1) <= hi) & (corners.max(axis=1) >= lo), axis=1)
        self.faces = np.flatnonzero(meet)  # ascending: the file's order
        used, local = np.unique(self.F[self.faces], return_inverse=True)
        self.local_V, self.local_F = self.V[used], local.reshape(-1, self.F.shape[1]).astype(np.int64)
        self.corners = corners[self.faces]
        from scipy.spatial import cKDTree  # here: scipy takes a quarter of a second to import
        self.tree = cKDTree(self.corners.mean(axis=1)) if len(self.faces) else None
        self.reach = float(np.max(np.linalg.norm(self.corners - self.corners.mean(axis=1)[:, None], axis=2))) \
            if len(self.faces) else 0.0
        self.held = (lo + 0.5 * self.margin, hi - 0.5 * self.margin)

    def contact(self, x: np.ndarray, t: float) -> tuple:
        """(signed gaps, unit normals out of the surface) of the points x (rows) at time t;
        gap < 0 inside, inf where no contact is seen."""
        import igl

        gap, normal = np.full(len(x), np.inf), np.zeros_like(x)
        if not len(x):
            return gap, normal
        c, R = self.pose(t)
        y = _product(x - c, R) + self.center0  # in the surface's frame
        if self.held is None or np.any(y < self.held[0]) or np.any(y > self.held[1]):
            self._hold(y)
        if not len(self.faces):
            return gap, normal
        near = np.flatnonzero(np.isfinite(self.tree.query(y, distance_upper_bound=0.5 * self.margin + self.reach)[0]))
        S = np.full(len(y), np.inf)  # the others are farther than half the margin from every held triangle
        if len(near):
            S[near] = igl.signed_distance(y[near], self.local_V, self.local_F, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)[0]
        inside = np.flatnonzero((S < 0.0) & (S > -0.5 * self.margin))
        if not len(inside):
            return gap, normal
        near = self.tree.query_ball_point(y[inside], -S[inside] * (1 + 1e-9) + self.reach)
        owner = np.repeat(np.arange(len(inside)), [len(c) for c in near])
        cand = np.concatenate([np.sort(c) for c in near]).astype(np.int64)
        points = self._closest(self.corners[cand], y[inside][owner])
        dist = np.linalg.norm(points - y[inside][owner], axis=1)
        order = np.lexsort([self.faces[cand], dist, owner])  # per particle: the nearest, then the lowest number
        first = order[np.r_[0, np.flatnonzero(np.diff(owner[order])) + 1]]
        touch = dist[first] > 0.0
        rows, first = inside[owner[first[touch]]], first[touch]
        gap[rows] = -dist[first]
        normal[rows] = _product((points[first] - y[rows]) / dist[first, None], R.T)
        return gap, normal

    def _closest(self, simplices: np.ndarray, points: np.ndarray) -> np.ndarray:
        """The closest points of the simplices (triangles, or segments in 2D) to the points."""
        if self.dim == 3:
            import trimesh
            return trimesh.triangles.closest_point(simplices, points)
        a, b = simplices[:, 0], simplices[:, 1]
        s = np.clip(np.einsum("na,na->n", points - a, b - a) / np.einsum("na,na->n", b - a, b - a), 0.0, 1.0)
        return a + s[:, None] * (b - a)

    def triangles(self, t: float) -> np.ndarray:
        """The surface at time t, (m, 3, dim): its triangles; in 2D each segment as a thin
        strip on its inside."""
        c, R = self.pose(t)
        V = (self.V - self.center0) @ R.T + c
        if self.dim == 3:
            return V[self.F]
        a, b = V[self.F[:, 0]], V[self.F[:, 1]]
        inward = 0.2 * self.margin * np.column_stack([-(b - a)[:, 1], (b - a)[:, 0]]) / \
            np.linalg.norm(b - a, axis=1)[:, None]
        return np.concatenate([np.stack([a, b, b + inward], axis=1), np.stack([a, b + inward, a + inward], axis=1)])
