"""Checkpoints: the complete state of a run, written atomically, and restart from them.

A checkpoint `OUT/checkpoints/step_NNNNNNNN.h5` holds, in global-id order, the reference
configuration (positions, measures, volumes, masses, kernel supports, group membership),
the state (displacement, velocity) and, in the updated formulation, the current reference
(X^r, F^r, V^r), plus the clock (time, step, dt, reference updates), the accumulated
energies, the output schedules, and the resolved scene with its hash. It is written by all
ranks together under a temporary name, closed, and renamed, so a checkpoint either exists
whole or not at all; the last K are kept. Every dataset carries an order-independent
checksum; a file that does not open, lacks a dataset or fails a checksum is refused. On
restart every rank reads (and checksums) only a contiguous block of the rows.
Restarting needs the same physics: only end time, step limit, wall-clock limit and output
settings may differ from the checkpoint's scene.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import re

import h5py
import numpy as np

from parsph import config
from parsph.errors import InputError
from parsph.io.h5 import ParticleFile
from parsph.parallel.decomposition import block_cuts
from parsph.parallel.runtime import collective, say

FORMAT = 2
# keys that may change on restart: they do not change the physics of the steps taken
RESTART_FREE = ("time.end", "time.max_steps", "time.wall_limit", "output.", "scene.description",
                "scene.expected", "scene.source")


def scene_hash(scene: dict) -> str:
    return hashlib.sha256(config.to_json(scene).encode()).hexdigest()


def checksum(gid: np.ndarray, rows: np.ndarray) -> int:
    """Order-independent checksum: sum over elements of bits x (position + 1), mod 2^64."""
    bits = np.ascontiguousarray(rows).view(np.uint8).reshape(len(rows), -1)
    words = np.zeros((len(rows), -(-bits.shape[1] // 8) * 8), np.uint8)
    words[:, : bits.shape[1]] = bits
    words = words.view(np.uint64)
    weight = (np.asarray(gid, np.uint64)[:, None] * np.uint64(words.shape[1])
              + np.arange(1, words.shape[1] + 1, dtype=np.uint64))
    with np.errstate(over="ignore"):
        return int(np.sum(words * weight, dtype=np.uint64))


def _sum_mod64(comm, value: int) -> int:
    return sum(comm.allgather(value)) % (1 << 64)


def write_checkpoint(out_dir: str, sim, schedules: dict, scene: dict, keep: int) -> str:
    """Collective: write the run's state; returns the checkpoint's path."""
    comm = sim.comm
    folder = os.path.join(out_dir, "checkpoints")
    with collective():
        if comm.rank == 0:
            os.makedirs(folder, exist_ok=True)
    name = f"step_{sim.step_count:08d}.h5"
    final = os.path.join(folder, name)
    tmp = os.path.join(folder, f".{name}.tmp")
    n = sim.n_owned
    gid = sim.gid[:n]
    state = sim.checkpoint_state()
    sums = {}
    fields = state["fields"]
    with collective():
        with ParticleFile(tmp, "w", comm) as out:
            for field, rows in fields.items():
                out.write_rows(field, gid, rows, sim.decomp.total)
                sums[field] = _sum_mod64(comm, checksum(gid, rows))
            if out.writer:
                attrs = out.file.attrs
                attrs["format"] = FORMAT
                attrs["scene"] = config.to_json(scene)
                attrs["scene_hash"] = scene_hash(scene)
                attrs["groups"] = json.dumps(state["group_names"])
                attrs["clock"] = json.dumps(state["clock"])
                attrs["fields"] = json.dumps(list(fields))
                attrs["totals"] = json.dumps(state["totals"])
                attrs["schedules"] = json.dumps(schedules)
                attrs["checksums"] = json.dumps({k: str(v) for k, v in sums.items()})
                attrs["particles"] = sim.decomp.total
    with collective():
        if comm.rank == 0:
            os.replace(tmp, final)
            older = sorted(glob.glob(os.path.join(folder, "step_*.h5")))[:-keep]
            for path in older:
                os.remove(path)
    return final


def _read_block(path: str, comm) -> dict:
    """This rank's contiguous block of a checkpoint's rows with their partial checksums, and
    the attributes; raises ValueError saying what is wrong."""
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"cannot be opened as HDF5 ({exc})") from None
    with f:
        try:
            attrs = {k: f.attrs[k] for k in ("format", "scene", "scene_hash", "groups", "clock",
                                              "totals", "schedules", "checksums", "particles", "fields")}
        except KeyError as exc:
            raise ValueError(f"is incomplete (attribute {exc} missing)") from None
        if attrs["format"] != FORMAT:
            raise ValueError(f"has format {attrs['format']}, this parsph reads format {FORMAT}")
        if scene_hash(json.loads(attrs["scene"])) != attrs["scene_hash"]:
            raise ValueError("is corrupted (scene hash does not match)")
        total = int(attrs["particles"])
        start, stop = block_cuts(total, comm.size)[comm.rank: comm.rank + 2]
        gid = np.arange(start, stop, dtype=np.int64)
        names = json.loads(attrs["fields"])
        expected = json.loads(attrs["checksums"])
        fields, sums = {"gid": gid}, {}
        for field in names:
            if field not in f or len(f[field]) != total or field not in expected:
                raise ValueError(f"is incomplete (dataset '{field}' missing or short)")
            try:
                fields[field] = f[field][start:stop]
            except OSError as exc:
                raise ValueError(f"dataset '{field}' cannot be read ({exc})") from None
            sums[field] = checksum(gid, fields[field])
    return {"attrs": attrs, "fields": fields, "sums": sums}


def read(path: str, comm) -> dict:
    """Collective: check checkpoint `path`, each rank reading a contiguous block of its rows;
    returns the block ("fields", with "gid") and the run's scene, groups, clock, totals and
    schedules. Raises the same ValueError on every rank if the file is not whole."""
    block, failure = None, None
    try:
        block = _read_block(path, comm)
    except ValueError as exc:
        failure = str(exc)
    failures = [m for m in comm.allgather(failure) if m]
    if failures:
        raise ValueError(failures[0])
    attrs = block["attrs"]
    expected = json.loads(attrs["checksums"])
    for field, part in block["sums"].items():
        if str(_sum_mod64(comm, part)) != expected[field]:
            raise ValueError(f"is corrupted (checksum of '{field}' does not match)")
    data = {"path": path, "fields": block["fields"], "scene": json.loads(attrs["scene"]),
            "group_names": json.loads(attrs["groups"])}
    for key in ("clock", "totals", "schedules"):
        data[key] = json.loads(attrs[key])
    return data


def load(spec: str, out_dir: str, comm) -> dict:
    """Collective: the checkpoint to restart from, read in blocks (`read`): `latest` is the
    newest valid one in OUT/checkpoints (invalid ones are skipped with a message), else
    the named file, which is refused if invalid."""
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
    """Keys whose values differ between two resolved scenes (lists compared whole)."""
    keys = []
    for k in sorted(set(old) | set(new)):
        path = f"{prefix}{k}"
        a, b = old.get(k), new.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            keys += differing_keys(a, b, path + ".")
        elif a != b:
            keys.append(path)
    return keys


def check_compatible(old_scene: dict, scene: dict, path: str) -> None:
    """Refuse a restart whose scene changes the physics of the checkpointed run."""
    changed = [k for k in differing_keys(old_scene, scene)
               if not any(k == free or (free.endswith(".") and k.startswith(free)) for free in RESTART_FREE)]
    if changed:
        raise InputError(f"the scene differs from checkpoint {path} in {', '.join(changed)}; "
                         "only time.end, time.max_steps, time.wall_limit and output settings may change "
                         "on restart")
