"""Generate a scene's particle set in parallel: reference positions, measures, volumes,
masses, kernel supports, global ids and named groups.

Each rank builds a contiguous block of the parts' particles (a part that exists only whole,
the Voronoi random patch, is built by rank 0, which hands out the blocks); the ranks then
send every particle to its owner (parallel RCB), drop particles coincident across parts,
and find kernel supports and groups with neighbour exchanges and global reductions. No
rank ever holds the whole set.
"""

from __future__ import annotations

import numpy as np

from parsph import geometry
from parsph.errors import InputError
from parsph.parallel.decomposition import LocalBody, add_ghosts, block_cuts, nearby, partition
from parsph.parallel.runtime import collective

PARTS = {"box": geometry.Box, "random_patch": geometry.RandomPatch, "cylinder": geometry.Cylinder,
         "ring": geometry.Ring, "disk": geometry.Disk}


def _generators(scene: dict) -> list:
    """The part generators of `scene`, checked (arguments, dimension) without building."""
    gens, dim = [], scene["scene"]["dimension"]
    for i, part in enumerate(scene["geometry"]["parts"]):
        args = {k: v for k, v in part.items() if k != "shape"}
        try:
            gens.append(PARTS[part["shape"]](**args))
        except ValueError as exc:
            raise InputError(f"geometry.parts[{i}]: {exc}") from None
        if gens[-1].blockwise and gens[-1].count:
            part_dim = gens[-1].rows(0, 1)[0].shape[1]
            if part_dim != dim:
                raise InputError(f"geometry.parts[{i}]: a {part_dim}D {part['shape']} in a {dim}D scene")
    if sum(g.count for g in gens) == 0:
        raise InputError("geometry.parts produce zero particles; check the shapes' sizes and spacing")
    return gens


def _block(gens: list, dim: int, comm) -> dict:
    """Particles cuts[r]..cuts[r+1]-1 of the parts (in part order) on rank r: candidate
    index "gid", positions "X", measures "measure"."""
    first = np.cumsum([0] + [g.count for g in gens])
    cuts = block_cuts(first[-1], comm.size)

    def rows(start, stop):
        X, measure = [np.zeros((0, dim))], [np.zeros(0)]
        for g, offset in zip(gens, first):
            a, b = max(start, offset), min(stop, offset + g.count)
            if a < b:
                x, m = g.rows(a - offset, b - offset)
                X.append(np.asarray(x, np.float64).reshape(-1, dim))
                measure.append(np.asarray(m, np.float64))
        return {"gid": np.arange(start, stop, dtype=np.int64), "X": np.concatenate(X),
                "measure": np.concatenate(measure)}

    if all(g.blockwise for g in gens):
        return rows(cuts[comm.rank], cuts[comm.rank + 1])
    blocks = None
    with collective(comm):
        if comm.rank == 0:
            blocks = [rows(cuts[r], cuts[r + 1]) for r in range(comm.size)]
    return comm.scatter(blocks, root=0)


def _drop_coincident(owned: dict, tol: float, comm) -> dict:
    """Drop each particle closer than `tol` to one of a lower index (parts overlapping at
    their surfaces) and renumber the global ids densely, keeping their order."""
    near = nearby(owned, owned["X"], tol, comm)
    drop = geometry.shadowed(owned["X"], owned["gid"], np.concatenate([owned["X"], near["X"]]),
                             np.concatenate([owned["gid"], near["gid"]]), tol)
    dropped = np.sort(np.concatenate(comm.allgather(owned["gid"][drop])))
    kept = {k: v[~drop] for k, v in owned.items()}
    kept["gid"] = kept["gid"] - np.searchsorted(dropped, kept["gid"])
    return kept


def _spacing(parts: list, measure: np.ndarray, dim: int) -> np.ndarray:
    """Particle spacing: the lattice spacing of the part a particle came from, or
    measure^(1/d) for random particle sets (boundary particles of a node lattice keep the
    lattice spacing although their lumped volume is smaller)."""
    lattice = [p["spacing"] for p in parts if "spacing" in p]
    if len(lattice) == len(parts):
        return np.full(len(measure), min(lattice))
    return measure ** (1.0 / dim)


def _neighbour_support(x: np.ndarray, target: int, comm) -> np.ndarray:
    """geometry.support_for_neighbours over all ranks' particles: each rank gathers the
    particles within a reach of its own, doubling the reach until every particle of every
    rank has its target + 1 nearest others inside it."""
    # 2 h_i >= d_{target+1}: a rank's own supports bound the reach its particles need
    local = 2.0 * geometry.support_for_neighbours(x, target).max() if len(x) >= target + 2 else np.inf
    bounds = [b for b in comm.allgather(float(local)) if np.isfinite(b)]
    reach = max(bounds) if bounds else 0.0
    if reach == 0.0:
        spans = [s for s in comm.allgather(float(np.ptp(x, axis=0).max()) if len(x) else None) if s]
        reach = max(spans) if spans else 1.0
    while True:
        others = nearby({"X": x}, x, reach, comm)["X"]
        support = geometry.support_for_neighbours(x, target, others, reach) if len(x) else np.zeros(0)
        if all(comm.allgather(bool(np.isfinite(support).all()))):
            return support
        reach *= 2.0


def build_particles(scene: dict, comm) -> dict:
    """This rank's owned particles of `scene` (arrays by global id: "gid", "X", "measure",
    "volume", "mass", "support", "groups" as uint8 columns by sorted group name).
    Collective; raises InputError on every rank for an empty or degenerate set."""
    dim = scene["scene"]["dimension"]
    with collective(comm):
        gens = _generators(scene)
        total = sum(g.count for g in gens)
        neighbours = scene["kernel"]["neighbours"]
        if neighbours > 0 and neighbours + 2 > total:
            raise InputError(f"kernel.neighbours = {neighbours} needs at least {neighbours + 2} "
                             f"particles, the scene has {total}")
    owned = partition(_block(gens, dim, comm), "X", comm)
    if len(gens) > 1:
        smallest = min(m for m in comm.allgather(float(owned["measure"].min()) if len(owned["X"]) else None)
                       if m is not None)
        owned = _drop_coincident(owned, 1e-6 * smallest ** (1.0 / dim), comm)
    X, measure = owned["X"], owned["measure"]
    factor = {1: scene["geometry"]["area"], 2: scene["geometry"]["thickness"], 3: 1.0}[dim]
    owned["volume"] = measure * factor
    owned["mass"] = owned["volume"] * scene["material"]["density"]
    if neighbours > 0:
        owned["support"] = _neighbour_support(X, neighbours, comm)
    else:
        owned["support"] = scene["kernel"]["support"] * _spacing(scene["geometry"]["parts"], measure, dim)
    names = sorted(scene["groups"])
    groups = np.zeros((len(X), len(names)), np.uint8)
    with collective(comm):
        for k, name in enumerate(names):
            try:
                groups[:, k] = geometry.select(scene["groups"][name], X, measure, owned["gid"], comm)
            except ValueError as exc:
                raise InputError(f"groups.{name}: {exc}") from None
    owned["groups"] = groups
    used = {item["group"] for key in ("bc", "walls", "tools", "initial", "probes") for item in scene[key]}
    counts = comm.allreduce(groups.sum(axis=0, dtype=np.int64))
    with collective(comm):
        for name in sorted(used):
            if not counts[names.index(name)]:
                raise InputError(f"group '{name}' selects no particles; check groups.{name}")
    return owned


def build_local(scene: dict, comm) -> LocalBody:
    """This rank's particles of `scene` with their ghost layers, ready for the solver."""
    return add_ghosts(build_particles(scene, comm), "X", comm)
