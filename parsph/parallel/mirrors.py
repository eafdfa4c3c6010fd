"""Symmetry planes by mirror images (scene `[[symmetry]]`).

A body symmetric about axis-aligned planes is computed on one side of them only, as the
punch of [V §2.4.3] is on a quarter of its domain. Every particle within two kernel
supports of a plane gets a mirror image beyond it (and an image across two or three planes
near their corner). Images join the neighbour search, the corrections and the sums like
ghosts do, with values reflected as their fields' kinds say (parsph.fields), so the
particles near a plane have full neighbourhoods and move as those of the whole body would;
no component is held fixed and no kernel is cut.

Images are layered like the ghosts of parallel.decomposition: layer-1 images (neighbours
of owned particles) come after the layer-1 ghosts and are refreshed from their source
particle (owned or a layer-1 ghost) after each ghost exchange; layer-2 images come after
the layer-2 ghosts and only serve to build the layer-1 rows. An image's global id is its
source's plus a multiple of the particle count, so sums over rows keep an order that does
not depend on the rank count. A particle on a plane (within 1e-9 supports) has no image:
hold its normal component with a fixed condition; half of it belongs to the other side, so
it counts by its share (1/2 for each plane it lies on: Mirrors.share) in the sums of the
energy balance (parsph.ledger), as the particles of the whole body would.

Neighbour lists kept between searches (ulsph, the Eulerian kernel: relations.Skin) get
images within the reaches plus the skin, as their ghosts do, and between searches every
image row of both layers is set from its source again (Mirrors.fill_all): the rows a
search would make. Contact images its own points (the contact particles near a plane, in
the current configuration: parsph.contact) by the same enumeration (plane_images), with the
same global ids, and refreshes them as a one-layer Mirrors.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsph import fields as registry
from parsph.errors import InputError, ParsphError
from parsph.cells import kdtree
from parsph.neighbors import pair_keys
from parsph.parallel.decomposition import LocalBody


@dataclass
class Mirrors:
    """The images of a rank's local arrays and how to refresh them."""

    start: int  # local row of the first layer-1 image
    source: np.ndarray  # local row of each layer-1 image's particle
    sign: np.ndarray  # (images, dim): the reflection, +1 or -1 per component
    start2: int  # local row of the first layer-2 image
    source2: np.ndarray  # local row of each layer-2 image's particle
    offset: np.ndarray  # (images, dim): a layer-1 image's point p reflects to sign * p + offset
    sign2: np.ndarray  # sign and offset of the layer-2 images
    offset2: np.ndarray
    share: np.ndarray | None = None  # each owned particle's share of itself in the part modelled (on_planes)

    @classmethod
    def one_layer(cls, start: int, source: np.ndarray, sign: np.ndarray, offset: np.ndarray) -> Mirrors:
        """Images in one layer, rows `start`, start + 1, ... (plane_images' sources, sign and
        offset): contact's."""
        none = np.zeros((0, sign.shape[1]))
        return cls(start, source, sign, start + len(source), np.zeros(0, np.int64), offset, none, none)

    def copy_all(self, arr: np.ndarray) -> None:
        """Set the image rows of both layers of `arr` (a field reflection leaves as it is:
        the damage state) to their sources' values, once the ghosts of both layers hold theirs."""
        arr[self.start: self.start + len(self.source)] = arr[self.source]
        arr[self.start2: self.start2 + len(self.source2)] = arr[self.source2]

    def fill(self, arr: np.ndarray, reflected: bool = True) -> None:
        """Set the layer-1 image rows of `arr` (scalars, vectors or tensors per particle)
        to their sources' values, reflected (or, not `reflected`, as they are)."""
        if not len(self.source):
            return
        value = arr[self.source]
        arr[self.start: self.start + len(self.source)] = \
            value if arr.ndim == 1 or not reflected else reflect(value, self.sign)

    def fill_all(self, arr: np.ndarray, field) -> None:
        """Set the image rows of both layers of `arr`, the values of the registered `field`
        (parsph.fields), to their sources' reflected as its kind says (Field.reflect), or
        copied (`field` None: a material state): the images of a search, between searches."""
        for start, source, sign, offset in ((self.start, self.source, self.sign, self.offset),
                                            (self.start2, self.source2, self.sign2, self.offset2)):
            if len(source):
                value = arr[source]
                arr[start: start + len(source)] = value if field is None else field.reflect(value, sign, offset)


