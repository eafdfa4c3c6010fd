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

import numpy as np

from parsph import config, fields, interactions, materials
from parsph.bc import BoundaryConditions, Tractions
from parsph.collocation import BoundaryCollocation, collocated
from parsph.formulations import FORMULATIONS, tlsph
from parsph.kernel_relation import Configuration
from parsph.parallel.decomposition import Decomposition, LocalBody
from parsph.parallel.mirrors import add_images
from parsph.parallel.runtime import collective
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
        self.relation = None  # its kernel relation (kernel_relation.KernelRelation), set by the topology
        self.stages = []


def settle(sim) -> None:
    """What the bodies settle for the whole particle set: whether a reference moves (in
    every step: Eulerian), whether some body has Hessian stabilisation or hourglass control
    (their arrays), and the owners of the registered fields the particles carry
    (parsph.fields). Each body's kernel, eta and schedule are its kernel relation's
    (parsph.kernel_relation)."""
    forms = [b.formulation for b in sim.bodies]
    moving = [b.formulation for b in sim.bodies if b.moves]  # their reference moves (all ulsph or all Eulerian: config)
    sim.updated = bool(moving)
    sim.eulerian = any(f.eulerian for f in moving)  # the reference moves at every step, inside it
    sim.eta = max(f.eta for f in forms)  # > 0: some body has Hessian stabilisation (its relation's eta)
    sim.hourglass = any(f.hourglass_form for f in forms)
    # the formulations, laws and their states, the updated reference and damage the bodies use
    sim.owners = {f.type for f in forms} | {b.law.name for b in sim.bodies} | {b.law.state for b in sim.bodies}
    if sim.updated:
        sim.owners.add("updated")
    if any(b.failure for b in sim.bodies):
        sim.owners.add("damage")
    if any(any(getattr(f, "viscosity", ())) for f in forms):
        sim.owners.add("viscosity")
    sim.carried = fields.carried(sim.owners)  # the registered fields the particles carry


