"""Shared test helpers: running `parsph` on one rank or under mpiexec."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "runs"


def mpiexec() -> str:
    """The launcher of the MPI that mpi4py was built against (MPICH on Debian)."""
    for name in ("mpiexec.mpich", "mpiexec"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no mpiexec on PATH")


def parsph(args, ranks: int = 1, timeout: float = 300, cwd=None, env=None) -> subprocess.CompletedProcess:
    """Run `python -m parsph ARGS` on `ranks` ranks (extra environment `env`)."""
    cmd = [sys.executable, "-m", "parsph", *map(str, args)]
    if ranks > 1:
        cmd = [mpiexec(), "-n", str(ranks), *cmd]
    env = {**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd or ROOT, env=env)


@pytest.fixture
def run_parsph():
    return parsph
