"""`Simulation`: the particle state of one rank and the explicit time step.

A step is velocity-Verlet (kick-drift-kick leap-frog):
    v += dt/2 a;  constrained v;  u += dt v;  constrained u;  t += dt
    halo(d) -> [gradient -> halo(f)] -> kinematics + stress -> halo(V P, f^s)
        -> [hessian_transpose -> halo(B)] -> forces -> a = f/m + b
    v += dt/2 a;  constrained v
    [updated reference: if an update is due, X^r = x, F^r = F, V^r = J V^0, new owners,
     migration, ghosts, neighbours and corrections in X^r, forces again]
Bracketed stages run only with Hessian stabilisation or the updated formulation. Local
arrays hold the rank's owned particles first, then its ghosts. Only the stages a scene
uses are compiled and run (formulations.tlsph). Sums over particles (energies, the work
accumulated step by step, obstacle forces) are exact (exact_sum), so that the history, like
the particle state, is the same bit for bit on any number of ranks.
"""

from __future__ import annotations

import collections
import math
import time

import numpy as np
from mpi4py import MPI

from parsph import config
from parsph.bc import BoundaryConditions, apply_initial_conditions
from parsph.diagnostics import global_diagnostics, probe_values
from parsph.errors import InputError, ParsphError
from parsph.exact_sum import Accumulator, Exact, allsum, total
from parsph.formulations import reference, tlsph
from parsph.materials.elastic import MODEL_IDS, first_piola_stresses
from parsph.parallel.decomposition import Decomposition, LocalBody, add_ghosts, partition
from parsph.parallel.mirrors import add_images
from parsph.parallel.runtime import collective
from parsph.walls import Walls

REFERENCE_STATE = ("Xr", "Fr", "measure_r", "volume_r")  # the updated reference [V §3.1]


