"""`snapshots.h5`: particle fields at chosen times, in global-id order, plus an XDMF index.

Each snapshot is a group `/step_NNNNNNNN` holding one dataset per field, written by all
ranks together (io.h5). The file is opened for each snapshot and closed after it, so a
killed run leaves every finished snapshot readable. `snapshots.xdmf` lists the snapshots as
a time series of point clouds that ParaView opens; rank 0 writes it whole when a run starts
or resumes (to a temporary name, then renamed) and then adds each snapshot's entry in one
write over the closing tags, so the cost of an entry does not grow with the run.
`write_points` and `point_grid` also write `parsph preview`'s particles: a snapshot file
of one snapshot, before any step.
"""

from __future__ import annotations

import os

import h5py
import numpy as np

from parsph import quantities
from parsph.errors import InputError, ParsphError
from parsph.io.h5 import ParticleFile
from parsph.parallel.runtime import collective

HEADER = ('<?xml version="1.0" ?>\n<Xdmf Version="3.0">\n<Domain>\n'
          '<Grid Name="particles" GridType="Collection" CollectionType="Temporal">\n')
FOOTER = "</Grid>\n</Domain>\n</Xdmf>\n"


def check_snapshots_readable(path: str) -> None:
    """InputError naming `path` if it exists but its snapshots cannot be listed."""
    if not os.path.exists(path):
        return
    try:
        with h5py.File(path, "r") as f:
            for name in f:
                if name.startswith("step_"):
                    f[name].attrs["step"], f[name].attrs["time"], f[name]["gid"].shape
    except Exception as exc:  # noqa: BLE001 - any damage: name the file
        raise InputError(f"{path} is damaged and cannot be continued ({type(exc).__name__}: {exc}); "
                         "restart into another --out with --restart CHECKPOINT_FILE") from None


def write_points(out: ParticleFile, group: str, gid: np.ndarray, total: int, values: dict, t: float, step: int,
                 connectivity: bool) -> None:
    """Collective: the group `group` (attributes time and step) of the open file `out`,
    with this rank's rows of the global ids `gid` (sorted) and of each field of `values`
    ({name: rows}); first, with `connectivity`, the Polyvertex connectivity 0..total-1
    (explicit, for readers that need it)."""
    if connectivity:
        out.write_rows("connectivity", gid, gid.astype(np.int64)[:, None], total)
    if out.writer:
        grp = out.file.create_group(group)
        grp.attrs["time"] = t
        grp.attrs["step"] = step
    out.write_rows(f"{group}/gid", gid, gid, total)
    for name, data in values.items():
        out.write_rows(f"{group}/{name}", gid, data, total)


def point_grid(h5_name: str, group: str, n: int, fields: dict, t: float | None = None) -> str:
    """The XDMF grid of a cloud of n points in the HDF5 file `h5_name` (beside the index):
    its /connectivity, and the datasets of `group`, `fields` {name: (shape per point,
    (XDMF number type, precision))}, "position" the geometry; at time `t` (None: none)."""
    lines = [f'<Grid Name="{group}" GridType="Uniform">' + ("" if t is None else f'<Time Value="{float(t)!r}"/>'),
             f'<Topology TopologyType="Polyvertex" NumberOfElements="{n}" NodesPerElement="1">'
             f'<DataItem Dimensions="{n} 1" Format="HDF" NumberType="Int" Precision="8">'
             f'{h5_name}:/connectivity</DataItem></Topology>',
             f'<Geometry GeometryType="XYZ"><DataItem Dimensions="{n} 3" Format="HDF" '
             f'NumberType="Float" Precision="8">{h5_name}:/{group}/position</DataItem></Geometry>']
    for name, (shape, (number, size)) in sorted(fields.items()):
        if name == "position":
            continue
        kind = "Scalar" if len(shape) == 0 else "Vector" if len(shape) == 1 else "Tensor"
        dims = " ".join(str(s) for s in (n,) + tuple(shape))
        lines.append(f'<Attribute Name="{name}" AttributeType="{kind}" Center="Node">'
                     f'<DataItem Dimensions="{dims}" Format="HDF" NumberType="{number}" '
                     f'Precision="{size}">{h5_name}:/{group}/{name}</DataItem></Attribute>')
    lines.append("</Grid>")
    return "\n".join(lines) + "\n"


