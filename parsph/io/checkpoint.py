"""Checkpoints: the complete state of a run, written atomically, and restart from them.

A checkpoint `OUT/checkpoints/step_NNNNNNNN.h5` holds, in global-id order, the reference
configuration (positions, measures, volumes, masses, kernel supports, group membership),
the state (displacement, velocity; where a force reads the velocity, the velocity its last
evaluation saw) and, in the updated formulation, the current reference
(X^r, F^r, V^r); the checkpointed fields of any other point set (stress points) in a group
of that name, in its global-id order; the pairs cracks have cut (material.break_pairs); plus
the clock (time, step, dt, reference updates), the accumulated energies, the output
schedules and the resolved scene. It is written by all ranks together
under a temporary name, made durable (fsync) and renamed, so a checkpoint either exists
whole or not at all; the last K are kept.

Every byte after the file's 512-byte HDF5 user block is covered by a SHA-256 digest kept in
that user block (`file_digest`): the file is cut into fixed 4 MiB chunks, the ranks hash the
chunks in parallel, and the digest is the hash of the chunks' hashes, so it does not depend
on the rank count. A restart checks the digest before HDF5 reads a byte, so a damaged
checkpoint, in its data or in its HDF5 structure, is refused with a message (and skipped by
`--restart latest`) and never reaches the reader. Restarting needs the same physics: only
end time, step limit, wall-clock limit and output settings may differ from the checkpoint's
scene.
"""

from __future__ import annotations

import copy
import glob
import hashlib
import json
import os
import re

import h5py
import numpy as np

from parsph import config, readouts
from parsph.errors import InputError, ParsphError
from parsph.io.h5 import ParticleFile
from parsph.io.output_dir import ensure_space
from parsph.parallel.decomposition import block_cuts
from parsph.parallel.runtime import collective, say

FORMAT = 3
USERBLOCK = 512  # bytes before the HDF5 data: magic, digest, zero padding
MAGIC = b"parsph checkpoint sha256 "
CHUNK = 4 << 20  # bytes per hashed chunk
# keys that may change on restart: they do not change the physics of the steps taken
RESTART_FREE = ("time.end", "time.max_steps", "time.wall_limit", "output.", "balance.", "scene.description",
                "scene.expected", "scene.source")
ATTRIBUTES = ("format", "scene", "groups", "clock", "totals", "schedules", "particles", "fields")


