"""The state of a rank: the scene's bodies (material law, formulation, owned rows) and
their point sets. The bodies share one particle set (global ids numbered body after body,
so each body's owned particles are a contiguous run of rows); the integration points of
the Galerkin methods (stress points, Gauss points: formulations.galerkin) are point sets
of their own. Which arrays a point carries, migrates, checkpoints and mirrors comes from
the field registry (parsph.fields); a material state field NAME has a work array
NAME_trial beside it, committed at the start of each step (points.PointSet.commit).
Local arrays hold the owned points first, then the ghosts.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Callable

import numpy as np

from parsph import fields, materials
from parsph.formulations import FORMULATIONS
from parsph.parallel.decomposition import Decomposition, LocalBody
from parsph.points import PointSet

BASE_FIELDS = tuple(f.name for f in fields.PARTICLE_FIELDS)
UPDATED_STATE = ("Xr", "Fr", "measure_r", "volume_r")  # the updated reference [V §3.1]


class Body:
    """One body of the scene: its particles' global ids first..last-1, its material law and
    constants, its formulation; lo..hi-1 are its owned rows on this rank."""

    def __init__(self, index: int, spec: dict, first: int, last: int, dim: int):
        self.index, self.name = index, spec.name
        self.first, self.last = first, last
        self.law = materials.LAWS[spec.material.model]
        self.constants = materials.constants(spec.material)
        failure = materials.failure_of(spec.material)  # materials.FAILURES: damage, johnson_cook_failure
        self.failure = failure.failure_id if failure else 0  # 0: none
        self.failure_strain = spec.material.failure_strain  # tensile damage's
        self.rigid = spec.rigid  # no stress: moves as one rigid body (parsph.rigid)
        self.breaks_pairs = spec.material.break_pairs  # a failed particle loses its pairs
        self.density = spec.material.density
        self.formulation = FORMULATIONS[spec.formulation.type](spec.formulation, dim, self.law.law_id,
                                                                     failure=self.failure)
        self.moves = self.formulation.updated and not self.rigid  # its reference moves (updated, Eulerian)
        self.lo = self.hi = 0
        self.set_rows = {}  # its owned rows of each other point set (stress points, Gauss points)
        # the factor on its own frequencies in the stable step (stability.StableStep.calibrate)
        self.step_factor = 1.0
        self.relation = None  # its kernel relation (kernel_relation.KernelRelation), set by the topology
        self.stages = []


@dataclass(frozen=True)
class Work:
    """A work array of the rank beside the carried fields: on the `rows` "local" (owned and
    ghosts: neighbours read it) or "owned", of one point's `shape` (scalar (), "vector" (dim,),
    "tensor" (dim, dim), "none" (0,)), allocated where the bodies `need` it (a flag of
    RankState; with none of its rows otherwise), filled with `fill`."""

    name: str
    rows: str
    shape: str = "scalar"
    need: str | None = None
    fill: float = 0.0
    dtype: type = np.float64


WORK = (
    Work("F", "local", "tensor"),  # deformation gradient (from the reference)
    Work("f", "local", "tensor", "hessian"),  # Hessian-stabilised gradient [V eq. 39]
    Work("B", "local", "tensor", "hessian"),  # its correction
    Work("VP", "local", "tensor"),  # volume times first Piola-Kirchhoff stress
    Work("S", "local", "tensor", "corrected_stress"),  # VP L^-1 / V, the force row's (formulations.tlsph)
    Work("J", "local", fill=1.0),  # det F
    Work("psi", "local"),  # strain energy density
    Work("no_state", "local", "none"),  # the state of a law without one
    Work("broken", "owned", dtype=bool),  # failed particles (materials.damage), set at commits
    Work("f_int", "owned", "vector"),  # the bodies' internal forces
    Work("f_hg", "owned", "vector", "hourglass"),  # hourglass control's forces
    Work("omega_hg2", "owned", need="hourglass"),  # its springs' squared frequency (stable step)
    Work("damper_rate2", "owned", need="damped"),  # MACHDYN's hourglass dampers' squared rate (stable step)
    Work("hg_psi", "owned", need="variational"),  # the variational hourglass penalty's energy
    Work("f_visc", "owned", "vector", "viscous"),  # artificial viscosity's forces
    Work("viscous_heating", "owned", need="viscous"),  # the power it turns to heat [W]
    # the step allowed by the particles' motion (closing pairs: viscosity, contact; surfaces)
    Work("step_limit", "owned", need="limited", fill=np.inf),
)


@dataclass(frozen=True)
class Force:
    """A force between particles that the bodies' stages write into the work array `name`
    (owned rows): summed into the internal force in FORCES' order where the bodies need the
    array; a force without a potential has its work (trapezoidal in the step) booked to the
    ledger's running total `work` for the bodies whose formulation `absorbs` it
    (ledger.Ledger.end)."""

    name: str
    work: str | None = None
    absorbs: Callable = lambda formulation: True


FORCES = (
    Force("f_int"),  # the stress's: its work is the strain energy
    Force("f_hg", "hourglass_work", lambda f: f.absorbs_hourglass_work),  # the variational form's is a potential
    Force("f_visc", "viscous_work"),  # artificial viscosity
)


class RankState:
    """The rank's particles of every body (its `bodies`, state.Body): the carried fields
    (parsph.fields) and the declared work arrays (WORK) on owned rows first, then ghosts,
    the other point sets (stress points, Gauss points), the halo plan and the flags the
    bodies settle for the whole particle set: whether a reference moves (`updated`; in every
    step: `eulerian`), Hessian stabilisation (`eta` > 0), hourglass control and artificial
    viscosity (their arrays), and the owners of the registered fields the particles carry.
    Each body's kernel, eta and schedule are its kernel relation's (parsph.kernel_relation)."""

    def __init__(self, bodies: list, offsets: np.ndarray, dim: int, comm, group_names: list, limited: bool,
                 interacting: bool = False):
        self.bodies, self.dim, self.comm, self.group_names = bodies, dim, comm, group_names
        self.offsets = offsets  # the first global id of each body, and the total
        forms = [b.formulation for b in bodies]
        moving = [b.formulation for b in bodies if b.moves]  # their reference moves
        self.updated = bool(moving)
        self.eulerian = any(f.eulerian for f in moving)  # the reference moves at every step, inside it
        self.eta = max(f.eta for f in forms)
        self.hourglass = any(f.hourglass_form for f in forms)
        self.viscous = any(f.viscous for f in forms)
        self.needs = {"hessian": self.eta > 0, "hourglass": self.hourglass, "viscous": self.viscous,
                      "damped": any(f.damped for f in forms),
                      "variational": any(f.hourglass_penalty for f in forms),
                      "corrected_stress": any(f.corrected_stress for f in forms) or self.eta > 0,
                      "limited": self.viscous or limited}
        # the formulations, laws and their states, the updated reference and damage the bodies use
        self.owners = {f.type for f in forms} | {b.law.name for b in bodies} | {b.law.state for b in bodies}
        if self.updated:
            self.owners.add("updated")
        if any(b.failure for b in bodies):
            self.owners.add("damage")
        if self.viscous:
            self.owners.add("viscosity")
        if self.viscous or self.needs["damped"] or interacting:  # forces that read the velocity
            self.owners.add("velocity forces")
        self.carried = fields.carried(self.owners)  # the registered fields the particles carry
        need = {w.name: w.need for w in WORK}
        self.forces = [f for f in FORCES if need[f.name] is None or self.needs[need[f.name]]]  # those the bodies need

    def adopt(self, local: LocalBody, decomp: Decomposition, body: np.ndarray, keep: int) -> None:
        """Take the first `keep` rows of `local` (owned particles, then ghosts; `body`: each
        row's body) with the halo plan `decomp` as this rank's particles: the carried fields
        as `local` has them (or their initial values), the work arrays, the other point sets."""
        fl, n, dim = local.fields, local.n_owned, self.dim
        self.n_owned, self.decomp = n, decomp
        self.gid = local.gid[:keep]
        self.body = body[:keep]
        self.moves = np.array([b.moves for b in self.bodies])[self.body]  # the rows whose reference moves
        for b in self.bodies:
            b.lo, b.hi = (int(k) for k in np.searchsorted(self.gid[:n], [b.first, b.last]))
        self.X, self.mass, self.volume = fl["X"][:keep], fl["mass"][:keep], fl["volume"][:keep]
        self.measure, self.support = fl["measure"][:keep], fl["support"][:keep]
        self.groups = {name: fl["groups"][:n, k].astype(bool) for k, name in enumerate(self.group_names)}
        self.u = fl["u"][:keep].copy() if "u" in fl else np.zeros((keep, dim))
        self.v = fl["v"][:keep].copy() if "v" in fl else np.zeros((keep, dim))
        # fields registered beyond the base and the updated reference: carried as declared
        extra = with_trials({name: initial(name, fl, keep, dim) for name in self.carried
                             if name not in BASE_FIELDS and name not in UPDATED_STATE}, "particles")
        shapes = {"scalar": (), "vector": (dim,), "tensor": (dim, dim), "none": (0,)}
        for w in WORK:
            rows = (keep if w.rows == "local" else n) if w.need is None or self.needs[w.need] else 0
            setattr(self, w.name, np.full((rows,) + shapes[w.shape], w.fill, w.dtype))
        self.d, self.fs = self.u, self.F  # total-Lagrangian: the reference is X, F^r = I
        if self.updated:
            eye = np.broadcast_to(np.eye(dim), (keep, dim, dim))
            self.Xr = fl["Xr"][:keep] if "Xr" in fl else self.X.copy()
            self.Fr = np.ascontiguousarray(fl["Fr"][:keep] if "Fr" in fl else eye)
            self.measure_r = fl["measure_r"][:keep] if "measure_r" in fl else self.measure.copy()
            self.volume_r = fl["volume_r"][:keep] if "volume_r" in fl else self.volume.copy()
            self.shift = self.reference_shift()
            self.d = np.zeros((keep, dim))
            self.fs = np.zeros((keep, dim, dim))
        self.scratch33 = np.empty((3, 3))  # of the kernels of the stable step and the read-outs
        self.youngs = np.array([b.constants.youngs for b in self.bodies])[self.body]
        arrays = dict(X=self.X, measure=self.measure, volume=self.volume, mass=self.mass, support=self.support,
                      groups=fl["groups"][:keep], u=self.u, v=self.v, d=self.d, F=self.F, fs=self.fs, f=self.f,
                      B=self.B, VP=self.VP, S=self.S, J=self.J, psi=self.psi, youngs=self.youngs, **extra)
        if self.updated:
            arrays.update(Xr=self.Xr, Fr=self.Fr, measure_r=self.measure_r, volume_r=self.volume_r)
        self.particles = PointSet("particles", self.gid, n, decomp, self.carried, arrays)
        self.sets = {name: self._adopt_set(name, other) for name, other in (local.sets or {}).items()}

    def _adopt_set(self, name: str, local: LocalBody) -> PointSet:
        """Another point set (stress points, Gauss points: formulations.galerkin): owned
        points, then ghosts (within the kernel support of an owned particle), the fields it
        carries, work arrays and halo plan; each body's rows of it."""
        dim, fl = self.dim, local.fields
        rows = local.n_owned + local.n_ghost
        carried = fields.carried(self.owners, name)
        arrays = with_trials({field: initial(field, fl, rows, dim, name) for field in carried}, name)
        arrays.update(F=np.zeros((rows, dim, dim)), VP=np.zeros((rows, dim, dim)), J=np.ones(rows),
                      psi=np.zeros(rows))
        if self.updated:  # the motion from the updated reference
            arrays["fs"] = np.zeros((rows, dim, dim))
        body = arrays["body"][: local.n_owned]
        for b in self.bodies:
            b.set_rows[name] = tuple(int(k) for k in np.searchsorted(body, [b.index, b.index + 1]))
        return PointSet(name, arrays["gid"], local.n_owned, Decomposition(local, self.comm), carried, arrays)

    @property
    def reference_positions(self) -> np.ndarray:
        """The positions the kernel relations' reference data were built at: X, or X^r when a
        reference moves (the pair loops form X_j - X_i from them)."""
        return self.Xr if self.updated else self.X

    @property
    def reference_measure(self) -> np.ndarray:
        """The measures the kernel relations' reference data were built with: the measure,
        or measure_r when a reference moves."""
        return self.measure_r if self.updated else self.measure

    def reference_shift(self) -> np.ndarray:
        """X^r - X, from which d = u - shift. An Eulerian kernel takes u itself where
        X^r = X + u (as it is after every move of its reference), so that d is exactly zero
        in the new reference, whether the lists were searched or kept: its forces use the
        stress of the last reference (formulations.tlsph.stress_at)."""
        if self.eulerian:
            return np.where((self.X + self.u == self.Xr) & self.moves[:, None], self.u, self.Xr - self.X)
        return self.Xr - self.X

    def point_set(self, name: str) -> PointSet:
        return self.particles if name == "particles" else self.sets[name]

    def point_sets(self) -> list:
        """The rank's point sets: the particles, then the others (stress points, Gauss points)."""
        return [self.particles] + list(self.sets.values())

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

    def refresh(self, names) -> None:
        """Refresh the ghost values of the named arrays: "NAME" of the particles, "SET.NAME"
        of another point set."""
        by_set = collections.defaultdict(list)
        for name in names:
            where, _, field = name.rpartition(".")
            by_set[where or "particles"].append(field)
        for points in self.point_sets():
            if by_set.get(points.name):
                points.refresh(*by_set[points.name])


def with_trials(arrays: dict, points: str) -> dict:
    """`arrays` with a work array NAME_trial beside each material state field NAME: the
    state the last stress evaluation computed (materials.update), committed at the start
    of the next step."""
    states = [name for name in arrays if fields.get(name, points).kind == "state"]
    return dict(arrays, **{name + "_trial": arrays[name].copy() for name in states})


def initial(name: str, fl: dict, keep: int, dim: int, points: str = "particles") -> np.ndarray:
    """A registered field's values on the local rows of a point set: as carried in `fl`
    (migrated, read from a checkpoint), else its declared initial values, else zeros. A
    state carried with fewer columns than declared (a checkpoint from before the state grew
    columns at its end) takes the initial values of the new ones."""
    field = fields.get(name, points)
    out = None
    if name in fl:
        out = fl[name][:keep].copy()
        if field.kind != "state" or out.shape[1] == field.columns:
            return out
    if field.initial is not None:
        values = np.asarray(field.initial(fl["X"][:keep], fl["gid"][:keep]), np.float64).copy()
    else:
        values = np.zeros((keep,) + field.shape(dim))
    if out is not None:
        values[:, :out.shape[1]] = out
    return values