class Simulation:
    """Lagrangian corrected SPH state and stepping for the particles this rank owns."""

    def __init__(self, scene: dict, local: LocalBody, comm, restart: dict | None = None):
        """Set up this rank's particles `local` (build.build_local, or a checkpoint's block
        partitioned); `restart` (io.checkpoint.load: clock and totals) continues a run."""
        self.scene = scene
        self.comm = comm
        self.dim = dim = scene["scene"]["dimension"]
        self.constants = config.material_constants(scene["material"])
        self.model = MODEL_IDS[scene["material"]["model"]]
        form = scene["formulation"]
        self.alpha = form["hourglass"]
        self.hourglass = self.alpha > 0.0
        self.hourglass_form = tlsph.HOURGLASS_FORMS[form["hourglass_form"]] if self.hourglass else 0
        self.pair_form = form["force_form"] == "pair"
        self.updated = form["type"] == "ulsph"
        self.eta = form["hessian"]
        self.weighted_hessian = form["hessian_correction"] == "weighted"
        self.update_every, self.update_strain = form["update_every"], form["update_strain"]
        self.rebalance = scene["parallel"]["rebalance"]
        self.group_names = sorted(scene["groups"])
        self._gradient, self._kinematics_stress, self._hessian_transpose, self._forces = \
            tlsph.compile_stages(dim, self.model, self.pair_form, self.hourglass_form, self.updated,
                                 self.eta > 0)
        self.stage_seconds = collections.defaultdict(float)  # wall time per stage of the step
        body_acc = scene["loads"]["body_acceleration"]
        self.body_acc = None if body_acc is None else np.asarray(body_acc)
        self.damping = scene["time"]["damping"]
        self.t = 0.0
        self.step_count = 0
        self.updates = 0  # reference updates so far
        self.since_update = 0  # steps since the last one
        # running totals of the work done on this rank's particles, exact (exact_sum)
        self.totals = {"hourglass_work": Accumulator(),  # absorbed by the "paper" hourglass forces
                       "hourglass_released": Accumulator(),  # penalty dropped at reference updates
                       "external_work": Accumulator()}
        self.walls = Walls(scene["walls"], scene["tools"], dim)
        self._adopt(local)
        n = self.n_owned
        if restart is None:
            apply_initial_conditions(scene["initial"], self.groups, self.X[:n], self.u[:n], self.v[:n])
            self.bcs.set_displacement(self.u[:n], 0.0)
            self.bcs.set_velocity(self.v[:n], 0.0)
        else:
            clock, totals = restart["clock"], restart["totals"]
            self.t, self.step_count = clock["t"], clock["step"]
            self.updates, self.since_update = clock.get("updates", 0), clock.get("since_update", 0)
            if comm.rank == 0:  # global totals and the last step's obstacle forces, carried by rank 0
                for name, acc in self.totals.items():
                    acc.set([Exact.from_json(totals[name])])
                self.walls.restore(totals["wall_force"])
        self._cfl_at = None  # with a fixed time.dt: (CFL step, step) at set-up, for messages
        self.compute_forces()
        self._external = self.external_force()  # at the current state, for the work integral
        if scene["time"]["dt"] > 0:
            self._cfl_at = (scene["time"]["cfl"] * self._stability()[0], self.step_count)
        self._stable_dt = restart["clock"]["dt"] if restart else self._stable_time_step()[0]

    # ----------------------------------------------------------------- set-up helpers
    def _adopt(self, local: LocalBody) -> None:
        """Take `local` (owned particles with two ghost layers and all their arrays) as this
        rank's particles: mirror images across symmetry planes (parallel.mirrors), halo plan,
        reference data in the reference configuration (X, or X^r when updated), state and
        work arrays for owned particles and layer-1 ghosts."""
        updated = self.updated and "Xr" in local.fields
        ref = ("Xr", "measure_r", "volume_r") if updated else ("X", "measure", "volume")
        with collective(self.comm):
            local, mirrors = add_images(local, ref[0], self.scene["symmetry"], self.comm)
            fl, n, dim = local.fields, local.n_owned, self.dim
            self.decomp = Decomposition(local, self.comm, mirrors)
            self.ref = reference.build(
                fl[ref[0]], fl[ref[1]], fl[ref[2]], fl["support"], local.gid, n, self.decomp.n_rows,
                self.scene["kernel"]["type"], self.hourglass_form, self.alpha, self.eta,
                self.weighted_hessian)
        self.decomp.trim()  # layer-2 ghosts only served to build the ghosts' rows
        keep = self.decomp.n_rows
        self.n_owned = n
        self.gid = local.gid[:keep]
        self.X, self.mass, self.volume = fl["X"][:keep], fl["mass"][:keep], fl["volume"][:keep]
        self.measure, self.support = fl["measure"][:keep], fl["support"][:keep]
        self.groups = {name: fl["groups"][:n, k].astype(bool) for k, name in enumerate(self.group_names)}
        self.u = fl["u"][:keep].copy() if "u" in fl else np.zeros((keep, dim))
        self.v = fl["v"][:keep].copy() if "v" in fl else np.zeros((keep, dim))
        self.F = np.zeros((keep, dim, dim))
        self.d, self.fs = self.u, self.F  # total-Lagrangian: the reference is X, F^r = I
        if self.updated:
            eye = np.broadcast_to(np.eye(dim), (keep, dim, dim))
            self.Xr = fl["Xr"][:keep] if "Xr" in fl else self.X.copy()
            self.Fr = np.ascontiguousarray(fl["Fr"][:keep] if "Fr" in fl else eye)
            self.measure_r = fl["measure_r"][:keep] if "measure_r" in fl else self.measure.copy()
            self.volume_r = fl["volume_r"][:keep] if "volume_r" in fl else self.volume.copy()
            self.shift = self.Xr - self.X
            self.d = np.zeros((keep, dim))
            self.fs = np.zeros((keep, dim, dim))
        self.f = np.zeros((keep, dim, dim) if self.eta > 0 else (0, dim, dim))
        self.B = np.zeros((keep, dim, dim) if self.eta > 0 else (0, dim, dim))
        self.VP = np.zeros((keep, dim, dim))
        self.J = np.ones(keep)
        self.psi = np.zeros(keep)
        self.f_int = np.zeros((n, dim))
        self.f_hg = np.zeros((n, dim) if self.hourglass else (0, dim))
        self.hg_psi = np.zeros(n if self.hourglass_form == tlsph.HOURGLASS_VARIATIONAL else 0)
        self.youngs = np.full(keep, self.constants.youngs)
        self.bcs = BoundaryConditions(self.scene["bc"], self.groups, dim)
        self.walls.select(self.groups)
        self._omega_hg2 = self._hourglass_frequencies()

    def _hourglass_frequencies(self) -> np.ndarray:
        """omega_hg^2 = 2 sum_j c_ij (E_i + E_j) / m_i: a Gershgorin bound on the stiffness of
        each particle's hourglass springs (zero without hourglass control)."""
        n, ref = self.n_owned, self.ref
        if not self.hourglass or not len(ref.idx):
            return np.zeros(n)
        rows = np.repeat(np.arange(n), np.diff(ref.ptr))
        k = ref.hgc * (self.youngs[rows] + self.youngs[ref.idx])
        return 2.0 * np.bincount(rows, weights=k, minlength=n) / self.mass[:n]

    def _stable_time_step(self) -> tuple:
        """(size of the next step, largest incremental log strain): time.dt if fixed, else
        time.cfl times the stable step; the strain for the adaptive reference update (0
        unless it is enabled). Collective."""
        settings = self.scene["time"]
        adaptive = self.updated and self.update_strain > 0
        if settings["dt"] > 0:
            return settings["dt"], self._stability()[1] if adaptive else 0.0
        step, strain = self._stability()
        return settings["cfl"] * step, strain

    def _stability(self) -> tuple:
        """(stable step, largest incremental log strain) over all ranks, from
        formulations.tlsph.stable_time_step (collective). A step of zero raises the error
        naming the particle with the smallest step on any rank."""
        dt, strain, smallest = tlsph.stable_time_step(
            self.n_owned, self.fs, self.F, self.J, self.ref.min_spacing, self.ref.stiffening,
            self._omega_hg2, self.constants.wave_speed, self.model, self.dim)
        reduced = np.array([-dt, strain])
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, reduced, op=MPI.MAX)
        if not -reduced[0] > 0.0:
            mine = [] if smallest < 0 else [(dt, int(self.gid[smallest]),
                                             tuple((self.X[smallest] + self.u[smallest]).tolist()))]
            _, gid, x = min(c for part in self.comm.allgather(mine) for c in part)
            where = ", ".join(f"{c:.6g}" for c in x)
            error = ParsphError(
                f"the stable time step collapsed to zero at step {self.step_count}, t = {self.t:.6g}: "
                f"particle {gid} at ({where}) is flattened (a principal stretch near zero); the run is "
                f"unstable: {self._advice()}")
            error.agreed = True  # every rank found the same particle and raises this
            raise error
        return -reduced[0], reduced[1]

    def _advice(self) -> str:
        """What to change when the run has become unstable."""
        dt = self.scene["time"]["dt"]
        if dt == 0:
            return "reduce time.cfl, raise formulation.hourglass or refine the particles"
        cfl = "" if self._cfl_at is None else \
            " (the CFL step, time.cfl times the stable step, was {:.3g} s at step {})".format(*self._cfl_at)
        return f"reduce time.dt = {dt:.3g} s{cfl}, raise formulation.hourglass or refine the particles"

    # ----------------------------------------------------------------- the step
    def compute_forces(self) -> None:
        """Stages of the force evaluation at the current u; sets self.acc (owned)."""
        n, ref = self.n_owned, self.ref
        lam, mu, bulk = self.constants.lam, self.constants.mu, self.constants.bulk
        clock = time.perf_counter
        stages = self.stage_seconds
        t0 = clock()
        if self.updated:
            np.subtract(self.u[:n], self.shift[:n], out=self.d[:n])
        self.decomp.refresh(self.d)
        t1 = clock()
        stages["halo"] += t1 - t0
        if self.eta > 0:
            self._gradient(n, ref.ptr, ref.idx, ref.g, self.d, self.f)
            t2 = clock()
            stages["kinematics+stress"] += t2 - t1
            self.decomp.refresh(self.f)
            t1 = clock()
            stages["halo"] += t1 - t2
        bad = self._kinematics_stress(
            n, ref.ptr, ref.idx, ref.g, ref.q, ref.gh, ref.dx, ref.hgc, self.d, self.volume, self.youngs,
            lam, mu, bulk, self.f, self.fs, self.F, self.Fr if self.updated else self.F, self.VP, self.J,
            self.psi, self.hg_psi)
        t2 = clock()
        stages["kinematics+stress"] += t2 - t1
        if bad >= 0:
            x = self.X[bad] + self.u[bad]
            where = ", ".join(f"{c:.6g}" for c in x)
            raise ParsphError(
                f"particle {int(self.gid[bad])} at ({where}) is inverted or its stress is not finite "
                f"(J = {self.J[bad]:.4g}) at step {self.step_count + 1}, t = {self.t:.6g}; the run is "
                f"unstable: {self._advice()}")
        self.decomp.refresh(self.VP, *((self.fs,) if self.hourglass else ()))
        if self.eta > 0:
            self._hessian_transpose(n, ref.ptr, ref.idx, ref.gh, ref.gh_rev, self.VP, self.B)
            self.decomp.refresh(self.B)
        t3 = clock()
        stages["halo"] += t3 - t2
        self._forces(n, ref.ptr, ref.idx, ref.g, ref.g_rev, ref.g_sum, ref.q, ref.q_rev, ref.q_sum, ref.dx,
                     ref.hgc, ref.hreg, self.d, self.fs, self.VP, self.B, self.youngs, self.f_int, self.f_hg)
        stages["forces+hourglass" if self.hourglass else "forces"] += clock() - t3
        force = self.f_int + self.f_hg if self.hourglass else self.f_int.copy()
        if self.body_acc is not None:
            force += self.mass[:n, None] * self.body_acc
        self.force = force
        self.acc = force / self.mass[:n, None]

    def external_force(self) -> np.ndarray:
        """Body force plus constraint reactions on the owned particles."""
        n = self.n_owned
        ext = np.zeros((n, self.dim))
        if self.body_acc is not None:
            ext += self.mass[:n, None] * self.body_acc
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

    def step(self, t_end: float = math.inf) -> float:
        """Advance one time step (and update the reference if due); returns the step size.
        A step that would reach or pass `t_end` (to a relative 1e-12) is shortened to end
        exactly at t_end."""
        start = time.perf_counter()
        inside = sum(self.stage_seconds.values())
        n = self.n_owned
        dt = self._stable_dt
        t_new = self.t + dt
        if t_new >= t_end * (1.0 - 1e-12):
            dt, t_new = t_end - self.t, t_end
        u_old = self.u[:n].copy()
        f_hg_old = self.f_hg.copy()
        f_ext_old = self._external
        self._kick(0.5 * dt)
        self.bcs.set_velocity(self.v[:n], self.t + 0.5 * dt)
        self.u[:n] += dt * self.v[:n]
        self.t = t_new
        self.bcs.set_displacement(self.u[:n], self.t)
        self.walls.enforce(self.X, self.u, self.v, self.mass, self.t, dt)
        self.compute_forces()
        self._kick(0.5 * dt)
        self.bcs.set_velocity(self.v[:n], self.t)
        du = self.u[:n] - u_old
        if self.hourglass_form == tlsph.HOURGLASS_PAPER:
            # not a potential force: its energy is the work it has absorbed
            self.totals["hourglass_work"].add(-0.5 * (f_hg_old + self.f_hg) * du)
        self._external = self.external_force()
        self.totals["external_work"].add(0.5 * (f_ext_old + self._external) * du)
        self.step_count += 1
        self.since_update += 1
        self.stage_seconds["integration"] += (time.perf_counter() - start
                                              - (sum(self.stage_seconds.values()) - inside))
        self._stable_dt, strain = self._stable_time_step()
        if self.updated and ((self.update_every and self.since_update >= self.update_every)
                             or (self.update_strain and strain > self.update_strain)):
            self.update_reference()
            self._stable_dt = self._stable_time_step()[0]
        return dt

    def update_reference(self) -> None:
        """Make the current configuration the reference [V §3.1]: X^r = x, F^r = F,
        V^r = J V^0 (Remark 1); re-decide ownership (parallel RCB of X^r) if the work is
        out of balance, migrate the particles with their state, find ghosts and neighbours
        in X^r, rebuild the corrections and evaluate the forces in the new reference."""
        start = time.perf_counter()
        n = self.n_owned
        owned = dict(self._owned_fields(), gid=self.gid[:n], Xr=self.X[:n] + self.u[:n], Fr=self.F[:n].copy(),
                     measure_r=self.J[:n] * self.measure[:n], volume_r=self.J[:n] * self.volume[:n])
        self.totals["hourglass_released"].add(self.hg_psi)  # the penalty restarts at 0
        if self.comm.size > 1:
            work = np.array(self.comm.allgather(len(self.ref.idx) + n), float)
            if work.max() > (1.0 + self.rebalance) * work.mean():
                owned = partition(owned, "Xr", self.comm)
        with collective(self.comm):
            local = add_ghosts(owned, "Xr", self.comm)
        try:
            self._adopt(local)
        except InputError as exc:  # the configuration, not the input, is at fault
            error = ParsphError(
                f"reference update {self.updates + 1} at step {self.step_count}, t = {self.t:.6g} failed: "
                f"{str(exc).rstrip('.')}. The particles are too disordered for a new reference: update "
                "earlier (formulation.update_strain), raise the stabilisation or refine the particles")
            error.agreed = getattr(exc, "agreed", False)
            raise error from None
        self.stage_seconds["reference update"] += time.perf_counter() - start
        self.compute_forces()
        self._external = self.external_force()
        self.updates += 1
        self.since_update = 0

    def _owned_fields(self) -> dict:
        """The owned particles' reference data and state, as migrated and checkpointed."""
        n = self.n_owned
        groups = (np.stack([self.groups[k] for k in self.group_names], axis=1).astype(np.uint8)
                  if self.group_names else np.zeros((n, 0), np.uint8))
        return {"X": self.X[:n], "measure": self.measure[:n], "volume": self.volume[:n],
                "mass": self.mass[:n], "support": self.support[:n], "groups": groups,
                "u": self.u[:n], "v": self.v[:n]}

    @property
    def dt(self) -> float:
        """The step size the next step will use (unless shortened to end at t_end)."""
        return self._stable_dt

    def checkpoint_state(self) -> dict:
        """Everything io.checkpoint stores (collective: totals): per-particle arrays of the
        owned particles (with the updated reference, if any); the accumulated totals over all
        ranks, exact (exact_sum.Exact.to_json), and the last step's obstacle forces."""
        n = self.n_owned
        totals = allsum(self.comm, [acc.sums()[0] for acc in self.totals.values()])
        fields = self._owned_fields()
        if self.updated:
            fields.update({k: getattr(self, k)[:n] for k in REFERENCE_STATE})
        return {
            "fields": fields, "group_names": self.group_names,
            "totals": {**{name: s.to_json() for name, s in zip(self.totals, totals)},
                       "wall_force": self.wall_forces().tolist()},
            "clock": {"t": self.t, "step": self.step_count, "dt": self.dt, "updates": self.updates,
                      "since_update": self.since_update},
        }

    # ----------------------------------------------------------------- read-outs
    def group_index(self, name: str) -> np.ndarray:
        return np.flatnonzero(self.groups[name])

    def quantity(self, name: str, sel: np.ndarray) -> np.ndarray:
        """A particle quantity on the owned particles `sel` (probes and snapshots)."""
        if name == "displacement":
            return self.u[sel]
        if name == "velocity":
            return self.v[sel]
        if name == "position":
            return self.X[sel] + self.u[sel]
        if name == "reaction":
            return self.reaction()[sel]
        if name == "force":
            return self.force[sel]
        if name == "J":
            return self.J[sel]
        if name == "von_mises":
            return self.von_mises(sel)
        if name == "cauchy_stress":
            return self.cauchy_stress(sel)
        if name == "disorder":
            return self.disorder()[sel]
        if name == "spacing_ratio":
            return self.spacing_ratio()[sel]
        raise ValueError(name)

    def disorder(self) -> np.ndarray:
        """Hourglass error eta_i of each owned particle (formulations.tlsph.hourglass_error)."""
        out = np.empty(self.n_owned)
        ref = self.ref
        tlsph.hourglass_error(self.n_owned, ref.ptr, ref.idx, ref.dx, ref.w, self.d, self.fs, out)
        return out

    def spacing_ratio(self) -> np.ndarray:
        """Current-configuration disorder of each owned particle (tlsph.spacing_ratio), with the
        ghosts where the last force evaluation saw them."""
        out = np.empty(self.n_owned)
        ref = self.ref
        x = self.Xr + self.d if self.updated else self.X + self.u
        tlsph.spacing_ratio(self.n_owned, ref.ptr, ref.idx, x, self.measure, self.F, self.dim, out)
        return out

    def cauchy_stress(self, sel: np.ndarray) -> np.ndarray:
        """sigma = J^-1 P(F) F^T (in-plane block in 2D), from the material law alone."""
        F = np.ascontiguousarray(self.F[sel])
        P = np.empty_like(F)
        c = self.constants
        first_piola_stresses(self.model, F, self.dim, c.lam, c.mu, c.bulk, P)
        return np.einsum("nab,ncb->nac", P, F) / self.J[sel, None, None]

    def von_mises(self, sel: np.ndarray) -> np.ndarray:
        s = self.cauchy_stress(sel)
        d = self.dim
        full = np.zeros((len(sel), 3, 3))
        full[:, :d, :d] = s
        dev = full - np.trace(full, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
        return np.sqrt(1.5 * np.einsum("nab,nab->n", dev, dev))

    def energy_sums(self) -> dict:
        """This rank's parts of the energies, exact: strain (sum V^0 psi of the owned
        particles), hourglass (their penalty, or the work absorbed on this rank by the paper
        form, plus the penalty released at reference updates) and external work."""
        n = self.n_owned
        acc = {name: a.sums()[0] for name, a in self.totals.items()}
        return {"strain": total(self.volume[:n] * self.psi[:n]),
                "hourglass": total(self.hg_psi) + acc["hourglass_work"] + acc["hourglass_released"],
                "external": acc["external_work"]}

    @property
    def strain_energy_local(self) -> float:
        """This rank's strain energy (energy_sums)."""
        return float(self.energy_sums()["strain"])

    @property
    def hourglass_energy_local(self) -> float:
        """This rank's hourglass energy (energy_sums)."""
        return float(self.energy_sums()["hourglass"])

    def wall_forces(self) -> np.ndarray:
        """Each wall's and tool's force on the body in the last step, (obstacles, dim), exact
        sums over all ranks (collective)."""
        sums = allsum(self.comm, self.walls.force_sums())
        return np.array([float(s) for s in sums]).reshape(len(self.walls.items), self.dim)

    def diagnostics(self) -> dict:
        """The history row: clock, global_diagnostics, obstacle forces and probes (collective)."""
        out = {"time": self.t, "step": float(self.step_count), "dt": self._stable_dt,
               "reference_updates": float(self.updates)}
        out.update(global_diagnostics(self))
        if len(self.walls.items):
            for label, f in zip(self.walls.names, self.wall_forces()):
                for a, name in enumerate("xyz"[: self.dim]):
                    out[f"{label}_force_{name}"] = f[a]
        out.update(probe_values(self.scene["probes"], self))
        return out
