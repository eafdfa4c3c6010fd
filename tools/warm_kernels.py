#!/usr/bin/env python3
"""Compile the kernels most scenes share into the on-disk cache, in parallel over the cores:
`tools/setup` runs this once per version of the compiled code, so that a new user's first
run of a shipped scene compiles only its own few stage variants (tools/first_run.py).

The scenes below are run for one step each, one process per core. Together they hold every
material law (each compiled once, for all dimensions), the 1D, 2D and 3D neighbour search
and corrections, the updated reference's kept lists, contact, the failure models and the
Galerkin shape functions; coarse copies where a scene's set-up is long.

usage: tools/warm_kernels.py [--jobs N]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENES = (  # scene, overrides: the slowest to compile first
    ("plate_impact", ()),  # J2, neo-Hookean, tensile damage, contact (2D)
    ("rings", ()),  # nearly incompressible neo-Hookean, updated reference, self-contact
    ("taylor_jc", ("parameters.layers=8",)),  # Johnson-Cook, 3D, a rigid wall
    ("rubber_ring", ()),  # Mooney-Rivlin, the Galerkin shape functions
    ("funnel", ()),  # Tait's fluid, the Eulerian kernel, artificial viscosity
    ("cylinder_bending_ul", ()),  # the updated reference's kept lists in 3D
    ("bar1d_ul", ()),  # and in 1D
    ("flyer_plate", ()),  # Mie-Grüneisen (1D)
    ("bar1d", ()),  # Saint Venant-Kirchhoff, 1D
    ("patch_random", ()),  # the default scene
)


def warm(scene: str, overrides: tuple, out: Path) -> tuple[str, int]:
    cmd = [sys.executable, "-m", "parsph", "run", str(ROOT / "runs" / f"{scene}.toml"), "--out", str(out / scene),
           "--quiet", "--set", "time.max_steps=1"]
    for o in overrides:
        cmd += ["--set", o]
    return scene, subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=out).returncode


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=len(os.sched_getaffinity(0)))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(max(args.jobs, 1)) as pool:
        failed = [scene for scene, rc in pool.map(lambda s: warm(*s, Path(tmp)), SCENES) if rc]
    if failed:
        print(f"warm_kernels: {', '.join(failed)} failed: their first runs compile instead", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
