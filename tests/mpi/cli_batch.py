"""Run under mpiexec: `parsph` command lines one after another in one MPI job, so that the
suite checks many bad inputs on several ranks without starting a job for each (a job's
start-up, ~1 s of CPU per rank, is most of such a case's time). For each case every rank
calls parsph.cli.main with the case's arguments, as `python -m parsph` does, with its
standard output and error going to files of its own; the exit code is main's return value
(or SystemExit's code: argparse's usage errors). Rank 0 writes every rank's exit codes.
A run holds its output directory's lock until its process ends (parsph.io.output_dir): after
each case the lock is dropped, as that end would drop it, so that a later case may use the
directory (a restart of the run, a refusal of its checkpoint).

usage: mpiexec -n P python cli_batch.py CASES.json RESULTS.json
  CASES.json: [{"argv": [...], "out": PREFIX}, ...]; rank r writes PREFIX.r.stdout and
  PREFIX.r.stderr; RESULTS.json: [[code of rank 0, code of rank 1, ...], ...] per case.
"""

import json
import os
import sys

from mpi4py import MPI

from parsph import cli
from parsph.io import output_dir

comm = MPI.COMM_WORLD


def run_case(argv: list, prefix: str) -> int:
    """main(argv) with this rank's file descriptors 1 and 2 sent to PREFIX.RANK.stdout/stderr."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(f"{prefix}.{comm.rank}.stdout", "w") as out, open(f"{prefix}.{comm.rank}.stderr", "w") as err:
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        try:
            try:
                code = cli.main(argv)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            if output_dir._lock_fd is not None:  # the lock the process's end would drop
                os.close(output_dir._lock_fd)
                output_dir._lock_fd = None
    return code


def main() -> None:
    cases_path, results_path = sys.argv[1:3]
    with open(cases_path) as fh:
        cases = json.load(fh)
    codes = []
    for case in cases:
        codes.append(run_case(case["argv"], case["out"]))
        comm.Barrier()  # the next case starts on every rank together, as a new job would
    every = comm.gather(codes, root=0)
    if comm.rank == 0:
        with open(results_path, "w") as fh:
            json.dump([list(case) for case in zip(*every)], fh)


main()
