"""Particles from a finite-element mesh (part shape "mesh"): one particle per element of the
scene's dimension, at the element's centroid with the element's exact volume, and the
mesh's sets as particle groups. The file is read with meshio (Gmsh .msh, Abaqus .inp, VTK
.vtu/.vtk and the other formats meshio reads), whole, by every rank that builds the part
(fine up to a few million elements); `rows` hands out only the asked block.

Every element is a trilinear hexahedron (a bilinear quadrilateral in 2D), collapsed for the
other shapes: a tetrahedron is the hexahedron of nodes 0 1 2 2 3 3 3 3, a wedge 0 1 2 2 3 4
5 5, a pyramid 0 1 2 3 4 4 4 4, a triangle the quadrilateral 0 1 2 2. Its volume (the
integral of det J) and first moment (of x det J) are the 2^D-point Gauss sums, exact for
these maps (det J has degree <= 2 on each reference axis, x det J <= 3): exact also for a
distorted hexahedron with non-planar faces (the trilinear element's volume). Quadratic
elements are taken by their corner nodes, straight-sided.

Elements of lower dimension than the scene's are no particles, but carry sets. An element
whose signed volume is zero or of the other sign than most of its block's is inverted
(refused); a block all of one sign is taken as written (VTK and Gmsh orient wedges oppositely).
"""

from __future__ import annotations

import contextlib
import io
import math
import os

import numpy as np

from .lattice import _check_count
from .solids import _affine

# corner nodes of each element type as a collapsed hexahedron (3D) or quadrilateral (2D)
CORNERS = {"hexahedron": [0, 1, 2, 3, 4, 5, 6, 7], "tetra": [0, 1, 2, 2, 3, 3, 3, 3],
           "wedge": [0, 1, 2, 2, 3, 4, 5, 5], "pyramid": [0, 1, 2, 3, 4, 4, 4, 4],
           "quad": [0, 1, 2, 3], "triangle": [0, 1, 2, 2]}
QUADRATIC = {"hexahedron20": "hexahedron", "hexahedron27": "hexahedron", "tetra10": "tetra",
             "wedge15": "wedge", "wedge18": "wedge", "pyramid13": "pyramid", "pyramid14": "pyramid",
             "quad8": "quad", "quad9": "quad", "triangle6": "triangle", "triangle7": "triangle"}
DIMENSION = {"vertex": 0, "line": 1, "triangle": 2, "quad": 2, "polygon": 2, "tetra": 3, "hexahedron": 3,
             "wedge": 3, "pyramid": 3, "polyhedron": 3}
IGNORED_SETS = ("gmsh:bounding_entities",)  # meshio's bookkeeping, not a set of the mesh


def cell_dimension(cell_type: str) -> int:
    """The topological dimension of a meshio cell type (line3 -> 1, tetra10 -> 3, ...)."""
    base = cell_type.rstrip("0123456789")
    if base not in DIMENSION:
        raise KeyError(cell_type)
    return DIMENSION[base]


def _reference(dim: int):
    """The reference corners (2^dim, dim) of a hexahedron / quadrilateral in meshio's (VTK)
    order, and the Gauss points (2^dim, dim) of the 2-point rule on each axis (weights 1)."""
    square = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    corners = square if dim == 2 else np.vstack([np.column_stack([square, -np.ones(4)]),
                                                 np.column_stack([square, np.ones(4)])])
    return corners, corners / math.sqrt(3.0)


