"""Ownership, migration of particles with their state, and the particles' ghost layers.

Particles are owned by position: recursive coordinate bisection (RCB) of the reference
positions balances the counts and keeps subdomains compact. The bisection runs in parallel
(`parallel_rcb`: each cut is found by bisection on the coordinate with global counts), so
no rank needs the whole particle set. A particle moves to its owner with all of its state
(`migrate`): every per-particle array travels with it. In the total-Lagrangian formulation
ownership is decided once; with an updated reference it is decided again at each update.

A rank's local arrays are ordered: owned particles (by global id), then layer-1 ghosts
(neighbours of owned particles, grouped by owner rank, by global id), then layer-2 ghosts
(neighbours of layer-1 ghosts, needed only to build the ghosts' corrected gradients, by
global id). `add_ghosts` finds both layers across ranks from the subdomains' bounding
boxes; `Decomposition.refresh(arrays...)` copies the owners' values into the layer-1 slots.
Both go through the halo machinery of parallel.halo, which contact's ghosts use too.

At start-up each rank generates (parsph.build) or reads (parsph.io.checkpoint) a contiguous
block of the particle set and `partition` sends every particle to its owner: no rank ever
holds the whole set.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsph.cells import kdtree
from parsph.parallel.halo import Halo, gather, requested, within_reach


def _smallest(c: np.ndarray, ids: np.ndarray, target: int, comm) -> np.ndarray:
    """Mask of the local entries among the `target` globally smallest keys (c, id): the
    cut coordinate by bisection on floats, ties broken by global id."""
    total = comm.allreduce(len(c))
    if target <= 0:
        return np.zeros(len(c), bool)
    if target >= total:
        return np.ones(len(c), bool)
    lo = comm.allreduce(float(c.min()) if len(c) else np.inf, op=MPI.MIN)
    hi = np.nextafter(comm.allreduce(float(c.max()) if len(c) else -np.inf, op=MPI.MAX), np.inf)
    # invariant: count(c < lo) <= target < count(c < hi)
    while True:
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if comm.allreduce(int(np.count_nonzero(c < mid))) > target:
            hi = mid
        else:
            lo = mid
    # every key in [lo, hi) has c == lo: take the smallest ids among them
    tie = c == lo
    need = target - comm.allreduce(int(np.count_nonzero(c < lo)))
    glo, ghi = 0, comm.allreduce(int(ids.max()) + 1 if len(ids) else 0, op=MPI.MAX)
    while ghi - glo > 1:
        gm = (glo + ghi) // 2
        if comm.allreduce(int(np.count_nonzero(tie & (ids < gm)))) > need:
            ghi = gm
        else:
            glo = gm
    return (c < lo) | (tie & (ids < glo))


def rcb(X: np.ndarray, gid: np.ndarray, comm) -> tuple[np.ndarray, list]:
    """Owner rank of each local particle: recursive bisection of all ranks' particles along
    the longest axis of each part, computed together by all ranks; and the cuts made, as
    (first rank, left ranks, axis, plane) in order, for `assign`.

    Part counts are split as evenly as possible (any number of ranks); the result depends
    only on the global set (positions and ids), not on where the particles are held.
    """
    owner = np.zeros(len(X), np.int64)
    cuts = []
    parts = [(0, comm.size)]
    while parts:
        halves = []
        for first, count in parts:
            if count == 1:
                continue
            mine = np.flatnonzero(owner == first)
            pts = X[mine]
            lo = pts.min(axis=0) if len(pts) else np.full(X.shape[1], np.inf)
            hi = pts.max(axis=0) if len(pts) else np.full(X.shape[1], -np.inf)
            comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
            comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
            total = comm.allreduce(len(mine))
            left = count // 2
            axis = int(np.argmax(hi - lo)) if total else 0
            keep = _smallest(pts[:, axis], gid[mine], int(round(total * left / count)), comm)
            owner[mine[~keep]] = first + left
            c = pts[:, axis]
            low = comm.allreduce(float(c[keep].max()) if keep.any() else -np.inf, op=MPI.MAX)
            high = comm.allreduce(float(c[~keep].min()) if (~keep).any() else np.inf, op=MPI.MIN)
            plane = 0.5 * (low + high) if np.isfinite(low) and np.isfinite(high) else min(low, high)
            cuts.append((first, left, axis, plane))
            halves += [(first, left), (first + left, count - left)]
        parts = halves
    return owner, cuts


def parallel_rcb(X: np.ndarray, gid: np.ndarray, comm) -> np.ndarray:
    """Owner rank of each local particle by `rcb`."""
    return rcb(X, gid, comm)[0]


def assign(cuts: list, Y: np.ndarray) -> np.ndarray:
    """Owner rank of points at `Y` by the planes of an `rcb` of the particles: the rank whose
    region holds the point (points on a plane go to the upper side)."""
    owner = np.zeros(len(Y), np.int64)
    for first, left, axis, plane in cuts:
        sel = np.flatnonzero(owner == first)
        owner[sel[Y[sel, axis] >= plane]] = first + left
    return owner


def _take(fields: dict, index: np.ndarray) -> dict:
    return {k: v[index] for k, v in fields.items()}


def _concat(chunks: list, like: dict) -> dict:
    chunks = [c for c in chunks if c is not None]
    if not chunks:
        return {k: v[:0] for k, v in like.items()}
    return {k: np.concatenate([c[k] for c in chunks]) for k in like}


def migrate(fields: dict, dest: np.ndarray, comm) -> dict:
    """Send every local particle, with all its arrays in `fields` (one row per particle,
    including "gid"), to rank `dest`; returns the particles this rank now owns, by gid."""
    if comm.size > 1:
        out = [_take(fields, np.flatnonzero(dest == r)) for r in range(comm.size)]
        fields = _concat(comm.alltoall(out), fields)
    order = np.argsort(fields["gid"], kind="stable")
    return _take(fields, order)


def block_cuts(total: int, ranks: int) -> np.ndarray:
    """Row bounds of the contiguous blocks in which ranks generate or read a set of `total`
    rows: rank r takes rows cuts[r]..cuts[r+1]-1."""
    return np.linspace(0, total, ranks + 1).round().astype(np.int64)


def partition(fields: dict, position: str, comm) -> dict:
    """Send every particle (all arrays of `fields`) to its owner by parallel RCB of the
    positions `fields[position]`; returns the particles this rank owns, by gid."""
    return migrate(fields, parallel_rcb(fields[position], fields["gid"], comm), comm)


def nearby(fields: dict, x: np.ndarray, reach: float, comm, region: np.ndarray | None = None) -> dict:
    """The points of other ranks (all arrays of `fields`, plus "owner") within `reach` of
    this rank's bounding box of the positions `region` (default `x`, the positions of the
    rows of `fields`)."""
    return gather(fields, within_reach(x, reach, comm, region), comm)


@dataclass
class LocalBody:
    """One rank's particles: owned (by global id), then layer-1 ghosts (by owner rank, then
    global id), then layer-2 ghosts (by global id). `fields` holds every per-particle array
    (reference data, state, groups) for all of them."""

    gid: np.ndarray
    owner: np.ndarray
    n_owned: int
    n_ghost: int  # layer-1 ghosts
    total: int  # particles over all ranks
    fields: dict
    offsets: np.ndarray | None = None  # first global id of each body, then the total (None: one body)
    sets: dict | None = None  # the other point sets (stress points, ...): name -> LocalBody


def add_ghosts(owned: dict, position: str, comm, also: np.ndarray | None = None, skin: float = 0.0) -> LocalBody:
    """This rank's owned particles `owned` (by gid) plus two ghost layers found across ranks:
    neighbours (within the largest kernel support plus `skin`, in the configuration
    `owned[position]`) of owned particles and of the points at `also` (this rank's owned
    points of other sets, whose neighbourhoods must be complete too), and neighbours of
    those. Each rank sends every other rank its particles within two reaches of that rank's
    bounding box."""
    n = len(owned["gid"])
    total = comm.allreduce(n)
    if comm.size == 1:
        return LocalBody(gid=owned["gid"], owner=np.zeros(n, np.int64), n_owned=n, n_ghost=0,
                         total=total, fields=owned)
    x = owned[position] if also is None else np.concatenate([owned[position], also])
    reach = comm.allreduce(float(owned["support"].max()) if n else 0.0, op=MPI.MAX) + skin
    cand = nearby(owned, owned[position], 2.0 * reach, comm, region=x)
    layer1 = layer2 = np.zeros(0, np.int64)
    if len(x) and len(cand["gid"]):
        dist1, _ = kdtree(x).query(cand[position], distance_upper_bound=reach)
        layer1 = np.flatnonzero(np.isfinite(dist1))
        rest = np.flatnonzero(~np.isfinite(dist1))
        if len(layer1) and len(rest):
            dist2, _ = kdtree(cand[position][layer1]).query(cand[position][rest], distance_upper_bound=reach)
            layer2 = rest[np.isfinite(dist2)]
    layer1 = layer1[np.lexsort((cand["gid"][layer1], cand["owner"][layer1]))]
    layer2 = layer2[np.argsort(cand["gid"][layer2], kind="stable")]
    ghosts = _take(cand, np.concatenate([layer1, layer2]))
    owner = np.concatenate([np.full(n, comm.rank, np.int64), ghosts.pop("owner")])
    fields = {k: np.concatenate([owned[k], ghosts[k]]) for k in owned}
    return LocalBody(gid=fields["gid"], owner=owner, n_owned=n, n_ghost=len(layer1), total=total,
                     fields=fields)


def add_set_ghosts(owned: dict, position: str, particles: np.ndarray, reach: float, comm) -> LocalBody:
    """This rank's owned points of another set (`owned`, by gid) plus, as ghosts, the points
    of that set owned by other ranks within `reach` of this rank's particles at `particles`
    (by owner rank, then gid): the integration points the owned particles' sums run over."""
    n = len(owned["gid"])
    total = comm.allreduce(n)
    if comm.size == 1:
        return LocalBody(gid=owned["gid"], owner=np.zeros(n, np.int64), n_owned=n, n_ghost=0,
                         total=total, fields=owned)
    cand = nearby(owned, owned[position], reach, comm, region=particles)
    ghost = np.zeros(0, np.int64)
    if len(particles) and len(cand["gid"]):
        dist, _ = kdtree(particles).query(cand[position], distance_upper_bound=reach)
        ghost = np.flatnonzero(np.isfinite(dist))
    ghost = ghost[np.lexsort((cand["gid"][ghost], cand["owner"][ghost]))]
    ghosts = _take(cand, ghost)
    owner = np.concatenate([np.full(n, comm.rank, np.int64), ghosts.pop("owner")])
    fields = {k: np.concatenate([owned[k], ghosts[k]]) for k in owned}
    return LocalBody(gid=fields["gid"], owner=owner, n_owned=n, n_ghost=len(ghost), total=total, fields=fields)


