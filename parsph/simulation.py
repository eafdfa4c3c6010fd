"""`Simulation`: the loop over one rank's particles of every body. A step is
velocity-Verlet (kick-drift-kick leap-frog):
    commit the material state, advance failure, break pairs   (points, failure)
    v += dt/2 a;  constrained v;  u += dt v;  constrained u   (conditions)
    obstacles; the formulations' stages, phase by phase, with the ghost refreshes their
        declarations require (an Eulerian kernel moves its reference inside) -> a
    v += dt/2 a;  constrained v;  the step's works            (ledger)
    the next step's size; a reference update if one is due    (stability, topology)
The state lives in the bodies and point sets (parsph.state); sums over particles are exact
(exact_sum), so that the history, like the particle state, is the same bit for bit on any
number of ranks.
"""

from __future__ import annotations

import collections
import math
import time

import numpy as np

from parsph import interactions, readouts
from parsph.bc import apply_initial_conditions
from parsph.conditions import (external_force, free_rigid_bodies, prescribe_displacement,
                               prescribe_velocity)
from parsph.diagnostics import history_row
from parsph.errors import ParsphError
from parsph.failure import Failure
from parsph.ledger import Ledger
from parsph.parallel.decomposition import LocalBody
from parsph.parallel.runtime import collective
from parsph.points import PointSet
from parsph.stability import StableStep, check_hourglass_stiffness
from parsph.state import Body, adopt, refresh, settle
from parsph.topology import Topology
from parsph.walls import Walls


