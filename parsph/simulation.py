"""`Simulation`: the loop over one rank's particles of every body. A step is
velocity-Verlet (kick-drift-kick leap-frog):
    commit the material state, advance failure, break pairs   (points, failure)
    v += dt/2 a;  constrained v;  u += dt v;  constrained u   (conditions)
    obstacles; the formulations' stages, phase by phase, with the ghost refreshes their
        declarations require (an Eulerian kernel moves its reference inside) -> a
    v += dt/2 a;  constrained v;  the step's works            (ledger)
    the next step's size; a reference update if one is due    (stability, topology)
The rank's particles live in its state (parsph.state.RankState); sums over particles are exact
(exact_sum), so that the history, like the particle state, is the same bit for bit on any
number of ranks.
"""

from __future__ import annotations

import collections
import math
import time

import numpy as np

from parsph import operator_frequency, readouts
from parsph.bc import apply_initial_conditions
from parsph.conditions import Conditions
from parsph.diagnostics import history_row
from parsph.errors import ParsphError
from parsph.fields import Field, register
from parsph.failure import Failure
from parsph.formulations.base import Running
from parsph.ledger import Ledger
from parsph.interactions import Interactions
from parsph.kernel_relation import Configuration
from parsph.parallel.decomposition import Decomposition, LocalBody
from parsph.parallel.mirrors import add_images
from parsph.parallel.runtime import collective
from parsph.stability import StableStep, check_hourglass_stiffness
from parsph.state import Body, RankState
from parsph.topology import Topology
from parsph.walls import Walls


# the velocity the last force evaluation saw (after the first half-kick and the obstacles):
# viscosity, MACHDYN's hourglass dampers, damped contact and ties read it, so a restart
# evaluates the forces at it, not at the step's end velocity
register(Field("v_forces", "vector", owner="velocity forces",
               doc="velocity at the last force evaluation [m/s] (a restart's forces)"))


