#!/usr/bin/env python3
"""The first run of every shipped scene, as a new user meets it: whole-process seconds of
`parsph run SCENE --set time.max_steps=5` with only the kernels `tools/setup` compiled in the
cache (each scene starts from a copy of that cache, so no scene profits from another), and
the seconds Numba spent compiling in it (tools/compile_clock).

  tools/first_run.py [--only NAME ...]

Run it after tools/setup; it never changes the user's cache.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def first_run(scene: Path, seed_cache: Path, work: Path) -> tuple[float, float, int, int]:
    """(wall seconds, compile seconds, kernels compiled, exit code) of one cold run."""
    cache = work / "cache"
    shutil.rmtree(cache, ignore_errors=True)
    if seed_cache.is_dir():
        shutil.copytree(seed_cache, cache / seed_cache.name)
    log = work / "compile"
    shutil.rmtree(log, ignore_errors=True)
    shutil.rmtree(work / "out", ignore_errors=True)
    log.mkdir()
    env = dict(os.environ, PARSPH_CACHE_DIR=str(cache), PARSPH_COMPILE_LOG=str(log),
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT / "tools" / "compile_clock"),
                                                        os.environ.get("PYTHONPATH")])))
    start = time.perf_counter()
    rc = subprocess.run([sys.executable, "-m", "parsph", "run", str(scene), "--out", str(work / "out"),
                         "--quiet", "--set", "time.max_steps=5"], env=env, cwd=work,
                        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode
    wall = time.perf_counter() - start
    lines = [line.split() for path in log.glob("*.txt") for line in path.read_text().splitlines()]
    return wall, sum(float(line[0]) for line in lines), len(lines), rc


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", help="scene names (default: every runs/*.toml)")
    args = parser.parse_args()
    import parsph

    seed = Path(parsph.NUMBA_CACHE)
    scenes = sorted((ROOT / "runs").glob("*.toml"))
    if args.only:
        scenes = [s for s in scenes if s.stem in args.only]
    print(f"first run, 5 steps, cache as tools/setup left it ({'present' if seed.is_dir() else 'EMPTY'})")
    print(f"{'scene':24s} {'whole s':>8s} {'compile s':>10s} {'kernels':>8s}")
    walls = []
    with tempfile.TemporaryDirectory() as tmp:
        for scene in scenes:
            wall, compiling, kernels, rc = first_run(scene, seed, Path(tmp))
            walls.append(wall)
            flag = "" if rc == 0 else f"  (exit {rc})"
            print(f"{scene.stem:24s} {wall:8.1f} {compiling:10.1f} {kernels:8d}{flag}", flush=True)
    if walls:
        print(f"{'largest':24s} {max(walls):8.1f}; median {sorted(walls)[len(walls) // 2]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
