"""Ownership by reference position and the ghost (halo) exchange.

Particles are partitioned by recursive coordinate bisection (RCB) of their reference
positions, which balances counts and keeps subdomains compact. In the total-Lagrangian
formulation the neighbour graph never changes, so the partition and the halo plan are made
once. Local arrays are ordered: owned particles (by global id), then layer-1 ghosts
(neighbours of owned particles, grouped by owner rank, by global id), then layer-2 ghosts
(neighbours of layer-1 ghosts, needed only at set-up to build the ghosts' corrected
gradients g_ji). `refresh(arrays...)` copies the owners' values of the named fields into
the layer-1 ghost slots.

Set-up currently reads the full reference geometry on every rank (built deterministically
from the scene); only the owned and ghost particles are kept.
"""

from __future__ import annotations

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


class Decomposition:
    """This rank's owned and ghost particles and the plan to refresh ghost values."""

    def __init__(self, body: Body, comm):
        self.comm = comm
        size, me = comm.size, comm.rank
        owner = rcb_partition(body.X, size) if size > 1 else np.zeros(body.count, np.int64)
        owned = np.flatnonzero(owner == me)
        self.n_owned = len(owned)
        self.total = body.count  # particles over all ranks
        if size == 1:
            self.local_gid = owned
            self.n_rows = self.n_owned
            self.n_ghost = 0
            self.recv_slices = {}
            self.send_index = {}
            return
        tree = cKDTree(body.X)
        reach = float(body.support.max())

        def neighbours_of(index: np.ndarray) -> np.ndarray:
            if len(index) == 0:
                return np.zeros(0, np.int64)
            hits = tree.query_ball_point(body.X[index], r=reach)
            return np.unique(np.concatenate([np.asarray(h, np.int64) for h in hits]))

        known = np.zeros(body.count, bool)
        known[owned] = True
        layer1 = neighbours_of(owned)
        layer1 = layer1[~known[layer1]]
        known[layer1] = True
        layer2 = neighbours_of(layer1)
        layer2 = layer2[~known[layer2]]
        layer1 = layer1[np.lexsort((layer1, owner[layer1]))]
        self.local_gid = np.concatenate([owned, layer1, np.sort(layer2)]).astype(np.int64)
        self.n_ghost = len(layer1)
        self.n_rows = self.n_owned + self.n_ghost

        # receive plan: contiguous ghost block per owner rank
        self.recv_slices = {}
        start = self.n_owned
        for r in np.unique(owner[layer1]):
            count = int(np.sum(owner[layer1] == r))
            self.recv_slices[int(r)] = slice(start, start + count)
            start += count
        # send plan: each owner learns which of its particles every other rank needs
        requests = [layer1[owner[layer1] == r] for r in range(size)]
        wanted = comm.alltoall(requests)
        position = {int(g): k for k, g in enumerate(owned)}
        self.send_index = {
            r: np.array([position[int(g)] for g in gids], np.int64)
            for r, gids in enumerate(wanted) if len(gids) and r != me
        }

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
