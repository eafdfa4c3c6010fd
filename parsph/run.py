"""`parsph run`: load the scene (or a checkpoint), step to the end time, write history,
snapshots and checkpoints; stop cleanly with a checkpoint on SIGTERM/SIGINT or at the
wall-clock limit."""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
from mpi4py import MPI

from parsph import config
from parsph.diagnostics import check_particle_ids
from parsph.errors import InputError
from parsph.io import checkpoint
from parsph.io.history import HistoryWriter
from parsph.io.snapshots import SnapshotWriter
from parsph.parallel.runtime import COMM, collective, say
from parsph.progress import Progress

RUN_FILES = ("history.h5", "snapshots.h5", "snapshots.xdmf", "scene.json")
PROBE_UNITS = {"displacement": "m", "velocity": "m/s", "position": "m", "reaction": "N", "force": "N",
               "J": "1", "von_mises": "Pa", "disorder": "1",
               "spacing_ratio": "1"}


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
                    "choose another --out, pass --overwrite to replace it, or --restart latest to continue it")
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

    def __init__(self, interval: float, every: int, next_time: float | None = None):
        self.interval, self.every = interval, every
        self.next = interval if next_time is None else next_time

    def due(self, t: float, step: int) -> bool:
        if self.interval > 0:
            if t >= self.next * (1 - 1e-12):
                while self.next <= t * (1 + 1e-12):
                    self.next += self.interval
                return True
            return False
        return self.every > 0 and step % self.every == 0


class StopRequest:
    """SIGTERM/SIGINT and the wall-clock limit, agreed on by all ranks at a step's end."""

    def __init__(self, wall_limit: float):
        self.signal = 0
        self.wall_limit = wall_limit
        self.start = time.monotonic()
        self.previous = {}
        for sig in (signal.SIGTERM, signal.SIGINT):
            self.previous[sig] = signal.signal(sig, self._handle)

    def _handle(self, signum, frame):
        self.signal = signum

    def check(self) -> int:
        """0 to go on; else the signal number, or -1 for the wall-clock limit (collective)."""
        flags = np.array([self.signal,
                          bool(self.wall_limit) and time.monotonic() - self.start >= self.wall_limit])
        if COMM.size > 1:
            COMM.Allreduce(MPI.IN_PLACE, flags, op=MPI.MAX)
        return int(flags[0]) or -int(flags[1])

    def restore(self) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)


def report_stages(seconds: dict, steps: int, particles: int) -> None:
    """Time per stage of the step (the slowest rank's), in ms per step and per cent."""
    names = sorted(COMM.allreduce(set(seconds), op=MPI.BOR) if COMM.size > 1 else seconds)
    worst = np.array([seconds.get(k, 0.0) for k in names])
    if COMM.size > 1:
        COMM.Allreduce(MPI.IN_PLACE, worst, op=MPI.MAX)
    total = worst.sum()
    parts = ", ".join(f"{k} {1e3 * v / steps:.3g} ms ({100 * v / total:.0f} %)" for k, v in zip(names, worst))
    say(f"parsph: per step: {parts}")


def _setup(scene_path, out_dir, overrides, overwrite, restart):
    """The scene, output directory, this rank's particles (with ghosts) and the checkpoint
    data of a run. Every rank builds (or reads) a block of the particle set; the blocks are
    partitioned among the ranks by position."""
    with collective():
        scene = config.load(scene_path, overrides)
    out_dir = out_dir or os.path.join("results", scene["scene"]["name"])
    from parsph.build import build_local
    from parsph.parallel.decomposition import add_ghosts, partition

    if restart is None:
        previous = check_output(out_dir, overwrite)
        return scene, out_dir, previous, build_local(scene, COMM), None
    data = checkpoint.load(restart, out_dir, COMM)
    with collective():
        checkpoint.check_compatible(data["scene"], scene, data["path"])
    fields = data.pop("fields")
    position = "Xr" if "Xr" in fields else "X"
    local = add_ghosts(partition(fields, position, COMM), position, COMM)
    say(f"parsph: restarting from {data['path']} at step {data['clock']['step']}, t = {data['clock']['t']:.6g} s")
    return scene, out_dir, [], local, data


