"""`history.h5`: one resizable 1-D dataset per diagnostic and probe, one row per output time.

Written by rank 0 (history values are already global reductions). Each row is flushed, so
a killed run leaves a readable file. The resolved scene is stored as the attribute `scene`.
"""

from __future__ import annotations

import os

import h5py
import numpy as np

UNITS = {
    "time": "s", "step": "1", "dt": "s", "kinetic_energy": "J", "strain_energy": "J",
    "hourglass_energy": "J", "external_work": "J", "total_energy": "J",
}


class HistoryWriter:
    def __init__(self, path: str, scene_json: str, probe_units: dict, resume_step: int | None = None):
        """A new file, or (resume_step given) the existing one cut back to the rows before
        that step, as a restarted run continues it."""
        self.probe_units = probe_units
        self.rows = 0
        if resume_step is not None and os.path.exists(path):
            self.file = h5py.File(path, "a")
            if "step" in self.file:
                self.rows = int(np.searchsorted(self.file["step"][()], resume_step))
                for name in self.file:
                    self.file[name].resize((self.rows,))
            self.file.attrs["scene"] = scene_json
            return
        self.file = h5py.File(path, "w")
        self.file.attrs["scene"] = scene_json

    def append(self, values: dict) -> None:
        for name, value in values.items():
            if name not in self.file:
                ds = self.file.create_dataset(name, shape=(0,), maxshape=(None,), dtype="f8", chunks=(256,))
                ds.attrs["units"] = UNITS.get(name, self.probe_units.get(name, ""))
            ds = self.file[name]
            ds.resize((self.rows + 1,))
            ds[self.rows] = value
        self.rows += 1
        self.file.flush()

    def close(self) -> None:
        self.file.close()


def read_history(path: str) -> dict:
    """All series of a history file as numpy arrays."""
    with h5py.File(path, "r") as f:
        return {name: np.asarray(f[name]) for name in f}
