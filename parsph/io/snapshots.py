"""`snapshots.h5`: particle fields at chosen times, in global-id order, plus an XDMF index.

Each snapshot is a group `/step_NNNNNNNN` holding one dataset per field; the fields are
gathered to rank 0, which writes them. `snapshots.xdmf` lists the snapshots as a time
series of point clouds that ParaView opens; it is rewritten after each snapshot (to a
temporary name, then renamed), so it stays valid if the run is killed.
"""

from __future__ import annotations

import os

import h5py
import numpy as np


class SnapshotWriter:
    def __init__(self, out_dir: str, scene_json: str, comm):
        self.comm = comm
        self.path = os.path.join(out_dir, "snapshots.h5")
        self.xdmf = os.path.join(out_dir, "snapshots.xdmf")
        self.entries = []
        self.times = []  # on every rank: when snapshots were taken
        if comm.rank == 0:
            with h5py.File(self.path, "w") as f:
                f.attrs["scene"] = scene_json

    def write(self, sim, fields: list) -> None:
        n = sim.n_owned
        sel = np.arange(n)
        local = {"gid": sim.gid[:n]}
        for name in fields:
            if name == "rank":
                local[name] = np.full(n, self.comm.rank, np.int32)
            elif name == "reference_position":
                local[name] = sim.X[:n]
            else:
                local[name] = sim.quantity(name, sel)
        self.times.append(sim.t)
        gathered = self.comm.gather(local, root=0)
        if self.comm.rank != 0:
            return
        gid = np.concatenate([g["gid"] for g in gathered])
        order = np.argsort(gid)
        group = f"step_{sim.step_count:08d}"
        with h5py.File(self.path, "a") as f:
            grp = f.require_group(group)
            grp.attrs["time"] = sim.t
            grp.attrs["step"] = sim.step_count
            for name in ["gid"] + list(fields):
                data = np.concatenate([g[name] for g in gathered])[order]
                if name == "position" and data.shape[1] < 3:
                    data = np.pad(data, ((0, 0), (0, 3 - data.shape[1])))
                if name in grp:
                    del grp[name]
                grp.create_dataset(name, data=data)
        self.entries.append((sim.t, group, len(gid), {k: np.concatenate([g[k] for g in gathered]).shape[1:]
                                                      for k in fields}))
        self._write_xdmf()

    def _write_xdmf(self) -> None:
        base = os.path.basename(self.path)
        lines = ['<?xml version="1.0" ?>', '<Xdmf Version="3.0">', "<Domain>",
                 '<Grid Name="particles" GridType="Collection" CollectionType="Temporal">']
        for t, group, n, shapes in self.entries:
            lines.append(f'<Grid Name="{group}" GridType="Uniform"><Time Value="{float(t)!r}"/>')
            lines.append(f'<Topology TopologyType="Polyvertex" NumberOfElements="{n}"/>')
            lines.append(f'<Geometry GeometryType="XYZ"><DataItem Dimensions="{n} 3" Format="HDF" '
                         f'NumberType="Float" Precision="8">{base}:/{group}/position</DataItem></Geometry>')
            for name, shape in shapes.items():
                if name == "position":
                    continue
                kind = "Scalar" if len(shape) == 0 else "Vector" if len(shape) == 1 else "Tensor"
                dims = " ".join(str(s) for s in (n,) + shape)
                number = "Int" if name == "rank" else "Float"
                size = 4 if name == "rank" else 8
                lines.append(f'<Attribute Name="{name}" AttributeType="{kind}" Center="Node">'
                             f'<DataItem Dimensions="{dims}" Format="HDF" NumberType="{number}" '
                             f'Precision="{size}">{base}:/{group}/{name}</DataItem></Attribute>')
            lines.append("</Grid>")
        lines += ["</Grid>", "</Domain>", "</Xdmf>"]
        tmp = self.xdmf + ".tmp"
        with open(tmp, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        os.replace(tmp, self.xdmf)
