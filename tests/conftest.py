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

# A copy of runs/bar1d.toml without the comments: 40 particles on the nodes of [0, 1] m.
BAR = """\
[scene]
name = "bar1d"
dimension = 1

[geometry]
area = 1.0e-4
[[geometry.parts]]
shape = "box"
lower = [0.0]
upper = [1.0]
spacing = 0.02564102564102564
placement = "node"

[kernel]
type = "cubic_spline"
support = 1.5

[material]
model = "saint_venant_kirchhoff"
density = 7850.0
youngs_modulus = 200.0e9
poisson_ratio = 0.0

[formulation]
type = "tlsph"
hourglass = 0.0

[time]
end = 3.2e-3
cfl = 0.5

[groups.A]
nearest = [0.0]
[groups.B]
nearest = [1.0]
[groups.right_quarter]
box = { lower = [0.75], upper = [1.0] }

[[initial]]
type = "velocity"
group = "right_quarter"
value = [5.0]

[[bc]]
type = "fixed"
group = "A"

[[probes]]
name = "tip_displacement"
group = "B"
quantity = "displacement"
component = 0

[output]
history_interval = 1.0e-5
"""


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
