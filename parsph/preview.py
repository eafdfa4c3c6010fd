"""`parsph preview`: what a scene will run, before any step: its particles as `parsph run`
builds them, its obstacles' surfaces, a picture and a summary.

Every rank builds its block of the particles (build.build_bodies, as `parsph run` does: no
rank holds every particle), and the ranks write them together, in global-id order, into
`particles.h5`: a snapshot file of one snapshot at t = 0 (io.snapshots; `parsph plot` and
`read_snapshots` read it) that `particles.xdmf` indexes for ParaView as a point cloud. Its
fields: position, body (the index; the names in the file's attribute "bodies"), one 0/1
field group_NAME per group, volume, mass, support (the kernel support radius), gid and
rank (the owner). The obstacles' surfaces at t = 0 go to `obstacles.xdmf` and
`obstacles.h5` (a triangle mesh, through meshio, with the obstacle's index per triangle):
an obstacle object's own triangles(t) if it has that method, else a wall's plane within
its lower..upper box or the particles' bounding box, and a tool's box with its rounded
edges approximated. `particles.png` shows the particles coloured by body (io.plots: in
3D the x-z projection; in 1D their volumes along x).
"""

from __future__ import annotations

import importlib.util
import os

import numpy as np

from parsph import config
from parsph.errors import InputError
from parsph.exact_sum import allsum, totals
from parsph.io import output_dir
from parsph.io.h5 import ParticleFile
from parsph.io.snapshots import point_grid, write_points
from parsph.parallel.runtime import COMM, collective, say, warn

FILES = ("particles.h5", "particles.xdmf", "particles.png", "obstacles.xdmf", "obstacles.h5")
GROUP = "step_00000000"  # the one snapshot: before step 1, at t = 0
XDMF_TYPES = {"f": "Float", "i": "Int", "u": "UInt"}


def preview(scene_path: str, out_dir: str | None, overrides: list, overwrite: bool) -> int:
    """Write the preview of a scene into `out_dir` (default results/NAME/preview) and print
    its summary; returns the exit code. Collective."""
    from parsph.build import build_bodies

    with collective():
        scene = config.load(scene_path, overrides)
    out_dir = out_dir or os.path.join("results", scene.scene.name, "preview")
    output_dir.lock(out_dir)
    previous = _previous(out_dir, overwrite)
    owned, offsets = build_bodies(scene, COMM)
    values = _fields(scene, owned, offsets)
    total = int(offsets[-1])
    row = sum(v.dtype.itemsize * int(np.prod(v.shape[1:])) for v in values.values()) + 16  # + gid, connectivity
    output_dir.ensure_space(out_dir, total * row + (1 << 20), "the preview")
    with collective():
        if COMM.rank == 0:
            for path in previous:  # the scene is built: only now is the previous preview replaced
                os.remove(path)
    _write_particles(out_dir, scene, owned["gid"], total, values)
    surfaces = obstacle_surfaces(scene, owned["X"])
    with collective():
        if COMM.rank == 0 and any(len(triangles) for _, triangles in surfaces):
            _write_obstacles(os.path.join(out_dir, "obstacles.xdmf"), surfaces)
    picture = _plot(out_dir, scene)
    _summary(scene, out_dir, owned, offsets, values, surfaces, picture)
    return 0


def _previous(out_dir: str, overwrite: bool) -> list:
    """Collective, changes nothing: the files of a previous preview in `out_dir` (replaced
    only with --overwrite)."""
    present = []
    with collective():
        if COMM.rank == 0:
            present = [os.path.join(out_dir, f) for f in FILES if os.path.exists(os.path.join(out_dir, f))]
            if present and not overwrite:
                raise InputError(f"output directory {out_dir} already holds a preview "
                                 f"({', '.join(os.path.basename(p) for p in present)}); choose another --out, "
                                 "or pass --overwrite to replace it")
    return present


def _group_field(name: str) -> str:
    return "group_" + name.replace("/", "_")  # a dataset's name: no "/"


def _fields(scene: config.Scene, owned: dict, offsets: np.ndarray) -> dict:
    """This rank's rows of the preview's fields (positions padded to 3D)."""
    X = owned["X"]
    values = {"position": np.pad(X, ((0, 0), (0, 3 - X.shape[1]))),
              "body": (np.searchsorted(offsets, owned["gid"], side="right") - 1).astype(np.int32),
              "volume": owned["volume"], "mass": owned["mass"], "support": owned["support"],
              "rank": np.full(len(X), COMM.rank, np.int32)}
    for k, name in enumerate(sorted(scene.groups)):
        if name != "all":
            values[_group_field(name)] = np.ascontiguousarray(owned["groups"][:, k])
    return values