def reflect(value: np.ndarray, sign: np.ndarray) -> np.ndarray:
    """Vectors (n, d) or tensors (n, d, d) of n particles reflected by `sign` (n, d), +1 or -1
    per component (tensors on both indices)."""
    if value.ndim == 2:
        return value * sign
    return value * sign[:, :, None] * sign[:, None, :]


def body_sides(x: np.ndarray, planes: list, tol: float, comm) -> list:
    """+1 or -1 for each plane: the side of it the body `x` (owned positions) lies on;
    InputError if a plane cuts the body."""
    sides = []
    for i, plane in enumerate(planes):
        s = x[:, plane["axis"]] - plane["position"]
        lo = comm.allreduce(float(s.min()) if len(s) else np.inf, op=MPI.MIN)
        hi = comm.allreduce(float(s.max()) if len(s) else -np.inf, op=MPI.MAX)
        if (lo < -tol and hi > tol) or (lo >= -tol and hi <= tol):
            raise InputError(
                f"symmetry[{i}]: the plane at coordinate {plane['position']:g} on axis {plane['axis']} "
                f"must bound the body, but the particles lie from {lo:+.6g} to {hi:+.6g} of it")
        sides.append(1.0 if hi > tol else -1.0)
    return sides


def add_images(local: LocalBody, position: str, planes: list, comm,
               skin: float = 0.0) -> tuple[LocalBody, Mirrors | None]:
    """`local` with the mirror images across `planes` (scene.symmetry) of its particles
    in the configuration `fields[position]` added as two layers, with reaches extended by
    `skin` (lists kept between searches, as the ghosts of add_ghosts); and their refresh
    plan (None without planes)."""
    if not planes:
        return local, None
    fields, n, n1 = local.fields, local.n_owned, local.n_owned + local.n_ghost
    x = fields[position]
    support = comm.allreduce(float(fields["support"][:n].max()) if n else 0.0, op=MPI.MAX)
    tol = 1e-9 * support
    reach = support + skin
    sides = body_sides(x[:n], planes, tol, comm)
    source, sign, offset, gid = plane_images(x, fields["gid"], planes, local.total,
                                             2.0 * reach, tol, sides)  # layer-2 images lie within two supports
    image_x = sign * x[source] + offset
    layer1 = layer2 = np.zeros(0, np.int64)
    if n and len(source):
        dist, _ = kdtree(x[:n]).query(image_x, distance_upper_bound=reach)
        layer1 = np.flatnonzero(np.isfinite(dist))
        rest = np.flatnonzero(~np.isfinite(dist))
        inner = np.concatenate([x[n:n1], image_x[layer1]])
        if len(inner) and len(rest):
            dist, _ = kdtree(inner).query(image_x[rest], distance_upper_bound=reach)
            layer2 = rest[np.isfinite(dist)]
    layer1 = layer1[np.argsort(gid[layer1], kind="stable")]
    layer2 = layer2[np.argsort(gid[layer2], kind="stable")]
    if (source[layer1] >= n1).any():
        raise ParsphError("internal: a layer-1 mirror image's source is not an owned or layer-1 particle")

    def images(which: np.ndarray) -> dict:
        out = {}
        for key, arr in fields.items():
            value = arr[source[which]]
            out[key] = gid[which] if key == "gid" else registry.get(key).reflect(value, sign[which], offset[which])
        return out

    first, second = images(layer1), images(layer2)
    merged = {k: np.concatenate([v[:n1], first[k], v[n1:], second[k]]) for k, v in fields.items()}
    none = np.full(len(layer1), -1, np.int64)
    owner = np.concatenate([local.owner[:n1], none, local.owner[n1:], np.full(len(layer2), -1, np.int64)])
    body = LocalBody(gid=merged["gid"], owner=owner, n_owned=n, n_ghost=local.n_ghost + len(layer1),
                     total=local.total, fields=merged)
    source2 = np.where(source[layer2] < n1, source[layer2], source[layer2] + len(layer1))  # rows once merged
    return body, Mirrors(n1, source[layer1], np.ascontiguousarray(sign[layer1]), len(x) + len(layer1), source2,
                         offset[layer1], sign[layer2], offset[layer2], on_planes(x[:n], planes, tol))


