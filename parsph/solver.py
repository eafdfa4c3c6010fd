"""`Simulation`: the particle state of one rank and the explicit time step.

A step is velocity-Verlet (kick-drift-kick leap-frog):
    v += dt/2 a;  constrained v;  u += dt v;  constrained u;  t += dt
    halo(u) -> kinematics + stress -> halo(V P, F) -> forces -> a = f/m + b
    v += dt/2 a;  constrained v
Local arrays hold the rank's owned particles first, then its ghosts. Only the stages a
scene uses are compiled and run (formulations.tlsph).
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
from parsph.errors import ParsphError
from parsph.formulations import tlsph
from parsph.kernels.correction import reference_pairs
from parsph.materials.elastic import MODEL_IDS
from parsph.neighbors import find_pairs
from parsph.parallel.decomposition import Decomposition, LocalBody
from parsph.parallel.runtime import collective


class Simulation:
    """Total-Lagrangian SPH state and stepping for the particles this rank owns."""

    def __init__(self, scene: dict, body: LocalBody, comm, restart: dict | None = None):
        """Set up this rank's particles (parallel.decomposition.distribute); `restart`
        (io.checkpoint.load, its particle state in body.extra) continues a run."""
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
        self._kinematics_stress, self._forces = tlsph.compile_stages(
            dim, self.model, self.pair_form, self.hourglass_form)
        self.stage_seconds = collections.defaultdict(float)  # wall time per stage of the step

        with collective(comm):
            self.decomp = Decomposition(body, comm)
            local = self.gid = body.gid
            self.n_owned = body.n_owned
            self.X, self.mass, self.volume = body.X, body.mass, body.volume
            self.measure, self.support = body.measure, body.support
            # rows for owned particles and for ghosts whose neighbourhood is complete
            rows = self.decomp.n_rows
            self.pairs = find_pairs(self.X, self.support, local, rows)
            self.ref = reference_pairs(self.X, self.measure, self.support, local, self.pairs,
                                       scene["kernel"]["type"])
        self._trim_to_owned()
        self.groups = {name: mask[: self.n_owned] for name, mask in body.groups.items()}  # owned only
        n_local = len(self.gid)
        self.u = np.zeros((n_local, dim))
        self.v = np.zeros((n_local, dim))
        self.F = np.zeros((n_local, dim, dim))
        self.VP = np.zeros((n_local, dim, dim))
        self.J = np.ones(n_local)
        self.psi = np.zeros(n_local)
        self.f_int = np.zeros((self.n_owned, dim))
        self.f_hg = np.zeros((self.n_owned, dim) if self.hourglass else (0, dim))
        self.youngs = np.full(n_local, self.constants.youngs)
        body_acc = scene["loads"]["body_acceleration"]
        self.body_acc = None if body_acc is None else np.asarray(body_acc)
        self.damping = scene["time"]["damping"]

        self.bcs = BoundaryConditions(scene["bc"], self.groups, dim)
        self.t = 0.0
        self.step_count = 0
        self.strain_energy_local = 0.0
        self.hourglass_energy_local = 0.0
        self.external_work_local = 0.0
        self._omega_hg2 = self._hourglass_frequencies()
        if restart is None:
            apply_initial_conditions(scene["initial"], self.groups, self.X[: self.n_owned],
                                     self.u[: self.n_owned], self.v[: self.n_owned])
            self.bcs.set_displacement(self.u[: self.n_owned], 0.0)
            self.bcs.set_velocity(self.v[: self.n_owned], 0.0)
        else:
            self.u[: self.n_owned] = body.extra["u"][: self.n_owned]
            self.v[: self.n_owned] = body.extra["v"][: self.n_owned]
            self.t, self.step_count = restart["clock"]["t"], restart["clock"]["step"]
            if comm.rank == 0:  # global totals, carried by rank 0
                self.hourglass_energy_local = restart["totals"]["hourglass_work"]
                self.external_work_local = restart["totals"]["external_work"]
        self.compute_forces()
        self._external = self.external_force()  # at the current state, for the work integral
        self._stable_dt = restart["clock"]["dt"] if restart else self._stable_time_step()

    # ----------------------------------------------------------------- set-up helpers
    def _trim_to_owned(self) -> None:
        """Keep per-pair data for owned rows only (ghost rows served to build g_ji) and
        drop the layer-2 ghosts, which only served to build the ghosts' rows."""
        self.decomp.trim()
        keep = len(self.decomp.local_gid)
        self.gid, self.X = self.gid[:keep], self.X[:keep]
        self.mass, self.volume = self.mass[:keep], self.volume[:keep]
        self.measure, self.support = self.measure[:keep], self.support[:keep]
        n = self.n_owned
        ptr = self.pairs.ptr[: n + 1]
        end = ptr[-1]
        ref = self.ref
        self.ptr = ptr
        self.idx = self.pairs.idx[:end].astype(np.int64)
        self.g = np.ascontiguousarray(ref.g[:end])
        self.g_rev = np.ascontiguousarray(ref.g_rev[:end])
        if np.isnan(self.g_rev).any():
            raise ParsphError("internal: a neighbour of an owned particle has no reference row")
        self.g_sum = np.ascontiguousarray(ref.g_sum[:n])
        self.dx = np.ascontiguousarray(ref.dx[:end])
        self.w = np.ascontiguousarray(ref.w[:end])
        self.hgc, self.hreg = np.zeros(0), np.zeros(0)
        if self.hourglass:
            self.hgc, self.hreg = tlsph.hourglass_coefficients(
                self.hourglass_form, self.pairs.row_of_pair()[:end], self.idx, self.dx, self.w,
                ref.h[:end], self.volume, self.measure, self.alpha)
        self.min_spacing = np.sqrt(np.minimum.reduceat(
            np.einsum("pa,pa->p", self.dx, self.dx), ptr[:-1])) if end else np.full(n, np.inf)
        del self.ref, self.pairs

    def _hourglass_frequencies(self) -> np.ndarray:
        """omega_hg^2 = 2 sum_j c_ij (E_i + E_j) / m_i: a Gershgorin bound on the stiffness of
        each particle's hourglass springs (zero without hourglass control)."""
        n = self.n_owned
        if not self.hourglass or not len(self.idx):
            return np.zeros(n)
        rows = np.repeat(np.arange(n), np.diff(self.ptr))
        k = self.hgc * (self.youngs[rows] + self.youngs[self.idx])
        return 2.0 * np.bincount(rows, weights=k, minlength=n) / self.mass[:n]

    def _stable_time_step(self) -> float:
        """CFL step (formulations.tlsph.stable_time_step) reduced over ranks, or the fixed dt."""
        settings = self.scene["time"]
        if settings["dt"] > 0:
            return settings["dt"]
        local = tlsph.stable_time_step(self.n_owned, self.F, self.J, self.min_spacing, self._omega_hg2,
                                       self.constants.wave_speed, self.model, self.dim)
        dt = settings["cfl"] * self.comm.allreduce(local, op=MPI.MIN)
        if not dt > 0.0:
            error = ParsphError(
                f"the stable time step collapsed to zero at step {self.step_count}, t = {self.t:.6g}: "
                "a particle is flattened (a principal stretch near zero); the run is unstable: raise "
                "formulation.hourglass or refine the particles")
            error.agreed = True  # every rank has the same reduced dt and raises this
            raise error
        return dt

    # ----------------------------------------------------------------- the step
    def compute_forces(self) -> None:
        """Stages of the force evaluation at the current u; sets self.acc (owned)."""
        n = self.n_owned
        lam, mu, bulk = self.constants.lam, self.constants.mu, self.constants.bulk
        clock = time.perf_counter
        t0 = clock()
        self.decomp.refresh(self.u)
        t1 = clock()
        energy, hg_energy, bad = self._kinematics_stress(
            n, self.ptr, self.idx, self.g, self.dx, self.hgc, self.u, self.volume, self.youngs,
            lam, mu, bulk, self.F, self.VP, self.J, self.psi)
        t2 = clock()
        if bad >= 0:
            x = self.X[bad] + self.u[bad]
            where = ", ".join(f"{c:.6g}" for c in x)
            raise ParsphError(
                f"particle {int(self.gid[bad])} at ({where}) is inverted or its stress is not finite "
                f"(J = {self.J[bad]:.4g}) at step {self.step_count + 1}, t = {self.t:.6g}; the run is "
                "unstable: reduce time.cfl, raise formulation.hourglass or refine the particles")
        self.strain_energy_local = energy
        if self.hourglass_form == tlsph.HOURGLASS_VARIATIONAL:
            self.hourglass_energy_local = hg_energy
        self.decomp.refresh(self.VP, *((self.F,) if self.hourglass else ()))
        t3 = clock()
        self._forces(n, self.ptr, self.idx, self.g, self.g_rev, self.g_sum, self.dx, self.hgc,
                     self.hreg, self.u, self.F, self.VP, self.youngs, self.f_int, self.f_hg)
        t4 = clock()
        stages = self.stage_seconds
        stages["halo"] += (t1 - t0) + (t3 - t2)
        stages["kinematics+stress"] += t2 - t1
        stages["forces+hourglass" if self.hourglass else "forces"] += t4 - t3
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

    def step(self) -> float:
        """Advance one time step; returns the step size used."""
        start = time.perf_counter()
        inside = sum(self.stage_seconds.values())
        n = self.n_owned
        dt = self._stable_dt
        u_old = self.u[:n].copy()
        f_hg_old = self.f_hg.copy()
        f_ext_old = self._external
        self._kick(0.5 * dt)
        self.bcs.set_velocity(self.v[:n], self.t + 0.5 * dt)
        self.u[:n] += dt * self.v[:n]
        self.t += dt
        self.bcs.set_displacement(self.u[:n], self.t)
        self.compute_forces()
        self._kick(0.5 * dt)
        self.bcs.set_velocity(self.v[:n], self.t)
        du = self.u[:n] - u_old
        if self.hourglass_form == tlsph.HOURGLASS_PAPER:
            # not a potential force: its energy is the work it has absorbed
            self.hourglass_energy_local -= 0.5 * np.sum((f_hg_old + self.f_hg) * du)
        self._external = self.external_force()
        self.external_work_local += 0.5 * np.sum((f_ext_old + self._external) * du)
        self.step_count += 1
        if self.scene["time"]["dt"] == 0:
            self._stable_dt = self._stable_time_step()
        self.stage_seconds["integration"] += (time.perf_counter() - start
                                              - (sum(self.stage_seconds.values()) - inside))
        return dt

    @property
    def dt(self) -> float:
        """The step size the next step will use."""
        return self._stable_dt

    def checkpoint_state(self) -> dict:
        """Everything io.checkpoint stores, for the owned particles (collective: totals)."""
        n = self.n_owned
        names = sorted(self.groups)
        totals = self.comm.allgather((self.hourglass_energy_local
                                      if self.hourglass_form == tlsph.HOURGLASS_PAPER else 0.0,
                                      self.external_work_local))
        return {
            "X": self.X[:n], "measure": self.measure[:n], "volume": self.volume[:n],
            "mass": self.mass[:n], "support": self.support[:n], "u": self.u[:n], "v": self.v[:n],
            "groups": np.stack([self.groups[k] for k in names], axis=1).astype(np.uint8),
            "group_names": names,
            "totals": {"hourglass_work": sum(h for h, _ in totals), "external_work": sum(e for _, e in totals)},
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
        raise ValueError(name)

    def disorder(self) -> np.ndarray:
        """Hourglass error eta_i of each owned particle (formulations.tlsph.hourglass_error)."""
        out = np.empty(self.n_owned)
        tlsph.hourglass_error(self.n_owned, self.ptr, self.idx, self.dx, self.w, self.u, self.F, out)
        return out

    def cauchy_stress(self, sel: np.ndarray) -> np.ndarray:
        """sigma = J^-1 P F^T (in-plane block in 2D)."""
        P = self.VP[sel] / self.volume[sel, None, None]
        return np.einsum("nab,ncb->nac", P, self.F[sel]) / self.J[sel, None, None]

    def von_mises(self, sel: np.ndarray) -> np.ndarray:
        s = self.cauchy_stress(sel)
        d = self.dim
        full = np.zeros((len(sel), 3, 3))
        full[:, :d, :d] = s
        dev = full - np.trace(full, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
        return np.sqrt(1.5 * np.einsum("nab,nab->n", dev, dev))

    def diagnostics(self) -> dict:
        out = {"time": self.t, "step": float(self.step_count), "dt": self._stable_dt}
        out.update(global_diagnostics(self))
        out.update(probe_values(self.scene["probes"], self))
        return out