def _write_particles(out_dir: str, scene: config.Scene, gid: np.ndarray, total: int, values: dict) -> None:
    """Collective: particles.h5 (a snapshot file of one snapshot) and its index particles.xdmf."""
    path = os.path.join(out_dir, "particles.h5")
    with collective():
        with ParticleFile(path, "w", COMM) as out:
            if out.writer:
                out.file.attrs["scene"] = config.to_json(scene)
                out.file.attrs["bodies"] = [body.name for body in scene.bodies]
            write_points(out, GROUP, gid, total, values, 0.0, 0, True)
    with collective():
        if COMM.rank == 0:
            fields = {name: (v.shape[1:], (XDMF_TYPES[v.dtype.kind], v.dtype.itemsize)) for name, v in values.items()}
            fields["gid"] = ((), ("Int", 8))
            with open(os.path.join(out_dir, "particles.xdmf"), "w") as fh:
                fh.write('<?xml version="1.0" ?>\n<Xdmf Version="3.0">\n<Domain>\n'
                         + point_grid("particles.h5", GROUP, total, fields) + "</Domain>\n</Xdmf>\n")


def obstacle_surfaces(scene: config.Scene, X: np.ndarray, t: float = 0.0) -> list:
    """[(name, triangles (m, 3, 3))] of the scene's obstacles at time t on rank 0 ([] on
    the others, and in 1D). An obstacle object that has a method triangles(t),
    returning its surface's triangles (m, 3, dimension) at time t, gives its own; a wall
    is its plane within its lower..upper box, or within the bounding box of all ranks'
    particles `X` (and the point of the plane nearest their centre) grown by a tenth of its
    diagonal; a tool is its box with rounded edges. Collective."""
    from parsph.walls import Tool, Wall, Walls

    dim = scene.scene.dimension
    obstacles = Walls(scene.walls, scene.tools, dim, scene.surfaces, scene.parameters)
    boxes = [box for box in COMM.allgather((X.min(axis=0), X.max(axis=0)) if len(X) else None) if box]
    lower, upper = np.min([lo for lo, _ in boxes], axis=0), np.max([hi for _, hi in boxes], axis=0)
    if COMM.rank != 0 or dim == 1:
        return []
    out = []
    for name, item in zip(obstacles.names, obstacles.items):
        if hasattr(item, "triangles"):
            triangles = np.asarray(item.triangles(t), float)
        elif isinstance(item, Wall):
            point = item.point + item.velocity * t
            box = (item.lower, item.upper)
            if item.lower is None:
                foot = 0.5 * (lower + upper) - ((0.5 * (lower + upper) - point) @ item.normal) * item.normal
                lo, hi = np.minimum(lower, foot), np.maximum(upper, foot)
                margin = 0.1 * max(float(np.linalg.norm(hi - lo)), 1e-12)
                box = (lo - margin, hi + margin)
            triangles = plane_patch(point, item.normal, *box)
        elif isinstance(item, Tool):
            triangles = rounded_box(item.center + item.velocity * t, item.core + item.radius, item.radius)
        else:
            warn(f"obstacle {name} ({type(item).__name__}) has no triangles(t): the preview leaves it out")
            continue
        out.append((name, np.pad(triangles, ((0, 0), (0, 0), (0, 3 - triangles.shape[2])))))
    return out