def plane_images(x: np.ndarray, gid: np.ndarray, planes: list, total: int, reach: float, tol: float,
                 sides: list | None = None) -> tuple:
    """The mirror images of the points at `x` (global ids `gid`) across each combination of
    the `planes` (_subsets): for each, the points farther than `tol` and nearer than `reach`
    from each of its planes, on the side of it `sides` gives (+1 or -1 per plane; None:
    either side). Returns their source rows, reflections (sign, offset: a point p reflects to
    sign * p + offset) and global ids (the source's plus k times `total`, k the combination's
    place in _subsets, from 1)."""
    dim = x.shape[1]
    plane_at = np.zeros(dim)  # a point on every plane
    for p in planes:
        plane_at[p["axis"]] = p["position"]
    source, sign, ids = [], [], []
    for k, subset in enumerate(_subsets(len(planes)), start=1):
        near = np.ones(len(x), bool)
        flip = np.ones(dim)
        for p in subset:
            gap = x[:, planes[p]["axis"]] - planes[p]["position"]
            gap = np.abs(gap) if sides is None else sides[p] * gap
            near &= (gap > tol) & (gap < reach)
            flip[planes[p]["axis"]] = -1.0
        rows = np.flatnonzero(near)
        source.append(rows)
        sign.append(np.broadcast_to(flip, (len(rows), dim)))
        ids.append(gid[rows] + k * total)
    source, sign = np.concatenate(source), np.concatenate(sign)
    return source, sign, (1.0 - sign) * plane_at, np.concatenate(ids)


def on_planes(x: np.ndarray, planes: list, tol: float) -> np.ndarray | None:
    """Each particle's share of itself in the part modelled: 1/2 for each plane it lies on
    (within `tol`: it has no image), or None where none lies on one."""
    share = np.ones(len(x))
    for p in planes:
        share[np.abs(x[:, p["axis"]] - p["position"]) <= tol] *= 0.5
    return share if (share < 1.0).any() else None


def _subsets(planes: int) -> list:
    """The combinations of the planes an image is reflected across, in the order of the
    multiples of the particle count its global id adds (1, 2, ...)."""
    return [s for k in range(1, planes + 1) for s in itertools.combinations(range(planes), k)]


def reflected_pairs(keys: np.ndarray, total: int, planes: int) -> np.ndarray:
    """The pairs `keys` (neighbors.pair_keys of global ids, images numbered as add_images
    numbers them) with their reflections across every combination of the planes: what the
    mirror images of a pair's particles make of it. Sorted, unique."""
    masks = np.array([0] + [sum(1 << p for p in s) for s in _subsets(planes)])
    image = np.empty(1 << planes, np.int64)  # the multiple of `total` of each combination
    image[masks] = np.arange(len(masks))
    a, b = keys >> 32, keys & 0xFFFFFFFF
    out = [keys]
    for mask in masks[1:]:
        out.append(pair_keys(a % total + image[masks[a // total] ^ mask] * total,
                             b % total + image[masks[b // total] ^ mask] * total))
    return np.unique(np.concatenate(out))
