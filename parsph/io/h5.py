"""Global particle datasets in HDF5, in global-id order, written by all ranks together.

With parallel HDF5 (h5py built with MPI, unless PARSPH_SERIAL_HDF5=1) every rank opens the file through MPI-IO and writes
its own rows: the runs of consecutive global ids it owns, selected as a union of
hyperslabs, in one collective write per dataset. Without it the rows are gathered to rank
0, which writes them. Either way the file is the same, whatever the rank count.
"""

from __future__ import annotations

import os

import h5py
import numpy as np

from parsph.parallel.decomposition import block_cuts
from parsph.parallel.runtime import warn

# PARSPH_SERIAL_HDF5=1 forces the rank-0 path (tests; file systems where MPI-IO misbehaves)
PARALLEL = bool(h5py.get_config().mpi) and os.environ.get("PARSPH_SERIAL_HDF5", "") in ("", "0")
_warned = False


def parallel_enabled(comm) -> bool:
    """Whether files are written collectively (else through rank 0, with a warning once)."""
    global _warned
    if comm.size > 1 and not PARALLEL and not _warned:
        warn("h5py has no MPI support: output is gathered to rank 0 and written there")
        _warned = True
    return PARALLEL and comm.size > 1


class ParticleFile:
    """An HDF5 file that every rank opens together (or only rank 0 without parallel HDF5)."""

    def __init__(self, path: str, mode: str, comm, **options):
        """`options` go to h5py.File (e.g. userblock_size)."""
        self.comm = comm
        self.collective = parallel_enabled(comm)
        self.file = None
        if self.collective:
            self.file = h5py.File(path, mode, driver="mpio", comm=comm, **options)
        elif comm.rank == 0:
            self.file = h5py.File(path, mode, **options)

    @property
    def writer(self) -> bool:
        """True on the ranks that call h5py (all ranks when collective, else rank 0)."""
        return self.file is not None

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def write_rows(self, name: str, gid: np.ndarray, rows: np.ndarray, total: int) -> None:
        """Collective: dataset `name` of `total` rows; this rank's `rows` go to rows `gid`
        (sorted, unique). Datasets are created by all writer ranks with the same shape."""
        rows = np.ascontiguousarray(rows)
        shape = (total,) + rows.shape[1:]
        dtype = rows.dtype.str
        if self.comm.size > 1:  # ranks without rows may hold an empty array of another type
            dtype = next((d for d in self.comm.allgather(dtype if len(rows) else None) if d), dtype)
        if self.collective:
            dset = self.file.create_dataset(name, shape=shape, dtype=dtype)
            _write_runs(dset, *_blocks(gid, rows.astype(dtype, copy=False), total, self.comm))
            return
        parts = self.comm.gather((gid, rows), root=0)
        if self.comm.rank == 0:
            data = np.empty(shape, dtype)
            for g, r in parts:
                data[g] = r
            self.file.create_dataset(name, data=data)


def runs(gid: np.ndarray):
    """(start, count) of each run of consecutive values in a sorted id array."""
    if len(gid) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    breaks = np.flatnonzero(np.diff(gid) != 1) + 1
    starts = np.concatenate([[0], breaks])
    counts = np.diff(np.concatenate([starts, [len(gid)]]))
    return gid[starts], counts


def _blocks(gid: np.ndarray, rows: np.ndarray, total: int, comm) -> tuple:
    """(gid, rows) of the rows this rank writes: those of ids cuts[r]..cuts[r+1]-1 (block_cuts),
    sent to it by the ranks that hold them, in id order. A rank's particles are scattered
    over many short runs of ids; one run per rank keeps the collective write's selection
    simple (HDF5's union of thousands of hyperslabs is slow)."""
    bounds = np.searchsorted(gid, block_cuts(total, comm.size))
    received = comm.alltoall([(gid[a:b], rows[a:b]) for a, b in zip(bounds[:-1], bounds[1:])])
    gid = np.concatenate([g for g, _ in received])
    order = np.argsort(gid, kind="stable")
    return gid[order], np.concatenate([r for _, r in received])[order]


def _write_runs(dset, gid: np.ndarray, rows: np.ndarray) -> None:
    """One collective write of `rows` into the union of hyperslabs given by `gid`."""
    from h5py import h5fd, h5p, h5s

    fspace = dset.id.get_space()
    fspace.select_none()
    tail = rows.shape[1:]
    for start, count in zip(*runs(gid)):
        fspace.select_hyperslab((int(start),) + (0,) * len(tail), (int(count),) + tail,
                                op=h5s.SELECT_OR)
    mspace = h5s.create_simple(rows.shape if rows.size else (1,) + tail)
    if not rows.size:
        mspace.select_none()
        rows = np.zeros((1,) + tail, rows.dtype)
    dxpl = h5p.create(h5p.DATASET_XFER)
    dxpl.set_dxpl_mpio(h5fd.MPIO_COLLECTIVE)
    dset.id.write(mspace, fspace, rows, dxpl=dxpl)
