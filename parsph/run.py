"""`parsph run`: load the scene, build, step to the end time, write history and snapshots."""

from __future__ import annotations

import json
import os
import time

import numpy as np

from parsph import config
from parsph.errors import InputError
from parsph.io.history import HistoryWriter
from parsph.io.snapshots import SnapshotWriter
from parsph.parallel.runtime import COMM, collective, say
from parsph.progress import Progress

RUN_FILES = ("history.h5", "snapshots.h5", "snapshots.xdmf", "scene.json")
PROBE_UNITS = {"displacement": "m", "velocity": "m/s", "position": "m", "reaction": "N", "force": "N",
               "J": "1", "von_mises": "Pa", "disorder": "1"}


def check_output(out_dir: str, overwrite: bool) -> list:
    """Rank 0 checks the output directory, changing nothing; returns the previous run's
    files there (to be replaced: only with --overwrite)."""
    present = []
    with collective():
        if COMM.rank == 0:
            if os.path.exists(out_dir) and not os.path.isdir(out_dir):
                raise InputError(f"output path {out_dir} exists and is not a directory")
            present = [f for f in RUN_FILES if os.path.exists(os.path.join(out_dir, f))]
            if present and not overwrite:
                raise InputError(
                    f"output directory {out_dir} already holds a run ({', '.join(present)}); "
                    "choose another --out or pass --overwrite to replace it")
    return present


def claim_output(out_dir: str, present: list) -> None:
    """Create the output directory and remove the previous run's files (--overwrite), once
    the new run has been set up without error."""
    with collective():
        if COMM.rank == 0:
            os.makedirs(out_dir, exist_ok=True)
            for f in present:
                os.remove(os.path.join(out_dir, f))
            if present:
                say(f"replacing the previous run in {out_dir} (--overwrite)")


class Schedule:
    """Fires every `interval` of simulated time, or every `every` steps if interval is 0."""

    def __init__(self, interval: float, every: int):
        self.interval, self.every = interval, every
        self.next = interval

    def due(self, t: float, step: int) -> bool:
        if self.interval > 0:
            if t >= self.next * (1 - 1e-12):
                while self.next <= t * (1 + 1e-12):
                    self.next += self.interval
                return True
            return False
        return self.every > 0 and step % self.every == 0


def run(scene_path: str, out_dir: str | None, overrides: list, overwrite: bool, quiet: bool) -> dict:
    """Run a scene; returns the last diagnostics row."""
    with collective():
        scene = config.load(scene_path, overrides)
    name = scene["scene"]["name"]
    out_dir = out_dir or os.path.join("results", name)
    previous = check_output(out_dir, overwrite)
    scene_json = config.to_json(scene)
    from parsph.build import build_body
    from parsph.solver import Simulation

    start = time.perf_counter()
    with collective():
        body = build_body(scene)
    count = body.count
    sim = Simulation(scene, body, COMM)
    del body
    setup_seconds = time.perf_counter() - start
    claim_output(out_dir, previous)
    say(f"parsph: scene '{name}': {count} particles, {scene['scene']['dimension']}D, "
        f"{COMM.size} rank(s), set-up {setup_seconds:.2f} s, output in {out_dir}")

    out = scene["output"]
    history = None
    if COMM.rank == 0:
        with open(os.path.join(out_dir, "scene.json"), "w") as fh:
            json.dump(scene, fh, indent=2, sort_keys=True)
        units = {p["name"]: PROBE_UNITS[p["quantity"]] for p in scene["probes"]}
        history = HistoryWriter(os.path.join(out_dir, "history.h5"), scene_json, units)
    snapshots = SnapshotWriter(out_dir, scene_json, COMM)
    history_due = Schedule(out["history_interval"], out["history_every"])
    snapshot_due = Schedule(out["snapshot_interval"], 0)
    end, max_steps = scene["time"]["end"], scene["time"]["max_steps"]
    progress = Progress(end, count, out["progress_seconds"], enabled=COMM.rank == 0 and not quiet)

    def record(values=None):
        values = values or sim.diagnostics()
        if history is not None:
            history.append(values)
        return values

    last = record()
    if out["snapshot_interval"] > 0:
        snapshots.write(sim, out["snapshot_fields"])
    loop_start = time.perf_counter()
    steps_at_start = sim.step_count
    try:
        while sim.t < end * (1 - 1e-12) and not (max_steps and sim.step_count >= max_steps):
            dt = sim.step()
            progress.update(sim.step_count, sim.t, dt)
            if history_due.due(sim.t, sim.step_count):
                last = record()
            if snapshot_due.due(sim.t, sim.step_count):
                snapshots.write(sim, out["snapshot_fields"])
        # the final state is always in the history and in the snapshots
        if last["step"] != sim.step_count:
            last = record()
        if not snapshots.times or snapshots.times[-1] != sim.t:
            snapshots.write(sim, out["snapshot_fields"])
    finally:
        progress.close()
        if history is not None:
            history.close()
    loop_seconds = time.perf_counter() - loop_start
    steps = sim.step_count - steps_at_start
    if steps:
        say(f"parsph: {steps} steps to t = {sim.t:.6g} s in {loop_seconds:.2f} s: "
            f"{1e6 * loop_seconds * COMM.size / (steps * count):.3f} us per particle-step "
            f"(x {COMM.size} rank(s))")
    return {"out_dir": out_dir, "steps": steps, "seconds": loop_seconds, "particles": count, **last}
