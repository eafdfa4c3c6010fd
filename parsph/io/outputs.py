"""A run's outputs on their schedules: the history rows (diagnostics.history_row, kept in
memory and written when due), the snapshots of the registered quantities
(parsph.quantities) and the checkpoints, each at a simulated-time interval or a step
count, continued from a checkpoint's schedule."""

from __future__ import annotations

import json
import math
import os
import time

from parsph import quantities
from parsph.balance_check import BalanceCheck
from parsph.diagnostics import RowReduction, check_finite, check_particle_ids, history_row
from parsph.io import checkpoint, output_dir
from parsph.io.history import HistoryWriter
from parsph.io.snapshots import SnapshotWriter
from parsph.errors import ParsphError
from parsph.exact_sum import allsum, total
from parsph.parallel.runtime import COMM, collective, warn


class Schedule:
    """Fires every `interval` of simulated time, or every `every` steps if interval is 0."""

    def __init__(self, interval: float, every: int, next_time: float | None = None):
        self.interval, self.every = interval, every
        self.next = interval if next_time is None else next_time

    def due(self, t: float, step: int) -> bool:
        if self.interval > 0:
            if t >= self.next * (1 - 1e-12):
                behind = (t * (1 + 1e-12) - self.next) / self.interval
                if behind > 16:  # an interval far below the step: skip ahead at once
                    self.next += math.floor(behind) * self.interval
                while self.next <= t * (1 + 1e-12):
                    self.next += self.interval
                return True
            return False
        return self.every > 0 and step % self.every == 0


class Outputs:
    """The history, snapshots and checkpoints of one run in `out_dir` (collective)."""

    def __init__(self, sim, scene, scene_json: str, out_dir: str, data: dict | None, debug: bool = False):
        """`data`: the checkpoint continued (its schedules), or None for a new run; `debug`
        checks at every history row that no particle was lost or duplicated; `scene` resolved
        (config.Scene), `scene_json` its canonical text (config.to_json)."""
        self.sim, self.scene_json, self.out_dir, self.debug = sim, scene_json, out_dir, debug
        out = self.settings = scene.output
        resume = None if data is None else sim.step_count
        nexts = {} if data is None else data["schedules"]
        units = {p.name: quantities.units(p.quantity) for p in scene.probes}
        self.history = None
        output_dir.ensure_space(out_dir, 3 * len(scene_json), "the run's first output")
        with collective():
            if COMM.rank == 0:
                with open(os.path.join(out_dir, "scene.json"), "w") as fh:
                    json.dump(scene.as_dict(), fh, indent=2, sort_keys=True)
                self.history = HistoryWriter(os.path.join(out_dir, "history.h5"), scene_json, units, resume)
        self.snapshots = SnapshotWriter(out_dir, scene_json, COMM, resume)
        self.history_due = Schedule(out.history_interval, out.history_every, nexts.get("history"))
        self.snapshot_due = Schedule(out.snapshot_interval, 0, nexts.get("snapshot"))
        self.checkpoint_due = Schedule(out.checkpoint_interval, out.checkpoint_every, nexts.get("checkpoint"))
        self.last = -1 if data is None else sim.step_count  # the step of the last history row
        self.balance = balance_check(sim, scene.balance, scene.symmetry, nexts.get("balance"))

    def start(self) -> None:
        """A new run's first history row and snapshot."""
        self.record()
        if self.settings.snapshot_interval > 0:
            self.snapshot()

    def after_step(self, stopped: int) -> str | None:
        """The outputs due after a step, and a checkpoint if the run is `stopped`; returns
        the checkpoint's path if one was written."""
        sim = self.sim
        if self.history_due.due(sim.t, sim.step_count):
            self.record()
        start = time.perf_counter()
        if self.snapshot_due.due(sim.t, sim.step_count):
            self.snapshot()
        path = None
        if self.checkpoint_due.due(sim.t, sim.step_count) or stopped:
            path = self.save_checkpoint()
        sim.stage_seconds["snapshots+checkpoints"] += time.perf_counter() - start
        return path

    def finish(self, stopped: int) -> None:
        """The end state in the history and the snapshots (a stopped run's is written when it
        is continued to its end); the history rows written."""
        sim = self.sim
        if not stopped:
            if self.last != sim.step_count:
                self.record()
            if not self.snapshots.times or self.snapshots.times[-1] != sim.t:
                self.snapshot()
        self.write_history()

    def record(self) -> None:
        """Collective: the history row of the present state, kept in memory; the rows are
        written when rank 0 finds a write due (one reduction over the ranks carries its
        answer with the row's sums)."""
        sim = self.sim
        start = time.perf_counter()
        if self.debug:
            check_particle_ids(sim)
        reduction = RowReduction(COMM)
        due = reduction.add_max([self.history is not None and self.history.write_due()])
        values = history_row(sim, reduction)
        check_finite(values, sim)
        try:
            warnings = self.balance.check(values)
        except ParsphError as error:  # a strict check: the row, the history and a checkpoint first
            if self.history is not None:
                self.history.append(values)
            error.args = (f"{error}; checkpoint {self.save_checkpoint()}",)
            raise
        for text in warnings:
            warn(text)
        if self.history is not None:
            if warnings:
                self.history.note("balance_warnings", self.balance.messages)
            self.history.append(values)
        if reduction.maxima[due]:
            self.write_history()
        sim.stage_seconds["diagnostics+history"] += time.perf_counter() - start
        self.last = sim.step_count

    def snapshot(self) -> None:
        fields, sim = self.settings.snapshot_fields, self.sim
        output_dir.ensure_space(self.out_dir, self.snapshots.estimate_bytes(sim, fields),
                                f"the snapshot at step {sim.step_count}")
        self.snapshots.write(sim, fields)

    def write_history(self) -> None:
        """Collective: the history rows in memory to the file (a restart from the next
        checkpoint finds every row up to it), if the disk has room for them."""
        with collective():
            if self.history is not None:
                output_dir.check_space(self.out_dir, self.history.pending_bytes(),
                                       f"the history rows up to step {self.sim.step_count}")
                self.history.write()

    def save_checkpoint(self) -> str:
        """Collective: the history written, then a checkpoint with the schedules; its path."""
        self.write_history()
        schedules = {"history": self.history_due.next, "snapshot": self.snapshot_due.next,
                     "checkpoint": self.checkpoint_due.next, "balance": self.balance.state()}
        return checkpoint.write_checkpoint(self.out_dir, self.sim, schedules, self.scene_json,
                                           self.settings.checkpoint_keep)

    def close(self) -> None:
        if self.history is not None:
            self.history.close()


def balance_check(sim, settings, symmetry: tuple, restored: dict | None) -> BalanceCheck:
    """The run's balance check (parsph.balance_check, with the scene's [balance] `settings`)
    of `sim`: its total mass, the axes no `symmetry` plane is normal to, and whether its
    formulations conserve momentum (collective)."""
    mass = float(allsum(sim.comm, [total(sim.state.mass[: sim.state.n_owned])])[0])
    planes = {plane.axis for plane in symmetry}
    free = [a for a in range(sim.state.dim) if a not in planes]
    momentum = all(b.formulation.conserves_momentum for b in sim.state.bodies)
    energy = all(b.formulation.conserves_energy for b in sim.state.bodies)
    return BalanceCheck(settings, sim.state.dim, mass, free, momentum, energy, restored)
