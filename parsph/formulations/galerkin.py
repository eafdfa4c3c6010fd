"""Meshfree Galerkin methods: F and the stress at integration points, forces from
test-function gradients [R §4.3-5.3; eq. 26-32, 37-43, 60, 63-69; in the forms below,
where [R] leaves them open]; a Lagrangian kernel, or for kbm and nodal efg an Eulerian one [R Table 2]
(the same sums in the updated reference, rebuilt at every step; the stress points move with
the body, `moved`).

  kbm          Krongauz-Belytschko: trial gradients G_J = A^-T grad W^S_J corrected from
               the Shepard functions W^S_J = W_J / S, S = sum_K W_K [R eq. 28-32]; Shepard
               test functions (Petrov-Galerkin [R eq. 64]); integration points: particles
               and stress points, weights the Voronoi volumes of both together [R eq. 65]
  efg nodal    element-free Galerkin: MLS shape functions with a linear basis [R eq. 37-42]
               as trial and test functions (Bubnov-Galerkin), the particles as integration
               points with their volumes [R eq. 60]
  efg cells    the same at the Gauss points of background cells [R eq. 66-69]

At each integration point q, from the particles J whose kernel covers it (|X_q - X_J| < h_J,
the particle itself included):

    F_q = I + sum_J (u_J - u_b) (x) G_J(X_q),    f_I = - sum_q w_q P(X_q) grad N_I(X_q)

with G the trial and N the test functions, u_b the displacement of the point itself (a
particle) or of its first particle (sum_J G_J = 0 to round-off: a rigid translation gives
F = I exactly). F and the stress are evaluated at the particles in every method (the time
step and the read-outs use them). The test gradient of particle I at a point q needs sums
over q's whole neighbourhood (S, grad S; or the MLS moment matrix and its gradient): the
owner of q computes them and they are copied to q's ghosts at each build. sum_I grad N_I = 0
at every q, so linear momentum is conserved; the sums run over particles, then the other
set, each in global-id order.

MLS gradient (the derivative of [R eq. 40]), with the basis centred at X_q and scaled by a length l of q,
p_J = (1, (X_J - X_q) / l), M = sum_J W_J p_J p_J^T, gamma = M^-1 e_0:
    d_a Phi_J = (M^-1 p_J)_(1+a) W_J / l - gamma . (d_a M) M^-1 p_J W_J + (gamma . p_J) d_a W_J.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from parsph import COMPILED_SOURCE, stability
from parsph.errors import InputError
from parsph.fields import Field, register
from parsph.formulations.base import CompiledOnce, Formulation, Running, Stage, check_shared_keys
from parsph.formulations.nodal import EULERIAN
from parsph.formulations.reference import PairOptions
from parsph.formulations import tlsph
from parsph.formulations.tlsph import gradient_row, stress_at
from parsph.kernels import shape as kernel_shape
from parsph.kernels.functions import KERNEL_NAMES
from parsph.keys import Key, one_of
from parsph.materials import update
from parsph.relations import KeptRelation, Relation, find_relation
from parsph.small_vectors import added, component

STRESS_POINTS, GAUSS_POINTS = "stress_points", "gauss_points"

register(Field("weight", "scalar", owner="kbm", doc="quadrature weight among particles and stress points [m^3]"))
for _set in (STRESS_POINTS, GAUSS_POINTS):
    register(
        Field("gid", "id", points=_set, doc="global id"),
        Field("X", "point", points=_set, doc="reference position [m]"),
        Field("volume", "scalar", points=_set, doc="quadrature weight [m^3]"),
        Field("body", "id", points=_set, doc="index of the body"),
    )
# the stress points of an Eulerian kernel move with the body: their updated reference
register(
    Field("Xr", "point", points=STRESS_POINTS, owner="updated", initial=lambda X, gid: X,
          doc="position in the updated reference [m]"),
    Field("Fr", "tensor", points=STRESS_POINTS, owner="updated",
          initial=lambda X, gid: np.broadcast_to(np.eye(X.shape[1]), (len(X), X.shape[1], X.shape[1])),
          doc="deformation gradient of the updated reference"),
)


def integration_set(formulation: dict) -> str | None:
    """The point set of integration points a formulation table needs besides the particles."""
    if formulation["type"] == "kbm":
        return STRESS_POINTS
    if formulation["type"] == "efg" and formulation.get("integration") == "cells":
        return GAUSS_POINTS
    return None


# ------------------------------------------------------------------ shape functions
def _what(points: str) -> str:
    return "particle" if points == "particles" else points[:-1].replace("_", " ")


def trial_gradients(shape: str, relation: Relation, x_rows, x_cols, support, kernel: str, gid_rows, active):
    """(G per pair of `relation` from integration points to particles, per-row data the
    test gradients need, the shape function values Phi_J(X_q) per pair), kernels.shape:
    "kbm" (Shepard) or "mls". Rows not `active` get neutral data; an active row with no
    particle or a singular matrix raises InputError naming it."""
    dim = x_rows.shape[1]
    m = dim + 1
    n, pairs = len(relation.ptr) - 1, len(relation.idx)
    G, phi = np.empty((pairs, dim)), np.empty(pairs)
    data = np.empty((n, kernel_shape.row_data_width(shape, dim)))
    kind, report = KERNEL_NAMES.index(kernel), np.zeros(2)
    size = dim if shape == "kbm" else m
    scratch = (np.empty((size, size)), np.empty((size, size)), np.empty((size, 2 * size)), np.empty(dim))
    kbm_trial, mls_trial, _ = kernel_shape.compile_shape(dim)
    if shape == "kbm":
        code = kbm_trial(relation.ptr, relation.idx, x_rows, x_cols, support, kind, active, G, data,
                                      phi, *scratch, report)
    else:
        code = mls_trial(relation.ptr, relation.idx, x_rows, x_cols, support, kind, active, G, data,
                                      phi, *scratch, np.empty(m), np.empty((dim, m, m)), np.empty(m), report)
    if code != kernel_shape.FINE:
        q = int(report[0])
        what = f"{_what(relation.rows)} {int(gid_rows[q])} at ({', '.join(f'{c:.6g}' for c in x_rows[q])})"
        if code == kernel_shape.EMPTY:
            raise InputError(f"{what} lies in no particle's kernel support; increase kernel.support")
        matrix = "correction matrix A" if shape == "kbm" else "moment matrix M"
        raise InputError(f"the {matrix} of {what} is singular or ill-conditioned (condition number {report[1]:.3g}, "
                         f"{int(relation.ptr[q + 1] - relation.ptr[q])} particles in reach). Increase kernel.support")
    return G, data, phi


def test_function_gradients(shape: str, relation: Relation, x_rows, x_cols, data, support, kernel: str):
    """grad N_I(X_q) per pair of `relation` from particles I to integration points q, from
    the row data of q (trial_gradients)."""
    dim = x_rows.shape[1]
    out = np.empty((len(relation.idx), dim))
    kernel_shape.compile_shape(dim)[2](shape == "mls", relation.ptr, relation.idx, x_rows, x_cols, support,
                                KERNEL_NAMES.index(kernel), data, out, np.empty(dim), np.empty(dim + 1),
                                np.empty(dim + 1))
    return out


# ------------------------------------------------------------------ the formulation
@dataclass
class Coupling:
    """The relations of one set of integration points with the particles of one body, in
    local rows, and their per-pair coefficients."""

    points: str  # "particles" or the set's name
    ptr: np.ndarray  # owned integration points -> particles: trial gradients
    idx: np.ndarray
    G: np.ndarray
    phi: np.ndarray  # trial shape function values Phi_J(X_q) per pair (boundary collocation)
    base: np.ndarray  # the particle whose displacement is subtracted
    test_ptr: np.ndarray  # owned particles -> integration points (owned and ghosts): test gradients
    test_idx: np.ndarray
    test_g: np.ndarray
    integrates: bool  # False: the particles of efg cells carry F and stress as read-outs only


class GalerkinFormulation(Formulation):
    """One body's Galerkin formulation: shape functions, integration points, compiled
    stages, strain energy (the members: base.Formulation; no hourglass control, Hessian
    stabilisation, artificial viscosity or strain trigger of reference updates)."""

    TYPES = {  # formulation.type names it serves
        "kbm": "Krongauz-Belytschko corrected gradients with stress points [R §5.2] (a box)",
        "efg": "element-free Galerkin, MLS with a linear basis [R §4.4]",
    }
    KEYS = {  # its formulation keys
        "integration": Key("str", None, one_of("nodal", "cells"),
                           "efg: at the particles (nodal) or at the Gauss points of background cells "
                           "[R §5.3] (cells: a box)"),
    }
    damage = False  # tensile damage is computed at the particles of the particle formulations

    @staticmethod
    def resolve(path: str, form: dict) -> None:
        """Its defaults and rules on a formulation table `form` checked against the schema
        (InputError naming the key at `path`)."""
        kind = form["type"]
        if form["hourglass"] is None:
            form["hourglass"] = 0.0
        if form["viscosity"] > 0 or form["viscosity_beta"] > 0:
            raise InputError(f"{path}.viscosity applies to tlsph, ulsph, sph and rlm, not to {kind}")
        if form["hourglass"] > 0:
            raise InputError(f"{path}.hourglass applies to tlsph, ulsph, sph and rlm, not to {kind} "
                             "(give 0 or leave it out)")
        if form["kernel"] == "eulerian" and form["integration"] == "cells":
            raise InputError(EULERIAN.format(path=path))
        if kind != "efg" and form["integration"] is not None:
            raise InputError(f"{path}.integration applies to type = 'efg'")
        if kind == "efg":
            form["integration"] = form["integration"] or "nodal"
        else:  # absent, as in scenes written before the key existed (checkpoints compare scenes)
            del form["integration"]
        check_shared_keys(path, form, kind, GalerkinFormulation.moves_reference(form))

    @staticmethod
    def moves_reference(form: dict) -> bool:
        """Whether a formulation table moves its reference (the Eulerian kernel)."""
        return form.get("kernel") == "eulerian"

    @staticmethod
    def check_body(body: dict, where: str, scene: dict) -> None:
        """kbm places its stress points in the cells of a box lattice or of a polar ring
        (geometry.stress_points), efg with cell integration its Gauss points in cells over a
        box lattice (geometry.gauss_points); neither set has mirror images, so symmetry planes
        are for nodal efg only."""
        form = body["formulation"]
        parts = body["parts"]
        what = {"kbm": "stress points in the cells of", "efg": "Gauss points in background cells over"}[form["type"]]
        box = len(parts) == 1 and parts[0]["shape"] == "box" and parts[0]["placement"] == "cell"
        polar = len(parts) == 1 and parts[0]["shape"] == "polar_ring"
        if form["type"] == "kbm" and not (box or polar):
            raise InputError(f"formulation.type = 'kbm' places {what} one lattice: {where}.parts must be a single "
                             "box with placement = 'cell' or a single polar_ring")
        if form["type"] == "efg" and form["integration"] == "cells" and not box:
            raise InputError(f"formulation.type = 'efg' places {what} one box lattice: "
                             f"{where}.parts must be a single box with placement = 'cell'")
        if scene["symmetry"] and integration_set(form):
            raise InputError(f"[[symmetry]] planes cannot be used with formulation.type = '{form['type']}' with "
                             f"{what.split(' in ')[0]} (they have no mirror images: only the particles have); use "
                             "efg with nodal integration, or model the whole body")

    def __init__(self, options: dict, dim: int, law: int, failure: int = 0):  # failure: particle methods only
        super().__init__(options, dim, law, failure)
        self.shape = "kbm" if self.type == "kbm" else "mls"
        self.points = integration_set(options)  # the other set, if any
        # the Eulerian kernel: the updated reference rebuilt at every step (as for sph, rlm)
        self.updated = self.eulerian = options.get("kernel") == "eulerian"
        self.conserves_momentum = True  # the shape functions' gradients sum to zero
        self.conserves_energy = self.type != "kbm"  # KBM's Petrov-Galerkin force is not its energy's gradient
        self.update_every = 1 if self.updated else 0
        # EFG's MLS functions reproduce linear fields: its constraints are collocated (parsph.collocation)
        self.collocates = self.shape == "mls"
        self.kinematics_stress, self.forces = compile_stages(dim, law, self.eulerian)
        self.couplings = []
        self.kept = {}  # the Eulerian kernel's relations kept between searches, by (set, trial or test)

    @property
    def pair_options(self) -> PairOptions:
        """The nodal pair data every particle has (nearest spacing for the time step, disorder)."""
        return PairOptions(corrected=True, hourglass_form=0, alpha=0.0)

    def build(self, state, body, kernel: str, skin: float = 0.0, search: bool = True) -> None:
        """The relations and coefficients of `body` in the reference configuration: X (once,
        Lagrangian kernel) or the updated reference X^r (Eulerian kernel, at every step:
        relations searched with the skin skin and kept, or with `search` False picked
        from the kept ones); the row data of the ghost integration points is copied from
        their owners."""
        P = state.particles.arrays
        n = state.n_owned
        X, support, gid = P["Xr" if self.updated else "X"], P["support"], P["gid"]
        mine = state.body == body.index
        group_rows = np.where(mine, 0, -1)
        group_cols = np.where(mine, 0, -2)
        sets = [("particles", state.particles)] + ([(self.points, state.sets[self.points])] if self.points else [])
        self.couplings = []
        for name, points in sets:
            A = points.arrays
            Y = X if name == "particles" else A["Xr" if self.updated else "X"]  # positions in the reference
            rows = len(A["gid"])
            active = (A["body"] == body.index) if name != "particles" else mine
            key = f"{self.shape}_data"

            def related(label, *args):
                if not self.updated:
                    return find_relation(*args)
                if search:
                    self.kept[name, label] = KeptRelation(find_relation(*args, skin=skin), args[6])
                return self.kept[name, label].current(args[2], args[3], args[5])
            trial = related("trial", name, "particles", Y[: points.n_owned], X, gid, support, "cols",
                            np.where(active, 0, -1)[: points.n_owned], group_cols)
            G, data, phi = trial_gradients(self.shape, trial, Y[: points.n_owned], X, support, kernel, A["gid"],
                                           active[: points.n_owned])
            if key not in A:
                A[key] = np.zeros((rows,) + data.shape[1:])
            rows_of_body = np.flatnonzero(active[: points.n_owned])
            A[key][rows_of_body] = data[rows_of_body]
            points.decomp.refresh(A[key], copied=[True])
            mirrors = points.decomp.mirrors if name == "particles" else None
            if mirrors is not None and len(mirrors.source):  # the images' row data, reflected
                A[key][mirrors.start: mirrors.start + len(mirrors.source)] *= \
                    kernel_shape.row_data_sign(self.shape, mirrors.sign)
            test = related("test", "particles", name, X[:n], Y, A["gid"], support, "rows", group_rows[:n],
                           np.where(active, 0, -2))
            if name == "particles":
                base = np.arange(points.n_owned, dtype=np.int64)
            else:  # a point's first particle (rows of other bodies, never run, take any)
                base = trial.idx[np.minimum(trial.ptr[:-1], len(trial.idx) - 1)] if len(trial.idx) else \
                    np.zeros(points.n_owned, np.int64)
            integrates = name != "particles" or self.type == "kbm" or self.points is None
            self.couplings.append(Coupling(
                name, trial.ptr, trial.idx, G, phi, base, test.ptr, test.idx,
                test_function_gradients(self.shape, test, X[:n], Y, A[key], support, kernel), integrates))

    def moved(self, state, body) -> np.ndarray:
        """Positions of the body's owned stress points in the current configuration: their
        updated reference moved by the Shepard interpolation of the particles' displacement
        since it, x_q = X^r_q + sum_J Phi_J(X^r_q) d_J (the Eulerian kernel's update)."""
        coupling = self.couplings[1]
        lo, hi = body.set_rows[coupling.points]
        A = state.sets[coupling.points].arrays
        rows = np.repeat(np.arange(len(coupling.ptr) - 1), np.diff(coupling.ptr))
        move = np.stack([np.bincount(rows, coupling.phi * state.d[coupling.idx, a], len(coupling.ptr) - 1)
                         for a in range(state.dim)], axis=1)
        return A["Xr"][lo:hi] + move[lo:hi]

    def weights(self, state, points: str) -> np.ndarray:
        """Quadrature weights of the integration points of set `points` (zeros: read-out only)."""
        if points != "particles":
            return state.sets[points].arrays["volume"]
        if self.type == "kbm":
            return state.particles.arrays["weight"]
        return state.volume if self.points is None else np.zeros(len(state.volume))

    def trial_functions(self) -> tuple:
        """(ptr, idx, Phi) of the trial relation from the body's particles to particles."""
        coupling = self.couplings[0]
        return coupling.ptr, coupling.idx, coupling.phi

    def stages(self, state, body, running: Running) -> list:
        """The passes of one force evaluation over `body`'s owned particles and integration
        points of `state`."""
        c = body.constants.values
        runs = []
        for coupling in self.couplings:
            if coupling.points == "particles":
                arrays = dict(fs=state.fs if self.updated else state.F, F=state.F, Fr=state.Fr if self.updated else state.F,
                              VP=state.VP, J=state.J, psi=state.psi)
                lo, hi = body.lo, body.hi
                fail = (lambda i: stability.unstable_particle(running, state, i))
            else:
                A = state.sets[coupling.points].arrays
                arrays = A if self.updated else dict(A, fs=A["F"], Fr=A["F"])  # total-Lagrangian: F^r = I
                lo, hi = body.set_rows[coupling.points]
                fail = (lambda q, name=coupling.points: stability.unstable_point(running, state, name, q))
            runs.append((coupling, arrays, lo, hi, fail, self.weights(state, coupling.points),
                         coupling.points))

        def displacement():  # from the updated reference, d = u - (X^r - X)
            np.subtract(state.u[body.lo:body.hi], state.shift[body.lo:body.hi], out=state.d[body.lo:body.hi])

        scratch = (np.empty((state.dim, state.dim)), np.empty((update.WORK, 3, 3)))  # the kernel's

        def kinematics_stress():
            for coupling, arrays, lo, hi, fail, weight, points in runs:
                bad = self.kinematics_stress(lo, hi, coupling.ptr, coupling.idx, coupling.G, coupling.base, state.d,
                                             weight, c, *state.material_state(body, points), arrays["fs"],
                                             arrays["F"], arrays["Fr"], arrays["VP"], arrays["J"], arrays["psi"],
                                             *scratch, running.dt)
                if bad >= 0:
                    raise fail(bad)

        def forces():
            state.f_int[body.lo:body.hi] = 0.0
            for coupling, arrays, *_ in runs:
                if coupling.integrates:
                    self.forces(body.lo, body.hi, coupling.test_ptr, coupling.test_idx, coupling.test_g,
                                arrays["VP"], state.f_int)

        prefix = f"{self.points}." if self.points else ""
        written = ("fs", "F", "VP", "J", "psi") + tuple(prefix + k for k in ("F", "VP", "J", "psi") if prefix)
        reads = tuple(("VP",) if self.points is None or self.type == "kbm" else ()) + \
            ((prefix + "VP",) if prefix else ())
        return [Stage("kinematics+stress", displacement, writes=("d",))] * state.updated + [
            Stage("kinematics+stress", kinematics_stress, reads=("d",), writes=written),
            Stage("forces", forces, reads=reads, writes=("f_int",), force_row=True)]

    def quadrature(self, state, body) -> list:
        """[(X, F, w)] of the body's owned integration points, set by set."""
        out = []
        for coupling in self.couplings:
            if coupling.integrates:
                weight = self.weights(state, coupling.points)
                if coupling.points == "particles":
                    lo, hi = body.lo, body.hi
                    out.append((state.X[lo:hi], state.F[lo:hi], weight[lo:hi]))
                else:
                    lo, hi = body.set_rows[coupling.points]
                    A = state.sets[coupling.points].arrays
                    out.append((A["X"][lo:hi], A["F"][lo:hi], weight[lo:hi]))
        return out

    def integrated(self, state, body, density) -> np.ndarray:
        """w_q q_q over the body's owned integration points, q = density(arrays) per row of
        a point set's arrays (a density per unit reference volume: psi, plastic work)."""
        terms = []
        for coupling in self.couplings:
            if not coupling.integrates:
                continue
            weight = self.weights(state, coupling.points)
            if coupling.points == "particles":
                lo, hi = body.lo, body.hi
            else:
                lo, hi = body.set_rows[coupling.points]
            terms.append(weight[lo:hi] * density(state.point_set(coupling.points).arrays)[lo:hi])
        return np.concatenate(terms)


# ------------------------------------------------------------------ compiled stages


def compile_stages(dim: int, law: int, eulerian: bool = False):
    """(kinematics_stress, forces) for one body's dimension, material law and reference
    (the initial one, or the current one of the Eulerian kernel)."""
    reference = tlsph.REFERENCE_CURRENT if eulerian else tlsph.REFERENCE_INITIAL
    @njit(cache=True, _nrt=False)
    def kinematics_stress(lo, hi, ptr, idx, G, base, d, weight, c, state, trial, fs, F, Fr, VP, J, psi, P, work, dt):
        """F = I + sum_J (d_J - d_base) (x) G_J, the stress, w P, J and psi at integration
        points lo..hi-1; returns the first inverted point or -1. With the Eulerian kernel
        that gradient is the motion fs from the last reference, F = fs F^r, and the forces,
        which use the reference moved to the current configuration, take w P F^T
        (formulations.tlsph.stress_at); in the total-Lagrangian case fs and F are one array.
        P (dim x dim) and work (update.WORK x 3 x 3): scratch."""
        undamaged = state[:, :0]  # damage is computed at particles only (config)
        first_bad = -1
        for q in range(lo, hi):
            gradient_row(dim, q, base[q], ptr, idx, G, d, fs)
            bad = stress_at(dim, law, reference, 0, q, fs, Fr, weight[q], c, state, trial, undamaged, undamaged, P,
                            work, F, VP, J, psi, dt)
            if bad and first_bad < 0:
                first_bad = q
        return first_bad

    @njit(cache=True, _nrt=False)
    def forces(lo, hi, ptr, idx, g, VP, f_int):
        """f_I -= sum_q w_q P_q grad N_I(X_q) over one set of integration points, for
        particles lo..hi-1."""
        for i in range(lo, hi):
            f0 = f_int[i, 0]  # the row's sums in locals, stored once (tlsph's `forces`)
            f1 = f_int[i, 1] if dim > 1 else 0.0
            f2 = f_int[i, 2] if dim > 2 else 0.0
            for p in range(ptr[i], ptr[i + 1]):
                q = idx[p]
                for a in range(dim):
                    s = 0.0
                    for b in range(dim):
                        s += VP[q, a, b] * g[p, b]
                    f0, f1, f2 = added(a, -s, f0, f1, f2)
            for a in range(dim):
                f_int[i, a] = component(a, f0, f1, f2)

    variant = f"{COMPILED_SOURCE} {dim} {law} {eulerian}"
    return CompiledOnce(kinematics_stress, variant), CompiledOnce(forces, variant)
