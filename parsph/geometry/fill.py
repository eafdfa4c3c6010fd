"""A solid (geometry.solids) filled with a cell-centred square/cubic lattice, generated in
blocks of rows: the lattice of spacing h centred on the solid's bounding box, the points
inside kept, layer after layer along the last axis (first axis fastest within a layer).
Every particle has the volume exact volume / count, so the volumes sum to the solid's.

The count needs every layer's inside count. The layers are classified in chunks (of about
CHUNK points, aligned on the lattice): with a communicator each rank classifies its share of
the chunks, keeps their masks (a bit per point) and the ranks exchange the layers' counts;
rows(start, stop) classifies only the chunks holding those rows that it does not keep. A
solid that can tell points far from its boundary (a closed surface) classifies whole blocks
of LEVELS cells, aligned on the lattice, by their centre. So the particles do not depend on
the rank count.
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from parsph.parallel.runtime import collective

from . import pack
from .lattice import MAX_PARTICLES
from .solids import solid

LEVELS = (16, 4, 2)  # block sizes (cells per side) classified at once when far from a surface
CHUNK = 1 << 20  # lattice points classified at once (about)
CHUNKS = 8  # a solid of many layers is classified in at least this many chunks
PACK_ITERATIONS = 20  # packing's relaxation steps unless a part says


class Fill:
    """`count` particles of `solid` at spacing `h`; `rows(start, stop)` -> (positions,
    volumes). `name` names the part in messages; `comm` (optional) shares the counting."""

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, solid, h: float, name: str, comm=None, pack: int = 0):
        self.solid, self.h, self.dim = solid, h, solid.dim
        lo, hi = solid.bounds
        if solid.volume is not None:
            estimate = solid.volume / h ** self.dim
            if not estimate <= MAX_PARTICLES:
                name += f" ({solid.path})" if hasattr(solid, "path") else ""
                raise ValueError(f"{name}: spacing {h:g} would fill the volume {solid.volume:.4g} with about "
                                 f"{estimate:.3g} particles, more than 2^31; are the geometry's units and the "
                                 "spacing's the same (a mesh in mm and a spacing in m?)")
        span = (hi - lo) / h
        if not np.prod(np.maximum(1.0, span)) <= 16 * MAX_PARTICLES:
            raise ValueError(f"{name}: the bounding box {span.round(1).tolist()} spacings wide is too large a "
                             "lattice to classify; use a larger spacing")
        self.n = np.maximum(1, np.ceil(span * (1.0 - 1e-12))).astype(np.int64)
        self.origin = 0.5 * (lo + hi) - 0.5 * self.n * h
        self.per_layer = int(np.prod(self.n[:-1]))
        top, layers = LEVELS[0], int(self.n[-1])
        # layers per chunk: on the blocks, about CHUNK points, and CHUNKS chunks or more for the ranks to share
        self.stride = top * max(1, min(CHUNK // (self.per_layer * top), -(-layers // (top * CHUNKS))))
        chunks = -(-layers // self.stride)
        cuts = np.linspace(0, chunks, (comm.size if comm else 1) + 1).round().astype(np.int64)
        rank = comm.rank if comm else 0
        self._kept = {}  # chunk -> packed inside mask, of the chunks this rank counted
        with collective(comm) if comm else contextlib.nullcontext():  # no rank may miss the allgather
            mine = [self._count(c) for c in range(cuts[rank], cuts[rank + 1])]
        counts = np.concatenate([np.zeros(0, np.int64), *(sum(comm.allgather(mine), []) if comm else mine)])
        self.first = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.count = int(self.first[-1])
        if self.count == 0:
            raise ValueError(f"{name}: no lattice point at spacing {h:g} falls inside the solid; use a smaller "
                             "spacing")
        self.lattice_volume = self.count * h ** self.dim
        self.volume = solid.volume if solid.volume is not None else self.lattice_volume
        self.each = self.volume / self.count
        self.packed = self._pack(range(cuts[rank], cuts[rank + 1]), pack, name, comm) if pack else None

    def _pack(self, chunks, iterations: int, name: str, comm):
        """(global ids, packed positions) of the boundary layer (geometry.pack), each rank
        finding the layer's particles in its chunks."""
        distance = pack.boundary(self.solid)
        with collective(comm) if comm else contextlib.nullcontext():
            mine = []
            for c in chunks:
                P = self._points(c)[1]
                P = P[np.unpackbits(self._kept[c], count=len(P)).astype(bool)]
                d = distance(P)[0]
                near = np.flatnonzero(d > -pack.NEIGHBOURS * self.h)
                mine.append((self.first[c * self.stride] + near, P[near], d[near] > -pack.BAND * self.h))
        layer = sum(comm.allgather(mine), []) if comm else mine
        gid, X, mobile = (np.concatenate([item[k] for item in layer]) for k in range(3))
        if len(gid) > pack.LIMIT:
            raise ValueError(f"{name}: pack: the boundary layer holds {len(gid)} particles, more than "
                             f"{pack.LIMIT} (every rank packs it whole); use a larger spacing or pack = false")
        return gid, pack.relax(X, mobile, self.h, distance, iterations)

    def report(self) -> str:
        """The count and the lattice's volume error, for the set-up output."""
        return (f"{self.count} particles at spacing {self.h:g}, volume {self.volume:.6g}, lattice volume "
                f"error {100.0 * (self.lattice_volume / self.volume - 1.0):+.3f} %")

    def _points(self, c: int):
        """Lattice indices (per axis) and positions of the points of chunk c, layers
        c·stride.. on."""
        k0 = c * self.stride
        layers = np.arange(k0, min(k0 + self.stride, int(self.n[-1])))
        index = [g.ravel(order="F") for g in np.meshgrid(*[np.arange(n) for n in self.n[:-1]], layers, indexing="ij")]
        return index, self.origin + (np.column_stack(index) + 0.5) * self.h

    def _chunk(self, c: int):
        """Positions of the lattice points of chunk c (layers c·stride.. on) and which are
        inside: blocks of LEVELS cells far from the boundary take their centre's side."""
        index, P = self._points(c)
        far = getattr(self.solid, "far", None)
        if far is None:
            return P, self.solid.inside(P)
        inside = np.zeros(len(P), dtype=bool)
        open_ = np.arange(len(P))
        for size in LEVELS:
            block = [i[open_] // size for i in index]
            base = [b.min() for b in block]
            shape = [int(b.max() - b0) + 1 for b, b0 in zip(block, base)]
            key = np.ravel_multi_index([b - b0 for b, b0 in zip(block, base)], shape)
            used = np.zeros(np.prod(shape), dtype=bool)
            used[key] = True
            ids = np.flatnonzero(used)
            centre = self.origin + (np.column_stack(np.unravel_index(ids, shape)) + base + 0.5) * size * self.h
            uniform = far(centre, 0.5 * size * self.h * math.sqrt(self.dim))
            side = np.zeros(np.prod(shape), dtype=bool)
            side[ids[uniform]] = self.solid.inside(centre[uniform])
            done = np.zeros(np.prod(shape), dtype=bool)
            done[ids[uniform]] = True
            inside[open_] = side[key]
            open_ = open_[~done[key]]
        inside[open_] = self.solid.inside(P[open_])
        return P, inside

    def _count(self, c: int) -> np.ndarray:
        """Inside points per layer of chunk c (its mask kept for rows)."""
        _, inside = self._chunk(c)
        self._kept[c] = np.packbits(inside)
        return inside.reshape(-1, self.per_layer).sum(axis=1)

    def rows(self, start: int, stop: int):
        if stop <= start:
            return np.zeros((0, self.dim)), np.zeros(0)
        first_layer = int(np.searchsorted(self.first, start, side="right")) - 1
        last_layer = int(np.searchsorted(self.first, stop - 1, side="right")) - 1
        kept = []
        for c in range(first_layer // self.stride, last_layer // self.stride + 1):
            if c in self._kept:
                P = self._points(c)[1]
                inside = np.unpackbits(self._kept[c], count=len(P)).astype(bool)
            else:
                P, inside = self._chunk(c)
            kept.append(P[inside])
        offset = int(self.first[first_layer // self.stride * self.stride])
        positions = np.concatenate(kept)[start - offset:stop - offset]
        if self.packed is not None:
            gid, X = self.packed
            a, b = np.searchsorted(gid, [start, stop])
            positions[gid[a:b] - start] = X[a:b]
        return positions, np.full(stop - start, self.each)


def fill(part: dict, name: str, dim: int, comm=None, warn=lambda message: None) -> Fill:
    """The Fill of a solid part table (solids.solid) at its spacing, packed if it says so."""
    iterations = part.get("pack_iterations", PACK_ITERATIONS) if part.get("pack") else 0
    return Fill(solid(part, name, dim, warn), part["spacing"], name, comm, iterations)
