"""Generate a scene's particle set in parallel: reference positions, measures, volumes,
masses, kernel supports, global ids and named groups.

Each rank builds a contiguous block of the parts' particles (a part that exists only whole,
the Voronoi random patch, is built by rank 0, which hands out the blocks); the ranks then
send every particle to its owner (parallel RCB), drop particles coincident across parts
(and warn of parts that overlap without coinciding), and find kernel supports and groups
with neighbour exchanges and global reductions. No rank ever holds the whole set.
"""

from __future__ import annotations

import numpy as np

from parsph import config, geometry
from parsph.errors import InputError
from parsph.formulations import galerkin
from parsph.geometry.gauss_points import BoxGaussPoints
from parsph.geometry.mesh_parts import MeshPart
from parsph.geometry.stress_points import stress_points_of
from parsph.parallel.decomposition import LocalBody, block_cuts, localize, nearby, partition
from parsph.parallel.runtime import collective, say, warn

PARTS = {"box": geometry.Box, "random_patch": geometry.RandomPatch, "cylinder": geometry.Cylinder,
         "ring": geometry.Ring, "disk": geometry.Disk, "polar_ring": geometry.PolarRing, "mesh": MeshPart}
MESH_EXTENT = 10.0  # a mesh part wider than this [m] is likely in mm without scale = 1e-3


def _generators(parts: list, where: str, dim: int, comm=None) -> list:
    """The part generators of one body's `parts` (named `where` in messages), checked
    (arguments, dimension) without building; solid parts (config.SOLIDS) are filled
    lattices whose counting the ranks of `comm` share."""
    gens = []
    for i, part in enumerate(parts):
        if part["shape"] in config.SOLIDS:
            try:
                gens.append(geometry.fill(part, f"{where}[{i}]", dim, comm, warn))
            except ValueError as exc:
                raise InputError(str(exc)) from None
            continue
        args = {k: v for k, v in part.items() if k != "shape"}
        if part["shape"] == "mesh":
            args["dimension"] = dim
        try:
            gens.append(PARTS[part["shape"]](**args))
        except ValueError as exc:
            raise InputError(f"{where}[{i}]: {exc}") from None
        if part["shape"] == "mesh" and gens[-1].extent > MESH_EXTENT:
            warn(f"{where}[{i}]: the mesh {part['file']} spans {gens[-1].extent:g} m at scale = {part['scale']:g}; "
                 "a mesh drawn in mm needs scale = 1e-3")
        if gens[-1].blockwise and gens[-1].count:
            part_dim = gens[-1].rows(0, 1)[0].shape[1]
            if part_dim != dim:
                raise InputError(f"{where}[{i}]: a {part_dim}D {part['shape']} in a {dim}D scene")
    total = sum(g.count for g in gens)
    if total == 0:
        raise InputError(f"{where} produce zero particles; check the shapes' sizes and spacing")
    if total > geometry.MAX_PARTICLES:
        raise InputError(f"{where} produce {total} particles in all, more than 2^31")
    return gens


def _block(gens: list, dim: int, comm) -> dict:
    """Rows cuts[r]..cuts[r+1]-1 of the generators (in order) on rank r: candidate index
    "gid" (and a copy, "source", that joining parts does not renumber), positions "X", and
    the second column of the rows, "measure" (the particles' measures, the integration
    points' weights)."""
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
        return {"gid": np.arange(start, stop, dtype=np.int64), "source": np.arange(start, stop, dtype=np.int64),
                "X": np.concatenate(X), "measure": np.concatenate(measure)}

    if all(g.blockwise for g in gens):
        return rows(cuts[comm.rank], cuts[comm.rank + 1])
    blocks = None
    with collective(comm):
        if comm.rank == 0:
            blocks = [rows(cuts[r], cuts[r + 1]) for r in range(comm.size)]
    return comm.scatter(blocks, root=0)


def _part_spacing(part: dict, gen) -> float:
    """A part's nominal particle spacing: its lattice spacing (a polar ring's coarser one),
    or (volume / count)^(1/D) for a random patch and a mesh (generator `gen`)."""
    if "spacing" in part:
        return part["spacing"]
    if part["shape"] in ("polar_ring", "mesh"):
        return gen.spacing
    size = np.subtract(part["upper"], part["lower"])
    return float(np.prod(size) / part["count"]) ** (1.0 / len(size))


