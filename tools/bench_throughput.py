#!/usr/bin/env python3
"""Throughput of the total-Lagrangian step on one core: microseconds per particle-step.

Elastic blocks in 2D and 3D (Saint Venant-Kirchhoff, cubic lattice, kernel radius 2.01 x
spacing as in MACHDYN examples), hourglass control off and on (alpha = 50), stepped from
a small random velocity field. Compile time and set-up are excluded; each case is timed
over --steps steps after a warm-up. Prints a table and writes it as JSON.

usage: tools/bench_throughput.py [--particles-2d 40000] [--particles-3d 27000] [--steps 200]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from mpi4py import MPI  # noqa: E402

from parsph import config  # noqa: E402
from parsph.build import build_body  # noqa: E402
from parsph.parallel.decomposition import distribute  # noqa: E402
from parsph.solver import Simulation  # noqa: E402


def block(dim: int, particles: int, alpha: float, form: str) -> dict:
    side = round(particles ** (1 / dim))
    spacing = 1.0 / side
    raw = {
        "scene": {"name": f"block{dim}d", "dimension": dim},
        "geometry": {"parts": [{"shape": "box", "lower": [0.0] * dim, "upper": [1.0] * dim,
                                "spacing": spacing}]},
        "kernel": {"type": "cubic_spline", "support": 2.01},
        "material": {"model": "saint_venant_kirchhoff", "density": 1000.0, "youngs_modulus": 1e9,
                     "poisson_ratio": 0.3},
        "formulation": {"hourglass": alpha, "hourglass_form": form},
        "time": {"end": 1.0},
    }
    return config.validate(raw)


def measure(dim, particles, alpha, form, steps):
    scene = block(dim, particles, alpha, form)
    sim = Simulation(scene, distribute(build_body(scene), MPI.COMM_SELF), MPI.COMM_SELF)
    rng = np.random.default_rng(0)
    sim.v[: sim.n_owned] = 1e-3 * rng.standard_normal(sim.v[: sim.n_owned].shape)
    for _ in range(5):
        sim.step()
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
    seconds = time.perf_counter() - start
    n = sim.n_owned
    pairs = int(sim.ref.ptr[-1])
    return {"dim": dim, "particles": n, "neighbours": pairs / max(n, 1), "alpha": alpha,
            "hourglass_form": form if alpha > 0 else "-", "steps": steps,
            "us_per_particle_step": 1e6 * seconds / (steps * n)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles-2d", type=int, default=40000)
    ap.add_argument("--particles-3d", type=int, default=27000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--json", default="results/bench_throughput.json")
    args = ap.parse_args()
    rows = []
    for dim, count in ((2, args.particles_2d), (3, args.particles_3d)):
        for alpha, form in ((0.0, "variational"), (50.0, "paper"), (50.0, "variational")):
            rows.append(measure(dim, count, alpha, form, args.steps))
            r = rows[-1]
            print(f"{r['dim']}D  {r['particles']:7d} particles  {r['neighbours']:5.1f} neighbours  "
                  f"alpha {r['alpha']:4.0f} {r['hourglass_form']:11s}  "
                  f"{r['us_per_particle_step']:.3f} us/particle-step", flush=True)
    os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
