"""The MPI communicator and how ranks fail together.

Rule: an error that every rank detects the same way (a scene error) is printed once by rank
0 and every rank exits with the error's code. An error that only some ranks see is either
caught inside a `collective()` block, where the ranks agree on it and all raise it, or it
ends the whole job at once through `MPI.Abort`, so no rank is left waiting in a collective.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time

from mpi4py import MPI

from parsph.errors import ParsphError

COMM = MPI.COMM_WORLD


def rank() -> int:
    return COMM.rank


def size() -> int:
    return COMM.size


def say(*args, **kwargs) -> None:
    """print() on rank 0 only."""
    if COMM.rank == 0:
        print(*args, **kwargs, flush=True)


def warn(message: str) -> None:
    if COMM.rank == 0:
        print(f"parsph: warning: {message}", file=sys.stderr, flush=True)


def warn_if_oversubscribed(comm=COMM) -> None:
    """Warn (rank 0, one line) when the ranks on a node outnumber the cores they may run on
    (the union of their CPU affinity sets; ranks per node from MPI's shared-memory split):
    waiting ranks busy-poll, so such ranks take each other's cores (collective)."""
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        cores = len(set().union(*node.allgather(_cores())))
        ranks, leader = node.size, node.rank == 0
    finally:
        node.Free()
    crowded = comm.gather((ranks, cores) if leader and ranks > cores else None, root=0)
    nodes = comm.allreduce(int(leader))
    if comm.rank == 0 and any(crowded):
        ranks, cores = next(c for c in crowded if c)
        fewer = f"-n {cores}" if nodes == 1 else f"at most {cores} ranks on that node"
        warn(f"{ranks} ranks share {cores} core(s) on a node: MPI ranks wait for each other by busy-polling "
             "(MPICH does), so ranks that outnumber the cores slow each other down by orders of magnitude; "
             f"run fewer ranks ({fewer})")


def _cores() -> set:
    """The cores this process may run on."""
    try:
        return os.sched_getaffinity(0)
    except AttributeError:  # no affinity on this system
        return set(range(os.cpu_count() or 1))


@contextlib.contextmanager
def collective(comm=COMM):
    """Run a block on every rank; if it raises on any rank, raise the same error on all ranks.

    The lowest failing rank's message is sent to everyone, with its type (a ParsphError
    subclass; any other exception becomes a ParsphError).
    """
    failure = None
    try:
        yield
    except ParsphError as exc:
        failure = (type(exc), str(exc))
    except Exception as exc:  # noqa: BLE001 - any failure must reach the other ranks
        failure = (ParsphError, f"{type(exc).__name__}: {exc}")
    failures = comm.allgather(failure)
    for r, item in enumerate(failures):
        if item is not None:
            kind, message = item
            prefix = f"[rank {r}] " if comm.size > 1 and kind is ParsphError else ""
            error = kind(prefix + message)
            error.agreed = True
            raise error


def fail_all(exc: BaseException) -> int:
    """Report an exception and end the job; returns the exit code when the job survives.

    An error all ranks agreed on (raised by `collective`, or any error on a single rank) is
    reported once by rank 0 and the caller exits with its code. Anything else may be
    unique to this rank: it prints its message (with a traceback if unexpected) and
    aborts every rank, so no rank hangs.
    """
    if isinstance(exc, ParsphError) and (getattr(exc, "agreed", False) or COMM.size == 1):
        if COMM.rank == 0:
            print(f"parsph: error: {exc}", file=sys.stderr, flush=True)
        return exc.exit_code
    if isinstance(exc, ParsphError):
        print(f"parsph: error on rank {COMM.rank}: {exc}", file=sys.stderr, flush=True)
        _abort(exc.exit_code)
    import traceback

    print(f"parsph: error on rank {COMM.rank}: {type(exc).__name__}: {exc}", file=sys.stderr, flush=True)
    traceback.print_exception(exc, file=sys.stderr)
    sys.stderr.flush()
    if COMM.size > 1:
        _abort(1)
    return 1


def _abort(code: int) -> None:
    """End every rank; first give the launcher a moment to forward this rank's stderr."""
    time.sleep(0.5)
    COMM.Abort(code)