def _join_parts(owned: dict, first: np.ndarray, spacing: np.ndarray, tol: float, comm):
    """Drop each particle closer than `tol` to one of an earlier part (parts meeting at their
    surfaces) and renumber the global ids densely, keeping their order. Parts are told apart
    by the candidate index (part p holds first[p]..first[p+1]-1; `spacing` by part).

    Returns the kept particles and `close`: close[q, p] kept particles of part p lie within
    half the smaller spacing of parts p and q (to 1e-6 relative, a lattice's tolerance) of a
    particle of the earlier part q, but do not coincide with it: the parts overlap. Parts
    that touch lie a spacing apart (half the smaller one where a cell lattice meets a node
    lattice, which is flagged too)."""
    n_parts, n = len(spacing), len(owned["gid"])
    limit = np.maximum(tol, 0.5 * (1.0 + 1e-6) * np.minimum.outer(spacing, spacing))
    near = nearby(owned, owned["X"], limit[~np.eye(n_parts, dtype=bool)].max(), comm)
    X = np.concatenate([owned["X"], near["X"]])
    part = np.searchsorted(first, np.concatenate([owned["gid"], near["gid"]]), side="right") - 1
    drop = np.zeros(n, dtype=bool)
    found = []  # (q, p, owned particles of part p close to part q)
    for p in range(1, n_parts):
        mine = np.flatnonzero(part[:n] == p)
        for q in range(p):
            i, _, dist = geometry.close_pairs(X[mine], X[part == q], limit[q, p])
            drop[mine[i[dist < tol]]] = True
            found.append((q, p, np.unique(mine[i[dist >= tol]])))
    close = np.zeros((n_parts, n_parts), np.int64)
    for q, p, index in found:
        close[q, p] = np.count_nonzero(~drop[index])
    dropped = np.sort(np.concatenate(comm.allgather(owned["gid"][drop])))
    kept = {k: v[~drop] for k, v in owned.items()}
    kept["gid"] = kept["gid"] - np.searchsorted(dropped, kept["gid"])
    return kept, comm.allreduce(close)


def _spacing(parts: list, gens: list, measure: np.ndarray, dim: int) -> np.ndarray:
    """Particle spacing: the lattice spacing of the part a particle came from, or
    measure^(1/d) for random particle sets and meshes (their elements' sizes; boundary
    particles of a node lattice keep the lattice spacing although their lumped volume is
    smaller)."""
    lattice = [_part_spacing(p, g) for p, g in zip(parts, gens) if p["shape"] not in ("random_patch", "mesh")]
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


def _body_particles(scene: config.Scene, body: dict, where: str, gens: list, comm) -> dict:
    """This rank's owned particles of one body (its parts united): "gid" numbered densely
    from 0, "X", "measure", "volume", "mass", "support"."""
    dim = scene.scene.dimension
    owned = partition(_block(gens, dim, comm), "X", comm)
    if len(gens) > 1:
        smallest = min(m for m in comm.allgather(float(owned["measure"].min()) if len(owned["X"]) else None)
                       if m is not None)
        parts = body.parts
        spacing = np.array([_part_spacing(part, g) for part, g in zip(parts, gens)])
        owned, close = _join_parts(owned, np.cumsum([0] + [g.count for g in gens]), spacing,
                                   1e-6 * smallest ** (1.0 / dim), comm)
        for q, p in zip(*np.nonzero(close)):
            warn(f"{where}[{q}] and {where}[{p}] overlap: {close[q, p]} particles of "
                 f"parts[{p}] lie within half a spacing ({0.5 * min(spacing[q], spacing[p]):g}) of "
                 f"parts[{q}]'s particles (not coincident, so both are kept and the density doubles there)")
    X, measure = owned["X"], owned["measure"]
    factor = config.thickness(scene)
    owned["volume"] = measure * factor
    owned["mass"] = owned["volume"] * body.material.density
    def with_stress_points(b):  # KBM: its particles integrate too, with their share of the cells
        return galerkin.integration_set(b.formulation) == galerkin.STRESS_POINTS

    if any(with_stress_points(b) for b in scene.bodies):  # quadrature weights
        owned["weight"] = owned["volume"] if not with_stress_points(body) else \
            stress_points_of(gens[0], factor).particle_weights(owned["gid"])
    neighbours = scene.kernel.neighbours
    if neighbours > 0:
        owned["support"] = _neighbour_support(X, neighbours, comm)
    else:
        owned["support"] = config.kernel_of(scene, body).support * _spacing(body.parts, gens, measure, dim)
    return owned


def _mesh_elements(owned: dict, gens: list, meshes: list) -> None:
    """Replace the candidate index "source" of one body's particles by "mesh", the index in
    `meshes` (the scene's mesh parts) of the mesh part a particle came from (-1: another
    shape), and "element", its row in that part."""
    first = np.cumsum([0] + [g.count for g in gens])
    source = owned.pop("source")
    part = np.searchsorted(first, source, side="right") - 1
    owned["mesh"] = np.full(len(source), -1, np.int64)
    owned["element"] = source - first[part]
    for p, g in enumerate(gens):
        if isinstance(g, MeshPart):
            owned["mesh"][part == p] = next(k for k, m in enumerate(meshes) if m is g)


def _mesh_set(spec: dict, owned: dict, meshes: list) -> np.ndarray:
    """Mask of the owned particles in the set `spec["mesh_set"]` of mesh part
    `spec["mesh_part"]` (inverted with `invert`)."""
    invert = spec.get("invert", False)
    if not isinstance(invert, bool):
        raise ValueError(f"invert must be true or false, got {invert!r}")
    k = spec["mesh_part"]
    members = meshes[k].set_mask(spec["mesh_set"])  # on every rank: an unknown set fails on all
    mine = owned["mesh"] == k
    mask = np.zeros(len(mine), bool)
    mask[mine] = members[owned["element"][mine]]
    return ~mask if invert else mask


