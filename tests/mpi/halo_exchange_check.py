"""Run under mpiexec: the halo machinery (parsph.parallel.halo) on points in a row, ten per
rank. Ghosts found by bounding boxes must be exactly the other ranks' points within the reach
of this rank's box; a Halo must put each owner's value in its ghost's row, with the ghosts in
blocks by owner (as found) and interleaved (non-contiguous rows, asked of their owners), and
from the owned rows of one array into the ghost rows of another. Prints OK and exits 0, or
prints the first difference and exits 1.

usage: mpiexec -n P python halo_exchange_check.py
"""

import sys

import numpy as np
from mpi4py import MPI

from parsph.parallel.halo import Halo, gather, requested, within_reach

comm = MPI.COMM_WORLD
rank, size = comm.rank, comm.size
reach = 0.25
gid = rank * 10 + np.arange(10)
x = np.stack([0.1 * gid + 0.03, np.zeros(10)], axis=1)  # rank r: [r + 0.03, r + 0.93]


def value(g, owner):
    """What the owner of point g holds for it: differs by owner, by point and by component."""
    return np.stack([1000.0 * owner + g, -(1000.0 * owner + g)], axis=1)


problems = []
send = within_reach(x, reach, comm)
ghosts = gather({"gid": gid, "x": x}, send, comm)
everyone = comm.allgather((gid, x))
expected = []
for r, (g, p) in enumerate(everyone):
    if r != rank:
        gap = np.maximum(0.0, np.maximum(x.min(axis=0) - p, p - x.max(axis=0)))
        expected += g[np.sqrt((gap ** 2).sum(axis=1)) <= reach].tolist()
if sorted(ghosts["gid"].tolist()) != sorted(expected):
    problems.append(f"rank {rank}: ghosts {sorted(ghosts['gid'].tolist())}, expected {sorted(expected)}")
if not np.array_equal(ghosts["owner"], ghosts["gid"] // 10):
    problems.append(f"rank {rank}: ghosts' owners {ghosts['owner']}")

n, m = len(gid), len(ghosts["gid"])
owners = set(ghosts["owner"].tolist())

# found by boxes, in blocks by owner: from the owned rows of `values` into the ghost rows of `into`
halo = Halo(comm, send, ghosts["owner"], n)
into = np.zeros((n + m, 2))
halo.exchange(value(gid, rank), into)
if not np.array_equal(into[n:], value(ghosts["gid"], ghosts["owner"])):
    problems.append(f"rank {rank}: exchange into another array: {into[n:].tolist()}")

# interleaved by owner (the rows of one owner not contiguous), the plan asked of the owners
order = np.argsort(ghosts["gid"] % 2, kind="stable")
ghost_gid, ghost_owner = ghosts["gid"][order], ghosts["owner"][order]
halo = Halo(comm, requested(gid, ghost_gid, ghost_owner, comm), ghost_owner, n)
values = np.zeros((n + m, 2))
values[:n] = value(gid, rank)
halo.exchange(values)
if not np.array_equal(values[n:], value(ghost_gid, ghost_owner)):
    problems.append(f"rank {rank}: exchange in place, interleaved: {values[n:].tolist()}")
if not np.array_equal(values[:n], value(gid, rank)):
    problems.append(f"rank {rank}: the owned rows changed")
interleaved = any(isinstance(rows, np.ndarray) for rows in halo.recv.values())

found = comm.gather((problems, len(owners), interleaved), root=0)
status = 0
if rank == 0:
    problems = [p for part in found for p in part[0]]
    if problems:
        print(problems[0])
        status = 1
    elif size > 2 and not any(count == 2 and mixed for _, count, mixed in found):
        print("no rank received interleaved ghosts from two owners: test is too weak")
        status = 1
    else:
        print(f"OK: ghosts from up to {max(part[1] for part in found)} owners")
sys.exit(comm.bcast(status, root=0))