class Simulation:
    """The particles this rank owns, of every body, and the loop that steps them."""

    def __init__(self, scene: dict, local: LocalBody, comm, restart: dict | None = None):
        """Set up this rank's particles `local` (build.build_local, or a checkpoint's block
        partitioned); `restart` (io.checkpoint.load: clock and totals) continues a run."""
        self.scene = scene
        self.comm = comm
        self.dim = dim = scene.scene.dimension
        specs = scene.bodies
        offsets = local.offsets if local.offsets is not None else np.array([0, local.total])
        self.offsets = np.asarray(offsets, np.int64)
        self.bodies = [Body(b, spec, int(self.offsets[b]), int(self.offsets[b + 1]), dim)
                       for b, spec in enumerate(specs)]
        self.failure = Failure(self.bodies, dim, comm, restart["cut"] if restart else None)
        self.topology = Topology(scene, self.bodies, local, comm)
        settle(self)
        self.rebalance = scene.parallel.rebalance
        self.group_names = sorted(scene.groups)
        self.stage_seconds = collections.defaultdict(float)  # wall time per stage of the step
        body_acc = scene.loads.body_acceleration
        self.body_acc = None if body_acc is None else np.asarray(body_acc)
        self.damping = scene.time.damping
        self.t = restart["clock"]["t"] if restart else 0.0  # the constraints in force depend on it
        self.step_count = 0
        self.step_dt = 0.0  # the step that brought F from the committed state (rate-dependent laws)
        self.ledger = Ledger(self.bodies)
        self.stable = StableStep(scene.time)
        self.walls = Walls(scene.walls, scene.tools, dim, scene.surfaces, scene.parameters)
        self.rigid_bodies = []  # the freely moving ones, made after the initial conditions
        adopt(self, local)
        check_hourglass_stiffness(self)
        n = self.n_owned
        if restart is None:
            with collective(comm):
                apply_initial_conditions(scene.initial, self.groups, self.X[:n], self.gid[:n], self.u[:n],
                                         self.v[:n], scene.parameters)
            prescribe_displacement(self, 0.0)
            prescribe_velocity(self, 0.0)
        self.rigid_bodies = free_rigid_bodies(self, restart)
        if restart is not None:
            clock, carried = restart["clock"], restart["totals"]
            self.t, self.step_count = clock["t"], clock["step"]
            self.step_dt = clock.get("step_dt", 0.0)
            self.topology.restore(clock)
            for interaction in self.interactions:
                interaction.restore(carried)
            if comm.rank == 0:  # global totals and the last step's obstacle forces, carried by rank 0
                self.ledger.restore(carried)
                self.walls.restore(carried["wall_force"], carried.get("surface_torque", ()))
        if self.contact is not None and restart is None:
            self.contact.check_apart(self.gid, self.body, self.X[:n] + self.u[:n], [b.name for b in self.bodies])
        self.compute_forces()
        self.ledger.external = external_force(self)  # at the current state, for the work integral
        self.stable.start(self, restart["clock"] if restart else None)

    def material_state(self, body: Body, points: str = "particles") -> tuple:
        """(committed, trial) state arrays of `body`'s material law on a point set (empty
        arrays for a law without state)."""
        if body.law.state is None:
            return self.no_state, self.no_state
        A = self.point_set(points).arrays
        return A[body.law.state], A[body.law.state + "_trial"]

    def damage_state(self, body: Body) -> tuple:
        """(committed, trial) damage state arrays of `body`'s particles (empty without damage)."""
        if not body.failure:
            return self.no_state, self.no_state
        return self.particles.arrays["damage"], self.particles.arrays["damage_trial"]

    def exclude_kernel_pairs(self) -> None:
        """Tell a self-contact the kernel's pairs, which it leaves out (parsph.contact)."""
        if self.contact:
            self.contact.exclude(self.topology.kernel_pairs(), self.gid)

    def point_set(self, name: str) -> PointSet:
        return self.particles if name == "particles" else self.sets[name]

    def point_sets(self) -> list:
        """The rank's point sets: the particles, then the others (stress points, Gauss points)."""
        return [self.particles] + list(self.sets.values())

    # ----------------------------------------------------------------- the step
    def compute_forces(self, move_reference: bool = False) -> None:
        """The bodies' stages at the current u, phase by phase; before each phase the ghost
        values of the fields it reads at neighbours that are stale are refreshed (the
        displacement always: the integrator moved it). With `move_reference` (an Eulerian
        kernel's step) the reference moves to the current configuration once F and the
        stress are known, before the force row. Sets self.force, of which self.internal_force
        is the part between particles, and self.acc (owned)."""
        n = self.n_owned
        clock = time.perf_counter
        seconds = self.stage_seconds
        stale = {"d", "v"}  # moved by the integrator (v is refreshed only if a stage reads it)
        self.step_limit.fill(np.inf)
        phases = max(len(b.stages) for b in self.bodies)
        k = 0
        while k < phases:
            phase = [b.stages[k] for b in self.bodies if k < len(b.stages)]
            if move_reference and any(stage.force_row for stage in phase):
                move_reference = False
                if self.topology.move(self):  # searched: new arrays, the whole evaluation in the new reference
                    self.compute_forces()
                    return
                continue  # the same phase, with the stages of the new reference
            reads = [name for name in dict.fromkeys(r for stage in phase for r in stage.reads) if name in stale]
            if reads:
                t0 = clock()
                refresh(self, reads)
                stale.difference_update(reads)
                seconds["halo"] += clock() - t0
            for stage in phase:
                t0 = clock()
                try:
                    stage.run()
                except ArithmeticError as exc:  # compiled code divided by zero: the state broke down
                    raise ParsphError(f"the {stage.name} stage failed ({exc}) at step {self.step_count + 1}, "
                                      f"t = {self.t:.6g}: particles coincide or are inverted; the run is "
                                      f"unstable: {self.stable.advice()}") from None
                seconds[stage.name] += clock() - t0
                stale.update(stage.writes)
            k += 1
        internal = self.f_int + self.f_hg if self.hourglass else self.f_int.copy()
        if self.viscous:
            internal += self.f_visc
        for interaction in self.interactions:  # parsph.interactions
            t0 = clock()
            reads = [name for name in interaction.reads if name in stale]
            if reads:
                refresh(self, reads)
                stale.difference_update(reads)
            try:
                interaction.evaluate(self.X[:n] + self.u[:n], self.v[:n], self.step_limit)
            except ArithmeticError:
                raise ParsphError(f"{interaction.name} failed at step {self.step_count + 1}, t = {self.t:.6g}: "
                                  f"particles of two bodies coincide; the run is unstable: "
                                  f"{self.stable.advice()}") from None
            internal += interaction.force
            seconds[interaction.name] += clock() - t0
        interactions.add_frequencies(self.interactions, self.omega_c2)
        if self.walls.turning:
            self.walls.limit_steps(self.X[:n] + self.u[:n], self.v[:n], self.t, self.step_limit)
        self.internal_force = internal  # the forces between particles (ledger: their impulses)
        force = internal
        if self.body_acc is not None or self.tractions:
            force = internal.copy()
            if self.body_acc is not None:
                force += self.mass[:n, None] * self.body_acc
            if self.tractions:
                self.tractions.add(force, self.t)
        self.force = force
        self.acc = force / self.mass[:n, None]

    def _kick(self, dt: float) -> None:
        if self.damping > 0:
            self.ledger.damp(self, math.exp(-self.damping * dt))
        self.v[:self.n_owned] += dt * self.acc

    def step(self, t_end: float = math.inf) -> float:
        """Advance one time step (and update the reference if due); returns the step size.
        A step that would reach or pass `t_end` (to a relative 1e-12) is shortened to end
        exactly at t_end."""
        start = time.perf_counter()
        inside = sum(self.stage_seconds.values())
        n = self.n_owned
        dt = self.stable.dt
        t_new = self.t + dt
        if t_new >= t_end * (1.0 - 1e-12):
            dt, t_new = t_end - self.t, t_end
        if not t_new > self.t:
            raise self.stable.standstill(self)
        for points in self.point_sets():  # the last evaluation's state is committed
            points.commit()
        self.ledger.give_heat(self)
        self.failure.advance(self, dt)
        if self.failure.breaking:
            self._break_pairs()
        if self.contact is not None and self.contact.dissipative:  # friction's limit
            self.contact.dt = dt
        self.ledger.begin(self)
        self._kick(0.5 * dt)
        prescribe_velocity(self, self.t + 0.5 * dt)
        self.u[:n] += dt * self.v[:n]
        for body in self.rigid_bodies:
            body.drift(dt, self.X, self.u, self.v, self.F)
        self.t = t_new
        prescribe_displacement(self, self.t)
        if self.walls.items:  # the obstacles' changes of velocity and displacement
            v_half, u_drift = self.v[:n].copy(), self.u[:n].copy()
            self.walls.enforce(self.X, self.u, self.v, self.mass, self.t, 0.5 * (self.step_dt + dt),
                               self.rigid_bodies)
            self.ledger.obstacles_moved(self, v_half, u_drift)
        self.step_dt = dt
        self.compute_forces(move_reference=self.eulerian)
        if self.contact is not None:
            self.contact.check_inside(self.gid, self.body, [b.name for b in self.bodies], self.step_count + 1, self.t)
        self._kick(0.5 * dt)
        prescribe_velocity(self, self.t)
        self.ledger.end(self, dt)
        self.step_count += 1
        self.topology.stepped()
        self.stage_seconds["integration"] += (time.perf_counter() - start
                                              - (sum(self.stage_seconds.values()) - inside))
        # an update that is due by count makes this configuration's stable step moot (unless
        # another relation may be due by strain)
        due = self.topology.due()
        if not due or self.topology.by_strain(due):
            clock = time.perf_counter()
            self.stable.dt, strains = self.stable.next_step(self)
            self.stage_seconds["stable step"] += time.perf_counter() - clock
            due = self.topology.due(strains)
        if due:
            self.update_reference(due)
            clock = time.perf_counter()
            self.stable.dt = self.stable.next_step(self)[0]
            self.stage_seconds["stable step"] += time.perf_counter() - clock
        return dt

    def update_reference(self, due: list | None = None) -> None:
        """Make the current configuration the reference [V §3.1] of the `due` kernel
        relations' bodies (None: of every body whose reference moves) between steps
        (topology.Topology.move) and evaluate the forces in it."""
        self.topology.move(self, [r for r in self.topology.relations if r.moves] if due is None else due)
        self.compute_forces()
        self.ledger.external = external_force(self)

    def _break_pairs(self) -> None:
        """Pairs of newly failed particles break (failure.Failure.break_pairs) and the forces
        are evaluated on the new pairs, twice where a plastic body keeps its elastic state
        through the change of F; the change does no work (failure.Failure.settle)."""
        broken = self.failure.break_pairs(self)
        if broken is None:
            return
        self.compute_forces()
        if self.failure.keep_elastic(self, broken):
            self.compute_forces()
        self.failure.settle(self, broken)

    @property
    def dt(self) -> float:
        """The step size the next step will use (unless shortened to end at t_end)."""
        return self.stable.dt

    # ----------------------------------------------------------------- the public read-outs
    def group_index(self, name: str) -> np.ndarray:
        """The owned particles of group `name` (rows)."""
        if name not in self.groups:
            raise ParsphError(f"unknown group '{name}'; the scene's groups: {', '.join(sorted(self.groups))}")
        return np.flatnonzero(self.groups[name])

    def quantity(self, name: str, sel: np.ndarray | None = None) -> np.ndarray:
        """A registered quantity at the owned particles `sel`, or all (readouts.quantity)."""
        return readouts.quantity(self, name, sel)

    def diagnostics(self) -> dict:
        """The history row (diagnostics.history_row, collective)."""
        return history_row(self)