def adopt(sim, local: LocalBody) -> None:
    """Take `local` (owned particles with two ghost layers and all their arrays) as this
    rank's particles: mirror images across symmetry planes (parallel.mirrors), halo plan,
    the kernel relations' reference data in the reference configuration (X, or X^r when
    updated; parsph.topology), the carried
    fields (parsph.fields) and work arrays for owned particles and layer-1 ghosts."""
    updated = sim.updated and "Xr" in local.fields
    ref = ("Xr", "measure_r", "volume_r") if updated else ("X", "measure", "volume")
    with collective(sim.comm):
        local, mirrors = add_images(local, ref[0], sim.scene.symmetry, sim.comm,
                                    skin=sim.topology.skin if sim.updated else 0.0)
        fl, n, dim = local.fields, local.n_owned, sim.dim
        # layer 2 kept to rebuild the ghosts' rows between searches, or when pairs break
        layer2 = sim.topology.keeps or sim.failure.breaking
        sim.decomp = Decomposition(local, sim.comm, mirrors, layer2=layer2)
        sim.ledger.share = mirrors.share if mirrors else None  # particles on a plane count by their share
        body = np.searchsorted(sim.offsets, local.gid % local.total, side="right") - 1
        sim.failure.detached = sim.failure.failed(fl.get("damage"), body)
        cut = sim.failure.known_cut(fl[ref[0]], fl[ref[1]], fl["support"], local.gid, n, sim.failure.detached,
                                    len(sim.scene.symmetry), local.total)
        sim.topology.build(Configuration(fl[ref[0]], fl[ref[1]], fl[ref[2]], fl["support"], local.gid, body, n,
                                         sim.decomp.n_rows), detached=sim.failure.detached, cut=cut)
    if layer2:
        keep = len(local.gid)
    else:
        sim.decomp.trim()  # layer-2 ghosts only served to build the ghosts' rows
        keep = sim.decomp.n_rows
    sim.n_owned = n
    sim.gid = local.gid[:keep]
    sim.body = body[:keep]
    sim.moves = np.array([b.moves for b in sim.bodies])[sim.body]  # the rows whose reference moves
    sim.all_move = bool(sim.moves.all())
    for b in sim.bodies:
        b.lo, b.hi = (int(k) for k in np.searchsorted(sim.gid[:n], [b.first, b.last]))
    sim.X, sim.mass, sim.volume = fl["X"][:keep], fl["mass"][:keep], fl["volume"][:keep]
    sim.measure, sim.support = fl["measure"][:keep], fl["support"][:keep]
    sim.groups = {name: fl["groups"][:n, k].astype(bool) for k, name in enumerate(sim.group_names)}
    sim.u = fl["u"][:keep].copy() if "u" in fl else np.zeros((keep, dim))
    sim.v = fl["v"][:keep].copy() if "v" in fl else np.zeros((keep, dim))
    # fields registered beyond the base and the updated reference: carried as declared
    extra = with_trials({name: initial(sim, name, fl, keep) for name in sim.carried
                               if name not in BASE_FIELDS and name not in UPDATED_STATE}, "particles")
    sim.F = np.zeros((keep, dim, dim))
    sim.d, sim.fs = sim.u, sim.F  # total-Lagrangian: the reference is X, F^r = I
    if sim.updated:
        eye = np.broadcast_to(np.eye(dim), (keep, dim, dim))
        sim.Xr = fl["Xr"][:keep] if "Xr" in fl else sim.X.copy()
        sim.Fr = np.ascontiguousarray(fl["Fr"][:keep] if "Fr" in fl else eye)
        sim.measure_r = fl["measure_r"][:keep] if "measure_r" in fl else sim.measure.copy()
        sim.volume_r = fl["volume_r"][:keep] if "volume_r" in fl else sim.volume.copy()
        sim.shift = reference_shift(sim)
        sim.d = np.zeros((keep, dim))
        sim.fs = np.zeros((keep, dim, dim))
    sim.f = np.zeros((keep, dim, dim) if sim.eta > 0 else (0, dim, dim))
    sim.B = np.zeros((keep, dim, dim) if sim.eta > 0 else (0, dim, dim))
    sim.VP = np.zeros((keep, dim, dim))
    sim.J = np.ones(keep)
    sim.psi = np.zeros(keep)
    sim.no_state = np.zeros((keep, 0))  # the hyperelastic laws carry no per-point state
    sim.broken = np.zeros(n, bool)  # failed particles (materials.damage), set at commits
    sim.f_int = np.zeros((n, dim))
    sim.f_hg = np.zeros((n, dim) if sim.hourglass else (0, dim))
    sim.omega_hg2 = np.zeros(n if sim.hourglass else 0)  # written by the forces stage
    sim.scratch33 = np.empty((3, 3))  # of the kernels of the stable step and the read-outs
    variational = any(b.formulation.hourglass_form == tlsph.HOURGLASS_VARIATIONAL for b in sim.bodies)
    sim.hg_psi = np.zeros(n if variational else 0)
    sim.viscous = any(any(getattr(b.formulation, "viscosity", ())) for b in sim.bodies)
    sim.f_visc = np.zeros((n if sim.viscous else 0, dim))
    sim.viscous_heating = np.zeros(n if sim.viscous else 0)  # the power the viscosity turns to heat [W]
    # the step allowed by the particles' motion (closing pairs: viscosity, contact; surfaces), set at each evaluation
    limited = sim.viscous or sim.scene.contact or sim.scene.surfaces
    sim.step_limit = np.full(n if limited else 0, np.inf)
    sim.youngs = np.array([b.constants.youngs for b in sim.bodies])[sim.body]
    arrays = dict(X=sim.X, measure=sim.measure, volume=sim.volume, mass=sim.mass, support=sim.support,
                  groups=fl["groups"][:keep], u=sim.u, v=sim.v, d=sim.d, F=sim.F, fs=sim.fs, f=sim.f,
                  B=sim.B, VP=sim.VP, J=sim.J, psi=sim.psi, youngs=sim.youngs, **extra)
    if sim.updated:
        arrays.update(Xr=sim.Xr, Fr=sim.Fr, measure_r=sim.measure_r, volume_r=sim.volume_r)
    sim.particles = PointSet("particles", sim.gid, n, sim.decomp, sim.carried, arrays)
    sim.failure.find_broken(sim)
    sim.sets = {name: adopt_set(sim, name, other) for name, other in (local.sets or {}).items()}
    with collective(sim.comm):  # the formulations' own relations
        for b in sim.bodies:
            b.formulation.build(sim, b, b.relation.kernel)
    with collective(sim.comm):
        parameters = sim.scene.parameters
        sim.bcs = BoundaryConditions(sim.scene.bc, sim.groups, sim.X[:n], sim.gid[:n], parameters,
                                      sim.t)
        sim.tractions = Tractions(sim.scene.tractions, sim.groups, sim.X[:n], sim.gid[:n],
                                   sim.measure[:n], config.thickness(sim.scene), parameters)
    efg = any(collocated(b.formulation) for b in sim.bodies)
    sim.collocation = BoundaryCollocation(sim) if efg and sim.scene.bc else None
    sim.walls.select(sim.groups)
    sim.interaction = interactions.build(sim)  # by kind: parsph.interactions
    sim.interactions = [i for i in sim.interaction.values() if i is not None]  # summed in this order
    sim.contact, sim.ties = sim.interaction["contact"], sim.interaction["ties"]
    sim.omega_c2 = interactions.frequency_bound(sim.interactions, n)
    sim.exclude_kernel_pairs()
    for b in sim.bodies:
        b.stages = [] if b.rigid else b.formulation.stages(sim, b)
        if b.rigid:
            sim.F[b.lo:b.hi] = np.eye(dim)


