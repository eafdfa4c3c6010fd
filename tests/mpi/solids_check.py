"""Run under mpiexec: each bad solid part (a scene file each) must end `parsph preview` with
exit code 2 on every rank and one message on rank 0 matching its pattern. Prints OK and
exits 0, or prints the first failure and exits 1.

usage: mpiexec -n P python solids_check.py CASES.json
(CASES.json: [[scene path, out dir, pattern], ...])
"""

import contextlib
import io
import json
import re
import sys

from mpi4py import MPI

from parsph.cli import main

comm = MPI.COMM_WORLD
for scene, out, pattern in json.load(open(sys.argv[1])):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["preview", scene, "--out", out])
    codes = comm.allgather(code)
    text = err.getvalue()
    if comm.rank == 0 and (codes != [2] * comm.size or text.count("parsph: error:") != 1
                           or not re.search(pattern, text) or "Traceback" in text):
        print(f"{scene}: exit codes {codes}, stderr:\n{text}\nexpected /{pattern}/", flush=True)
        comm.Abort(1)
    comm.Barrier()
if comm.rank == 0:
    print("OK")