def file_digest(path: str, comm) -> str:
    """Collective: SHA-256 (hex) of the file's size and of the SHA-256 of each 4 MiB chunk
    after the user block, the chunks shared out among the ranks. Raises the same
    ValueError on every rank if any rank cannot read its chunks."""
    mine, failure = {}, None
    try:
        size = os.path.getsize(path)
        count = -(-(size - USERBLOCK) // CHUNK) if size > USERBLOCK else 0
        with open(path, "rb") as fh:
            for k in range(comm.rank, count, comm.size):
                fh.seek(USERBLOCK + k * CHUNK)
                mine[k] = hashlib.sha256(fh.read(CHUNK)).digest()
    except OSError as exc:
        failure = f"cannot be read ({exc.strerror or exc})"
    parts = comm.allgather((failure, mine))
    failures = [f for f, _ in parts if f]
    if failures:
        raise ValueError(failures[0])
    chunks = {}
    for _, part in parts:
        chunks.update(part)
    whole = hashlib.sha256(size.to_bytes(8, "little"))
    for k in range(count):
        whole.update(chunks[k])
    return whole.hexdigest()


def _header(digest: str) -> bytes:
    return (MAGIC + digest.encode()).ljust(USERBLOCK, b"\0")


def _collective_check(comm, check) -> None:
    """Run `check()` on every rank; raise the first rank's ValueError (or OSError, as a
    ValueError) on all ranks."""
    failure = None
    try:
        check()
    except (ValueError, OSError) as exc:
        failure = str(exc) if isinstance(exc, ValueError) else f"cannot be read ({exc.strerror or exc})"
    failures = [m for m in comm.allgather(failure) if m]
    if failures:
        raise ValueError(failures[0])


def verify(path: str, comm) -> None:
    """Collective: raise ValueError (same message on every rank) unless `path` is a whole
    checkpoint: its user block holds the magic and the digest of the rest of the file."""
    stored = []

    def header():
        with open(path, "rb") as fh:
            block = fh.read(USERBLOCK)
        if len(block) < USERBLOCK or not block.startswith(MAGIC):
            raise ValueError("is not a parsph checkpoint (no checkpoint header; written by an older "
                             "parsph, or damaged)")
        if block != _header(block[len(MAGIC): len(MAGIC) + 64].decode("latin-1")):
            raise ValueError("is damaged (its header was changed)")
        stored.append(block[len(MAGIC): len(MAGIC) + 64].decode("latin-1"))

    _collective_check(comm, header)
    if file_digest(path, comm) != stored[0]:
        raise ValueError("is damaged or truncated (its SHA-256 digest does not match the content)")


def state_of(sim) -> dict:
    """Everything io.checkpoint stores (collective: totals): per-particle arrays of the
    owned particles (with the updated reference, if any); the accumulated totals over all
    ranks, exact (exact_sum.Exact.to_json), and the last step's obstacle forces."""
    return {
        "fields": sim.state.particles.checkpointed(), "group_names": sim.state.group_names,
        "sets": {p.name: (p.gid[: p.n_owned], p.total, p.checkpointed()) for p in sim.state.point_sets()[1:]},
        "totals": {**sim.ledger.checkpoint(sim.comm), "wall_force": readouts.wall_forces(sim).tolist(),
                   "surface_torque": readouts.surface_torques(sim).tolist(),
                   "rigid": [body.state() for body in sim.conditions.rigid_bodies], **sim.interactions.checkpoint()},
        "clock": {"t": sim.t, "step": sim.step_count, "dt": sim.dt, "step_dt": sim.step_dt,
                  **sim.topology.clock(), "first_stable": sim.stable.first,
                  "step_factors": [b.step_factor for b in sim.state.bodies], "measured_step": sim.stable.measured},
    }


def _estimate_bytes(fields: dict, scene_json: str, comm) -> int:
    local = sum(np.asarray(rows).nbytes for rows in fields.values())
    return comm.allreduce(local) + len(scene_json) + 64 * 1024 + USERBLOCK


def write_checkpoint(out_dir: str, sim, schedules: dict, scene_json: str, keep: int) -> str:
    """Collective: write the run's state, with the resolved scene `scene_json`
    (config.to_json); returns the checkpoint's path."""
    comm = sim.comm
    folder = os.path.join(out_dir, "checkpoints")
    name = f"step_{sim.step_count:08d}.h5"
    final = os.path.join(folder, name)
    tmp = os.path.join(folder, f".{name}.tmp")
    gid = sim.state.gid[:sim.state.n_owned]
    state = state_of(sim)
    fields = state["fields"]
    with collective():
        if comm.rank == 0:
            os.makedirs(folder, exist_ok=True)
    sets = state["sets"]
    size = _estimate_bytes(dict(fields, **{f"{name}/{k}": v for name, (_, _, f) in sets.items() for k, v in f.items()}),
                           scene_json, comm)
    ensure_space(out_dir, size, f"the checkpoint at step {sim.step_count}")
    try:
        with collective():
            with ParticleFile(tmp, "w", comm, userblock_size=USERBLOCK) as out:
                for field, rows in fields.items():
                    out.write_rows(field, gid, rows, sim.state.decomp.total)
                for name, (set_gid, set_total, set_fields) in sets.items():
                    for field, rows in set_fields.items():
                        out.write_rows(f"{name}/{field}", set_gid, rows, set_total)
                cut = sim.failure.cut
                if cut is not None:  # the pairs cracks have cut (failure.Failure.crack), the same on every rank
                    mine = cut if comm.rank == 0 else cut[:0]
                    out.write_rows("cut_pairs", np.arange(len(mine)), mine, len(cut))
                if out.writer:
                    attrs = out.file.attrs
                    attrs["format"] = FORMAT
                    attrs["scene"] = scene_json
                    attrs["groups"] = json.dumps(state["group_names"])
                    attrs["clock"] = json.dumps(state["clock"])
                    attrs["fields"] = json.dumps(list(fields))
                    attrs["totals"] = json.dumps(state["totals"])
                    attrs["schedules"] = json.dumps(schedules)
                    attrs["particles"] = sim.state.decomp.total
                    if sets:  # the other point sets: name -> (points, fields)
                        attrs["sets"] = json.dumps({name: [int(total), list(f)] for name, (_, total, f)
                                                    in sets.items()})
                    if len(sim.state.offsets) > 2:  # the first global id of each body
                        attrs["bodies"] = json.dumps(sim.state.offsets.tolist())
        try:
            digest = file_digest(tmp, comm)
        except ValueError as exc:
            raise ParsphError(f"the written file {exc}") from None
        with collective():
            if comm.rank == 0:
                with open(tmp, "r+b") as fh:
                    fh.write(_header(digest))
                    fh.flush()
                    os.fsync(fh.fileno())
                os.replace(tmp, final)
                _fsync_directory(folder)
    except ParsphError as exc:
        with collective():
            if comm.rank == 0 and os.path.exists(tmp):
                os.remove(tmp)
        raise ParsphError(f"writing checkpoint {final} failed: {exc}") from None
    with collective():
        if comm.rank == 0:
            older = sorted(glob.glob(os.path.join(folder, "step_*.h5")))[:-keep]
            for path in older:
                os.remove(path)
    return final


def _fsync_directory(folder: str) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _read_block(path: str, comm) -> dict:
    """This rank's contiguous block of a verified checkpoint's rows and the attributes;
    raises ValueError saying what is wrong."""
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"cannot be opened as HDF5 ({exc})") from None
    with f:
        try:
            attrs = {k: f.attrs[k] for k in ATTRIBUTES}
        except KeyError as exc:
            raise ValueError(f"is incomplete (attribute {exc} missing)") from None
        if attrs["format"] != FORMAT:
            raise ValueError(f"has format {attrs['format']}, this parsph reads format {FORMAT}")
        total = int(attrs["particles"])
        start, stop = block_cuts(total, comm.size)[comm.rank: comm.rank + 2]
        fields = {"gid": np.arange(start, stop, dtype=np.int64)}
        for field in json.loads(attrs["fields"]):
            if field not in f or len(f[field]) != total:
                raise ValueError(f"is incomplete (dataset '{field}' missing or short)")
            fields[field] = f[field][start:stop]
        attrs["bodies"] = f.attrs.get("bodies", "null")
        cut = f["cut_pairs"][:] if "cut_pairs" in f else None
        sets = {}
        for name, (count, names) in json.loads(f.attrs.get("sets", "{}")).items():
            start, stop = block_cuts(count, comm.size)[comm.rank: comm.rank + 2]
            sets[name] = {"gid": np.arange(start, stop, dtype=np.int64)}
            for field in names:
                key = f"{name}/{field}"
                if key not in f or len(f[key]) != count:
                    raise ValueError(f"is incomplete (dataset '{key}' missing or short)")
                sets[name][field] = f[key][start:stop]
    return {"attrs": attrs, "fields": fields, "sets": sets, "cut": cut}