def localize(fields: dict, sets: dict, position: str, comm, skin: float = 0.0) -> LocalBody:
    """The particles `fields` (any block of them, by gid) sent to their owners by parallel
    RCB of `fields[position]`, with their ghost layers; and each other point set of `sets`
    (name -> a block of its points, by gid) sent to the owners of the regions holding its
    points, with its ghosts (in `.sets`); reaches extended by `skin` (add_ghosts)."""
    if not sets:
        return add_ghosts(partition(fields, position, comm), position, comm, skin=skin)
    owner, cuts = rcb(fields[position], fields["gid"], comm)
    owned = migrate(fields, owner, comm)
    others = {name: migrate(block, assign(cuts, block[position]), comm) for name, block in sets.items()}
    also = np.concatenate([np.zeros((0, owned[position].shape[1]))] + [o[position] for o in others.values()])
    local = add_ghosts(owned, position, comm, also=also, skin=skin)
    reach = comm.allreduce(float(owned["support"].max()) if len(owned["gid"]) else 0.0, op=MPI.MAX) + skin
    local.sets = {name: add_set_ghosts(o, position, owned[position], reach, comm) for name, o in others.items()}
    return local


class Decomposition:
    """This rank's owned and ghost particles and the plan to refresh ghost values."""

    def __init__(self, local: LocalBody, comm, mirrors=None, layer2: bool = False):
        """`mirrors` (parallel.mirrors.Mirrors): the layer-1 mirror images, refreshed from
        their sources after the exchange; their owner is -1. `layer2`: keep the layer-2
        ghosts and a plan to refresh them too (refresh_all: an Eulerian kernel rebuilds the
        ghosts' rows between neighbour searches)."""
        self.comm = comm
        self.mirrors = mirrors
        self.n_owned = local.n_owned
        self.n_ghost = local.n_ghost
        self.n_rows = self.n_owned + self.n_ghost  # particles whose neighbourhood is complete
        self.total = local.total
        self.local_gid = local.gid
        owned = local.gid[: self.n_owned]
        owner1, gid1 = local.owner[self.n_owned: self.n_rows], local.gid[self.n_owned: self.n_rows]
        self.halo = Halo(comm, requested(owned, gid1, owner1, comm), owner1, self.n_owned)  # layer 1
        self.halo2 = Halo(comm, {}, np.zeros(0, np.int64), self.n_rows)  # layer 2, kept with `layer2`
        if layer2:
            owner2, gid2 = local.owner[self.n_rows:], local.gid[self.n_rows:]
            self.halo2 = Halo(comm, requested(owned, gid2, owner2, comm), owner2, self.n_rows)

    def trim(self) -> None:
        """Forget layer-2 ghosts once reference data is built."""
        self.local_gid = self.local_gid[: self.n_rows]

    def refresh(self, *arrays: np.ndarray, copied=()) -> None:
        """Copy owners' values of `arrays` (indexed by local particle) into the ghost slots,
        then the reflected values of the mirror images' sources into theirs (copied as they
        are where `copied` says so, per array)."""
        for k, arr in enumerate(arrays):
            self.halo.exchange(arr)
            if self.mirrors is not None:
                self.mirrors.fill(arr, reflected=not (k < len(copied) and copied[k]))

    def refresh_all(self, *arrays: np.ndarray, fields=()) -> None:
        """refresh, and the layer-2 ghosts too (a Decomposition made with layer2); then the
        mirror images of both layers, reflected as the registered `fields` (parsph.fields,
        one per array) say, or copied (no `fields`: material states)."""
        for k, arr in enumerate(arrays):
            self.halo.exchange(arr)
            self.halo2.exchange(arr)
            if self.mirrors is not None:
                self.mirrors.fill_all(arr, fields[k] if fields else None)
