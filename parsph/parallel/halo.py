"""The halo: copies on one rank of points owned by other ranks (ghosts), how they are found,
and how their values are refreshed from their owners.

Ghosts are found by bounding boxes (`within_reach`: each rank's points within a reach of
another rank's box; `gather`: their fields sent to that rank) and refreshed by a `Halo`, a
plan between ranks: the owned rows each other rank receives and the local rows each other
rank's values land in. The particles' kernel ghosts (parallel.decomposition) and contact's
ghosts (parsph.contact) are two plans of it; the mirror images across symmetry planes
(parallel.mirrors) are filled from their sources after the exchange.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

TAG = 7  # one tag for all: every rank runs the exchanges in the same order, each completed before
#          the next, so their messages match in order (MPI does not let messages overtake)


def within_reach(x: np.ndarray, reach: float, comm, region: np.ndarray | None = None) -> dict:
    """rank -> the rows of the points `x` within `reach` of that rank's bounding box of its
    points `region` (default `x`), for every other rank with some (collective)."""
    region = x if region is None else region
    boxes = comm.allgather((region.min(axis=0), region.max(axis=0)) if len(region) else None)
    rows = {}
    for r, box in enumerate(boxes):
        if r == comm.rank or box is None or not len(x):
            continue
        gap = np.maximum(0.0, np.maximum(box[0] - x, x - box[1]))
        sel = np.flatnonzero(np.einsum("na,na->n", gap, gap) <= reach ** 2)
        if len(sel):
            rows[r] = sel
    return rows


def gather(fields: dict, rows: dict, comm) -> dict:
    """The rows of every other rank's `fields` (name -> one row per point) that it selected
    for this rank (`rows` on that rank: rank -> its rows), by rank, with "owner", the rank
    that sent each (collective)."""
    like = dict(fields, owner=np.zeros(0, np.int64))
    if comm.size == 1:
        return {k: v[:0] for k, v in like.items()}
    out = [None] * comm.size
    for r, sel in rows.items():
        out[r] = dict({k: v[sel] for k, v in fields.items()}, owner=np.full(len(sel), comm.rank, np.int64))
    chunks = [c for c in comm.alltoall(out) if c is not None]
    if not chunks:
        return {k: v[:0] for k, v in like.items()}
    return {k: np.concatenate([c[k] for c in chunks]) for k in like}


def requested(owned_gid: np.ndarray, gid: np.ndarray, owner: np.ndarray, comm) -> dict:
    """rank -> the owned rows (of the sorted global ids `owned_gid`) that rank holds copies
    of, from the global ids `gid` of this rank's copies and their owners `owner` (collective)."""
    if comm.size == 1:
        return {}
    wanted = comm.alltoall([gid[owner == r] for r in range(comm.size)])
    return {r: np.searchsorted(owned_gid, gids) for r, gids in enumerate(wanted) if len(gids) and r != comm.rank}


class Halo:
    """The plan of a refresh: `send` (rank -> the owned rows that rank holds copies of) and
    `recv` (rank -> the local rows of its copies here, a slice where they are contiguous)."""

    def __init__(self, comm, send: dict, owner: np.ndarray, first: int):
        """`owner`: the owner rank of each of the local rows `first`, `first` + 1, ... (-1:
        no rank's, a mirror image)."""
        self.comm, self.send = comm, send
        self.recv = {}
        for r in np.unique(owner):
            if r < 0:
                continue
            rows = first + np.flatnonzero(owner == r)
            contiguous = rows[-1] - rows[0] + 1 == len(rows)
            self.recv[int(r)] = slice(int(rows[0]), int(rows[-1]) + 1) if contiguous else rows

    def exchange(self, values: np.ndarray, into: np.ndarray | None = None) -> None:
        """Copy the owners' `values` (rows: local rows, owned first) into the copies' rows of
        `into` (default `values`)."""
        if not self.recv and not self.send:
            return
        into = values if into is None else into
        requests, buffers = [], []
        for r, rows in self.recv.items():
            if isinstance(rows, slice) and into.flags.c_contiguous:  # received in place
                requests.append(self.comm.Irecv(into[rows], source=r, tag=TAG))
                continue
            buf = np.empty((len(rows),) + into.shape[1:], into.dtype)
            buffers.append((rows, buf))
            requests.append(self.comm.Irecv(buf, source=r, tag=TAG))
        sends = []
        for r, index in self.send.items():
            data = np.ascontiguousarray(values[index])
            sends.append(data)
            requests.append(self.comm.Isend(data, dest=r, tag=TAG))
        MPI.Request.Waitall(requests)
        for rows, buf in buffers:
            into[rows] = buf
