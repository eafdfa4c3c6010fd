"""`history.h5`: one resizable 1-D dataset per diagnostic and probe, one row per output time.

Written by rank 0 (history values are already global reductions). Rows are kept in memory
and written in blocks, each flushed: the first row at once, then at least every
WRITE_SECONDS of wall time, before every checkpoint (a restart finds every row up to it)
and at the end, also of a failed run. A killed run leaves a readable file without at most
the last WRITE_SECONDS of rows, which a restart from its checkpoint computes again. The
resolved scene is stored as the attribute `scene`; every series carries its units as the
attribute `units`.
"""

from __future__ import annotations

import os
import time

import h5py
import numpy as np

from parsph import quantities
from parsph.errors import InputError, ParsphError
from parsph.io.output_dir import check_space

WRITE_SECONDS = 1.0  # the longest wall time a row waits in memory


def units_of(name: str, probe_units: dict) -> str:
    """Units of a history series: a probe's, or those quantities.history_units gives."""
    return probe_units[name] if name in probe_units else quantities.history_units(name)


class HistoryWriter:
    def __init__(self, path: str, scene_json: str, probe_units: dict, resume_step: int | None = None):
        """A new file, or (resume_step given) the existing one cut back to the rows up to
        that step, as a restarted run continues it."""
        self.path = path
        self.probe_units = probe_units
        self.rows = 0  # in the file
        self.pending = []  # rows not yet written: dicts of values
        self.written_at = time.monotonic()
        self.series = {}  # name -> open dataset
        if resume_step is not None and os.path.exists(path):
            try:
                self.file = h5py.File(path, "a")
                if "step" in self.file:
                    self.rows = int(np.searchsorted(self.file["step"][()], resume_step, side="right"))
                    for name in self.file:
                        self.file[name].resize((self.rows,))
                self.file.attrs["scene"] = scene_json
            except Exception as exc:  # noqa: BLE001 - any damage: name the file
                raise InputError(f"{path} cannot be continued ({type(exc).__name__}: {exc}); restart into "
                                 "another --out with --restart CHECKPOINT_FILE") from None
            return
        self.file = h5py.File(path, "w")
        self.file.attrs["scene"] = scene_json

    def note(self, name: str, texts: list) -> None:
        """Keep `texts` (the run's warnings) as the file's attribute `name`, one per line."""
        self.file.attrs[name] = "\n".join(texts)

    def pending_bytes(self) -> int:
        """Bytes the rows in memory can add to the file, at most: per series a new chunk
        every 256 rows and, for a series not yet in the file, its header and chunk index."""
        rows = len(self.pending)
        if not rows:
            return 0
        chunks = (self.rows + rows - 1) // 256 - (self.rows - 1) // 256
        new = sum(name not in self.series for name in self.pending[0])
        return len(self.pending[0]) * 2048 * chunks + new * 4096

    def append(self, values: dict) -> None:
        """Add one row, kept in memory until `write`."""
        self.pending.append(values)

    def write_due(self) -> bool:
        """Whether WRITE_SECONDS have passed since the last write, or the file has no row
        yet (the first row makes the series: later rows need little room)."""
        return not self.rows or time.monotonic() - self.written_at >= WRITE_SECONDS

    def write(self) -> None:
        """Write the rows in memory to the file and flush it; a failure is a ParsphError
        naming the file."""
        self.written_at = time.monotonic()
        if not self.pending:
            return
        rows, end = self.pending, self.rows + len(self.pending)
        try:
            for name in rows[0]:
                ds = self.series.get(name)
                if ds is None:
                    ds = self.series[name] = self.file.require_dataset(
                        name, shape=(self.rows,), maxshape=(None,), dtype="f8", chunks=(256,))
                    ds.attrs["units"] = units_of(name, self.probe_units)
                ds.resize((end,))
                ds[self.rows:end] = np.array([row[name] for row in rows], dtype=np.float64)
            self.file.flush()
        except Exception as exc:  # noqa: BLE001 - h5py raises several types
            raise ParsphError(f"writing {self.path} failed ({type(exc).__name__}: {exc})") from None
        self.rows, self.pending = end, []

    def close(self) -> None:
        """Close the file, writing the rows still in memory if the disk has room for them: on
        the way out of a failed run a failure to write loses only those rows and does not
        hide the error that stopped the run (a finished run has written them with `write`)."""
        try:
            check_space(os.path.dirname(self.path) or ".", self.pending_bytes(), "the history rows in memory",
                        margin=0)  # the run has stopped: no other output is to follow
            self.write()
        except ParsphError:
            pass
        finally:
            self.file.close()


def read_units(path: str) -> dict:
    """The units attribute of every series of a history file."""
    with h5py.File(path, "r") as f:
        return {name: str(f[name].attrs.get("units", "")) for name in f}


def read_reached(path: str) -> tuple | None:
    """(time, step) of the last row of a history file, None if it does not exist or has no
    rows; InputError if it cannot be read."""
    if not os.path.exists(path):
        return None
    try:
        with h5py.File(path, "r") as f:
            if "time" not in f or not len(f["time"]):
                return None
            return float(f["time"][-1]), int(f["step"][-1])
    except Exception as exc:  # noqa: BLE001 - any damage: name the file
        raise InputError(f"{path} is damaged and cannot be continued ({type(exc).__name__}: {exc}); "
                         "restart into another --out with --restart CHECKPOINT_FILE") from None
