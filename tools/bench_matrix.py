#!/usr/bin/env python3
"""Accuracy per second: formulation x stabilisation x resolution on problems with an answer.

Problems: the beam of [G §4.2] (compliance against Euler-Bernoulli, C = 53657 N/m) and the
1D bar of [V §3.3.1] (tip displacement over two periods against the Fourier series).
Variants: total-Lagrangian SPH with alpha = 0, alpha = 50 (paper form) and alpha = 50
(variational form) on both problems; on the bar also Hessian's-difference stabilisation
(eta = 0.3) and the updated-Lagrangian formulation with the reference updated every 3
steps, without and with eta = 0.3 [V §3.3-3.4]; on the beam the updated formulation with
eta = 0.3 and an update every 30 steps. For every case it records the error, the wall time of the time loop
(set-up and compilation excluded), microseconds per particle-step and the bytes of solver
arrays per particle; it fits convergence rates and writes a table (CSV, JSON) and plots:
error against wall time (work-precision), error against resolution, throughput.

The `stress` preset runs stability stress tests instead: the random patch for 1000
periods, the random patch with its reference updated every step (20 periods, with and
without stabilisation), a block spinning at high speed, the rubber strip pulled to 500 %, recording
whether and when a run fails and how its disorder and hourglass energy grow (energies
relative to the largest kinetic + strain energy of the run).

The ranks are a dimension of the matrix: run the script under `mpiexec -n R` and every case
runs decomposed over R ranks (rank 0 reports; results go to OUT/PRESET_rR).

usage: [mpiexec -n R] tools/bench_matrix.py [--preset quick|full|stress] [--out results/bench_matrix]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))

from mpi4py import MPI  # noqa: E402
from physics import simulation  # noqa: E402

from parsph.analytic import bar_tip_displacement, cantilever_stiffness  # noqa: E402
from parsph.errors import ParsphError  # noqa: E402

UL3 = ["formulation.type='ulsph'", "formulation.update_every=3"]
VARIANTS = {  # name: (overrides, problems)
    "TL a=0": (["formulation.hourglass=0"], ("beam", "bar")),
    "TL a=50 paper": (["formulation.hourglass=50", "formulation.hourglass_form='paper'"], ("beam",)),
    "TL a=50 variational": (["formulation.hourglass=50", "formulation.hourglass_form='variational'"],
                            ("beam",)),
    "UL30 eta=0.3": (["formulation.type='ulsph'", "formulation.update_every=30", "formulation.hourglass=0",
                      "formulation.hessian=0.3"], ("beam",)),
    "TL eta=0.3": (["formulation.hessian=0.3"], ("bar",)),
    "UL3 eta=0": (UL3, ("bar",)),
    "UL3 eta=0.3": (UL3 + ["formulation.hessian=0.3"], ("bar",)),
}
PRESETS = {"quick": {"beam": (4, 8), "bar": (40, 80, 160)},
           "full": {"beam": (4, 8, 16, 32), "bar": (40, 80, 160, 320, 640)}}


COMM = MPI.COMM_WORLD


def say(text: str) -> None:
    if COMM.rank == 0:
        print(text, flush=True)


def solver_bytes(sim) -> int:
    """Bytes of solver arrays over all ranks (ghost copies included)."""
    return COMM.allreduce(sum(v.nbytes for v in vars(sim).values() if isinstance(v, np.ndarray)))


def timed_run(sim, end, probe=None, every=1):
    values, times = [], []
    start = time.perf_counter()
    while sim.t < end * (1 - 1e-12):
        sim.step()
        if probe is not None and sim.step_count % every == 0:
            values.append(probe(sim))
            times.append(sim.t)
    return COMM.allreduce(time.perf_counter() - start, op=MPI.MAX), np.array(times), np.array(values)


def beam_case(n, overrides):
    sim = simulation("beam_bending", [f"parameters.n={n}"] + overrides, comm=COMM)
    seconds, _, _ = timed_run(sim, sim.scene["time"]["end"])
    reaction = -COMM.allreduce(sim.reaction()[sim.group_index("tip"), 1].sum()) / 1e-4
    exact = cantilever_stiffness(100e9, 0.3, 8e-3, 1e-3, 1e-3)
    return sim, seconds, abs(reaction / exact - 1), n


def bar_case(particles, overrides):
    sim = simulation("bar1d", [f"geometry.parts.0.spacing={1.0 / (particles - 1)!r}"] + overrides, comm=COMM)
    c = np.sqrt(200e9 / 7850)

    def tip(s):  # the free end B, wherever it is owned
        return COMM.allreduce(float(s.u[s.group_index("B"), 0].sum()))

    seconds, t, u = timed_run(sim, 8.0 / c, probe=tip, every=5)
    exact = bar_tip_displacement(t, 1.0, c, 5.0)
    return sim, seconds, np.linalg.norm(u - exact) / np.linalg.norm(exact), particles


def accuracy(preset: str, out: str) -> None:
    rows = []
    for problem, maker in (("beam", beam_case), ("bar", bar_case)):
        for variant, (overrides, problems) in VARIANTS.items():
            if problem not in problems:
                continue
            for resolution in PRESETS[preset][problem]:
                sim, seconds, error, res = maker(resolution, overrides)
                n = sim.decomp.total
                rows.append({"problem": problem, "variant": variant, "ranks": COMM.size, "resolution": res,
                             "particles": n,
                             "steps": sim.step_count, "error": error, "seconds": seconds,
                             "us_per_particle_step": 1e6 * seconds * COMM.size / (n * sim.step_count),
                             "bytes_per_particle": solver_bytes(sim) / n})
                r = rows[-1]
                say(f"{problem:5s} {variant:20s} res {res:4d}  N {n:6d}  error {error:.3e}  "
                    f"{seconds:7.2f} s  {r['us_per_particle_step']:.3f} us/p-step (x {COMM.size} rank(s))  "
                    f"{r['bytes_per_particle']:.0f} B/particle")
    rates = {}
    for problem in ("beam", "bar"):
        for variant in VARIANTS:
            sel = [r for r in rows if r["problem"] == problem and r["variant"] == variant]
            if len(sel) >= 2:
                x = np.log([r["resolution"] for r in sel])
                y = np.log([r["error"] for r in sel])
                rates[f"{problem} {variant}"] = float(np.polyfit(x, y, 1)[0])
    say("fitted convergence rates (slope of log error vs log resolution):")
    for k, v in rates.items():
        say(f"  {k:28s} {v:6.2f}")
    if COMM.rank == 0:
        write(rows, {"rates": rates}, out)
        plot(rows, out)


def stress(out: str, only: str = "") -> None:
    cases = [
        ("patch alpha=0, 1000 periods", "patch_random", ["formulation.hourglass=0"], 1550.0),
        ("patch alpha=50 variational, 1000 periods", "patch_random", [], 1550.0),
        ("patch alpha=50 paper, 1000 periods", "patch_random", ['formulation.hourglass_form="paper"'], 1550.0),
        ("rubber pull to 500 %, coarse", "rubber_pull", ["parameters.l0=1.3333333333333333e-4"], 5.0e-4),
        ("patch UL every step, no stabilisation, 20 periods", "patch_random",
         ["formulation.type='ulsph'", "formulation.update_every=1", "formulation.hourglass=0"], 31.0),
        ("patch UL every step, eta=0.3, 20 periods", "patch_random",
         ["formulation.type='ulsph'", "formulation.update_every=1", "formulation.hourglass=0",
          "formulation.hessian=0.3"], 31.0),
        ("patch UL every step, alpha=50, 20 periods", "patch_random",
         ["formulation.type='ulsph'", "formulation.update_every=1"], 31.0),
    ]
    spin = ("spin at 0.3 x wave speed, 50 turns", "patch_random",
            ["formulation.hourglass=50", "time.end=1.0"], None)
    rows = []
    for name, scene, overrides, end in [c for c in cases + [spin] if only in c[0]]:
        sim = simulation(scene, overrides)
        if end is None:  # rigid spin: surface speed 0.3 c about the centre
            omega = 0.3 * sim.bodies[0].constants.wave_speed / 0.5
            rel = sim.X[: sim.n_owned] - 0.5
            sim.u[:] = 0.0
            sim.v[: sim.n_owned] = omega * np.stack([-rel[:, 1], rel[:, 0]], axis=1)
            sim.compute_forces()
            end = 50 * 2 * np.pi / omega
        first = sim.diagnostics()
        e0 = first["total_energy"]
        scale = first["kinetic_energy"] + first["strain_energy"]  # energies are reported relative to it
        worst, failed, start = 0.0, None, time.perf_counter()
        samples = []
        try:
            while sim.t < end:
                sim.step()
                if sim.step_count % 200 == 0:
                    d = sim.diagnostics()
                    worst = max(worst, d["disorder"])
                    scale = max(scale, d["kinetic_energy"] + d["strain_energy"])
                    samples.append((sim.t, d["disorder"], d["hourglass_energy"], d["total_energy"]))
        except ParsphError as exc:
            failed = f"t = {sim.t:.4g}: {str(exc)[:60]}"
        last = samples[-1] if samples else (0, 0, 0, e0)
        rows.append({"case": name, "end": end, "reached": sim.t, "failed": failed or "", "max_disorder": worst,
                     "final_hourglass_energy": last[2] / scale, "energy_change": (last[3] - e0) / scale,
                     "seconds": time.perf_counter() - start})
        r = rows[-1]
        print(f"{name:42s} {'FAILED ' + failed if failed else 'ok':10s} max disorder {worst:8.3g}  "
              f"hourglass energy {r['final_hourglass_energy']:8.2e} E  energy change {r['energy_change']:+.2e} E  "
              f"{r['seconds']:.0f} s", flush=True)
    write(rows, {}, out)


def write(rows, extra, out):
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "table.csv"), "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    with open(os.path.join(out, "table.json"), "w") as fh:
        json.dump({"rows": rows, **extra}, fh, indent=2)


def plot(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    for problem, marker in (("beam", "o"), ("bar", "s")):
        for variant in VARIANTS:
            sel = [r for r in rows if r["problem"] == problem and r["variant"] == variant]
            if not sel:
                continue
            label = f"{problem}, {variant}"
            axes[0].loglog([r["seconds"] for r in sel], [r["error"] for r in sel], marker=marker, label=label)
            axes[1].loglog([r["resolution"] for r in sel], [r["error"] for r in sel], marker=marker, label=label)
            axes[2].semilogx([r["particles"] for r in sel], [r["us_per_particle_step"] for r in sel],
                             marker=marker, label=label)
    axes[0].set(xlabel="wall time of the time loop [s]", ylabel="relative error", title="work-precision")
    axes[1].set(xlabel="resolution (beam: n, bar: particles)", ylabel="relative error", title="convergence")
    axes[2].set(xlabel="particles", ylabel="µs per particle-step x ranks",
                title=f"throughput ({COMM.size} rank(s))")
    axes[2].xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # no crowded minor labels
    for ax in axes:
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "work_precision.png"), dpi=110)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=("quick", "full", "stress"), default="quick")
    ap.add_argument("--only", default="", help="stress preset: only the cases whose name contains this")
    ap.add_argument("--out", default="results/bench_matrix")
    args = ap.parse_args()
    if args.preset == "stress":
        if COMM.size > 1:
            sys.exit("the stress preset runs on one rank")
        stress(os.path.join(args.out, "stress"), args.only)
    else:
        accuracy(args.preset, os.path.join(args.out, args.preset + (f"_r{COMM.size}" if COMM.size > 1 else "")))


if __name__ == "__main__":
    main()
