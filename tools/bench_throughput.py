#!/usr/bin/env python3
"""Throughput of the Lagrangian step on one core: microseconds per particle-step.

Elastic blocks in 2D and 3D (Saint Venant-Kirchhoff, cubic lattice, kernel radius 2.01 x
spacing as in MACHDYN examples), stepped from a small random velocity field, in the
formulations: total-Lagrangian with hourglass control off and on (alpha = 50, both forms),
with Hessian's-difference stabilisation (eta = 1), updated-Lagrangian with eta = 1 and
the reference updated every 3 steps (the paper's stress setting) or every 30, and [R]'s
symmetrised SPH, RLM, KBM with stress points and EFG with nodal and cell integration
and the Eulerian kernel for SPH, RLM, KBM and nodal EFG (neighbours searched at most every
30 steps, shape functions rebuilt at every step; timed over a quarter of the steps) (µs
per particle-step counts particles only, as [R] Tables 5-6 do); and total-Lagrangian with
alpha = 50 (paper form) with the J2 and the Johnson-Cook elasto-plastic laws (the return mapping's eigen
decomposition runs at every particle whether it yields or not) and with tensile damage; and
total-Lagrangian with alpha = 50 (paper form) as two bodies, the block's halves, in
contact across the middle (parsph.contact), against the same block as one body, with the
time of one contact search (ghosts and candidate lists) per particle. Each updated row also gives
the time of one reference update per particle. Compile time and set-up are excluded; each
case is timed over --steps steps after a warm-up. Prints a table and writes it as JSON.

usage: tools/bench_throughput.py [--particles-2d 40000] [--particles-3d 27000] [--steps 200]
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np

from mpi4py import MPI

from parsph import config
from parsph.build import build_local
from parsph.simulation import Simulation


LAWS = {"j2_plasticity": {"model": "j2_plasticity", "yield_stress": 1e6},
        "johnson_cook": {"model": "johnson_cook", "jc_a": 1e6, "jc_b": 1e6, "jc_n": 0.3, "jc_c": 0.01,
                         "room_temperature": 300.0, "melting_temperature": 1000.0, "specific_heat": 400.0},
        "damage": {"failure_strain": 0.08}}  # over the elastic block's material


def raw_block(dim: int, particles: int, alpha: float, form: str, eta: float = 0.0, every: int = 0,
              method: str = "tlsph", law: str = "") -> dict:
    """The block's scene as written (tools/bench_versions.py hands it to two versions); with
    law "contact" as its two halves in contact (halves_in_contact)."""
    side = round(particles ** (1 / dim))
    spacing = 1.0 / side
    raw = {
        "scene": {"name": f"block{dim}d", "dimension": dim},
        "geometry": {"parts": [{"shape": "box", "lower": [0.0] * dim, "upper": [1.0] * dim,
                                "spacing": spacing}]},
        "kernel": {"type": "cubic_spline", "support": 2.01},
        "material": {"model": "saint_venant_kirchhoff", "density": 1000.0, "youngs_modulus": 1e9,
                     "poisson_ratio": 0.3},
        "formulation": {"hourglass": alpha, "hourglass_form": form, "hessian": eta,
                        "type": "ulsph" if every else method.split("_")[0], "update_every": every},
        "time": {"end": 1.0},
    }
    raw["material"].update(LAWS.get(law, {}))
    if method.startswith("efg"):
        raw["formulation"]["integration"] = "cells" if method.endswith("_cells") else "nodal"
    if method.endswith("_eulerian"):
        raw["formulation"]["kernel"] = "eulerian"
    return halves_in_contact(raw) if law == "contact" else raw


def block(*args, **kwargs) -> dict:
    """The block's scene, validated (raw_block's arguments)."""
    return config.validate(raw_block(*args, **kwargs))


def halves_in_contact(raw: dict) -> dict:
    """The block's scene as two bodies, its halves (split at the lattice plane nearest
    x = 1/2), in contact."""
    part = raw["geometry"].pop("parts")[0]
    middle = round(0.5 / part["spacing"]) * part["spacing"]
    halves = []
    for k, (lo, hi) in enumerate(((0.0, middle), (middle, 1.0))):
        box = dict(part, lower=[lo] + part["lower"][1:], upper=[hi] + part["upper"][1:])
        halves.append({"name": f"half{k}", "parts": [box], "material": raw.pop("material") if k == 0 else
                       dict(halves[0]["material"])})
    raw["bodies"] = halves
    raw["contact"] = [{"bodies": ["half0", "half1"]}]
    return raw


def measure(dim, particles, alpha, form, steps, eta=0.0, every=0, method="tlsph", law=""):
    scene = block(dim, particles, alpha, form, eta, every, method, law)
    sim = Simulation(scene, build_local(scene, MPI.COMM_SELF), MPI.COMM_SELF)
    rng = np.random.default_rng(0)
    sim.state.v[: sim.state.n_owned] = 1e-3 * rng.standard_normal(sim.state.v[: sim.state.n_owned].shape)
    for _ in range(5):
        sim.step()
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
    seconds = time.perf_counter() - start
    n = sim.state.n_owned
    pairs = int(sim.topology.relations[0].ref.ptr[-1])
    update = sim.stage_seconds.get("reference update", 0.0) / max(sim.topology.count, 1)
    if sim.interactions.contact:  # a contact search, timed alone
        x = sim.state.X[:n] + sim.state.u[:n]
        start = time.perf_counter()
        for _ in range(5):
            sim.interactions.contact.search(x)
        update = (time.perf_counter() - start) / 5
    return {"method": method + (f" + {law}" if law else ""), "dim": dim, "particles": n, "neighbours": pairs / max(n, 1), "alpha": alpha,
            "hourglass_form": form if alpha > 0 else "-", "eta": eta, "update_every": every,
            "steps": steps, "us_per_particle_step": 1e6 * seconds / (steps * n),
            "us_per_particle_update": 1e6 * update / n}


# (formulation, alpha, hourglass form, eta, update every N steps)
CASES = (("tlsph", 0.0, "variational", 0.0, 0), ("tlsph", 50.0, "paper", 0.0, 0),
         ("tlsph", 50.0, "variational", 0.0, 0), ("tlsph", 0.0, "variational", 1.0, 0),
         ("tlsph", 0.0, "variational", 1.0, 3), ("tlsph", 0.0, "variational", 1.0, 30),
         ("sph", 0.0, "variational", 0.0, 0), ("rlm", 0.0, "variational", 0.0, 0),
         ("kbm", 0.0, "variational", 0.0, 0), ("efg", 0.0, "variational", 0.0, 0),
         ("efg_cells", 0.0, "variational", 0.0, 0), ("sph_eulerian", 0.0, "variational", 0.0, 0),
         ("rlm_eulerian", 0.0, "variational", 0.0, 0), ("kbm_eulerian", 0.0, "variational", 0.0, 0),
         ("efg_eulerian", 0.0, "variational", 0.0, 0), ("tlsph", 50.0, "paper", 0.0, 0, "j2_plasticity"),
         ("tlsph", 50.0, "paper", 0.0, 0, "johnson_cook"),
         ("tlsph", 50.0, "paper", 0.0, 0, "damage"), ("tlsph", 50.0, "paper", 0.0, 0, "contact"))
NAMES = {"tlsph": "TL", "sph": "SPH", "rlm": "RLM", "kbm": "KBM", "efg": "EFG nodal", "efg_cells": "EFG cells",
         "sph_eulerian": "SPH Eul.", "rlm_eulerian": "RLM Eul.", "kbm_eulerian": "KBM Eul.",
         "efg_eulerian": "EFG Eul."}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles-2d", type=int, default=40000)
    ap.add_argument("--particles-3d", type=int, default=27000)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--json", default="results/bench_throughput.json")
    args = ap.parse_args()
    rows = []
    for dim, count in ((2, args.particles_2d), (3, args.particles_3d)):
        for method, alpha, form, eta, every, *law in CASES:
            steps = args.steps // 4 if method.endswith("_eulerian") else args.steps
            rows.append(measure(dim, count, alpha, form, steps, eta, every, method, *law))
            r = rows[-1]
            kind = f"UL every {every:2d}" if every else (NAMES[method] + (f" {law[0]}" if law else "")).ljust(11)
            print(f"{r['dim']}D  {r['particles']:7d} particles  {r['neighbours']:5.1f} neighbours  {kind} "
                  f"alpha {r['alpha']:4.0f} {r['hourglass_form']:11s} eta {eta:3.1f}  "
                  f"{r['us_per_particle_step']:.3f} us/particle-step"
                  + (f"  (an update {r['us_per_particle_update']:.2f} us/particle)" if r["update_every"]
                     or method.endswith("_eulerian") else "")
                  + (f"  (a search {r['us_per_particle_update']:.2f} us/particle)" if law == ["contact"] else ""),
                  flush=True)
    os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
    with open(args.json, "w") as fh:
        json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
