"""Run a scene as a user would (`parsph run`, under mpiexec for several ranks), for the
study tools (taylor_study, failure_study)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def launcher(ranks: int) -> list:
    """The command prefix that starts `ranks` ranks (none for one)."""
    if ranks == 1:
        return []
    mpiexec = subprocess.run(["bash", os.path.join(ROOT, "tools", "mpiexec"), "--which"], capture_output=True,
                             text=True, check=True).stdout.strip()
    return [mpiexec, "-n", str(ranks)]


def run_scene(scene: str, out: str, overrides: list, ranks: int, fields: list) -> float:
    """Run runs/SCENE.toml into `out` (replacing it) with `--set` overrides and these
    snapshot fields; returns the wall time in seconds."""
    sets = [a for o in overrides for a in ("--set", o)]
    snapshot = "output.snapshot_fields=[" + ",".join(f'"{f}"' for f in fields) + "]"
    path = os.path.join(ROOT, "runs", f"{scene}.toml")
    start = time.perf_counter()
    subprocess.run([*launcher(ranks), sys.executable, "-m", "parsph", "run", path, "--out", out, "--overwrite",
                    "--quiet", *sets, "--set", snapshot], check=True)
    return time.perf_counter() - start