def adopt_set(sim, name: str, local: LocalBody) -> PointSet:
    """Another point set (stress points, Gauss points: formulations.galerkin): owned
    points, then ghosts (within the kernel support of an owned particle), the fields it
    carries, work arrays and halo plan; each body's rows of it."""
    dim, fl = sim.dim, local.fields
    rows = local.n_owned + local.n_ghost
    carried = fields.carried(sim.owners, name)
    arrays = with_trials({field: initial(sim, field, fl, rows, name) for field in carried}, name)
    arrays.update(F=np.zeros((rows, dim, dim)), VP=np.zeros((rows, dim, dim)), J=np.ones(rows),
                  psi=np.zeros(rows))
    if sim.updated:  # the motion from the updated reference
        arrays["fs"] = np.zeros((rows, dim, dim))
    body = arrays["body"][: local.n_owned]
    for b in sim.bodies:
        b.set_rows[name] = tuple(int(k) for k in np.searchsorted(body, [b.index, b.index + 1]))
    return PointSet(name, arrays["gid"], local.n_owned, Decomposition(local, sim.comm), carried, arrays)


def with_trials(arrays: dict, points: str) -> dict:
    """`arrays` with a work array NAME_trial beside each material state field NAME: the
    state the last stress evaluation computed (materials.update), committed at the start
    of the next step."""
    states = [name for name in arrays if fields.get(name, points).kind == "state"]
    return dict(arrays, **{name + "_trial": arrays[name].copy() for name in states})


def initial(sim, name: str, fl: dict, keep: int, points: str = "particles") -> np.ndarray:
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
        values = np.zeros((keep,) + field.shape(sim.dim))
    if out is not None:
        values[:, :out.shape[1]] = out
    return values


def reference_shift(sim) -> np.ndarray:
    """X^r - X, from which d = u - shift. An Eulerian kernel takes u itself where
    X^r = X + u (as it is after every move of its reference), so that d is exactly zero
    in the new reference, whether the lists were searched or kept: its forces use the
    stress of the last reference (formulations.tlsph.stress_at)."""
    if sim.eulerian:
        return np.where((sim.X + sim.u == sim.Xr) & sim.moves[:, None], sim.u, sim.Xr - sim.X)
    return sim.Xr - sim.X


def refresh(sim, names) -> None:
    """Refresh the ghost values of the named arrays: "NAME" of the particles, "SET.NAME"
    of another point set."""
    by_set = collections.defaultdict(list)
    for name in names:
        where, _, field = name.rpartition(".")
        by_set[where or "particles"].append(field)
    for points in sim.point_sets():
        if by_set.get(points.name):
            points.refresh(*by_set[points.name])