class Simulation:
    """The particles this rank owns, of every body, and the loop that steps them."""

    def __init__(self, scene, local: LocalBody, comm, restart: dict | None = None):
        """Set up this rank's particles `local` (build.build_local, or a checkpoint's block
        partitioned); `restart` (io.checkpoint.load: clock and totals) continues a run."""
        self.scene = scene
        self.comm = comm
        dim = scene.scene.dimension
        offsets = np.asarray(local.offsets if local.offsets is not None else [0, local.total], np.int64)
        bodies = [Body(b, spec, int(offsets[b]), int(offsets[b + 1]), dim)
                  for b, spec in enumerate(scene.bodies)]
        # the step allowed by the particles' motion is limited by contact and surfaces (and viscosity)
        limited = bool(scene.contact or scene.surfaces)
        self.state = state = RankState(bodies, offsets, dim, comm, sorted(scene.groups), limited,
                                       bool(scene.contact or scene.ties))
        self.failure = Failure(bodies, dim, comm, restart["cut"] if restart else None)
        self.topology = Topology(scene, bodies, local, comm)
        self.stage_seconds = collections.defaultdict(float)  # wall time per stage of the step
        self.ledger = Ledger(bodies)
        self.stable = StableStep(scene.time)
        # the clock, and what the stages read while the run goes (formulations.base.Running)
        self.running = Running(self.ledger, self.stable, restart["clock"]["t"] if restart else 0.0)
        self.walls = Walls(scene.walls, scene.tools, dim, scene.surfaces, scene.parameters)
        self.conditions = Conditions(scene)
        self.adopt(local)
        check_hourglass_stiffness(state, self.topology)
        n = state.n_owned
        if restart is None:
            with collective(comm):
                apply_initial_conditions(scene.initial, state.groups, state.X[:n], state.gid[:n], state.u[:n],
                                         state.v[:n], scene.parameters)
            self.conditions.prescribe_displacement(state, 0.0)
            self.conditions.prescribe_velocity(state, 0.0)
        self.conditions.free_rigid_bodies(state, restart)
        if restart is not None:
            clock, carried = restart["clock"], restart["totals"]
            self.running.t, self.running.step = clock["t"], clock["step"]
            self.running.dt = clock.get("step_dt", 0.0)
            self.topology.restore(clock)
            for interaction in self.interactions:
                interaction.restore(carried)
            if comm.rank == 0:  # global totals and the last step's obstacle forces, carried by rank 0
                self.ledger.restore(carried)
                self.walls.restore(carried["wall_force"], carried.get("surface_torque", ()))
        if self.interactions.contact is not None and restart is None:
            self.interactions.contact.check_apart(state.gid, state.body, state.X[:n] + state.u[:n],
                                                  [b.name for b in bodies])
        self._forces_at_set_up(restart is not None and "v_forces" in local.fields)  # (older checkpoints lack it)
        factors = restart["clock"].get("step_factors") if restart else None
        if factors is None:
            # a flattened particle stops the run here, named, before the measurement perturbs it
            self.stable.limit(state, self.topology, self.interactions, self.step_count, self.t)
            start = time.perf_counter()
            self._measure_operator(tighten=False)
            self.stage_seconds["step operator"] += time.perf_counter() - start
        else:
            for b, factor in zip(bodies, factors):
                b.step_factor = factor
            self.stable.measured = restart["clock"].get("measured_step", 0)
        self.ledger.external = self.conditions.external_force(state, self.t)  # for the work integral
        self.stable.start(state, self.topology, self.interactions, self.step_count, self.t,
                          restart["clock"] if restart else None)

    def _forces_at_set_up(self, checkpointed: bool) -> None:
        """The first force evaluation; with a checkpoint's `v_forces`, at the velocity the
        checkpointed step's evaluation saw, where a force reads the velocity (then the step's
        end velocity is restored), so that the run continues bit for bit."""
        state, n = self.state, self.state.n_owned
        if not (checkpointed and "v_forces" in state.carried):
            self.compute_forces()
            return
        v_end = state.v[:n].copy()
        state.v[:n] = state.particles.owned("v_forces")
        self.compute_forces()
        state.v[:n] = v_end

    def adopt(self, local: LocalBody) -> None:
        """Take `local` (owned particles with two ghost layers and all their arrays) as this
        rank's particles (at set-up, and after a search of the reference: topology.Topology.move):
        mirror images across symmetry planes (parallel.mirrors), halo plan, the kernel
        relations' reference data in the reference configuration (X, or X^r when updated), the
        rank state's fields (state.RankState.adopt), the formulations' own relations and
        stages, the conditions and the interactions on them."""
        state, scene, comm = self.state, self.scene, self.comm
        updated = state.updated and "Xr" in local.fields
        ref = ("Xr", "measure_r", "volume_r") if updated else ("X", "measure", "volume")
        with collective(comm):
            local, mirrors = add_images(local, ref[0], scene.symmetry, comm,
                                        skin=self.topology.skin if state.updated else 0.0)
            fl, n = local.fields, local.n_owned
            # layer 2 kept to rebuild the ghosts' rows between searches, or when pairs break
            layer2 = self.topology.keeps or self.failure.breaking
            decomp = Decomposition(local, comm, mirrors, layer2=layer2)
            self.ledger.share = mirrors.share if mirrors else None  # particles on a plane count by their share
            body = np.searchsorted(state.offsets, local.gid % local.total, side="right") - 1
            self.failure.detached = self.failure.failed(fl.get("damage"), body)
            cut = self.failure.known_cut(fl[ref[0]], fl[ref[1]], fl["support"], local.gid, n, self.failure.detached,
                                         len(scene.symmetry), local.total)
            self.topology.build(Configuration(fl[ref[0]], fl[ref[1]], fl[ref[2]], fl["support"], local.gid, body, n,
                                              decomp.n_rows), detached=self.failure.detached, cut=cut)
        if not layer2:
            decomp.trim()  # layer-2 ghosts only served to build the ghosts' rows
        state.adopt(local, decomp, body, len(local.gid) if layer2 else decomp.n_rows)
        self.failure.find_broken(state)
        with collective(comm):  # the formulations' own relations
            for b in state.bodies:
                b.formulation.build(state, b, b.relation.kernel, self.topology.skin)
        self.conditions.adopt(state, self.t)
        self.walls.select(state.groups)
        self.interactions = Interactions(scene, state, self.ledger, self.topology)  # parsph.interactions
        self.make_stages()

    def make_stages(self) -> None:
        """The bodies' stages on the adopted state (formulations.base); a rigid body has none."""
        for b in self.state.bodies:
            b.stages = [] if b.rigid else b.formulation.stages(self.state, b, self.running)
            if b.rigid:
                self.state.F[b.lo:b.hi] = np.eye(self.state.dim)

    # ----------------------------------------------------------------- the step
    def compute_forces(self, move_reference: bool = False) -> None:
        """The bodies' stages at the current u, phase by phase; before each phase the ghost
        values of the fields it reads at neighbours that are stale are refreshed (the
        displacement always: the integrator moved it). With `move_reference` (an Eulerian
        kernel's step) the reference moves to the current configuration once F and the
        stress are known, before the force row. Sets the state's force, of which
        internal_force is the part between particles, and acc (owned)."""
        state = self.state
        n = state.n_owned
        clock = time.perf_counter
        seconds = self.stage_seconds
        stale = self._run_stages(seconds, move_reference)
        if stale is None:  # searched: the whole evaluation was made in the new reference
            return
        internal = self._bodies_force()
        for interaction in self.interactions:  # parsph.interactions
            t0 = clock()
            reads = [name for name in interaction.reads if name in stale]
            if reads:
                state.refresh(reads)
                stale.difference_update(reads)
            try:
                interaction.evaluate(state.X[:n] + state.u[:n], state.v[:n], state.step_limit)
            except ArithmeticError:
                raise ParsphError(f"{interaction.name} failed at step {self.step_count + 1}, t = {self.t:.6g}: "
                                  f"particles of two bodies coincide; the run is unstable: "
                                  f"{self.stable.advice()}") from None
            internal += interaction.force
            seconds[interaction.name] += clock() - t0
        self.interactions.add_frequencies()
        if self.walls.turning:
            self.walls.limit_steps(state.X[:n] + state.u[:n], state.v[:n], self.t, state.step_limit)
        state.internal_force = internal  # the forces between particles (ledger: their impulses)
        force = internal
        if self.conditions.body_acc is not None or self.conditions.tractions:
            force = internal.copy()
            self.conditions.add_loads(state, force, self.t)
        state.force = force
        state.acc = force / state.mass[:n, None]

    def _run_stages(self, seconds: dict, move_reference: bool = False) -> set | None:
        """The bodies' stages at the current u, phase by phase (as compute_forces), their
        wall times added to `seconds`; returns the fields written whose ghost values are
        stale, or None if an Eulerian move searched and compute_forces was run anew."""
        state = self.state
        clock = time.perf_counter
        stale = {"d", "v"}  # moved by the integrator (v is refreshed only if a stage reads it)
        state.step_limit.fill(np.inf)
        phases = max(len(b.stages) for b in state.bodies)
        k = 0
        while k < phases:
            phase = [b.stages[k] for b in state.bodies if k < len(b.stages)]
            if move_reference and any(stage.force_row for stage in phase):
                move_reference = False
                if self._move_reference([r for r in self.topology.relations if r.eulerian]):
                    self.compute_forces()  # searched: new arrays, the whole evaluation in the new reference
                    return None
                continue  # the same phase, with the stages of the new reference
            reads = [name for name in dict.fromkeys(r for stage in phase for r in stage.reads) if name in stale]
            if reads:
                t0 = clock()
                state.refresh(reads)
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
        return stale

    def internal_force(self) -> np.ndarray:
        """The bodies' internal force (their stages' forces, state.FORCES) on the owned rows at
        the current u: no interactions, obstacles or loads. It writes the arrays the stages
        write (F, stress, trial states) as an evaluation at this u does; the state stays
        consistent once compute_forces has run at the run's own u."""
        self._run_stages(collections.defaultdict(float))
        return self._bodies_force()

    def _bodies_force(self) -> np.ndarray:
        """The sum of the force arrays the bodies' stages wrote (state.FORCES, in order), a new array."""
        state = self.state
        internal = None
        for force in state.forces:  # state.FORCES
            if internal is None:
                internal = getattr(state, force.name).copy()
            else:
                internal += getattr(state, force.name)
        return internal

    def _kick(self, dt: float) -> None:
        state = self.state
        if self.conditions.damping > 0:
            self.ledger.damp(state, self.conditions.bcs, math.exp(-self.conditions.damping * dt))
        state.v[:state.n_owned] += dt * state.acc

    def step(self, t_end: float = math.inf) -> float:
        """Advance one time step (and update the reference if due); returns the step size.
        A step that would reach or pass `t_end` (to a relative 1e-12) is shortened to end
        exactly at t_end."""
        start = time.perf_counter()
        inside = sum(self.stage_seconds.values())
        state, conditions, contact = self.state, self.conditions, self.interactions.contact
        n = state.n_owned
        dt = self.stable.dt
        t_new = self.t + dt
        if t_new >= t_end * (1.0 - 1e-12):
            dt, t_new = t_end - self.t, t_end
        if not t_new > self.t:
            raise self.stable.standstill(self.step_count, self.t)
        for points in state.point_sets():  # the last evaluation's state is committed
            points.commit()
        self.ledger.give_heat(state)
        self.failure.advance(state, dt)
        if self.failure.breaking:
            self._break_pairs()
        if contact is not None and contact.dissipative:  # friction's limit
            contact.dt = dt
        self.ledger.begin(state, conditions, self.interactions)
        self._kick(0.5 * dt)
        conditions.prescribe_velocity(state, self.t + 0.5 * dt)
        state.u[:n] += dt * state.v[:n]
        for body in conditions.rigid_bodies:
            body.drift(dt, state.X, state.u, state.v, state.F)
        self.running.t = t_new
        conditions.prescribe_displacement(state, self.t)
        if self.walls.items:  # the obstacles' changes of velocity and displacement
            v_half, u_drift = state.v[:n].copy(), state.u[:n].copy()
            self.walls.enforce(state.X, state.u, state.v, state.mass, self.t, 0.5 * (self.step_dt + dt),
                               conditions.rigid_bodies)
            self.ledger.obstacles_moved(state, v_half, u_drift)
        self.running.dt = dt
        if "v_forces" in state.carried:
            state.particles.owned("v_forces")[:] = state.v[:n]
        self.compute_forces(move_reference=state.eulerian)
        if contact is not None:
            contact.check_inside(state.gid, state.body, [b.name for b in state.bodies], self.step_count + 1, self.t)
        self._kick(0.5 * dt)
        conditions.prescribe_velocity(state, self.t)
        self.ledger.end(state, conditions, self.interactions, self.t, dt)
        self.running.step += 1
        self.topology.stepped()
        self.stage_seconds["integration"] += (time.perf_counter() - start
                                              - (sum(self.stage_seconds.values()) - inside))
        # an update that is due by count makes this configuration's stable step moot (unless
        # another relation may be due by strain)
        due = self.topology.due()
        if not due or self.topology.by_strain(due):
            clock = time.perf_counter()
            self.stable.dt, strains = self._next_step()
            self.stage_seconds["stable step"] += time.perf_counter() - clock
            due = self.topology.due(strains)
        if due:
            self.update_reference(due)
        # the step factors measured again where a reference moves between steps (not with a
        # fixed time.dt, nor an Eulerian kernel's, which moves inside the force evaluation)
        measure = (state.updated and not state.eulerian and self.scene.time.dt == 0
                   and self.step_count - self.stable.measured >= operator_frequency.EVERY)
        if measure:
            clock = time.perf_counter()
            self._measure_operator()
            self.stage_seconds["step operator"] += time.perf_counter() - clock
        if due or measure:
            clock = time.perf_counter()
            self.stable.dt = self._next_step()[0]
            self.stage_seconds["stable step"] += time.perf_counter() - clock
        return dt

    def _measure_operator(self, tighten: bool = True) -> None:
        """The bodies' step factors measured (stability.StableStep.calibrate) at set-up, and,
        where a reference moves, again every operator_frequency.EVERY steps, where they only
        rise (`tighten`): the updated operator changes with the particles' arrangement in
        each new reference and may stiffen faster than the estimate's stretch and stiffening
        follow (over the bending of the Hessian-stabilised updated cylinder its top frequency
        rises 1.34 times against the estimate's). A total-Lagrangian operator changes with
        the deformation alone, which the estimate follows, conservatively where it was seen
        (the compressed punch's top frequency falls to 0.54 of the estimate's, the rubber
        ring's to 0.45). The stages are run again at the run's own u, which gives back every
        array they wrote bit for bit; the interactions' motion limits are kept."""
        state = self.state
        limit = state.step_limit.copy()
        squared = operator_frequency.largest_frequencies(state, self.internal_force)
        self._run_stages(collections.defaultdict(float))
        state.step_limit[:] = limit
        self.stable.calibrate(state, squared, tighten)
        self.stable.measured = self.step_count

    def _next_step(self) -> tuple:
        """The next step's size and the relations' strains (stability.StableStep.next_step)."""
        return self.stable.next_step(self.state, self.topology, self.interactions, self.step_count, self.t)

    def update_reference(self, due: list | None = None) -> None:
        """Make the current configuration the reference [V §3.1] of the `due` kernel
        relations' bodies (None: of every body whose reference moves) between steps and
        evaluate the forces in it."""
        self._move_reference([r for r in self.topology.relations if r.moves] if due is None else due)
        self.compute_forces()
        self.ledger.external = self.conditions.external_force(self.state, self.t)

    def _move_reference(self, due: list) -> bool:
        """The reference update of the `due` kernel relations (topology.Topology.move): the
        particles of a search adopted, or the collocation and the stages made on what the kept
        lists rebuilt. Returns whether it searched (the arrays are new)."""
        start = time.perf_counter()
        with self.topology.failing(self.step_count, self.t):
            local = self.topology.move(self.state, self.ledger, due)
            if local is not None:
                self.adopt(local)
        if local is None:
            self.conditions.recollocate(self.state)
            self.make_stages()
        self.topology.moved(self.state, due, local is not None)
        self.stage_seconds["reference update"] += time.perf_counter() - start
        return local is not None

    def _break_pairs(self) -> None:
        """Pairs of newly failed particles break (failure.Failure.break_pairs) and the forces
        are evaluated on the new pairs, twice where a plastic body keeps its elastic state
        through the change of F; the change does no work (failure.Failure.settle)."""
        broken = self.failure.break_pairs(self.state, self.topology, len(self.scene.symmetry))
        if broken is None:
            return
        self.compute_forces()
        if self.failure.keep_elastic(self.state, broken):
            self.compute_forces()
        self.failure.settle(self.state, self.ledger, broken)
        self.ledger.external = self.conditions.external_force(self.state, self.t)

    @property
    def dt(self) -> float:
        """The step size the next step will use (unless shortened to end at t_end)."""
        return self.stable.dt

    # the clock (formulations.base.Running): the time reached, the steps taken, the size of the
    # last step (which brought F from the committed state: rate-dependent laws)
    t = property(lambda self: self.running.t)
    step_count = property(lambda self: self.running.step)
    step_dt = property(lambda self: self.running.dt)

    # ----------------------------------------------------------------- the public read-outs
    def group_index(self, name: str) -> np.ndarray:
        """The owned particles of group `name` (rows)."""
        groups = self.state.groups
        if name not in groups:
            raise ParsphError(f"unknown group '{name}'; the scene's groups: {', '.join(sorted(groups))}")
        return np.flatnonzero(groups[name])

    def quantity(self, name: str, sel: np.ndarray | None = None) -> np.ndarray:
        """A registered quantity at the owned particles `sel`, or all (readouts.quantity)."""
        return readouts.quantity(self, name, sel)

    def diagnostics(self) -> dict:
        """The history row (diagnostics.history_row, collective)."""
        return history_row(self)