def read(path: str, comm) -> dict:
    """Collective: verify checkpoint `path` (digest), then each rank reads a contiguous
    block of its rows; returns the block ("fields", with "gid") and the run's scene,
    groups, clock, totals and schedules. Raises the same ValueError on every rank if the
    file is not whole."""
    verify(path, comm)
    block = []

    def read_block():
        try:
            block.append(_read_block(path, comm))
        except ValueError:
            raise
        except Exception as exc:  # noqa: BLE001 - a verified file should not fail; say how it did
            raise ValueError(f"cannot be read ({type(exc).__name__}: {exc})") from None

    _collective_check(comm, read_block)
    attrs = block[0]["attrs"]
    data = {"path": path, "fields": block[0]["fields"], "sets": block[0]["sets"], "scene": json.loads(attrs["scene"]),
            "group_names": json.loads(attrs["groups"]), "offsets": json.loads(attrs["bodies"]),
            "cut": block[0]["cut"]}
    for key in ("clock", "totals", "schedules"):
        data[key] = json.loads(attrs[key])
    return data


def load(spec: str, out_dir: str, comm) -> dict:
    """Collective: the checkpoint to restart from, verified and read in blocks (`read`):
    `latest` is the newest valid one in OUT/checkpoints (invalid ones are skipped with a
    message), else the named file, which is refused if invalid."""
    candidates = None
    with collective(comm):
        if comm.rank == 0:
            if spec == "latest":
                candidates = sorted(glob.glob(os.path.join(out_dir, "checkpoints", "step_*.h5")),
                                    key=lambda p: int(re.findall(r"\d+", os.path.basename(p))[0]))[::-1]
                if not candidates:
                    raise InputError(f"--restart latest: no checkpoints in {out_dir}/checkpoints")
            elif not os.path.isfile(spec):
                raise InputError(f"--restart: checkpoint not found: {spec}")
            else:
                candidates = [spec]
    for path in comm.bcast(candidates, root=0):
        try:
            return read(path, comm)
        except ValueError as exc:
            with collective(comm):
                if spec != "latest":
                    raise InputError(f"--restart: checkpoint {spec} {exc}")
            say(f"parsph: skipping checkpoint {path}: it {exc}")
    with collective(comm):
        raise InputError(f"--restart latest: no valid checkpoint in {out_dir}/checkpoints")