def build_integration_points(scene: config.Scene, comm) -> dict:
    """This rank's blocks of the point sets of integration points the scene's bodies need
    (formulations.galerkin: stress points, Gauss points; global ids body after body):
    "gid", "X", "volume" (quadrature weight), "body". Collective."""
    specs = scene.bodies
    dim = scene.scene.dimension
    kinds = {galerkin.STRESS_POINTS: stress_points_of, galerkin.GAUSS_POINTS: BoxGaussPoints}
    out = {}
    for name, kind in kinds.items():
        users = [b for b, spec in enumerate(specs) if galerkin.integration_set(spec.formulation) == name]
        if not users:
            continue
        gens = [kind(_generators(specs[b].parts, "geometry.parts", dim)[0], config.thickness(scene))
                for b in users]
        block = _block(gens, dim, comm)  # its "measure" is the points' quadrature weight
        first = np.cumsum([0] + [g.count for g in gens])
        out[name] = {"gid": block["gid"], "X": block["X"], "volume": block["measure"],
                     "body": np.asarray(users, np.int64)[np.searchsorted(first, block["gid"], side="right") - 1]}
    return out


def build_bodies(scene: config.Scene, comm) -> tuple[dict, np.ndarray]:
    """This rank's owned particles of `scene` (arrays by global id: "gid", "X", "measure",
    "volume", "mass", "support", "groups" as uint8 columns by sorted group name), and the
    first global id of each body (with the total at the end): bodies are numbered one
    after the other. Collective; raises InputError on every rank for an empty or
    degenerate set."""
    dim = scene.scene.dimension
    specs = scene.bodies
    many = len(specs) > 1
    wheres = [f"bodies[{b}].parts" if many else "geometry.parts" for b in range(len(specs))]
    with collective(comm):
        gens = [_generators(body.parts, where, dim, comm) for body, where in zip(specs, wheres)]
        for body_gens, where in zip(gens, wheres):
            for i, g in enumerate(body_gens):
                if isinstance(g, geometry.Fill):
                    say(f"parsph: {where}[{i}]: {g.report()}")
        total = sum(g.count for body_gens in gens for g in body_gens)
        if total > geometry.MAX_PARTICLES:
            raise InputError(f"the bodies produce {total} particles in all, more than 2^31")
        neighbours = scene.kernel.neighbours
        if neighbours > 0 and neighbours + 2 > total:
            raise InputError(f"kernel.neighbours = {neighbours} needs at least {neighbours + 2} "
                             f"particles, the scene has {total}")
    blocks, offsets = [], [0]
    meshes = [g for body_gens in gens for g in body_gens if isinstance(g, MeshPart)]
    for body, where, body_gens in zip(specs, wheres, gens):
        owned = _body_particles(scene, body, where, body_gens, comm)
        _mesh_elements(owned, body_gens, meshes)
        owned["gid"] = owned["gid"] + offsets[-1]
        blocks.append(owned)
        offsets.append(offsets[-1] + comm.allreduce(len(owned["gid"])))
    owned = blocks[0] if not many else partition(
        {k: np.concatenate([b[k] for b in blocks]) for k in blocks[0]}, "X", comm)
    X, measure = owned["X"], owned["measure"]
    names = sorted(scene.groups)
    groups = np.zeros((len(X), len(names)), np.uint8)
    with collective(comm):
        for k, name in enumerate(names):
            spec = scene.groups[name]
            try:
                groups[:, k] = _mesh_set(spec, owned, meshes) if "mesh_set" in spec else \
                    geometry.select(spec, X, measure, owned["gid"], comm)
            except ValueError as exc:
                raise InputError(f"groups.{name}: {exc}") from None
    owned["groups"] = groups
    del owned["mesh"], owned["element"]
    used = {item.group for key in ("bc", "tractions", "walls", "tools", "surfaces", "initial", "probes")
            for item in getattr(scene, key)}
    counts = comm.allreduce(groups.sum(axis=0, dtype=np.int64))
    with collective(comm):
        for name in sorted(used):
            if not counts[names.index(name)]:
                raise InputError(f"group '{name}' selects no particles; check groups.{name}")
    return owned, np.array(offsets, np.int64)


def build_particles(scene: config.Scene, comm) -> dict:
    """This rank's owned particles of `scene` (build_bodies without the body offsets)."""
    return build_bodies(scene, comm)[0]


def build_local(scene: config.Scene, comm) -> LocalBody:
    """This rank's particles of `scene` with their ghost layers (and the other point sets,
    if any), ready for the simulation."""
    owned, offsets = build_bodies(scene, comm)
    local = localize(owned, build_integration_points(scene, comm), "X", comm)
    local.offsets = offsets
    return local