def volumes_and_centroids(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed volumes (n,) and centroids (n, D) of the trilinear (bilinear) elements of corner
    coordinates x (n, 2^D, D), by the exact 2^D-point Gauss rule."""
    dim = x.shape[2]
    corners, points = _reference(dim)
    volume, moment = np.zeros(len(x)), np.zeros((len(x), dim))
    for g in points:
        factors = 0.5 * (1.0 + corners * g)  # (2^D, D): the 1D shape functions at g
        shape = factors.prod(axis=1)
        grad = np.empty_like(factors)  # dN_a / d xi_k
        for k in range(dim):
            others = np.delete(factors, k, axis=1).prod(axis=1)
            grad[:, k] = 0.5 * corners[:, k] * others
        det = np.linalg.det(np.einsum("nai,ak->nik", x, grad))
        volume += det
        moment += det[:, None] * np.einsum("nai,a->ni", x, shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        return volume, moment / volume[:, None]


class MeshPart:
    """The elements of dimension `dimension` of the mesh `file` (optionally only those of the
    mesh sets `cells`), scaled by `scale` about the origin, mirrored, rotated (as a solid part,
    geometry.solids) and translated by `translate`
    (`points`, the nodes so placed): `count` particles, in the file's order (cell block after
    cell block), at the elements' centroids with their volumes; `spacing` is the mean
    (volume / count)^(1/D)."""

    blockwise = True  # rows(start, stop) slices the elements read

    def __init__(self, file, scale=1.0, translate=None, cells=None, dimension=3, mirror=None, rotate=None):
        import meshio

        self.file, self.dim = file, dimension
        if not os.path.isfile(file):
            raise ValueError(f"mesh file not found: {file}")
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # meshio prints the formats it failed to read as
                mesh = meshio.read(file)
        except Exception as exc:  # meshio's readers raise anything on a damaged file
            raise ValueError(f"mesh file {file} cannot be read: {type(exc).__name__}: {exc}") from None
        self.mesh = mesh
        points = np.asarray(mesh.points, np.float64)
        if points.ndim != 2 or points.shape[1] < dimension:
            raise ValueError(f"mesh file {file}: its points have {points.shape[-1]} coordinates, "
                             f"a {dimension}D scene needs {dimension}")
        self.blocks = []  # (index in mesh.cells, first element, corner connectivity (m, 2^D))
        first, types = 0, set()
        for b, block in enumerate(mesh.cells):
            try:
                dim_b = cell_dimension(block.type)
            except KeyError:
                raise ValueError(f"mesh file {file}: cells of type '{block.type}' are not supported") from None
            if dim_b > dimension:
                raise ValueError(f"mesh file {file} has {dim_b}D elements ({block.type}): not a {dimension}D mesh")
            if dim_b < dimension or len(block.data) == 0:
                continue
            base = QUADRATIC.get(block.type, block.type)
            if base not in CORNERS:
                raise ValueError(f"mesh file {file}: elements of type '{block.type}' are not supported "
                                 f"(use {', '.join(t for t in CORNERS if DIMENSION[t] == dimension)})")
            self.blocks.append((b, first, np.asarray(block.data)[:, CORNERS[base]]))
            first += len(block.data)
            types.add(block.type)
        self.total = first
        if not self.total:
            found = ", ".join(sorted({c.type for c in mesh.cells})) or "none"
            raise ValueError(f"mesh file {file} has no {dimension}D elements (its cells: {found})")
        _check_count("mesh", self.total, f"the elements of {file}")
        if dimension == 2 and points.shape[1] > 2:
            used = np.unique(np.concatenate([c.ravel() for _, _, c in self.blocks]))
            z = points[used, 2:]
            if np.ptp(z) > 1e-12 * max(np.abs(points[used, :2]).max(), 1.0):
                raise ValueError(f"mesh file {file}: a 2D scene needs a plane mesh (z constant), "
                                 f"its z spans {z.min():g} to {z.max():g}")
        x = points[:, :dimension] * float(scale)
        if mirror is not None or rotate is not None:
            A, _ = _affine({"mirror": mirror, "rotate": rotate}, f"mesh file {file}", dimension)
            x = x @ A.T
        if translate is not None:
            x = x + np.asarray(translate, np.float64)
        self.points = x
        volume, centroid = np.zeros(self.total), np.zeros((self.total, dimension))
        for b, start, corners in self.blocks:
            v, c = volumes_and_centroids(x[corners])
            sign = -1.0 if np.count_nonzero(v < 0) > np.count_nonzero(v > 0) else 1.0
            bad = np.flatnonzero(~(sign * v > 0))
            if bad.size:
                k = int(bad[0])
                raise ValueError(f"mesh file {file}: element {k} of cell block {b} ({mesh.cells[b].type}, "
                                 f"nodes {mesh.cells[b].data[k].tolist()}) is inverted or degenerate: "
                                 f"its volume is {sign * v[k]:g} ({bad.size} such element(s) in the block)")
            volume[start:start + len(v)] = sign * v
            centroid[start:start + len(v)] = c
        self.selected = np.arange(self.total)
        if cells is not None:
            self.selected = np.flatnonzero(np.any([self._elements_of(name) for name in cells], axis=0))
            if not self.selected.size:
                raise ValueError(f"mesh file {file}: the sets {cells} hold no {dimension}D element")
        self.volume, self.centroid = volume[self.selected], centroid[self.selected]
        self.count = len(self.selected)
        self.spacing = float(self.volume.sum() / self.count) ** (1.0 / dimension)
        self.extent = np.ptp(self.centroid, axis=0).max() if self.count > 1 else self.spacing

    def rows(self, start: int, stop: int):
        return self.centroid[start:stop].copy(), self.volume[start:stop].copy()

    def set_names(self) -> list[str]:
        """The names `mesh_set` may take: cell sets (Gmsh physical groups, Abaqus element
        sets), point sets (Abaqus node sets), Gmsh physical names, and KEY=VALUE for the
        values of integer cell data (VTK tags: CellEntityIds=3, gmsh:physical=2)."""
        names = [n for n in self.mesh.cell_sets if n not in IGNORED_SETS]
        if "gmsh:physical" in self.mesh.cell_data:
            names += list(self.mesh.field_data)
        names += list(self.mesh.point_sets)
        for key, values in sorted(self._tags().items()):
            names += [f"{key}={v}" for v in values]
        return sorted(dict.fromkeys(names))

    def _tags(self) -> dict:
        """The distinct values of each integer cell data array."""
        tags = {}
        for key, arrays in self.mesh.cell_data.items():
            arrays = [np.asarray(a) for a in arrays]
            if arrays and all(a.ndim == 1 and np.issubdtype(a.dtype, np.integer) for a in arrays):
                tags[key] = np.unique(np.concatenate(arrays)).tolist()
        return tags

    def _elements_of(self, name: str) -> np.ndarray:
        """Mask over all the part's elements (before `cells`) of the set `name`: its elements
        of the scene's dimension, and those touching a node of its nodes or of its elements of
        lower dimension (faces, edges). A name that is both an element set and a node set
        (Abaqus allows it) is the element set."""
        mesh = self.mesh
        members = {}  # cell block -> mask of its cells in the set
        nodes = np.zeros(len(mesh.points), bool)
        if name in mesh.cell_sets and name not in IGNORED_SETS:
            for b, index in enumerate(mesh.cell_sets[name]):
                if index is not None and len(index):
                    members[b] = np.zeros(len(mesh.cells[b].data), bool)
                    members[b][np.asarray(index, np.int64)] = True
        elif name in mesh.field_data and "gmsh:physical" in mesh.cell_data:
            tag, dim = (int(v) for v in np.asarray(mesh.field_data[name]).ravel()[:2])
            for b, block in enumerate(mesh.cells):
                if cell_dimension(block.type) == dim:
                    members[b] = np.asarray(mesh.cell_data["gmsh:physical"][b]) == tag
        elif name in mesh.point_sets:
            nodes[np.asarray(mesh.point_sets[name], np.int64)] = True
        elif "=" in name and name.rsplit("=", 1)[0] in self._tags():
            key, value = name.rsplit("=", 1)
            try:
                value = int(value)
            except ValueError:
                value = None
            for b, data in enumerate(mesh.cell_data[key]):
                members[b] = np.asarray(data) == value
        else:
            known = self.set_names()
            raise ValueError(f"mesh file {self.file} has no set '{name}'; its sets: "
                             f"{', '.join(known) if known else 'none'}")
        mask = np.zeros(self.total, bool)
        for b, inside in members.items():
            if cell_dimension(mesh.cells[b].type) < self.dim:
                nodes[np.asarray(mesh.cells[b].data)[inside].ravel()] = True
        for b, start, corners in self.blocks:
            full = np.asarray(mesh.cells[b].data)
            mask[start:start + len(full)] = members.get(b, np.zeros(len(full), bool)) | nodes[full].any(axis=1)
        return mask

    def set_mask(self, name: str) -> np.ndarray:
        """Mask over the part's particles (its elements after `cells`) of the mesh set `name`;
        ValueError naming the file and its sets for an unknown one."""
        return self._elements_of(name)[self.selected]
