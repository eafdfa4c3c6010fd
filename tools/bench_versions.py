#!/usr/bin/env python3
"""Throughput of two versions of parsph, interleaved in one run: is a change slower?

For each case of tools/bench_throughput.py that both versions can run, one worker process
per version builds the same block and warms it up; then the workers take turns, `--slices`
times, stepping `--steps` steps each. The ratio of each pair of neighbouring slices (new
over old) sees the same machine load, so its median is steady even on a busy machine.
The old version is checked out as a git worktree of REV (removed afterwards).

usage: tools/bench_versions.py REV [--particles-2d 20000] [--particles-3d 8000]
                               [--steps 20] [--slices 9]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

WORKER = r"""
import json, os, sys, time
import numpy as np
from mpi4py import MPI
import parsph
from parsph import config
from parsph.build import build_local
assert parsph.__file__.startswith(sys.argv[1]), parsph.__file__
if os.path.exists(os.path.join(sys.argv[1], "parsph", "simulation.py")):
    from parsph.simulation import Simulation
else:  # before the loop was parsph.simulation
    from parsph.solver import Simulation
sim = None
for line in sys.stdin:
    cmd = json.loads(line)
    if cmd["do"] == "setup":
        try:
            scene = config.validate(cmd["scene"])
            sim = Simulation(scene, build_local(scene, MPI.COMM_SELF), MPI.COMM_SELF)
        except Exception as exc:  # the old version may not know the case
            print(json.dumps({"error": f"{type(exc).__name__}: {exc}"}), flush=True)
            continue
        state = getattr(sim, "state", sim)  # before the rank's particles were a class of their own
        rng = np.random.default_rng(0)
        state.v[: state.n_owned] = 1e-3 * rng.standard_normal(state.v[: state.n_owned].shape)
        for _ in range(5):
            sim.step()
        print(json.dumps({"particles": int(state.n_owned)}), flush=True)
    else:
        start = time.perf_counter()
        for _ in range(cmd["steps"]):
            sim.step()
        print(json.dumps({"seconds": time.perf_counter() - start}), flush=True)
"""


def worker(tree: str):
    env = dict(os.environ, PYTHONPATH=tree)
    return subprocess.Popen([sys.executable, "-c", WORKER, tree], cwd=tree, env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE)


def ask(proc, **cmd) -> dict:
    proc.stdin.write(json.dumps(cmd) + "\n")
    proc.stdin.flush()
    return json.loads(proc.stdout.readline())


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", help="the old version (a git revision)")
    ap.add_argument("--particles-2d", type=int, default=20000)
    ap.add_argument("--particles-3d", type=int, default=8000)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--slices", type=int, default=9)
    args = ap.parse_args()
    sys.path.insert(0, os.path.join(ROOT, "tools"))
    import bench_throughput as bt

    old_tree = tempfile.mkdtemp(prefix="parsph-old-")
    subprocess.run(["git", "-C", ROOT, "worktree", "add", "--detach", old_tree, args.rev], check=True,
                   capture_output=True)
    try:
        print(f"old: {args.rev}, new: the working tree; {args.steps} steps per slice, {args.slices} slices each")
        print("case                                        old us   new us   new/old (median of slice ratios)")
        for dim, count in ((2, args.particles_2d), (3, args.particles_3d)):
            for method, alpha, form, eta, every, *law in bt.CASES:
                scene = bt.raw_block(dim, count, alpha, form, eta, every, method, *law)
                old, new = worker(old_tree), worker(ROOT)
                try:
                    a, b = ask(old, do="setup", scene=scene), ask(new, do="setup", scene=scene)
                    label = (f"{dim}D {method}{' ' + law[0] if law else ''} alpha {alpha:g} {form if alpha else '-'} "
                             f"eta {eta:g} every {every}")
                    if "error" in a or "error" in b:
                        print(f"{label:42s}  skipped ({a.get('error') or b.get('error')})")
                        continue
                    t_old, t_new = [], []
                    for _ in range(args.slices):
                        t_old.append(ask(old, do="run", steps=args.steps)["seconds"])
                        t_new.append(ask(new, do="run", steps=args.steps)["seconds"])
                    ratios = sorted(n / o for n, o in zip(t_new, t_old))
                    scale = 1e6 / (args.steps * a["particles"])
                    print(f"{label:42s} {min(t_old) * scale:7.3f}  {min(t_new) * scale:7.3f}   "
                          f"{ratios[len(ratios) // 2]:.3f} (range {ratios[0]:.2f}-{ratios[-1]:.2f})", flush=True)
                finally:
                    for proc in (old, new):
                        proc.stdin.close()
                        proc.wait()
    finally:
        subprocess.run(["git", "-C", ROOT, "worktree", "remove", "--force", old_tree], capture_output=True)


if __name__ == "__main__":
    main()
