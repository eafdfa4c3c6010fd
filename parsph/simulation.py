"""`Simulation`: the loop. One rank's particles of every body, the explicit time step,
the bodies' formulation stages, topology and halo, energy bookkeeping and read-outs.

A step is velocity-Verlet (kick-drift-kick leap-frog):
    v += dt/2 a;  constrained v;  u += dt v;  constrained u;  t += dt
    the formulations' stages (formulations.nodal), phase by phase over the bodies, with
        the ghost refreshes derived from what each stage reads and writes -> a = f/m + b
    v += dt/2 a;  constrained v
    [updated reference: if an update is due, X^r = x, F^r = F, V^r = J V^0, new owners,
     migration, ghosts, neighbours and corrections in X^r, forces again]
The scene's bodies share one particle set (global ids numbered body after body, so each
body's owned particles are a contiguous run of rows); each body has its material law and
formulation, and particles of different bodies are not neighbours. The particles are a
point set (parsph.points): which arrays a particle carries, migrates, checkpoints and
mirrors comes from the field registry (parsph.fields), and ghost values are refreshed by
name, as the stages' declarations require. The integration points of the Galerkin methods
(stress points, Gauss points: formulations.galerkin) are point sets of their own, `sets`,
with their owners, ghosts and checkpoint rows.
Local arrays hold the rank's owned particles first, then its ghosts. Sums over particles
(energies, the work accumulated step by step, obstacle forces) are exact (exact_sum), so
that the history, like the particle state, is the same bit for bit on any number of ranks.
"""

from __future__ import annotations

import collections
import math
import time

import numpy as np

from parsph import config, fields, materials, quantities
from parsph.bc import BoundaryConditions, Tractions, apply_initial_conditions
from parsph.collocation import BoundaryCollocation, collocated
from parsph.contact import Contact
from parsph.diagnostics import RowReduction, contact_parts, global_parts, probe_parts, rigid_parts
from parsph.errors import ParsphError
from parsph.exact_sum import allsum
from parsph.formulations import FORMULATIONS, reference, tlsph
from parsph.failure import Failure
from parsph.ledger import Ledger
from parsph.stability import StableStep, check_hourglass_stiffness
from parsph.topology import Topology, reference_shift
from parsph.materials import damage, update
from parsph.neighbors import find_pairs
from parsph.parallel.decomposition import Decomposition, LocalBody
from parsph.parallel.mirrors import add_images
from parsph.parallel.runtime import collective
from parsph.points import PointSet
from parsph import rigid
from parsph.rigid import RigidBody
from parsph.walls import Walls

BASE_FIELDS = tuple(f.name for f in fields.PARTICLE_FIELDS)
UPDATED_STATE = ("Xr", "Fr", "measure_r", "volume_r")  # the updated reference [V §3.1]


class Body:
    """One body of the scene: its particles' global ids first..last-1, its material law and
    constants, its formulation; lo..hi-1 are its owned rows on this rank."""

    def __init__(self, index: int, spec: dict, first: int, last: int, dim: int):
        self.index, self.name = index, spec["name"]
        self.first, self.last = first, last
        self.law = materials.LAWS[spec["material"]["model"]]
        self.constants = materials.constants(spec["material"])
        self.failure_strain = spec["material"]["failure_strain"]  # tensile damage, if not None
        self.rigid = spec.get("rigid", False)  # no stress: moves as one rigid body (parsph.rigid)
        self.breaks_pairs = spec["material"].get("break_pairs", False)  # a failed particle loses its pairs
        self.density = spec["material"]["density"]
        self.formulation = FORMULATIONS[spec["formulation"]["type"]](spec["formulation"], dim, self.law.law_id,
                                                                     damaged=self.failure_strain is not None)
        self.moves = self.formulation.updated and not self.rigid  # its reference moves (updated, Eulerian)
        self.lo = self.hi = 0
        self.set_rows = {}  # its owned rows of each other point set (stress points, Gauss points)
        self.stages = []


