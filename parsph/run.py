"""`parsph run`: load the scene (or a checkpoint), step to the end time, write history,
snapshots and checkpoints; stop cleanly with a checkpoint on SIGTERM/SIGINT or at the
wall-clock limit."""

from __future__ import annotations

import glob
import os
import shlex
import signal
import time

import numpy as np
from mpi4py import MPI

from parsph import config
from parsph.errors import InputError, ParsphError
from parsph.io import checkpoint, output_dir
from parsph.io.history import read_reached
from parsph.io.outputs import Outputs
from parsph.io.snapshots import check_snapshots_readable
from parsph.parallel.runtime import COMM, collective, say
from parsph.progress import Progress, format_duration

REASONABLE_SECONDS = 30 * 86400.0  # a run expected to take longer than this gets a warning


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


def report_stages(seconds: dict, steps: int, profile=None, sim=None) -> None:
    """Time per stage of the step (the slowest rank's), in ms per step and per cent; with a
    `profile` (parsph.profile.Profile) of `sim`, a table of what each stage does with the
    core. Collective."""
    names = sorted(COMM.allreduce(set(seconds), op=MPI.BOR) if COMM.size > 1 else seconds)
    worst = np.array([seconds.get(k, 0.0) for k in names])
    if COMM.size > 1:
        COMM.Allreduce(MPI.IN_PLACE, worst, op=MPI.MAX)
    if profile is not None:
        for line in profile.report(sim, dict(zip(names, worst.tolist())), steps):
            say(line)
        return
    total = worst.sum()
    parts = ", ".join(f"{k} {1e3 * v / steps:.3g} ms ({100 * v / total:.0f} %)" for k, v in zip(names, worst))
    say(f"parsph: per step: {parts}")


def _setup(scene_path, out_dir, overrides, overwrite, restart):
    """The scene, output directory (locked for this run), this rank's particles (with
    ghosts) and the checkpoint data of a run. Every rank builds (or reads) a block of the
    particle set; the blocks are partitioned among the ranks by position."""
    with collective():
        scene = config.load(scene_path, overrides)
    out_dir = out_dir or os.path.join("results", scene.scene.name)
    from parsph.build import build_local
    from parsph.parallel.decomposition import localize

    output_dir.lock(out_dir)
    if restart is None:
        previous = output_dir.check_output(out_dir, overwrite)
        return scene, out_dir, previous, build_local(scene, COMM), None
    data = checkpoint.load(restart, out_dir, COMM)
    previous = []
    with collective():
        checkpoint.check_compatible(data["scene"], scene, data["path"])
        if COMM.rank == 0:
            previous = other_run(out_dir, data["scene"], data["path"], overwrite)
            if not previous:
                check_resumable(scene.time, out_dir)
    fields = data.pop("fields")
    position = "Xr" if "Xr" in fields else "X"
    local = localize(fields, data.pop("sets"), position, COMM)
    local.offsets = None if data["offsets"] is None else np.array(data["offsets"], np.int64)
    say(f"parsph: restarting from {data['path']} at step {data['clock']['step']}, t = {data['clock']['t']:.6g} s")
    return scene, out_dir, previous, local, data


def other_run(out_dir: str, checkpoint_scene: dict, checkpoint_path: str, overwrite: bool) -> list:
    """Refuse a restart into an output directory that holds a run of another scene (the
    restart would cut and mix its history and remove its snapshots): [] if `out_dir` holds
    nothing or the checkpointed run; with --overwrite, the other run's files to remove
    (once the restart has been set up)."""
    try:
        held = output_dir.held_scene(out_dir)
        changed = [] if held is None else checkpoint.physics_changes(held, checkpoint_scene)
    except InputError:
        if not overwrite:
            raise
        changed = ["an unreadable scene"]
    if not changed:
        return []
    if not overwrite:
        shown = ", ".join(changed[:6]) + (", ..." if len(changed) > 6 else "")
        raise InputError(f"{out_dir} holds a run of another scene than checkpoint {checkpoint_path} (they differ "
                         f"in {shown}): continuing into it would cut and mix that run's history and remove its "
                         "snapshots; restart into another --out, or pass --overwrite to replace that run")
    keep = os.path.realpath(checkpoint_path)
    return [p for p in output_dir.run_files(out_dir) if os.path.realpath(p) != keep]


def check_resumable(settings, out_dir: str) -> None:
    """Refuse, before anything is changed, a restart whose history or snapshots in `out_dir`
    are damaged, or that would stop before the end (the scene's [time] `settings`) of what
    `out_dir` already holds (it would cut the history and snapshots written after its end)."""
    reached = read_reached(os.path.join(out_dir, "history.h5"))
    check_snapshots_readable(os.path.join(out_dir, "snapshots.h5"))
    if reached is None:
        return
    t_last, step_last = reached
    end, max_steps = settings.end, settings.max_steps
    if end < t_last * (1 - 1e-12) or (max_steps and max_steps < step_last):
        raise InputError(
            f"{out_dir} already holds the run to step {step_last}, t = {t_last:.6g} s; a restart that "
            f"ends earlier (time.end = {end:.6g} s" + (f", time.max_steps = {max_steps}" if max_steps else "")
            + ") would discard what was written after its end: give a later end, or restart into "
            "another --out with --restart CHECKPOINT_FILE")


def continue_command(scene_path: str, out_dir: str, overrides: list) -> str:
    """The command that continues a stopped run, with the run's --set options."""
    words = ["parsph", "run", scene_path, "--out", out_dir]
    for text in overrides:
        words += ["--set", text]
    return shlex.join(words + ["--restart", "latest"])