def differing_keys(old: dict, new: dict, prefix: str = "") -> list:
    """Keys whose values differ between two resolved scenes, as --set names them
    (`bodies.1.material.density`): arrays of tables of the same length compared entry by
    entry, other lists whole; a key absent from one and empty or None in the other does not
    differ."""
    keys = []
    for k in sorted(set(old) | set(new)):
        path = f"{prefix}{k}"
        a, b = old.get(k), new.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            keys += differing_keys(a, b, path + ".")
        elif _tables(a) and _tables(b) and len(a) == len(b):
            for i, (x, y) in enumerate(zip(a, b)):
                keys += differing_keys(x, y, f"{path}.{i}.")
        elif a != b and (a or b):  # an absent list and an empty one are the same
            keys.append(path)
    return keys


def _tables(value) -> bool:
    """Whether `value` is an array of tables ([[bodies]], [[contact]], ...)."""
    return isinstance(value, list) and bool(value) and all(isinstance(x, dict) for x in value)


def physics_changes(old_scene: dict, scene: dict) -> list:
    """The keys in which two resolved scenes differ beyond what a restart may change
    (RESTART_FREE): an empty list if one run can continue the other."""
    return [k for k in differing_keys(old_scene, scene)
            if not any(k == free or (free.endswith(".") and k.startswith(free)) for free in RESTART_FREE)]


def check_compatible(old_scene: dict, scene: config.Scene, path: str) -> None:
    """Refuse a restart whose scene changes the physics of the checkpointed run (`old_scene`
    as stored)."""
    old_scene = copy.deepcopy(old_scene)
    config.upgrade(old_scene)  # as a scene of today states it
    changed = physics_changes(old_scene, scene.as_dict())
    if changed:
        raise InputError(f"the scene differs from checkpoint {path} in {', '.join(changed)}; "
                         "only time.end, time.max_steps, time.wall_limit, output and balance settings may change "
                         "on restart")