class SnapshotWriter:
    def __init__(self, out_dir: str, scene_json: str, comm, resume_step: int | None = None):
        """Collective: a new file, or (resume_step given) the existing one with the
        snapshots after that step removed, as a restarted run continues it."""
        self.comm = comm
        self.path = os.path.join(out_dir, "snapshots.h5")
        self.xdmf = os.path.join(out_dir, "snapshots.xdmf")
        self.entries = []  # rank 0: (time, group, count, field shapes)
        self.end = 0  # rank 0: offset of the XDMF closing tags
        with collective(comm):
            if comm.rank == 0:
                if resume_step is None or not os.path.exists(self.path):
                    with h5py.File(self.path, "w") as f:
                        f.attrs["scene"] = scene_json
                else:
                    self._resume(resume_step)
                self._write_xdmf()
        self.times = comm.bcast([e[0] for e in self.entries], root=0)  # every rank: snapshot times

    def _resume(self, resume_step: int) -> None:
        try:
            with h5py.File(self.path, "a") as f:
                for name in sorted(k for k in f if k.startswith("step_")):
                    grp = f[name]
                    if grp.attrs["step"] > resume_step:
                        del f[name]
                        continue
                    shapes = {k: grp[k].shape[1:] for k in grp if k != "gid"}
                    self.entries.append((float(grp.attrs["time"]), name, len(grp["gid"]), shapes))
                if not self.entries and "connectivity" in f:  # written again with the first snapshot
                    del f["connectivity"]
        except Exception as exc:  # noqa: BLE001 - any damage: name the file
            raise InputError(f"{self.path} cannot be continued ({type(exc).__name__}: {exc}); restart "
                             "into another --out with --restart CHECKPOINT_FILE") from None

    def estimate_bytes(self, sim, fields: list) -> int:
        """Bytes one snapshot of `fields` adds to the file (data and HDF5 metadata)."""
        per_particle = sum(quantities.bytes_per_point(name, sim.state.dim) for name in fields) + 8
        first = 0 if self.times else 8 * sim.state.decomp.total  # the connectivity
        return sim.state.decomp.total * per_particle + first + 1024 * (len(fields) + 2)

    def write(self, sim, fields: list) -> None:
        """Collective: one snapshot of the owned particles' `fields`; a value that is not
        finite stops the run before anything of the snapshot is written, naming the field,
        the particle and the step."""
        n = sim.state.n_owned
        gid = sim.state.gid[:n]
        total = sim.state.decomp.total
        group = f"step_{sim.step_count:08d}"
        first = not self.times
        with collective(self.comm):
            values = {name: self._values(sim, name) for name in fields}
            for name, data in values.items():
                bad = np.flatnonzero(~np.isfinite(data).all(axis=tuple(range(1, data.ndim))))
                if len(bad):
                    k = bad[np.argmin(gid[bad])]
                    raise ParsphError(f"the snapshot at step {sim.step_count}, t = {sim.t:.6g} s: {name} of particle "
                                      f"{gid[k]} is not finite ({data[k]}); the run is stopped (the output written "
                                      "so far is intact)")
        shapes = {name: data.shape[1:] for name, data in values.items()}
        with collective(self.comm):
            with ParticleFile(self.path, "a", self.comm) as out:
                write_points(out, group, gid, total, values, sim.t, sim.step_count, first)
        self.times.append(sim.t)
        if self.comm.rank == 0:
            entry = (sim.t, group, total, shapes)
            self.entries.append(entry)
            with open(self.xdmf, "r+") as fh:  # the entry and the closing tags in one write
                fh.seek(self.end)
                text = self._grid(*entry)
                fh.write(text + FOOTER)
            self.end += len(text)

    def _values(self, sim, name: str) -> np.ndarray:
        """This rank's rows of a snapshot field (positions padded to 3D)."""
        data = sim.quantity(name)
        if name in ("position", "reference_position") and data.shape[1] < 3:
            data = np.pad(data, ((0, 0), (0, 3 - data.shape[1])))
        return data

    def _grid(self, t: float, group: str, n: int, shapes: dict) -> str:
        """The XDMF grid of one snapshot."""
        fields = {name: (shape, ("Int", 4) if name == "rank" else ("Float", 8)) for name, shape in shapes.items()}
        return point_grid(os.path.basename(self.path), group, n, fields, t)

    def _write_xdmf(self) -> None:
        """The whole index (to a temporary name, then renamed); remembers where the closing
        tags start."""
        body = HEADER + "".join(self._grid(*entry) for entry in self.entries)
        tmp = self.xdmf + ".tmp"
        with open(tmp, "w") as fh:
            fh.write(body + FOOTER)
        os.replace(tmp, self.xdmf)
        self.end = len(body)