def run(scene_path: str, out_dir: str | None, overrides: list, overwrite: bool, quiet: bool,
        restart: str | None = None, debug: bool = False, profile: bool = False) -> int:
    """Run a scene (or continue it from a checkpoint); returns the exit code. `debug` checks
    at every history row that no particle was lost or duplicated; `profile` reports what
    each stage does with the core (parsph.profile) instead of its time alone."""
    # numpy's overflow warnings would only repeat, without saying where, what the run's own
    # checks report with the particle and step (stress evaluation, time step, history rows)
    np.seterr(over="ignore", invalid="ignore", divide="ignore")
    scene, out_dir, previous, local, data = _setup(scene_path, out_dir, overrides, overwrite, restart)
    from parsph.simulation import Simulation

    name = scene.scene.name
    scene_json = config.to_json(scene)
    start = time.perf_counter()
    count = local.total
    sim = Simulation(scene, local, COMM, restart=data)
    del local
    setup_seconds = time.perf_counter() - start
    output_dir.claim_output(out_dir, previous)
    say(f"parsph: scene '{name}': {count} particles, {scene.scene.dimension}D, "
        f"{COMM.size} rank(s), set-up {setup_seconds:.2f} s, output in {out_dir}")

    outputs = Outputs(sim, scene, scene_json, out_dir, data, debug)
    end, max_steps = scene.time.end, scene.time.max_steps
    progress = Progress(end, max_steps, count, scene.output.progress_seconds,
                        enabled=COMM.rank == 0 and not quiet)
    stop = StopRequest(scene.time.wall_limit)
    sim.stage_seconds.clear()  # the set-up's force evaluation (and compilation) is not a step
    loop_start = time.perf_counter()
    steps_at_start = sim.step_count
    stopped = 0
    profiler = None
    if profile:
        from parsph.profile import Profile

        profiler = Profile()
    try:
        if data is None:
            outputs.start()
        while sim.t < end and not (max_steps and sim.step_count >= max_steps):
            if profiler is not None and not profiler.step and (
                    sim.t >= 0.5 * end or (max_steps and sim.step_count >= max_steps // 2)):  # half-way
                dt = profiler.record(sim, lambda: sim.step(end))
            else:
                dt = sim.step(end)
            progress.update(sim.step_count, sim.t, dt)
            if sim.step_count - steps_at_start == 10:
                warn_if_endless(sim, end, max_steps, time.perf_counter() - loop_start, 10)
            stopped = stop.check() if sim.step_count % 10 == 0 else 0
            path = outputs.after_step(stopped)
            if stopped:
                break
        outputs.finish(stopped)
    except output_dir.OutputFull as exc:
        error = ParsphError(f"{exc}; stopped at step {sim.step_count}, t = {sim.t:.6g} s. "
                            f"{_checkpoint_after_full(outputs.save_checkpoint, out_dir, scene_path, overrides)}")
        error.agreed = True  # every rank met the same (collective) condition and wrote the same
        raise error from None
    finally:  # a signal while the outputs close (a failing run's too) waits for them to be whole
        progress.close()
        outputs.close()
        stop.restore()
    loop_seconds = time.perf_counter() - loop_start
    steps = sim.step_count - steps_at_start
    if steps:
        say(f"parsph: {steps} steps to t = {sim.t:.6g} s in {loop_seconds:.2f} s: "
            f"{1e6 * loop_seconds * COMM.size / (steps * count):.3f} us per particle-step "
            f"(x {COMM.size} rank(s))")
        report_stages(sim.stage_seconds, steps, profiler if profiler and profiler.step else None, sim)
    if stopped:
        why = "the wall-clock limit" if stopped < 0 else signal.Signals(stopped).name
        say(f"parsph: stopped by {why} at step {sim.step_count}; checkpoint {path}; "
            f"continue with: {continue_command(scene_path, out_dir, overrides)}")
        return 0 if stopped < 0 else 128 + stopped
    return 0


def _checkpoint_after_full(save_checkpoint, out_dir: str, scene_path: str, overrides: list) -> str:
    """Collective, after the disk filled: write a checkpoint if it fits; says what was done."""
    try:
        path = save_checkpoint()
    except output_dir.OutputFull:
        latest = sorted(glob.glob(os.path.join(out_dir, "checkpoints", "step_*.h5")))
        where = f"the newest checkpoint is {latest[-1]}" if latest else "there is no checkpoint to continue from"
        return f"The output written so far is intact; no room for a checkpoint either: {where}."
    return (f"The output written so far is intact; checkpoint {path} written. Free space, then continue "
            f"with: {continue_command(scene_path, out_dir, overrides)}")


def warn_if_endless(sim, end: float, max_steps: int, seconds: float, steps: int) -> None:
    """Warn (rank 0) when the steps left at the present step size would take longer than
    REASONABLE_SECONDS of wall-clock time at the speed of the first `steps` steps."""
    left = (end - sim.t) / sim.dt
    if max_steps:
        left = min(left, max_steps - sim.step_count)
    expected = seconds / steps * left
    if expected > REASONABLE_SECONDS:
        from parsph.parallel.runtime import warn

        warn(f"this run would take about {format_duration(expected)} ({left:.3g} steps of dt = "
             f"{sim.dt:.3g} s to time.end = {end:.6g} s); check time.end, time.dt and the material "
             "constants (the step size follows the wave speed sqrt(E / density) and the spacing)")
