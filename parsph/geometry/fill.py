"""A solid (geometry.solids) filled with a cell-centred square/cubic lattice, generated in
blocks of rows: the lattice of spacing h centred on the solid's bounding box, the points
inside kept, layer after layer along the last axis (first axis fastest within a layer).
Every particle has the volume exact volume / count, so the volumes sum to the solid's.

The count needs every layer's inside count: with a communicator each rank classifies its
share of the layers and the ranks exchange the counts; rows(start, stop) classifies again
only the layers holding those rows. Layers are handled in slabs of SLAB layers aligned on
the lattice, and a solid that can tell points far from its boundary (a closed surface)
classifies whole blocks of SLAB^3 cells by their centre, so the particles do not depend on
the rank count.
"""

from __future__ import annotations

import math

import numpy as np

from parsph.parallel.runtime import collective

from .lattice import MAX_PARTICLES
from .solids import solid

SLAB = 4  # layers per slab; blocks of SLAB^3 cells far from a surface are classified at once
CHUNK = 1 << 20  # lattice points classified at once (about)


class Fill:
    """`count` particles of `solid` at spacing `h`; `rows(start, stop)` -> (positions,
    volumes). `name` names the part in messages; `comm` (optional) shares the counting."""

    blockwise = True  # rows(start, stop) builds only those rows

    def __init__(self, solid, h: float, name: str, comm=None):
        self.solid, self.h, self.dim = solid, h, solid.dim
        lo, hi = solid.bounds
        if solid.volume is not None:
            estimate = solid.volume / h ** self.dim
            if not estimate <= MAX_PARTICLES:
                raise ValueError(f"{name}: spacing {h:g} would fill the volume {solid.volume:.4g} with about "
                                 f"{estimate:.3g} particles, more than 2^31; are the geometry's units and the "
                                 "spacing's the same (a mesh in mm and a spacing in m?)")
        span = (hi - lo) / h
        if not np.prod(np.maximum(1.0, span)) <= 16 * MAX_PARTICLES:
            raise ValueError(f"{name}: the bounding box {span.round(1).tolist()} spacings wide is too large a "
                             "lattice to classify; use a larger spacing")
        self.n = np.maximum(1, np.ceil(span * (1.0 - 1e-12))).astype(np.int64)
        origin = 0.5 * (lo + hi) - 0.5 * self.n * h
        self.origin = origin
        self.axes = [origin[k] + (np.arange(self.n[k]) + 0.5) * h for k in range(self.dim)]
        self.per_layer = int(np.prod(self.n[:-1]))
        self.stride = SLAB * max(1, (CHUNK // max(self.per_layer, 1)) // SLAB)  # layers per chunk
        layers = int(self.n[-1])
        slabs = -(-layers // SLAB)
        if comm is None:
            counts = self._counts(0, layers)
        else:
            cuts = np.linspace(0, slabs, comm.size + 1).round().astype(np.int64) * SLAB
            with collective(comm):  # a rank that fails here must not meet the others' allgather below
                mine = self._counts(min(int(cuts[comm.rank]), layers), min(int(cuts[comm.rank + 1]), layers))
            counts = np.concatenate(comm.allgather(mine))
        self.first = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.count = int(self.first[-1])
        if self.count == 0:
            raise ValueError(f"{name}: no lattice point at spacing {h:g} falls inside the solid; use a smaller "
                             "spacing")
        self.lattice_volume = self.count * h ** self.dim
        self.volume = solid.volume if solid.volume is not None else self.lattice_volume
        self.each = self.volume / self.count

    def report(self) -> str:
        """The count and the lattice's volume error, for the set-up output."""
        return (f"{self.count} particles at spacing {self.h:g}, volume {self.volume:.6g}, lattice volume "
                f"error {100.0 * (self.lattice_volume / self.volume - 1.0):+.3f} %")

    def _layers(self, k0: int, k1: int):
        """Positions of the lattice points of layers k0..k1-1 (k0 on a slab) and which are
        inside."""
        grids = np.meshgrid(*self.axes[:-1], self.axes[-1][k0:k1], indexing="ij")
        P = np.column_stack([g.ravel(order="F") for g in grids])
        far = getattr(self.solid, "far", None)
        if far is None:
            return P, self.solid.inside(P)
        # blocks of SLAB^d cells, aligned on the lattice: those far from the surface take their centre's side
        index = np.meshgrid(*[np.arange(len(a)) // SLAB for a in self.axes[:-1]],
                            np.arange(k0, k1) // SLAB, indexing="ij")
        blocks = [np.unique(i) for i in index]
        shape = [len(b) for b in blocks]
        local = np.ravel_multi_index([(i - b[0]).ravel(order="F") for i, b in zip(index, blocks)], shape, order="F")
        centre_grids = np.meshgrid(*[self.origin[k] + (b + 0.5) * SLAB * self.h for k, b in enumerate(blocks)],
                                   indexing="ij")
        centres = np.column_stack([g.ravel(order="F") for g in centre_grids])
        uniform = far(centres, 0.5 * SLAB * self.h * math.sqrt(self.dim))
        side = np.zeros(len(centres), dtype=bool)
        side[uniform] = self.solid.inside(centres[uniform])
        inside = side[local]
        near = ~uniform[local]
        inside[near] = self.solid.inside(P[near])
        return P, inside

    def _chunks(self, k0: int, k1: int):
        for a in range(k0, k1, self.stride):
            yield a, self._layers(a, min(a + self.stride, k1))

    def _counts(self, k0: int, k1: int) -> np.ndarray:
        counts = [np.zeros(0, np.int64)]
        for a, (_, inside) in self._chunks(k0, k1):
            counts.append(inside.reshape(-1, self.per_layer).sum(axis=1))
        return np.concatenate(counts)

    def rows(self, start: int, stop: int):
        if stop <= start:
            return np.zeros((0, self.dim)), np.zeros(0)
        first_layer = int(np.searchsorted(self.first, start, side="right")) - 1
        last_layer = int(np.searchsorted(self.first, stop - 1, side="right")) - 1
        k0 = first_layer // SLAB * SLAB
        k1 = min(int(self.n[-1]), (last_layer // SLAB + 1) * SLAB)
        kept = [P[inside] for _, (P, inside) in self._chunks(k0, k1)]
        offset = int(self.first[k0])
        positions = np.concatenate(kept)[start - offset:stop - offset]
        return positions, np.full(stop - start, self.each)


def fill(part: dict, name: str, dim: int, comm=None, warn=lambda message: None) -> Fill:
    """The Fill of a solid part table (solids.solid) at its spacing."""
    return Fill(solid(part, name, dim, warn), part["spacing"], name, comm)