class Simulation:
    """The particles this rank owns, of every body, and the loop that steps them."""

    def __init__(self, scene: dict, local: LocalBody, comm, restart: dict | None = None):
        """Set up this rank's particles `local` (build.build_local, or a checkpoint's block
        partitioned); `restart` (io.checkpoint.load: clock and totals) continues a run."""
        self.scene = scene
        self.comm = comm
        self.dim = dim = scene["scene"]["dimension"]
        specs = config.bodies(scene)
        offsets = local.offsets if local.offsets is not None else np.array([0, local.total])
        self.offsets = np.asarray(offsets, np.int64)
        self.bodies = [Body(b, spec, int(self.offsets[b]), int(self.offsets[b + 1]), dim)
                       for b, spec in enumerate(specs)]
        forms = [b.formulation for b in self.bodies]
        moving = [b.formulation for b in self.bodies if b.moves]  # their reference moves, together (config)
        self.updated = bool(moving)
        self.eulerian = any(f.eulerian for f in moving)  # the reference moves at every step, inside it
        self.failure = Failure(self.bodies, dim, comm)
        self.eta = max(f.eta for f in forms)  # the bodies with Hessian stabilisation share it (config)
        self.weighted_hessian = next((f.weighted_hessian for f in forms if f.eta > 0), True)
        self.hourglass = any(f.hourglass_form for f in forms)
        self.topology = Topology(scene, self.bodies, local, comm)
        # the formulations, laws and their states, the updated reference and damage the bodies use
        self.owners = {f.type for f in forms} | {b.law.name for b in self.bodies} | {b.law.state for b in self.bodies}
        if self.updated:
            self.owners.add("updated")
        if any(b.failure_strain is not None for b in self.bodies):
            self.owners.add("damage")
        self.carried = fields.carried(self.owners)  # the registered fields the particles carry
        self.rebalance = scene["parallel"]["rebalance"]
        self.group_names = sorted(scene["groups"])
        self.stage_seconds = collections.defaultdict(float)  # wall time per stage of the step
        body_acc = scene["loads"]["body_acceleration"]
        self.body_acc = None if body_acc is None else np.asarray(body_acc)
        self.damping = scene["time"]["damping"]
        self.t = restart["clock"]["t"] if restart else 0.0  # the constraints in force depend on it
        self.step_count = 0
        self.step_dt = 0.0  # the step that brought F from the committed state (rate-dependent laws)
        self.ledger = Ledger(self.bodies)
        self.stable = StableStep(scene["time"])
        self.walls = Walls(scene["walls"], scene["tools"], dim)
        self.rigid_bodies = []  # the freely moving ones, made after the initial conditions
        self._adopt(local)
        check_hourglass_stiffness(self)
        n = self.n_owned
        if restart is None:
            with collective(comm):
                apply_initial_conditions(scene["initial"], self.groups, self.X[:n], self.gid[:n], self.u[:n],
                                         self.v[:n], scene["parameters"])
            self._prescribe_displacement(0.0)
            self._prescribe_velocity(0.0)
        self.rigid_bodies = self._rigid_bodies(restart)
        if restart is not None:
            clock, carried = restart["clock"], restart["totals"]
            self.t, self.step_count = clock["t"], clock["step"]
            self.step_dt = clock.get("step_dt", 0.0)
            self.topology.restore(clock)
            if comm.rank == 0:  # global totals and the last step's obstacle forces, carried by rank 0
                self.ledger.restore(carried)
                self.walls.restore(carried["wall_force"])
        self.compute_forces()
        self.ledger.external = self.external_force()  # at the current state, for the work integral
        self.stable.start(self, restart["clock"] if restart else None)

    def _rigid_bodies(self, restart: dict | None) -> list:
        """The freely moving rigid bodies (parsph.rigid), from the particles' initial
        velocities or the checkpoint (collective)."""
        out = []
        for b in self.bodies:
            with collective(self.comm):
                free = b.rigid and not rigid.held(b, self.bcs.items, self.dim, self.comm)
            if free:
                body = RigidBody(b, self.mass, self.X, self.comm)
                if restart is None:
                    body.project(self.mass, self.X + self.u, self.v)
                else:
                    body.restore(restart["totals"]["rigid"][len(out)])
                out.append(body)
        return out

    # ----------------------------------------------------------------- set-up helpers
    def _adopt(self, local: LocalBody) -> None:
        """Take `local` (owned particles with two ghost layers and all their arrays) as this
        rank's particles: mirror images across symmetry planes (parallel.mirrors), halo plan,
        reference data in the reference configuration (X, or X^r when updated), the carried
        fields (parsph.fields) and work arrays for owned particles and layer-1 ghosts."""
        updated = self.updated and "Xr" in local.fields
        ref = ("Xr", "measure_r", "volume_r") if updated else ("X", "measure", "volume")
        with collective(self.comm):
            local, mirrors = add_images(local, ref[0], self.scene["symmetry"], self.comm)
            fl, n, dim = local.fields, local.n_owned, self.dim
            # layer 2 kept to rebuild the ghosts' rows between searches, or when pairs break
            layer2 = self.topology.rule.every > 1 or self.failure.breaking
            self.decomp = Decomposition(local, self.comm, mirrors, layer2=layer2)
            body = np.searchsorted(self.offsets, local.gid % local.total, side="right") - 1
            self.failure.detached = self.failure.failed(fl.get("damage"), body)
            failed = self.failure.detached is not None and self.failure.detached[:n].any()
            searched = find_pairs(fl["X"], fl["support"], local.gid, n) if failed else None
            cut = self.failure.crack(searched, fl["X"], fl["measure"], local.gid, n, self.failure.detached)
            self.ref = reference.build(
                fl[ref[0]], fl[ref[1]], fl[ref[2]], fl["support"], local.gid, n, self.decomp.n_rows,
                self.scene["kernel"]["type"], body, [b.formulation.pair_options for b in self.bodies],
                self.eta, self.weighted_hessian, skin=self.topology.skin if self.updated else None, detached=self.failure.detached,
                cut=cut)
        if layer2:
            keep = len(local.gid)
        else:
            self.decomp.trim()  # layer-2 ghosts only served to build the ghosts' rows
            keep = self.decomp.n_rows
        self.n_owned = n
        self.gid = local.gid[:keep]
        self.body = body[:keep]
        self.moves = np.array([b.moves for b in self.bodies])[self.body]  # the rows whose reference moves
        self.all_move = bool(self.moves.all())
        for b in self.bodies:
            b.lo, b.hi = (int(k) for k in np.searchsorted(self.gid[:n], [b.first, b.last]))
        self.X, self.mass, self.volume = fl["X"][:keep], fl["mass"][:keep], fl["volume"][:keep]
        self.measure, self.support = fl["measure"][:keep], fl["support"][:keep]
        self.groups = {name: fl["groups"][:n, k].astype(bool) for k, name in enumerate(self.group_names)}
        self.u = fl["u"][:keep].copy() if "u" in fl else np.zeros((keep, dim))
        self.v = fl["v"][:keep].copy() if "v" in fl else np.zeros((keep, dim))
        # fields registered beyond the base and the updated reference: carried as declared
        extra = self._with_trials({name: self._initial(name, fl, keep) for name in self.carried
                                   if name not in BASE_FIELDS and name not in UPDATED_STATE}, "particles")
        self.F = np.zeros((keep, dim, dim))
        self.d, self.fs = self.u, self.F  # total-Lagrangian: the reference is X, F^r = I
        if self.updated:
            eye = np.broadcast_to(np.eye(dim), (keep, dim, dim))
            self.Xr = fl["Xr"][:keep] if "Xr" in fl else self.X.copy()
            self.Fr = np.ascontiguousarray(fl["Fr"][:keep] if "Fr" in fl else eye)
            self.measure_r = fl["measure_r"][:keep] if "measure_r" in fl else self.measure.copy()
            self.volume_r = fl["volume_r"][:keep] if "volume_r" in fl else self.volume.copy()
            self.shift = reference_shift(self)
            self.d = np.zeros((keep, dim))
            self.fs = np.zeros((keep, dim, dim))
        self.f = np.zeros((keep, dim, dim) if self.eta > 0 else (0, dim, dim))
        self.B = np.zeros((keep, dim, dim) if self.eta > 0 else (0, dim, dim))
        self.VP = np.zeros((keep, dim, dim))
        self.J = np.ones(keep)
        self.psi = np.zeros(keep)
        self.no_state = np.zeros((keep, 0))  # the hyperelastic laws carry no per-point state
        self.broken = np.zeros(n, bool)  # failed particles (materials.damage), set at commits
        self.f_int = np.zeros((n, dim))
        self.f_hg = np.zeros((n, dim) if self.hourglass else (0, dim))
        self.omega_hg2 = np.zeros(n if self.hourglass else 0)  # written by the forces stage
        self.scratch33 = np.empty((3, 3))  # of the kernels of the stable step and the read-outs
        variational = any(b.formulation.hourglass_form == tlsph.HOURGLASS_VARIATIONAL for b in self.bodies)
        self.hg_psi = np.zeros(n if variational else 0)
        self.viscous = any(any(getattr(b.formulation, "viscosity", ())) for b in self.bodies)
        self.f_visc = np.zeros((n if self.viscous else 0, dim))
        self.youngs = np.array([b.constants.youngs for b in self.bodies])[self.body]
        arrays = dict(X=self.X, measure=self.measure, volume=self.volume, mass=self.mass, support=self.support,
                      groups=fl["groups"][:keep], u=self.u, v=self.v, d=self.d, F=self.F, fs=self.fs, f=self.f,
                      B=self.B, VP=self.VP, J=self.J, psi=self.psi, youngs=self.youngs, **extra)
        if self.updated:
            arrays.update(Xr=self.Xr, Fr=self.Fr, measure_r=self.measure_r, volume_r=self.volume_r)
        self.particles = PointSet("particles", self.gid, n, self.decomp, self.carried, arrays)
        self.failure.find_broken(self)
        self.sets = {name: self._adopt_set(name, other) for name, other in (local.sets or {}).items()}
        with collective(self.comm):  # the formulations' own relations
            for b in self.bodies:
                b.formulation.build(self, b, self.scene["kernel"]["type"])
        with collective(self.comm):
            parameters = self.scene["parameters"]
            self.bcs = BoundaryConditions(self.scene["bc"], self.groups, self.X[:n], self.gid[:n], parameters,
                                          self.t)
            self.tractions = Tractions(self.scene["tractions"], self.groups, self.X[:n], self.gid[:n],
                                       self.measure[:n], config.thickness(self.scene), parameters)
        efg = any(collocated(b.formulation) for b in self.bodies)
        self.collocation = BoundaryCollocation(self) if efg and self.scene["bc"] else None
        self.walls.select(self.groups)
        self.contact = Contact(self.scene["contact"], self.bodies, self.body, self.measure, self.mass, self.gid, n, dim,
                               config.thickness(self.scene), self.comm) if self.scene.get("contact") else None
        self.omega_c2 = self.contact.omega2 if self.contact else np.zeros(0)
        self.exclude_kernel_pairs()
        for b in self.bodies:
            b.stages = [] if b.rigid else b.formulation.stages(self, b)
            if b.rigid:
                self.F[b.lo:b.hi] = np.eye(dim)

    def _adopt_set(self, name: str, local: LocalBody) -> PointSet:
        """Another point set (stress points, Gauss points: formulations.galerkin): owned
        points, then ghosts (within the kernel support of an owned particle), the fields it
        carries, work arrays and halo plan; each body's rows of it."""
        dim, fl = self.dim, local.fields
        rows = local.n_owned + local.n_ghost
        carried = fields.carried(self.owners, name)
        arrays = self._with_trials({field: self._initial(field, fl, rows, name) for field in carried}, name)
        arrays.update(F=np.zeros((rows, dim, dim)), VP=np.zeros((rows, dim, dim)), J=np.ones(rows),
                      psi=np.zeros(rows))
        if self.updated:  # the motion from the updated reference
            arrays["fs"] = np.zeros((rows, dim, dim))
        body = arrays["body"][: local.n_owned]
        for b in self.bodies:
            b.set_rows[name] = tuple(int(k) for k in np.searchsorted(body, [b.index, b.index + 1]))
        return PointSet(name, arrays["gid"], local.n_owned, Decomposition(local, self.comm), carried, arrays)

    @staticmethod
    def _with_trials(arrays: dict, points: str) -> dict:
        """`arrays` with a work array NAME_trial beside each material state field NAME: the
        state the last stress evaluation computed (materials.update), committed at the start
        of the next step."""
        states = [name for name in arrays if fields.get(name, points).kind == "state"]
        return dict(arrays, **{name + "_trial": arrays[name].copy() for name in states})

    def material_state(self, body: Body, points: str = "particles") -> tuple:
        """(committed, trial) state arrays of `body`'s material law on a point set (empty
        arrays for a law without state)."""
        if body.law.state is None:
            return self.no_state, self.no_state
        A = self.point_set(points).arrays
        return A[body.law.state], A[body.law.state + "_trial"]

    def damage_state(self, body: Body) -> tuple:
        """(committed, trial) damage state arrays of `body`'s particles (empty without damage)."""
        if body.failure_strain is None:
            return self.no_state, self.no_state
        return self.particles.arrays["damage"], self.particles.arrays["damage_trial"]

    def exclude_kernel_pairs(self) -> None:
        """Tell a self-contact the kernel's pairs, which it leaves out (parsph.contact)."""
        if self.contact:
            self.contact.exclude(self.ref, self.gid)

    def point_set(self, name: str) -> PointSet:
        return self.particles if name == "particles" else self.sets[name]

    def point_sets(self) -> list:
        """The rank's point sets: the particles, then the others (stress points, Gauss points)."""
        return [self.particles] + list(self.sets.values())

    def _refresh(self, names) -> None:
        """Refresh the ghost values of the named arrays: "NAME" of the particles, "SET.NAME"
        of another point set."""
        by_set = collections.defaultdict(list)
        for name in names:
            where, _, field = name.rpartition(".")
            by_set[where or "particles"].append(field)
        for points in self.point_sets():
            if by_set.get(points.name):
                points.refresh(*by_set[points.name])

    def _initial(self, name: str, fl: dict, keep: int, points: str = "particles") -> np.ndarray:
        """A registered field's values on the local rows of a point set: as carried in `fl`
        (migrated, read from a checkpoint), else its declared initial values, else zeros."""
        if name in fl:
            return fl[name][:keep].copy()
        field = fields.get(name, points)
        if field.initial is not None:
            return np.asarray(field.initial(fl["X"][:keep], fl["gid"][:keep]), np.float64).copy()
        return np.zeros((keep,) + field.shape(self.dim))

    # ----------------------------------------------------------------- the step
    def compute_forces(self, move_reference: bool = False) -> None:
        """The bodies' stages at the current u, phase by phase; before each phase the ghost
        values of the fields it reads at neighbours that are stale are refreshed (the
        displacement always: the integrator moved it). With `move_reference` (an Eulerian
        kernel's step) the reference moves to the current configuration once F and the
        stress are known, before the force row. Sets self.force and self.acc (owned)."""
        n = self.n_owned
        clock = time.perf_counter
        seconds = self.stage_seconds
        stale = {"d", "v"}  # moved by the integrator (v is refreshed only if a stage reads it)
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
                self._refresh(reads)
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
        force = self.f_int + self.f_hg if self.hourglass else self.f_int.copy()
        if self.viscous:
            force += self.f_visc
        if self.contact:
            t0 = clock()
            try:
                self.contact.evaluate(self.X[:n] + self.u[:n], self.v[:n])
            except ArithmeticError:
                raise ParsphError(f"contact failed at step {self.step_count + 1}, t = {self.t:.6g}: particles of "
                                  f"two bodies coincide; the run is unstable: {self.stable.advice()}") from None
            force += self.contact.force
            seconds["contact"] += clock() - t0
        if self.body_acc is not None:
            force += self.mass[:n, None] * self.body_acc
        if self.tractions:
            self.tractions.add(force, self.t)
        self.force = force
        self.acc = force / self.mass[:n, None]

    def external_force(self) -> np.ndarray:
        """Body force, tractions and constraint reactions on the owned particles."""
        n = self.n_owned
        ext = np.zeros((n, self.dim))
        if self.body_acc is not None:
            ext += self.mass[:n, None] * self.body_acc
        if self.tractions:
            self.tractions.add(ext, self.t)
        ext[self.bcs.mask] -= self.force[self.bcs.mask]
        return ext

    def reaction(self) -> np.ndarray:
        """Force the constraints exert on each owned particle (zero where unconstrained)."""
        r = np.zeros((self.n_owned, self.dim))
        r[self.bcs.mask] = -self.force[self.bcs.mask]
        return r

    def _kick(self, dt: float) -> None:
        n = self.n_owned
        v = self.v[:n]
        if self.damping > 0:
            v *= math.exp(-self.damping * dt)
        v += dt * self.acc

    def _prescribe_velocity(self, t: float) -> None:
        """The constrained velocities at t (collocated on EFG bodies: parsph.collocation),
        and the rigid velocities of the free rigid bodies' particles."""
        self.bcs.set_velocity(self.v[: self.n_owned], t)
        if self.collocation:
            self.collocation.velocity(t)
        n = self.n_owned
        for body in self.rigid_bodies:
            body.project(self.mass, self.X[:n] + self.u[:n], self.v)

    def _prescribe_displacement(self, t: float) -> None:
        self.bcs.set_displacement(self.u[: self.n_owned], t)
        if self.collocation:
            self.collocation.displacement(t)

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
        for points in self.point_sets():  # the last evaluation's state is committed
            points.commit()
        self.failure.grow(self, dt)
        if self.failure.breaking:
            self.failure.break_pairs(self)
        if self.contact is not None and self.contact.dissipative:  # friction's limit
            self.contact.dt = dt
        self.ledger.begin(self)
        self._kick(0.5 * dt)
        self._prescribe_velocity(self.t + 0.5 * dt)
        self.u[:n] += dt * self.v[:n]
        for body in self.rigid_bodies:
            body.drift(dt, self.X, self.u, self.v, self.F)
        self.t = t_new
        self._prescribe_displacement(self.t)
        if self.walls.items:  # the obstacles' changes of velocity and displacement
            v_half, u_drift = self.v[:n].copy(), self.u[:n].copy()
            self.walls.enforce(self.X, self.u, self.v, self.mass, self.t, dt)
            self.ledger.obstacles_moved(self, v_half, u_drift)
        self.step_dt = dt
        self.compute_forces(move_reference=self.eulerian)
        self._kick(0.5 * dt)
        self._prescribe_velocity(self.t)
        self.ledger.end(self, dt)
        self.step_count += 1
        self.topology.since += 1
        self.stage_seconds["integration"] += (time.perf_counter() - start
                                              - (sum(self.stage_seconds.values()) - inside))
        # an update that is due by count makes this configuration's stable step moot
        due = self.topology.due(self)
        if not due:
            clock = time.perf_counter()
            self.stable.dt, strain = self.stable.next_step(self)
            self.stage_seconds["stable step"] += time.perf_counter() - clock
            due = self.topology.due(self, strain)
        if due:
            self.topology.update(self)
            clock = time.perf_counter()
            self.stable.dt = self.stable.next_step(self)[0]
            self.stage_seconds["stable step"] += time.perf_counter() - clock
        return dt

    @property
    def dt(self) -> float:
        """The step size the next step will use (unless shortened to end at t_end)."""
        return self.stable.dt

    def checkpoint_state(self) -> dict:
        """Everything io.checkpoint stores (collective: totals): per-particle arrays of the
        owned particles (with the updated reference, if any); the accumulated totals over all
        ranks, exact (exact_sum.Exact.to_json), and the last step's obstacle forces."""
        return {
            "fields": self.particles.checkpointed(), "group_names": self.group_names,
            "sets": {p.name: (p.gid[: p.n_owned], p.total, p.checkpointed()) for p in self.point_sets()[1:]},
            "totals": {**self.ledger.checkpoint(self.comm), "wall_force": self.wall_forces().tolist(),
                       "rigid": [body.state() for body in self.rigid_bodies]},
            "clock": {"t": self.t, "step": self.step_count, "dt": self.dt, "step_dt": self.step_dt,
                      "updates": self.topology.count, "since_update": self.topology.since, "first_stable": self.stable.first},
        }

    # ----------------------------------------------------------------- read-outs
    def group_index(self, name: str) -> np.ndarray:
        return np.flatnonzero(self.groups[name])

    def quantity(self, name: str, sel: np.ndarray) -> np.ndarray:
        """A particle quantity on the owned particles `sel` (probes and snapshots): computed as
        parsph.quantities registers it, or a registered field's values."""
        q = quantities.BUILT_IN.get(name)
        if q is not None and q.compute is not None:
            return q.compute(self, sel)
        if fields.known(name) and fields.get(name).units is not None:  # a registered field
            return self.particles.arrays[name][sel]
        raise ValueError(name)

    def quadrature(self) -> tuple:
        """(X, F, w): reference positions, deformation gradients and quadrature weights of
        this rank's owned integration points, body after body (the particles for the nodal
        methods; particles, stress or Gauss points for the Galerkin ones)."""
        parts = [q for b in self.bodies for q in b.formulation.quadrature(self, b)]
        return tuple(np.concatenate([p[k] for p in parts]) for k in range(3))

    def disorder(self) -> np.ndarray:
        """Hourglass error eta_i of each owned particle (formulations.tlsph.hourglass_error)."""
        out = np.empty(self.n_owned)
        ref = self.ref
        tlsph.hourglass_error(self.dim)(self.n_owned, ref.ptr, ref.idx, ref.dx, ref.w, self.d, self.fs, out,
                                        self.scratch33)
        return out

    def spacing_ratio(self) -> np.ndarray:
        """Current-configuration disorder of each owned particle (tlsph.spacing_ratio), with the
        ghosts where the last force evaluation saw them."""
        out = np.empty(self.n_owned)
        ref = self.ref
        x = self.Xr + self.d if self.updated else self.X + self.u
        tlsph.spacing_ratio(self.n_owned, ref.ptr, ref.idx, x, self.measure, self.F, self.dim, out, self.scratch33)
        return out

    def cauchy_stress(self, sel: np.ndarray, full: bool = False) -> np.ndarray:
        """sigma = J^-1 P(F) F^T at the owned particles `sel`, from the material law (with the
        committed state: the stress of the last evaluation) and its damage: the dim x dim
        block, or (full) all 3 x 3 components, the out-of-plane ones of plane strain (2D) and
        uniaxial strain (1D) included (the law evaluated with F padded by unit stretches)."""
        d = 3 if full else self.dim
        F = np.zeros((len(sel), d, d))
        F[:, :self.dim, :self.dim] = self.F[sel]
        for a in range(self.dim, d):
            F[:, a, a] = 1.0
        P = np.empty_like(F)
        body = self.body[sel]
        for b in self.bodies:
            rows = np.arange(len(sel)) if len(self.bodies) == 1 else np.flatnonzero(body == b.index)
            state = np.ascontiguousarray(self.material_state(b)[0][sel[rows]]) if b.law.state else self.no_state
            part = np.empty_like(F[rows])
            update.stresses(b.law.law_id, np.ascontiguousarray(F[rows]), d, b.constants.values, state,
                            state.copy(), part, np.empty(len(rows)), self.step_dt)
            if b.failure_strain is not None:
                damage.degraded_stresses(part, np.ascontiguousarray(F[rows]), d,
                                         np.ascontiguousarray(self.damage_state(b)[0][sel[rows]]),
                                         np.empty((update.WORK, 3, 3)))
            P[rows] = part
        return np.einsum("nab,ncb->nac", P, F) / self.J[sel, None, None]

    def law_readout(self, sel: np.ndarray, name: str) -> np.ndarray:
        """The material laws' read-out `name` (materials.law.Readout) of their last stress
        evaluation's state at the owned particles `sel` (0 for the laws without it)."""
        out = np.zeros(len(sel))
        for b in self.bodies:
            readout = b.law.readouts.get(name)
            if readout is not None:
                rows = np.flatnonzero(self.body[sel] == b.index)
                out[rows] = readout.compute(b.constants.values, self.material_state(b)[1][sel[rows]])
        return out

    def von_mises(self, sel: np.ndarray) -> np.ndarray:
        """sqrt(3/2 s:s) of the full Cauchy stress (out-of-plane components included)."""
        s = self.cauchy_stress(sel, full=True)
        dev = s - np.trace(s, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
        return np.sqrt(1.5 * np.einsum("nab,nab->n", dev, dev))

    def wall_forces(self) -> np.ndarray:
        """Each wall's and tool's force on the body in the last step, (obstacles, dim), exact
        sums over all ranks (collective)."""
        sums = allsum(self.comm, self.walls.force_sums())
        return np.array([float(s) for s in sums]).reshape(len(self.walls.items), self.dim)

    def diagnostics(self, reduction: RowReduction | None = None) -> dict:
        """The history row: clock, diagnostics.global_parts, obstacle forces and probes
        (collective: one reduction over the ranks, `reduction` if given, holding what the
        caller added)."""
        reduction = reduction or RowReduction(self.comm)
        energies = global_parts(self, reduction)
        walls = reduction.add_sums(self.walls.contacts)  # obstacle-major, then component
        contact = contact_parts(self, reduction)
        rigid = rigid_parts(self, reduction)
        probes = probe_parts(self.scene["probes"], self, reduction)
        reduction.reduce()
        out = {"time": self.t, "step": float(self.step_count), "dt": self.stable.dt,
               "reference_updates": float(self.topology.count)}
        out.update(energies())
        for k, label in enumerate(self.walls.names):
            for a, name in enumerate("xyz"[: self.dim]):
                out[f"{label}_force_{name}"] = float(reduction.sums[walls + k * self.dim + a])
        out.update(contact())
        out.update(rigid())
        out.update(probes())
        return out
