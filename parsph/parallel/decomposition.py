"""Ownership by reference position, distribution of the particles, and the ghost (halo) exchange.

Particles are partitioned by recursive coordinate bisection (RCB) of their reference
positions, which balances counts and keeps subdomains compact. In the total-Lagrangian
formulation the neighbour graph never changes, so the partition and the halo plan are made
once. Local arrays are ordered: owned particles (by global id), then layer-1 ghosts
(neighbours of owned particles, grouped by owner rank, by global id), then layer-2 ghosts
(neighbours of layer-1 ghosts, needed only at set-up to build the ghosts' corrected
gradients g_ji). `refresh(arrays...)` copies the owners' values of the named fields into
the layer-1 ghost slots.

Rank 0 builds (or reads) the reference set, partitions it and sends each rank its part
(`distribute`); no other rank ever holds the whole set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from parsph.build import Body


def rcb_partition(X: np.ndarray, parts: int) -> np.ndarray:
    """Owner rank of each particle: recursive bisection along the longest axis.

    Part counts are split as evenly as possible (parts need not be a power of two); ties in
    the coordinate are broken by index, so the result is deterministic.
    """
    owner = np.zeros(len(X), np.int64)

    def split(index: np.ndarray, first: int, count: int) -> None:
        if count == 1 or len(index) == 0:
            owner[index] = first
            return
        left_parts = count // 2
        pts = X[index]
        axis = int(np.argmax(pts.max(axis=0) - pts.min(axis=0))) if len(index) else 0
        order = np.lexsort((index, pts[:, axis]))
        cut = int(round(len(index) * left_parts / count))
        split(index[order[:cut]], first, left_parts)
        split(index[order[cut:]], first + left_parts, count - left_parts)

    split(np.arange(len(X)), 0, parts)
    return owner


@dataclass
class LocalBody:
    """One rank's part of the reference particle set: owned particles (by global id), then
    layer-1 ghosts (by owner rank, then global id), then layer-2 ghosts (by global id)."""

    gid: np.ndarray
    owner: np.ndarray
    X: np.ndarray
    measure: np.ndarray
    volume: np.ndarray
    mass: np.ndarray
    support: np.ndarray
    groups: dict  # name -> bool mask over the local particles
    n_owned: int
    n_ghost: int  # layer-1 ghosts
    total: int  # particles over all ranks
    extra: dict  # further per-particle arrays sent along (a checkpoint's state)


def _ghost_layers(X: np.ndarray, support: np.ndarray, owner: np.ndarray, rank: int):
    """Owned particles of `rank`, their neighbours owned elsewhere (layer 1) and the
    neighbours of those (layer 2), each as sorted global ids (layer 1 by owner, then id)."""
    tree = cKDTree(X)
    reach = float(support.max())

    def neighbours_of(index: np.ndarray) -> np.ndarray:
        if len(index) == 0:
            return np.zeros(0, np.int64)
        hits = tree.query_ball_point(X[index], r=reach)
        return np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits]))

    owned = np.flatnonzero(owner == rank)
    known = np.zeros(len(X), bool)
    known[owned] = True
    layer1 = neighbours_of(owned)
    layer1 = layer1[~known[layer1]]
    known[layer1] = True
    layer2 = neighbours_of(layer1)
    layer2 = np.sort(layer2[~known[layer2]])
    return owned, layer1[np.lexsort((layer1, owner[layer1]))], layer2


def distribute(body: Body | None, comm, extra: dict | None = None) -> LocalBody:
    """Rank 0 partitions `body` (given on rank 0 only) by RCB of the reference positions and
    sends every rank its owned particles with two ghost layers, plus its rows of `extra`.
    After this no rank holds the whole particle set."""
    parts = None
    if comm.rank == 0:
        extra = extra or {}
        owner = rcb_partition(body.X, comm.size) if comm.size > 1 else np.zeros(body.count, np.int64)
        parts = []
        for r in range(comm.size):
            if comm.size == 1:
                owned, layer1, layer2 = np.arange(body.count), np.zeros(0, np.int64), np.zeros(0, np.int64)
            else:
                owned, layer1, layer2 = _ghost_layers(body.X, body.support, owner, r)
            local = np.concatenate([owned, layer1, layer2]).astype(np.int64)
            parts.append(LocalBody(
                gid=local, owner=owner[local], X=np.ascontiguousarray(body.X[local]),
                measure=body.measure[local], volume=body.volume[local], mass=body.mass[local],
                support=body.support[local], groups={k: m[local] for k, m in body.groups.items()},
                n_owned=len(owned), n_ghost=len(layer1), total=body.count,
                extra={k: v[local] for k, v in extra.items()}))
    return comm.scatter(parts, root=0) if comm.size > 1 else parts[0]


class Decomposition:
    """This rank's owned and ghost particles and the plan to refresh ghost values."""

    def __init__(self, local: LocalBody, comm):
        self.comm = comm
        size, me = comm.size, comm.rank
        self.n_owned = local.n_owned
        self.n_ghost = local.n_ghost
        self.n_rows = self.n_owned + self.n_ghost  # particles whose neighbourhood is complete
        self.total = local.total
        self.local_gid = local.gid
        owned = local.gid[: self.n_owned]
        layer1 = local.gid[self.n_owned: self.n_rows]
        owner1 = local.owner[self.n_owned: self.n_rows]
        # receive plan: contiguous ghost block per owner rank
        self.recv_slices = {}
        start = self.n_owned
        for r in np.unique(owner1):
            count = int(np.sum(owner1 == r))
            self.recv_slices[int(r)] = slice(start, start + count)
            start += count
        # send plan: each owner learns which of its particles every other rank needs
        self.send_index = {}
        if size > 1:
            wanted = comm.alltoall([layer1[owner1 == r] for r in range(size)])
            self.send_index = {r: np.searchsorted(owned, gids) for r, gids in enumerate(wanted)
                               if len(gids) and r != me}

    def trim(self) -> None:
        """Forget layer-2 ghosts once reference data is built."""
        self.local_gid = self.local_gid[: self.n_rows]

    def refresh(self, *arrays: np.ndarray) -> None:
        """Copy owners' values of `arrays` (indexed by local particle) into the ghost slots."""
        if not self.recv_slices and not self.send_index:
            return
        from mpi4py import MPI

        for arr in arrays:
            requests = []
            buffers = []
            for r, sl in self.recv_slices.items():
                buf = np.empty((sl.stop - sl.start,) + arr.shape[1:], arr.dtype)
                buffers.append((sl, buf))
                requests.append(self.comm.Irecv(buf, source=r, tag=7))
            sends = []
            for r, index in self.send_index.items():
                data = np.ascontiguousarray(arr[index])
                sends.append(data)
                requests.append(self.comm.Isend(data, dest=r, tag=7))
            MPI.Request.Waitall(requests)
            for sl, buf in buffers:
                arr[sl] = buf
