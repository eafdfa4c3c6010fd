"""A finished (or running) run's output read back as arrays: the public way for scripts,
notebooks, tools and tests to get at `history.h5` and `snapshots.h5` without knowing their
layout. A file that is not the kind asked for, or that cannot be read, is an InputError
naming it.

    from parsph.io import read_history, read_snapshots
    h = read_history("results/taylor_impact")        # {"time": array, "kinetic_energy": array, ...}
    last = read_snapshots("results/taylor_impact")[-1]
    last.time, last["position"], last["von_mises"]    # rows in global-id order
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass

import h5py
import numpy as np

from parsph.errors import InputError


@dataclass(frozen=True)
class Snapshot:
    """The particle fields of one snapshot, rows in global-id order."""

    step: int
    time: float
    fields: dict

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.fields[name]
        except KeyError:
            raise KeyError(f"no field '{name}' in the snapshot of step {self.step}; it has: "
                           f"{', '.join(sorted(self.fields))}") from None


def _file(out: str | os.PathLike, name: str | None) -> str:
    """`out` itself if it is a file, else the file `name` of the run directory `out`."""
    path = os.fspath(out)
    if name is None and os.path.isdir(path):
        raise InputError(f"{path} is a directory: give a run's history.h5 or snapshots.h5")
    path = path if os.path.isfile(path) or name is None else os.path.join(path, name)
    if not os.path.isfile(path):
        raise InputError(f"{path} does not exist" + (f": give a run's output directory or its {name}" if name else ""))
    return path


@contextlib.contextmanager
def _open(out: str | os.PathLike, name: str | None):
    """The run's file `name` (history.h5 or snapshots.h5; `out`: it or the run's directory;
    None: the file `out`, of either kind) open for reading, checked to be of that kind; any
    failure to read it is an InputError naming it."""
    path = _file(out, name)
    try:
        with h5py.File(path, "r") as f:
            _check_kind(f, path, name)
            yield f
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - h5py raises several types for a damaged file
        raise InputError(f"{path} cannot be read: it is not an HDF5 file, or it is damaged or truncated "
                         f"({type(exc).__name__}: {exc})") from None


def _check_kind(f, path: str, name: str) -> None:
    """InputError unless the open file `f` is a history (1-D series at its root) or a
    snapshots file (step_* groups and their connectivity), as `name` asks (None: either)."""
    groups = sorted(k for k in f if isinstance(f[k], h5py.Group))
    series = sorted(k for k in f if k not in groups and k != "connectivity")
    if name == "history.h5" and (groups or "connectivity" in f):
        raise InputError(f"{path} is not a run's history: it holds snapshots ({', '.join(groups[:3]) or 'connectivity'}"
                         f"{', ...' if len(groups) > 3 else ''}); read it with read_snapshots, or give history.h5")
    if name == "snapshots.h5" and series:
        raise InputError(f"{path} is not a run's snapshots: it holds the series {', '.join(series[:3])}"
                         f"{', ...' if len(series) > 3 else ''}; read it with read_history, or give snapshots.h5")


def file_kind(path: str | os.PathLike) -> str:
    """What the run's file `path` holds: "history" or "snapshots" (InputError if neither,
    or nothing yet)."""
    with _open(path, None) as f:
        if not len(f):
            raise InputError(f"{path} holds no history rows or snapshots yet")
        return "snapshots" if "connectivity" in f or any(isinstance(f[k], h5py.Group) for k in f) else "history"


def read_history(out: str | os.PathLike) -> dict:
    """Every series of the run's history (`out`: its output directory or history.h5), one
    array per name, one entry per history row."""
    with _open(out, "history.h5") as f:
        data = {name: np.asarray(f[name]) for name in f}
        shapes = [values.shape for values in data.values()]
        common = max(set(shapes), key=shapes.count, default=(0,))
        odd = [f"{name} {values.shape}" for name, values in data.items() if values.shape != common]
        if odd or len(common) != 1:
            raise InputError(f"{f.filename} is damaged: its series are not one entry per history row each (most "
                             f"have shape {common}; {', '.join(odd[:4]) or 'none is 1-D'})")
        return data


def snapshot_steps(out: str | os.PathLike) -> list:
    """[(step, time)] of the run's snapshots in order (`out`: its directory or snapshots.h5)."""
    with _open(out, "snapshots.h5") as f:
        return sorted((int(f[g].attrs["step"]), float(f[g].attrs["time"])) for g in f if g.startswith("step_"))


def _pick(groups: list, which) -> list:
    """The snapshot groups `which` picks by position (an index, a slice or a list of
    indices); InputError naming an index out of range."""
    if isinstance(which, slice):
        return groups[which]
    many = not isinstance(which, (int, np.integer))
    indices = list(which) if many and isinstance(which, (list, tuple, range, np.ndarray)) else [which]
    for k in indices:
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
            raise InputError(f"which = {which!r}: give an index, a slice or a list of indices (integers)")
        if not -len(groups) <= k < len(groups):
            raise InputError(f"which = {which!r}: the run has {len(groups)} snapshot(s), so an index must be in "
                             f"[{-len(groups)}, {len(groups) - 1}]" if groups else
                             f"which = {which!r}: the run has no snapshot")
    return [groups[k] for k in indices]


def read_snapshots(out: str | os.PathLike, fields=None, which=slice(None)) -> list:
    """The run's snapshots in order as Snapshot objects (`out`: its directory or
    snapshots.h5), with all their fields or only `fields` (names, or one name); `which`
    picks some by position (an index, a slice or a list of indices: -1 the last)."""
    fields = [fields] if isinstance(fields, str) else fields
    with _open(out, "snapshots.h5") as f:
        groups = sorted(g for g in f if g.startswith("step_"))
        out_list = []
        for g in _pick(groups, which):
            names = list(f[g]) if fields is None else list(fields)
            missing = [n for n in names if n not in f[g]]
            if missing:
                raise InputError(f"no field {', '.join(repr(n) for n in missing)} in snapshot {g}; it has: "
                                 f"{', '.join(sorted(f[g]))}")
            out_list.append(Snapshot(int(f[g].attrs["step"]), float(f[g].attrs["time"]),
                                     {n: f[g][n][()] for n in names}))
        return out_list
