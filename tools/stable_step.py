#!/usr/bin/env python3
"""The largest fixed time step each scene runs at, against the step parsph chooses.

For each scene of runs/ (SCENES: the overrides that keep a run to seconds): a reference run
at a small step (time.cfl = REFERENCE_CFL times the stable-step estimate) over STEPS of its
first steps (at most to the scene's end); then the scene's default step (its own time.cfl)
over the same simulated time, and runs with a fixed `time.dt`, the step doubled from the
reference's until a run fails the test, then bisected to 5 %. The default run's step may fall
as the scene stiffens (compression, contact): its smallest step over the window is listed
beside its first. Two tests, each with its own
largest step:
  stable:   the run ends without an error and its energy balance, max |total - initial|
            over the run, stays below 0.1 of its largest kinetic + strain energy or 3 times
            the reference's (a step beyond leapfrog's limit blows up);
  accurate: stable, its energy balance within 3 times the reference's (at least 1e-3 of
            that energy) and every probe at the end within 2 % of its range over the
            reference run: the same answer within the method's error.
The walls' and tools' forces are left out: they are the impulse of one step over its length.

usage: tools/stable_step.py [--scenes NAME ...] [--steps 2000] [--set KEY=VALUE ...]
(--set: overrides of every run of every scene, after the scene's own, e.g. time.cfl=0.8)
"""

from __future__ import annotations

import argparse
import math
import os
import re
import time

import numpy as np
from mpi4py import MPI

from parsph import config
from parsph.build import build_local
from parsph.errors import ParsphError
from parsph.simulation import Simulation

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
SCENES = {  # scene: overrides (the particle spacing that sets the step stays the scene's)
    "bar1d": [], "bar1d_ul": [], "patch_random": [], "beam_bending": [], "rubber_pull": [],
    "cylinder_bending": [], "cylinder_bending_ul": [], "rings": [], "punch": [], "punch_hessian": [],
    "punch_ul": [], "two_blocks": [], "cantilever": [], "plate_tension": [],
    "rod": ["parameters.n=4"], "rod_pulse": ["parameters.n=4"], "taylor_impact": [], "tensile_failure": [],
    "ring_shear_bands": [], "rubber_ring": [], "funnel": [],
}
BLOW_UP = 0.1  # energy balance error, of the largest kinetic + strain energy, that counts as unstable
PROBE_TOLERANCE = 0.02  # of a probe's range over the reference run
REFERENCE_CFL = 0.3  # the reference run's step: the default before the estimate was tightened


def simulation(name: str, overrides: list) -> Simulation:
    scene = config.load(os.path.join(ROOT, "runs", f"{name}.toml"), overrides)
    return Simulation(scene, build_local(scene, MPI.COMM_SELF), MPI.COMM_SELF)


def run(name: str, overrides: list, end: float, dt: float | None) -> tuple:
    """(final diagnostics, their series every 10 steps, energy balance error) of `name`
    to `end` at the default step (dt None) or a fixed one; ParsphError if the run fails."""
    sim = simulation(name, overrides + [f"time.end={end!r}", "time.max_steps=0"] + ([f"time.dt={dt!r}"] if dt else []))
    rows = [sim.diagnostics()]
    with np.errstate(all="ignore"):
        while sim.t < end * (1 - 1e-12):
            sim.step(end)
            if sim.step_count % 10 == 0:
                rows.append(sim.diagnostics())
        rows.append(sim.diagnostics())
    series = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    scale = np.nanmax(series["kinetic_energy"] + series["strain_energy"])
    balance = np.nanmax(np.abs(series["total_energy"] - series["total_energy"][0])) / scale
    return rows[-1], series, balance if np.isfinite(balance) else math.inf


def probes(row: dict) -> dict:
    """The scene's own probes in a history row (not the diagnostics, not contact forces)."""
    skip = ("time", "step", "dt", "reference_updates", "disorder", "disorder_max", "angular_momentum")
    return {k: v for k, v in row.items() if k not in skip and not re.search(
        r"energy|_work|momentum_|(wall|tool)[0-9]+_force_", k)}


def verdict(name, overrides, end, dt, reference) -> tuple:
    """(stable, accurate, the smallest step taken) at the fixed step dt, or the default one
    (dt None)."""
    final_ref, series_ref, balance_ref = reference
    try:
        final, series, balance = run(name, overrides, end, dt)
    except ParsphError:
        return False, False, math.nan
    smallest = float(np.min(series["dt"]))
    if not balance <= max(BLOW_UP, 3.0 * balance_ref):
        return False, False, smallest
    close = all(abs(final[k] - v) <= PROBE_TOLERANCE * max(np.ptp(series_ref[k]), 1e-12 * abs(v))
                for k, v in probes(final_ref).items())
    return True, close and balance <= max(3.0 * balance_ref, 1e-3), smallest


def largest(test, chosen: float) -> tuple:
    """(largest step that passes test(dt), capped): doubling from the chosen step to 32
    times it, then bisection to 5 %."""
    low, high = chosen, None
    factor = 2.0
    while high is None and factor <= 32.0:
        if test(chosen * factor):
            low = chosen * factor
            factor *= 2.0
        else:
            high = chosen * factor
    while high is not None and high / low > 1.05:
        mid = math.sqrt(low * high)
        low, high = (mid, high) if test(mid) else (low, mid)
    return low, high is None


def measure(name: str, overrides: list, steps: int) -> dict:
    """The default step, how the default run fares, and the largest stable and accurate
    fixed steps."""
    start = time.perf_counter()
    sim = simulation(name, overrides)
    chosen = float(sim.diagnostics()["dt"])
    small = overrides + [f"time.cfl={min(REFERENCE_CFL, sim.scene.time.cfl)}"]  # a scene's own smaller cfl
    first = float(simulation(name, small).diagnostics()["dt"])
    end = min(steps * first, sim.scene.time.end)
    reference = run(name, small, end, None)
    default = verdict(name, overrides, end, None, reference)
    cache = {}

    def judged(dt):
        if dt not in cache:
            cache[dt] = verdict(name, overrides, end, dt, reference)
        return cache[dt]

    stable = largest(lambda dt: judged(dt)[0], first)
    accurate = largest(lambda dt: judged(dt)[1], first)
    return {"chosen": chosen, "default": default[:2], "smallest": default[2], "stable": stable, "accurate": accurate,
            "balance": reference[2],
            "runs": len(cache) + 2, "seconds": time.perf_counter() - start}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--steps", type=int, default=2000, help="steps of the reference run")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="an override of every run (after the scene's own), e.g. time.cfl=0.8")
    args = parser.parse_args()
    print(f"| scene | default step [s] | default run | smallest default step | largest stable | ratio | "
          f"largest accurate | ratio | stable / smallest | balance at cfl {REFERENCE_CFL} | runs | wall [s] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.scenes:
        r = measure(name, SCENES.get(name, []) + args.set, args.steps)
        cells = []
        for limit, capped in (r["stable"], r["accurate"]):
            cells += [f"{'> ' if capped else ''}{limit:.3g}", f"{limit / r['chosen']:.2f}"]
        fares = {(True, True): "accurate", (True, False): "stable", (False, False): "UNSTABLE"}[r["default"]]
        print(f"| {name} | {r['chosen']:.3g} | {fares} | {r['smallest']:.3g} | {' | '.join(cells)} | "
              f"{r['stable'][0] / r['smallest']:.2f} | {r['balance']:.1e} | {r['runs']} | {r['seconds']:.0f} |",
              flush=True)


if __name__ == "__main__":
    main()
