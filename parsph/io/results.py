"""A finished (or running) run's output read back as arrays: the public way for scripts,
notebooks, tools and tests to get at `history.h5` and `snapshots.h5` without knowing their
layout.

    from parsph.io import read_history, read_snapshots
    h = read_history("results/taylor_impact")        # {"time": array, "kinetic_energy": array, ...}
    last = read_snapshots("results/taylor_impact")[-1]
    last.time, last["position"], last["von_mises"]    # rows in global-id order
"""

from __future__ import annotations

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


def _file(out: str | os.PathLike, name: str) -> str:
    """`out` itself if it is a file, else the file `name` of the run directory `out`."""
    path = os.fspath(out)
    path = path if os.path.isfile(path) else os.path.join(path, name)
    if not os.path.isfile(path):
        raise InputError(f"{path} does not exist: give a run's output directory or its {name}")
    return path


def read_history(out: str | os.PathLike) -> dict:
    """Every series of the run's history (`out`: its output directory or history.h5), one
    array per name, one entry per history row."""
    with h5py.File(_file(out, "history.h5"), "r") as f:
        return {name: np.asarray(f[name]) for name in f}


def snapshot_steps(out: str | os.PathLike) -> list:
    """[(step, time)] of the run's snapshots in order (`out`: its directory or snapshots.h5)."""
    with h5py.File(_file(out, "snapshots.h5"), "r") as f:
        return sorted((int(f[g].attrs["step"]), float(f[g].attrs["time"])) for g in f if g.startswith("step_"))


def read_snapshots(out: str | os.PathLike, fields=None, which=slice(None)) -> list:
    """The run's snapshots in order as Snapshot objects (`out`: its directory or
    snapshots.h5), with all their fields or only `fields` (names); `which` picks some by
    position (an index, a slice or a list of indices: -1 the last)."""
    with h5py.File(_file(out, "snapshots.h5"), "r") as f:
        groups = sorted(g for g in f if g.startswith("step_"))
        picked = [groups[which]] if isinstance(which, (int, np.integer)) else \
            groups[which] if isinstance(which, slice) else [groups[k] for k in which]
        out_list = []
        for g in picked:
            names = list(f[g]) if fields is None else list(fields)
            missing = [n for n in names if n not in f[g]]
            if missing:
                raise InputError(f"no field {', '.join(repr(n) for n in missing)} in snapshot {g}; it has: "
                                 f"{', '.join(sorted(f[g]))}")
            out_list.append(Snapshot(int(f[g].attrs["step"]), float(f[g].attrs["time"]),
                                     {n: f[g][n][()] for n in names}))
        return out_list