def plane_patch(point: np.ndarray, normal: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Triangles (m, 3, d) of the plane through `point` with unit `normal` within the box
    lower..upper (none if it misses the box): in 3D the polygon it cuts from the box, in
    2D the segment it cuts, drawn as a strip a twentieth of its length wide on the side
    away from the material."""
    dim = len(point)
    corners = np.array(np.meshgrid(*zip(lower, upper), indexing="ij")).reshape(dim, -1).T
    side = (corners - point) @ normal
    cut = [corners[i] + (corners[j] - corners[i]) * side[i] / (side[i] - side[j])
           for i in range(len(corners)) for j in range(i + 1, len(corners))
           if np.count_nonzero(corners[i] != corners[j]) == 1 and side[i] * side[j] < 0]
    cut += [c for c, s in zip(corners, side) if s == 0]
    if len(cut) < dim:
        return np.zeros((0, 3, dim))
    cut = np.unique(np.array(cut), axis=0)
    if dim == 2:
        a, b = cut[0], cut[-1]
        back = -0.05 * np.linalg.norm(b - a) * normal
        return np.array([[a, b, b + back], [a, b + back, a + back]])
    u = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    w = np.cross(normal, u)
    centre = cut.mean(axis=0)
    ring = cut[np.argsort(np.arctan2((cut - centre) @ w, (cut - centre) @ u))]
    return np.array([[centre, ring[k], ring[(k + 1) % len(ring)]] for k in range(len(ring))])


def rounded_box(center: np.ndarray, half: np.ndarray, radius: float) -> np.ndarray:
    """Triangles (m, 3, d) of the box center +- half with edges rounded by `radius`: the
    points of a sphere (3D; a circle in 2D, whose fan from the centre fills the shape)
    of that radius, each moved out to the corner of the shrunk box on its side. In 3D a
    triangle across the sphere's octants lies on a face or an edge of the box."""
    dim = len(center)
    core = half - radius
    if dim == 2:
        angle = np.linspace(0.0, 2.0 * np.pi, 65)[:-1]
        ring = np.stack([np.cos(angle), np.sin(angle)], axis=1)
        outline = center + np.sign(ring) * core + radius * ring
        triangles = np.array([[center, outline[k], outline[(k + 1) % len(outline)]] for k in range(len(outline))])
    else:
        import trimesh

        sphere = trimesh.creation.icosphere(subdivisions=2)
        points = center + np.sign(sphere.vertices) * core + radius * sphere.vertices
        triangles = points[sphere.faces]
    edges = np.pad(triangles[:, 1:] - triangles[:, :1], ((0, 0), (0, 0), (0, 3 - dim)))
    area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    return triangles[area > 1e-12 * float(np.max(half)) ** 2]  # not the sphere's points moved to one corner


def _write_obstacles(path: str, surfaces: list) -> None:
    """The obstacles' triangles as one triangle mesh (meshio's XDMF, with its .h5), the
    obstacle's index per triangle in the cell field "obstacle"."""
    import meshio

    points = np.concatenate([tri.reshape(-1, 3) for _, tri in surfaces])
    index = np.concatenate([np.full(len(tri), k, np.int32) for k, (_, tri) in enumerate(surfaces)])
    cells = np.arange(len(points)).reshape(-1, 3)
    meshio.write(path, meshio.Mesh(points, [("triangle", cells)], cell_data={"obstacle": [index]}))


def _plot(out_dir: str, scene: config.Scene) -> str | None:
    """particles.png: the particles coloured by body (in 1D their volumes along x; rank 0;
    None without matplotlib)."""
    from parsph.io.plots import plot_snapshots

    if importlib.util.find_spec("matplotlib") is None:
        warn("no particles.png: plotting needs matplotlib (pip install matplotlib)")
        return None
    with collective():
        if COMM.rank == 0:
            bodies = len(scene.bodies)
            field, limits = ("volume", None) if scene.scene.dimension == 1 else ("body", (0, max(bodies - 1, 1)))
            plot_snapshots(os.path.join(out_dir, "particles.h5"), field, 1, os.path.join(out_dir, "particles.png"),
                           limits)
    return os.path.join(out_dir, "particles.png")


def _summary(scene: config.Scene, out_dir: str, owned: dict, offsets: np.ndarray, values: dict, surfaces: list,
             picture: str | None) -> None:
    """Per body its particles, volume and mass, per group its particles, the obstacles and
    the files (rank 0 prints; exact sums: the same on any rank count)."""
    names = [body.name for body in scene.bodies]
    body = values["body"]
    counts = COMM.allreduce(np.bincount(body, minlength=len(names)))
    sums = allsum(COMM, totals([values[k][body == b] for b in range(len(names)) for k in ("volume", "mass")]))
    groups = [name for name in sorted(scene.groups) if name != "all"]
    members = COMM.allreduce(np.array([int(values[_group_field(g)].sum()) for g in groups], np.int64))
    say(f"parsph: preview of scene '{scene.scene.name}': {_particles(offsets[-1])}, "
        f"{scene.scene.dimension}D, {COMM.size} rank(s), in {out_dir}")
    for b, name in enumerate(names):
        say(f"  body {b} '{name}': {_particles(counts[b])}, volume {float(sums[2 * b]):.6g} m^3, "
            f"mass {float(sums[2 * b + 1]):.6g} kg")
    for g, count in zip(groups, members):
        say(f"  group '{g}': {_particles(count)}")
    if surfaces:
        say("  obstacles: " + ", ".join(f"{name} ({len(tri)} triangles)" for name, tri in surfaces))
    meshed = any(len(triangles) for _, triangles in surfaces)
    files = ["particles.h5", "particles.xdmf (ParaView)"] + (["obstacles.xdmf", "obstacles.h5"] if meshed else []) \
        + (["particles.png"] if picture else [])
    say(f"  files: {', '.join(files)}")


def _particles(n: int) -> str:
    return f"{int(n)} particle{'s' * (int(n) != 1)}"
