#!/usr/bin/env python3
"""Accuracy per second: formulation x stabilisation x resolution on problems with an answer.

Problems: the beam of [G §4.2] (compliance against Euler-Bernoulli, C = 53657 N/m) and the
1D bar of [V §3.3.1] (tip displacement over two periods against the Fourier series).
Variants: total-Lagrangian SPH with alpha = 0, alpha = 50 (paper form) and alpha = 50
(variational form) on both problems; on the bar also Hessian's-difference stabilisation
(eta = 0.3) and the updated-Lagrangian formulation with the reference updated every 3
steps, without and with eta = 0.3 [V §3.3-3.4]; on the beam the updated formulation with
eta = 0.3 and an update every 30 steps.

And Rabczuk, Belytschko & Xiao's two benchmarks [R §9.1-9.2], for every
method x kernel of the table METHODS (one line a row): corrected SPH (tlsph) with alpha = 0
and 50, symmetrised SPH (and, on the cantilever, SPH with the support of n = 4 kept at every
resolution, [R Fig. 7]), RLM, KBM, EFG with nodal and with cell integration, each with the
Lagrangian kernel, and the Eulerian kernel (formulation.kernel = 'eulerian') where parsph
has it; a row the scene's configuration refuses is printed as "skipped: <message>".
- `cantilever`: Timoshenko & Goodier's beam (runs/cantilever.toml) at n particles across
  the depth; errors L2 of u [R eq. 71-72] and energy norm [R eq. 73-74] over each method's
  own integration points, by tools/bench_cantilever.py's `errors` (the particles and
  integration points of all ranks gathered to rank 0 for it). `error` = the energy norm.
- `rod`: the free rod with a Gaussian velocity pulse (runs/rod.toml) at n particles across
  its 5 mm height (n = 40: [R]'s 0.125 mm, 19,200 particles); the velocity error of [R]
  eq. 75 when the pulse is back in place, at 0.01155 and 0.0231 ms (snapshots taken as
  `parsph run` takes them, judged by tools/rod_error.py's `rod_errors`), printed beside
  [R] Table 3. `error` = the error at 0.0231 ms.

For every case it records the error(s), the wall time of the time loop (set-up,
compilation and the rod's snapshots excluded), microseconds per particle-step and the bytes
of solver arrays per particle; it fits convergence rates and writes a table (CSV, JSON) and
plots: for beam and bar error against wall time (work-precision), error against resolution,
throughput (work_precision.png); for the cantilever and the rod each error against wall
time, one colour and marker per method (cantilever.png, rod.png; the cantilever's also
against n).

The `stress` preset runs stability stress tests instead: the random patch for 1000
periods, the random patch with its reference updated every step (20 periods, with and
without stabilisation), a block spinning at high speed, the rubber strip pulled to 500 %, recording
whether and when a run fails and how its disorder and hourglass energy grow (energies
relative to the largest kinetic + strain energy of the run).

The ranks are a dimension of the matrix: run the script under `mpiexec -n R` and every case
runs decomposed over R ranks (rank 0 reports; results go to OUT/PRESET_rR).

Presets: quick (a few minutes on 2 cores: beam n = 4, 8; bar 40-160 particles; cantilever
n = 4, 8, with the Eulerian kernel n = 4 only; rod n = 10, 4 x [R]'s spacing), full (beam n = 4-32; bar 40-640; cantilever
n = 4, 8, 16; rod n = 40, [R]'s spacing), stress.

usage: [mpiexec -n R] tools/bench_matrix.py [--preset quick|full|stress] [--problems beam bar cantilever rod]
                                            [--only TEXT] [--out results/bench_matrix]
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shutil
import sys
import tempfile
import time
from collections import namedtuple
from types import SimpleNamespace

import numpy as np

from bench_cantilever import errors as cantilever_errors
from mpi4py import MPI
from rod_error import PAPER as ROD_PAPER
from rod_error import rod_errors

from parsph import config, readouts
from parsph.api import build, load_scene
from parsph.analytic import bar_tip_displacement, cantilever_stiffness
from parsph.build import build_local
from parsph.errors import InputError, ParsphError
from parsph.io.snapshots import SnapshotWriter
from parsph.simulation import Simulation

RUNS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "runs")
UL3 = ["formulation.type='ulsph'", "formulation.update_every=3"]


def scene_from(name: str, overrides=()) -> dict:
    """The resolved scene runs/NAME.toml with `--set`-style overrides."""
    return load_scene(os.path.join(RUNS, f"{name}.toml"), overrides)


def simulation(name: str, overrides=(), comm=MPI.COMM_SELF):
    return build(scene_from(name, overrides), comm)
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


def fixed_support(n: int) -> str:
    """The support of n = 4 at every resolution n of the cantilever (as bench_cantilever's sph_fixed)."""
    return f"kernel.support={2.0 * n / 4!r}"


# [R]'s methods x kernels on the cantilever and the rod: one line a row. `overrides` are
# --set texts or functions of the resolution giving one; `paper` is the row's key in
# [R] Table 3 (rod_error.PAPER). A row the scene's configuration refuses is skipped.
Method = namedtuple("Method", "name overrides problems paper", defaults=(None,))
RB = ("cantilever", "rod")
EULERIAN = "formulation.kernel='eulerian'"
METHODS = [
    Method("TL a=50", ["formulation.type='tlsph'", "formulation.hourglass=50"], RB),
    Method("TL a=0", ["formulation.type='tlsph'", "formulation.hourglass=0"], RB),
    Method("SPH", ["formulation.type='sph'"], RB, "sph"),
    Method("SPH fixed support", ["formulation.type='sph'", fixed_support], ("cantilever",)),
    Method("RLM", ["formulation.type='rlm'"], RB, "rlm"),
    Method("KBM", ["formulation.type='kbm'"], RB, "kbm"),
    Method("EFG nodal", ["formulation.type='efg'", "formulation.integration='nodal'"], RB, "efg_nodal"),
    Method("EFG cells", ["formulation.type='efg'", "formulation.integration='cells'"], RB, "efg_cells"),
    Method("SPH Eulerian", ["formulation.type='sph'", EULERIAN], RB),
    Method("RLM Eulerian", ["formulation.type='rlm'", EULERIAN], RB),
    Method("KBM Eulerian", ["formulation.type='kbm'", EULERIAN], RB),
    Method("EFG nodal Eulerian", ["formulation.type='efg'", "formulation.integration='nodal'", EULERIAN], RB),
]
ROD_HEIGHT = 0.005  # runs/rod.toml: parameters.H; resolution n sets the spacing H / n
RB_SCENES = {  # problem: (scene in runs/, overrides of the resolution n)
    "cantilever": ("cantilever", lambda n: [f"parameters.n={n}"]),
    "rod": ("rod", lambda n: [f"parameters.dx={ROD_HEIGHT / n!r}"]),
}
PROBLEMS = ("beam", "bar", "cantilever", "rod")
# "PROBLEM eulerian": other resolutions for the rows with the Eulerian kernel (its reference
# rebuilt at every step costs 10-100 times a Lagrangian step: quick runs them coarsest only)
PRESETS = {"quick": {"beam": (4, 8), "bar": (40, 80, 160), "cantilever": (4, 8), "rod": (10,),
                     "cantilever eulerian": (4,)},
           "full": {"beam": (4, 8, 16, 32), "bar": (40, 80, 160, 320, 640), "cantilever": (4, 8, 16),
                    "rod": (40,)}}


COMM = MPI.COMM_WORLD


def say(text: str) -> None:
    if COMM.rank == 0:
        print(text, flush=True)


def solver_bytes(sim) -> int:
    """Bytes of solver arrays over all ranks (ghost copies included)."""
    return COMM.allreduce(sum(v.nbytes for v in vars(sim).values() if isinstance(v, np.ndarray)))


def timed_run(sim, end, probe=None, every=1, at=None, clip=False):
    """Step to `end`: (wall time of the loop, the slowest rank's; times; probe values).
    probe(sim) runs every `every` steps, inside the timing, or, with `at` (times), once at
    the first step reaching each of them, outside it (as `parsph run` takes snapshots).
    `clip` shortens the last step to end at `end` exactly (sim.step(end), as `parsph run`
    and bench_cantilever step)."""
    values, times = [], []
    pending = sorted(at) if at is not None else []
    seconds, start = 0.0, time.perf_counter()
    while sim.t < end * (1 - 1e-12):
        sim.step(end if clip else math.inf)
        if probe is None:
            continue
        if at is None:
            if sim.step_count % every == 0:
                values.append(probe(sim))
                times.append(sim.t)
        elif pending and sim.t >= pending[0] * (1 - 1e-12):
            seconds += time.perf_counter() - start
            while pending and pending[0] <= sim.t * (1 + 1e-12):
                pending.pop(0)
            values.append(probe(sim))
            times.append(sim.t)
            start = time.perf_counter()
    seconds += time.perf_counter() - start
    return COMM.allreduce(seconds, op=MPI.MAX), np.array(times), np.array(values)


def beam_case(n, overrides):
    sim = simulation("beam_bending", [f"parameters.n={n}"] + overrides, comm=COMM)
    seconds, _, _ = timed_run(sim, sim.scene.time.end)
    reaction = -COMM.allreduce(sim.conditions.reaction(sim.state)[sim.group_index("tip"), 1].sum()) / 1e-4
    exact = cantilever_stiffness(100e9, 0.3, 8e-3, 1e-3, 1e-3)
    return sim, seconds, abs(reaction / exact - 1), n


def bar_case(particles, overrides):
    sim = simulation("bar1d", [f"geometry.parts.0.spacing={1.0 / (particles - 1)!r}"] + overrides, comm=COMM)
    c = np.sqrt(200e9 / 7850)

    def tip(s):  # the free end B, wherever it is owned
        return COMM.allreduce(float(s.state.u[s.group_index("B"), 0].sum()))

    seconds, t, u = timed_run(sim, 8.0 / c, probe=tip, every=5)
    exact = bar_tip_displacement(t, 1.0, c, 5.0)
    return sim, seconds, np.linalg.norm(u - exact) / np.linalg.norm(exact), particles


def gathered(sim):
    """On rank 0, the owned particles and integration points of every rank, as an object
    with what bench_cantilever.errors reads of a Simulation; None on the other ranks."""
    n = sim.state.n_owned
    parts = COMM.gather((sim.state.X[:n], sim.state.u[:n], sim.state.volume[:n], *readouts.quadrature(sim)), root=0)
    if COMM.rank != 0:
        return None
    X, u, volume, Xq, Fq, wq = (np.concatenate(p) for p in zip(*parts))
    return SimpleNamespace(scene=sim.scene, bodies=sim.state.bodies, n_owned=len(X), X=X, u=u, volume=volume,
                           quadrature=lambda: (Xq, Fq, wq))


def cantilever_case(scene):
    """Dynamic relaxation to rest; {L2 error of u, energy-norm error} [R eq. 71-74]."""
    sim = Simulation(scene, build_local(scene, COMM), COMM)
    seconds, _, _ = timed_run(sim, scene.time.end, clip=True)
    proxy = gathered(sim)
    l2, energy = COMM.bcast(cantilever_errors(proxy) if COMM.rank == 0 else None, root=0)
    return sim, seconds, {"error_l2": l2, "error_energy": energy}


def rod_times(scene) -> list:
    """The rod's snapshot times: every output.snapshot_interval up to time.end."""
    interval, end = scene.output.snapshot_interval, scene.time.end
    return [k * interval for k in range(1, int(round(end / interval)) + 1)]


def rod_column(t: float) -> str:
    return f"error_{t * 1e3:.4g}ms"


def rod_case(scene):
    """The pulse's run; {velocity error [R eq. 75] at each snapshot time}. The snapshots go
    through parsph's own writer to a temporary directory that rod_error.rod_errors reads."""
    sim = Simulation(scene, build_local(scene, COMM), COMM)
    folder = COMM.bcast(tempfile.mkdtemp(prefix="bench_matrix_rod_") if COMM.rank == 0 else None, root=0)
    try:
        if COMM.rank == 0:
            with open(os.path.join(folder, "scene.json"), "w") as fh:
                json.dump(scene.as_dict(), fh)
        writer = SnapshotWriter(folder, config.to_json(scene), COMM)
        fields = ["position", "velocity", "displacement"]
        seconds, _, _ = timed_run(sim, scene.time.end, probe=lambda s: writer.write(s, fields),
                                  at=rod_times(scene), clip=True)
        found = COMM.bcast(rod_errors(folder) if COMM.rank == 0 else None, root=0)  # after every write
    finally:
        if COMM.rank == 0:
            shutil.rmtree(folder, ignore_errors=True)
    # the columns are named by the nominal times (a snapshot is taken at the first step past one)
    return sim, seconds, {rod_column(t): row[2] for t, row in zip(rod_times(scene), found, strict=True)}


def rb_rows(preset: str, problem: str, only: str) -> list:
    """The rows of [R]'s `problem` for every method of METHODS at the preset's resolutions."""
    rows = []
    name, resolution_overrides = RB_SCENES[problem]
    for method in METHODS:
        if problem not in method.problems or only not in method.name:
            continue
        resolutions = PRESETS[preset][problem]
        if EULERIAN in method.overrides:
            resolutions = PRESETS[preset].get(f"{problem} eulerian", resolutions)
        for res in resolutions:
            overrides = [o(res) if callable(o) else o for o in method.overrides] + resolution_overrides(res)
            try:
                scene = scene_from(name, overrides)
            except (InputError, ParsphError) as exc:  # the configuration refuses the row
                say(f"{problem:10s} {method.name:20s} skipped: {exc}")
                break
            sim, seconds, errors = (cantilever_case if problem == "cantilever" else rod_case)(scene)
            n = sim.state.decomp.total
            primary = errors["error_energy" if problem == "cantilever" else rod_column(rod_times(scene)[-1])]
            rows.append({"problem": problem, "variant": method.name, "ranks": COMM.size, "resolution": res,
                         "particles": n, "steps": sim.step_count, "error": primary, **errors, "seconds": seconds,
                         "us_per_particle_step": 1e6 * seconds * COMM.size / (n * sim.step_count),
                         "bytes_per_particle": solver_bytes(sim) / n})
            r = rows[-1]
            paper = ROD_PAPER.get(method.paper) if problem == "rod" else None
            text = "  ".join(f"{k[6:]} {v:.3e}" for k, v in errors.items())
            say(f"{problem:10s} {method.name:20s} n {res:3d}  N {n:6d}  error {text}"
                + (f"  [R] {paper[0]:.4f} {paper[1]:.4f}" if paper else "")
                + f"  {seconds:7.2f} s  {r['us_per_particle_step']:.3f} us/p-step (x {COMM.size} rank(s))  "
                  f"{r['bytes_per_particle']:.0f} B/particle")
    return rows


def accuracy(preset: str, out: str, problems=PROBLEMS, only: str = "") -> None:
    rows = []
    for problem, maker in (("beam", beam_case), ("bar", bar_case)):
        if problem not in problems:
            continue
        for variant, (overrides, variant_problems) in VARIANTS.items():
            if problem not in variant_problems or only not in variant:
                continue
            for resolution in PRESETS[preset][problem]:
                sim, seconds, error, res = maker(resolution, overrides)
                n = sim.state.decomp.total
                rows.append({"problem": problem, "variant": variant, "ranks": COMM.size, "resolution": res,
                             "particles": n,
                             "steps": sim.step_count, "error": error, "seconds": seconds,
                             "us_per_particle_step": 1e6 * seconds * COMM.size / (n * sim.step_count),
                             "bytes_per_particle": solver_bytes(sim) / n})
                r = rows[-1]
                say(f"{problem:5s} {variant:20s} res {res:4d}  N {n:6d}  error {error:.3e}  "
                    f"{seconds:7.2f} s  {r['us_per_particle_step']:.3f} us/p-step (x {COMM.size} rank(s))  "
                    f"{r['bytes_per_particle']:.0f} B/particle")
    for problem in RB:
        if problem in problems:
            rows += rb_rows(preset, problem, only)
    if not rows:
        say("no cases selected")
        return
    rates = {}
    for problem in PROBLEMS:
        for variant in dict.fromkeys(r["variant"] for r in rows if r["problem"] == problem):
            sel = [r for r in rows if r["problem"] == problem and r["variant"] == variant]
            if len(sel) < 2:
                continue
            x = np.log([r["resolution"] for r in sel])
            keys = ["error"] if problem in ("beam", "bar") else [k for k in sel[0] if k.startswith("error_")]
            for key in keys:
                name = f"{problem} {variant}" + ("" if key == "error" else f" {key[6:]}")
                rates[name] = float(np.polyfit(x, np.log([r[key] for r in sel]), 1)[0])
    if rates:
        say("fitted convergence rates (slope of log error vs log resolution):")
    for k, v in rates.items():
        say(f"  {k:40s} {v:6.2f}")
    if COMM.rank == 0:
        extra = {"rates": rates}
        if any(r["problem"] == "rod" for r in rows):
            extra["rod_paper_table3"] = {m.name: ROD_PAPER[m.paper] for m in METHODS if m.paper}
        write(rows, extra, out)
        plot(rows, out)
        plot_rb(rows, out)


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
            omega = 0.3 * sim.state.bodies[0].constants.wave_speed / 0.5
            rel = sim.state.X[: sim.state.n_owned] - 0.5
            sim.state.u[:] = 0.0
            sim.state.v[: sim.state.n_owned] = omega * np.stack([-rel[:, 1], rel[:, 0]], axis=1)
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
    fields = list(dict.fromkeys(k for r in rows for k in r))  # every row's columns, in order
    with open(os.path.join(out, "table.csv"), "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, restval="")
        writer.writeheader()
        writer.writerows(rows)
    with open(os.path.join(out, "table.json"), "w") as fh:
        json.dump({"rows": rows, **extra}, fh, indent=2)


def plot(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    if not any(r["problem"] in ("beam", "bar") for r in rows):
        return
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


def plot_rb(rows, out):
    """cantilever.png, rod.png: each error against the wall time of the time loop (top row)
    and, with several resolutions, against n (bottom row); one colour and marker per method
    of METHODS, the Eulerian kernel dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    colours = list(plt.get_cmap("tab10").colors) + ["black", "goldenrod", "darkslategray", "lime"]
    markers = "osD^v<>pPX*hH8d"
    style = {m.name: dict(color=colours[k % len(colours)], marker=markers[k % len(markers)],
                          linestyle="--" if EULERIAN in m.overrides else "-")
             for k, m in enumerate(METHODS)}
    titles = {"cantilever": ("Timoshenko-Goodier cantilever [R §9.1] (runs/cantilever.toml)", "depth"),
              "rod": ("rod, Gaussian velocity pulse [R §9.2] (runs/rod.toml)", "height")}
    labels = {"error_l2": "L2 error of u [R eq. 71]", "error_energy": "energy-norm error [R eq. 73]"}
    for problem in RB:
        mine = [r for r in rows if r["problem"] == problem]
        if not mine:
            continue
        keys = list(dict.fromkeys(k for r in mine for k in r if k.startswith("error_")))
        resolutions = sorted({r["resolution"] for r in mine})
        xs = ["seconds"] + (["resolution"] if len(resolutions) > 1 else [])
        fig, axes = plt.subplots(len(xs), len(keys), figsize=(5.0 * len(keys) + 2.2, 4.2 * len(xs)),
                                 squeeze=False, layout="constrained")
        for m in METHODS:
            sel = [r for r in mine if r["variant"] == m.name]
            for row, x in enumerate(xs):
                for ax, key in zip(axes[row], keys):
                    if sel:
                        ax.loglog([r[x] for r in sel], [r[key] for r in sel], label=m.name, **style[m.name])
        for row, x in enumerate(xs):
            for ax, key in zip(axes[row], keys):
                ax.set_ylabel(labels.get(key, f"velocity error [R eq. 75] at {key[6:-2]} ms"))
                if x == "seconds":
                    ax.set(xlabel=f"wall time of the time loop [s], {COMM.size} rank(s)", title="work-precision")
                else:
                    ax.set(xlabel=f"n (particles across the {titles[problem][1]})", title="convergence")
                    ax.set_xticks(resolutions, [str(n) for n in resolutions])
                ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())  # no crowded minor labels
                ax.grid(alpha=0.3, which="both")
        handles, names = axes[0][0].get_legend_handles_labels()
        fig.legend(handles, names, loc="outside right center", fontsize=8)
        fig.suptitle(f"{titles[problem][0]}, n = {', '.join(str(n) for n in resolutions)}")
        fig.savefig(os.path.join(out, f"{problem}.png"), dpi=110)
        plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", choices=("quick", "full", "stress"), default="quick")
    ap.add_argument("--only", default="", help="only the cases (stress) or variants/methods whose name contains this")
    ap.add_argument("--problems", nargs="+", choices=PROBLEMS, default=list(PROBLEMS),
                    help="quick/full presets: the problems to run (default all)")
    ap.add_argument("--out", default="results/bench_matrix")
    args = ap.parse_args()
    if args.preset == "stress":
        if COMM.size > 1:
            sys.exit("the stress preset runs on one rank")
        stress(os.path.join(args.out, "stress"), args.only)
    else:
        accuracy(args.preset, os.path.join(args.out, args.preset + (f"_r{COMM.size}" if COMM.size > 1 else "")),
                 args.problems, args.only)


if __name__ == "__main__":
    main()
