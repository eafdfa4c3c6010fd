"""The output directory of a run: claimed by one run at a time, replaced only on request,
and never filled past the free space of its disk.

A run holds an exclusive lock (`flock`) on `OUT/.parsph.lock` from set-up to exit, so a
second run into the same directory is refused before it changes anything; the kernel drops
the lock when the process ends, however it ends, so a killed run leaves nothing stuck.
"""

from __future__ import annotations

import errno
import fcntl
import glob
import json
import os
import shutil
import socket

import h5py

from parsph.errors import InputError, ParsphError
from parsph.parallel.runtime import COMM, collective, say

RUN_FILES = ("history.h5", "snapshots.h5", "snapshots.xdmf", "scene.json")
LOCK_NAME = ".parsph.lock"
SPACE_MARGIN = 64 * 1024  # bytes left free beyond an estimate (HDF5 metadata, other writers)

_lock_fd = None  # kept open for the life of the process: closing it would drop the lock


def _checkpoint_files(out_dir: str) -> list:
    folder = os.path.join(out_dir, "checkpoints")
    return sorted(glob.glob(os.path.join(folder, "step_*.h5")) + glob.glob(os.path.join(folder, ".step_*.tmp")))


def lock(out_dir: str) -> None:
    """Collective: create `out_dir` if needed and take its lock (rank 0), or refuse with a
    message naming the run that holds it."""
    global _lock_fd
    with collective():
        if COMM.rank == 0:
            if os.path.islink(out_dir) and not os.path.exists(out_dir):
                raise InputError(f"output directory {out_dir} is a dangling symbolic link "
                                 f"(to {os.readlink(out_dir)})")
            if os.path.exists(out_dir) and not os.path.isdir(out_dir):
                raise InputError(f"output path {out_dir} exists and is not a directory")
            try:
                os.makedirs(out_dir, exist_ok=True)
                fd = os.open(os.path.join(out_dir, LOCK_NAME), os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise InputError(f"cannot use output directory {out_dir}: {exc.strerror or exc}") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "unknown"
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    raise InputError(f"output directory {out_dir} is in use by another run ({holder}); "
                                     "wait for it to end or choose another --out") from None
                raise InputError(f"cannot lock output directory {out_dir}: {exc.strerror or exc}") from None
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}\n".encode(), 0)
                probe = os.path.join(out_dir, f".parsph.write-test.{os.getpid()}")
                with open(probe, "wb") as fh:
                    fh.write(b"x")
                os.remove(probe)
            except OSError as exc:
                os.close(fd)
                raise InputError(f"cannot write to output directory {out_dir}: {exc.strerror or exc}") from None
            _lock_fd = fd


def run_files(out_dir: str) -> list:
    """The files of a run in `out_dir`: history, snapshots, scene and checkpoints."""
    present = [os.path.join(out_dir, f) for f in RUN_FILES if os.path.exists(os.path.join(out_dir, f))]
    return present + _checkpoint_files(out_dir)


def held_scene(out_dir: str) -> dict | None:
    """The resolved scene of the run `out_dir` holds (its scene.json, else the attribute of
    its history), None if it holds no history, snapshots or scene; InputError if neither
    can be read."""
    for name in ("scene.json", "history.h5", "snapshots.h5"):
        path = os.path.join(out_dir, name)
        if not os.path.exists(path):
            continue
        try:
            if name == "scene.json":
                with open(path) as fh:
                    return json.load(fh)
            with h5py.File(path, "r") as f:
                return json.loads(f.attrs["scene"])
        except Exception as exc:  # noqa: BLE001 - any damage: name the file
            raise InputError(f"cannot tell which run {out_dir} holds: {path} cannot be read "
                             f"({type(exc).__name__}: {exc}); restart into another --out, or pass "
                             "--overwrite to replace that run") from None
    return None


def check_output(out_dir: str, overwrite: bool) -> list:
    """Collective, changes nothing: the previous run's files in `out_dir` (to be replaced by
    a new run: only with --overwrite)."""
    present = []
    with collective():
        if COMM.rank == 0:
            present = run_files(out_dir)
            if present and not overwrite:
                shown = sorted({os.path.relpath(p, out_dir).split(os.sep)[0] for p in present})
                raise InputError(
                    f"output directory {out_dir} already holds a run ({', '.join(shown)}); "
                    "choose another --out, pass --overwrite to replace it, or --restart latest to continue it")
    return present


def claim_output(out_dir: str, present: list) -> None:
    """Collective: remove the previous run's files (--overwrite), checkpoints included, once
    the new run has been set up without error."""
    with collective():
        if COMM.rank == 0:
            for path in present:
                os.remove(path)
            if present:
                say(f"replacing the previous run in {out_dir} (--overwrite)")


def check_space(out_dir: str, nbytes: int, what: str, margin: int = SPACE_MARGIN) -> None:
    """Raise OutputFull if the disk of `out_dir` has less than `nbytes` plus `margin` free,
    so that `what` is not written half-way (on the rank that writes)."""
    free = shutil.disk_usage(out_dir).free
    if free < nbytes + margin:
        raise OutputFull(f"the disk holding {out_dir} is full: {what} needs about "
                         f"{_size(nbytes + margin)}, {_size(free)} free")


def ensure_space(out_dir: str, nbytes: int, what: str) -> None:
    """Collective: check_space on rank 0, the same OutputFull raised on every rank."""
    with collective():
        if COMM.rank == 0:
            check_space(out_dir, nbytes, what)


class OutputFull(ParsphError):
    """Not enough free space for the next output; what was written before is intact."""


def _size(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1000.0
    return f"{n:.3g} TB"