def run(scene_path: str, out_dir: str | None, overrides: list, overwrite: bool, quiet: bool,
        restart: str | None = None, debug: bool = False) -> int:
    """Run a scene (or continue it from a checkpoint); returns the exit code. `debug` checks
    at every history row that no particle was lost or duplicated."""
    scene, out_dir, previous, local, data = _setup(scene_path, out_dir, overrides, overwrite, restart)
    from parsph.solver import Simulation

    name = scene["scene"]["name"]
    scene_json = config.to_json(scene)
    start = time.perf_counter()
    count = local.total
    sim = Simulation(scene, local, COMM, restart=data)
    del local
    setup_seconds = time.perf_counter() - start
    if data is None:
        claim_output(out_dir, previous)
    say(f"parsph: scene '{name}': {count} particles, {scene['scene']['dimension']}D, "
        f"{COMM.size} rank(s), set-up {setup_seconds:.2f} s, output in {out_dir}")

    out = scene["output"]
    resume = None if data is None else sim.step_count
    nexts = {} if data is None else data["schedules"]
    history = None
    if COMM.rank == 0:
        with open(os.path.join(out_dir, "scene.json"), "w") as fh:
            json.dump(scene, fh, indent=2, sort_keys=True)
        units = {p["name"]: PROBE_UNITS[p["quantity"]] for p in scene["probes"]}
        history = HistoryWriter(os.path.join(out_dir, "history.h5"), scene_json, units, resume)
    snapshots = SnapshotWriter(out_dir, scene_json, COMM, resume)
    history_due = Schedule(out["history_interval"], out["history_every"], nexts.get("history"))
    snapshot_due = Schedule(out["snapshot_interval"], 0, nexts.get("snapshot"))
    checkpoint_due = Schedule(out["checkpoint_interval"], out["checkpoint_every"], nexts.get("checkpoint"))
    end, max_steps = scene["time"]["end"], scene["time"]["max_steps"]
    progress = Progress(end, count, out["progress_seconds"], enabled=COMM.rank == 0 and not quiet)
    stop = StopRequest(scene["time"]["wall_limit"])

    def record():
        start = time.perf_counter()
        if debug:
            check_particle_ids(sim)
        values = sim.diagnostics()
        if history is not None:
            history.append(values)
        sim.stage_seconds["diagnostics+history"] += time.perf_counter() - start
        return values

    def save_checkpoint():
        schedules = {"history": history_due.next, "snapshot": snapshot_due.next,
                     "checkpoint": checkpoint_due.next}
        return checkpoint.write_checkpoint(out_dir, sim, schedules, scene, out["checkpoint_keep"])

    last = record()
    if data is None and out["snapshot_interval"] > 0:
        snapshots.write(sim, out["snapshot_fields"])
    loop_start = time.perf_counter()
    steps_at_start = sim.step_count
    stopped = 0
    try:
        while sim.t < end * (1 - 1e-12) and not (max_steps and sim.step_count >= max_steps):
            dt = sim.step()
            progress.update(sim.step_count, sim.t, dt)
            if history_due.due(sim.t, sim.step_count):
                last = record()
            output_start = time.perf_counter()
            if snapshot_due.due(sim.t, sim.step_count):
                snapshots.write(sim, out["snapshot_fields"])
            stopped = stop.check() if sim.step_count % 10 == 0 else 0
            if checkpoint_due.due(sim.t, sim.step_count) or stopped:
                path = save_checkpoint()
            sim.stage_seconds["snapshots+checkpoints"] += time.perf_counter() - output_start
            if stopped:
                break
        # the final state is always in the history and in the snapshots
        if last["step"] != sim.step_count:
            last = record()
        if not snapshots.times or snapshots.times[-1] != sim.t:
            snapshots.write(sim, out["snapshot_fields"])
    finally:
        stop.restore()
        progress.close()
        if history is not None:
            history.close()
    loop_seconds = time.perf_counter() - loop_start
    steps = sim.step_count - steps_at_start
    if steps:
        say(f"parsph: {steps} steps to t = {sim.t:.6g} s in {loop_seconds:.2f} s: "
            f"{1e6 * loop_seconds * COMM.size / (steps * count):.3f} us per particle-step "
            f"(x {COMM.size} rank(s))")
        report_stages(sim.stage_seconds, steps, count)
    if stopped:
        why = "the wall-clock limit" if stopped < 0 else signal.Signals(stopped).name
        say(f"parsph: stopped by {why} at step {sim.step_count}; checkpoint {path}; "
            f"continue with: parsph run {scene_path} --out {out_dir} --restart latest")
        return 0 if stopped < 0 else 128 + stopped
    return 0
