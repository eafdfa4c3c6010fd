#!/usr/bin/env python3
"""Strong scaling of the total-Lagrangian step: the same 3D elastic block on 1 and 2 ranks.

Default: a 60^3 = 216 000 particle cube (spiky kernel, support 2.01 spacings, Saint
Venant-Kirchhoff, hourglass alpha = 50), stepped from a smooth velocity field with a fixed
time step. Reports, per rank count, the time to generate and partition the particles
(build_local: each rank generates its own block), the whole set-up, the wall time per
step, the time per step spent in the ghost (halo) exchange, the speed-up and the parallel
efficiency, and the largest rank's peak resident memory.
The driver starts one MPI job per rank count (mpiexec) and runs them one after another.

usage: tools/bench_scaling.py [--side 60] [--steps 50] [--ranks 1 2] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def worker(side: int, steps: int) -> None:
    from mpi4py import MPI

    from parsph import config
    from parsph.build import build_local
    from parsph.simulation import Simulation

    comm = MPI.COMM_WORLD
    spacing = 1.0 / side
    scene = config.validate({
        "scene": {"name": "scaling", "dimension": 3},
        "geometry": {"parts": [{"shape": "box", "lower": [0.0] * 3, "upper": [1.0] * 3, "spacing": spacing}]},
        "kernel": {"type": "spiky", "support": 2.01},
        "material": {"model": "saint_venant_kirchhoff", "density": 1000.0, "youngs_modulus": 1e9,
                     "poisson_ratio": 0.3},
        "formulation": {"hourglass": 50.0, "hourglass_form": "paper"},
        "time": {"end": 1.0, "dt": 0.1 * spacing / 1160.0},
    })
    comm.Barrier()
    start = time.perf_counter()
    local = build_local(scene, comm)
    comm.Barrier()
    build = time.perf_counter() - start
    sim = Simulation(scene, local, comm)
    del local
    setup = time.perf_counter() - start
    n = sim.state.n_owned
    X = sim.state.X[:n]
    sim.state.v[:n] = 1e-3 * np.sin(np.pi * X) * np.cos(np.pi * X[:, ::-1])
    for _ in range(3):
        sim.step()
    sim.stage_seconds.clear()
    comm.Barrier()
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
    comm.Barrier()
    seconds = time.perf_counter() - start
    halo = comm.allreduce(sim.stage_seconds["halo"], op=MPI.MAX)
    peak = comm.allreduce(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3, op=MPI.MAX)
    counts = comm.gather(n, root=0)
    if comm.rank == 0:
        print(json.dumps({"ranks": comm.size, "particles": int(sum(counts)), "owned": counts,
                          "build_s": build, "setup_s": setup, "step_ms": 1e3 * seconds / steps, "halo_ms": 1e3 * halo / steps, "peak_mb": peak,
                          "us_per_particle_step_core": 1e6 * seconds * comm.size / (steps * sum(counts))}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--side", type=int, default=60, help="particles per cube edge")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--json", default="results/bench_scaling.json")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(args.side, args.steps)
        return
    launcher = "mpiexec.mpich" if subprocess.run(["which", "mpiexec.mpich"], capture_output=True).returncode == 0 \
        else "mpiexec"
    rows = []
    for ranks in args.ranks:
        proc = subprocess.run([launcher, "-n", str(ranks), sys.executable, os.path.abspath(__file__), "--worker",
                               "--side", str(args.side), "--steps", str(args.steps)],
                              capture_output=True, text=True, env=dict(os.environ, NUMBA_NUM_THREADS="1"))
        if proc.returncode != 0:
            sys.exit(f"{ranks} rank(s) failed:\n{proc.stderr}")
        rows.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    base = rows[0]["step_ms"] * rows[0]["ranks"]
    print(f"{'ranks':>5} {'particles':>10} {'build s':>8} {'set-up s':>9} {'ms/step':>9} {'halo ms':>8} {'speed-up':>9} "
          f"{'efficiency':>10} {'us/particle-step/core':>22} {'peak MB/rank':>13}")
    for r in rows:
        r["speedup"] = base / r["step_ms"]
        r["efficiency"] = r["speedup"] / r["ranks"]
        print(f"{r['ranks']:5d} {r['particles']:10d} {r['build_s']:8.2f} {r['setup_s']:9.1f} {r['step_ms']:9.1f} {r['halo_ms']:8.2f} "
              f"{r['speedup']:9.2f} {r['efficiency']:10.2f} {r['us_per_particle_step_core']:22.3f} {r['peak_mb']:13.0f}")
    os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
