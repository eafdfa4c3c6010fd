"""What a formulation gives the simulation loop: the members every family has
(Formulation, the protocol the rest of the code reads a body's formulation through), the
fields it carries per particle and the stages of a force evaluation, each declaring the
fields it reads at neighbours and the ones it writes on owned points.

The loop (simulation.Simulation.compute_forces) runs the stages of all bodies phase by
phase; before a phase it refreshes the ghost values of every field the phase reads at
neighbours that was written since its last refresh (by a stage, or by the integrator for
the displacement). No refresh is placed by hand.
"""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
import fcntl
import hashlib
import os
import tempfile
from dataclasses import dataclass
from typing import Callable

import numpy as np

from parsph.errors import InputError
from parsph.keys import Key, in_range, one_of, positive

# the formulation keys of the reference every family reads
KEYS = {
    "kernel": Key("str", None, one_of("lagrangian", "eulerian"),
                  "sph, rlm, kbm, efg (nodal): the kernel and neighbours in the reference configuration "
                  "(lagrangian, the default) or in the current one, rebuilt at every step (eulerian) "
                  "[R eq. 16-17, Table 2]"),
    "search_every": Key("int", None, positive,
                        "eulerian, ulsph: find neighbours, rebalance and exchange ghosts at most every "
                        "N reference updates (default 30, as [R §9.3]; an Eulerian kernel updates at "
                        "every step), sooner when a particle has moved half the skin; the corrections "
                        "and shape functions are recomputed at every update (kbm, efg: their point "
                        "relations too, from this rank's points); the result is that of a search at "
                        "every update"),
    "skin": Key("float", None, in_range(0.0, 2.0),
                "eulerian, ulsph: how far beyond the support neighbours are kept between searches, "
                "as a fraction of the support (default 0.25; at most 2: the lists hold (1 + skin)^d "
                "times the pairs)"),
}


class Formulation(ABC):
    """One body's formulation as the rest of the code sees it: what a family (formulations.nodal,
    formulations.galerkin) declares, the options the loop and the kernel relations read, and
    what it builds, evaluates and integrates. The defaults are those of a family without the
    feature (no hourglass control, no Hessian stabilisation, no artificial viscosity, no
    reference update by count or strain, no points of its own, no collocation)."""

    TYPES: dict = {}  # the formulation.type names it serves, with a line each
    KEYS: dict = {}  # its formulation keys (the other families refuse those that do not apply to them)
    damage = False  # tensile damage (materials.damage) is computed at its particles

    type: str  # formulation.type
    updated = False  # its reference moves (ulsph, an Eulerian kernel)
    eulerian = False  # the reference moves at every step, inside it (an Eulerian kernel)
    conserves_momentum = True  # its internal forces sum to zero (the balance check's momenta)
    conserves_energy = True  # its forces are its strain energy's gradient (the balance check's energy)
    alpha = 0.0  # hourglass coefficient [G eq. 31]
    hourglass_form = 0  # tlsph.HOURGLASS_*: HOURGLASS_OFF (0) without hourglass control
    hourglass_penalty = False  # its hourglass force derives from a penalty energy (the variational form)
    absorbs_hourglass_work = False  # its hourglass force is not a potential one: its work is absorbed [G eq. 32]
    viscous = False  # it adds Monaghan's artificial viscosity
    damped = False  # a yielded pair takes MACHDYN's viscous hourglass force: its dampers bound the step
    eta = 0.0  # Hessian's-difference stabilisation [V eq. 17]: 0 without
    corrected_stress = False  # its force row reads S = V P L^-1 / V at the neighbours (formulations.tlsph)
    weighted_hessian = True  # the Hessian's linear correction weighted by the kernel (with eta > 0)
    update_every = 0  # steps between reference updates (1 with an Eulerian kernel; 0: not by count)
    update_strain = 0.0  # the log strain since the reference that updates it (0: not by strain)
    collocates = False  # its constraints act through its trial functions (parsph.collocation)

    @staticmethod
    @abstractmethod
    def resolve(path: str, form: dict) -> None:
        """Its defaults and rules on a formulation table `form` checked against the schema
        (InputError naming the key at `path`)."""

    @staticmethod
    def check_body(body: dict, where: str, scene: dict) -> None:
        """Its rules on a resolved body of the scene (InputError naming `where`)."""

    @staticmethod
    @abstractmethod
    def moves_reference(form: dict) -> bool:
        """Whether a formulation table moves its reference."""

    def __init__(self, options: dict, dim: int, law: int, failure: int = 0):
        """Its options from the resolved formulation table, compiled for the dimension, the
        material law and the failure model (0: none) of its body."""
        self.type = options["type"]

    @property
    @abstractmethod
    def pair_options(self):
        """The options of its particle pairs in its kernel relation
        (formulations.reference.PairOptions)."""

    def build(self, state, body, kernel: str, skin: float = 0.0, search: bool = True) -> None:
        """Its own relations on the adopted state (state.RankState) besides the particle
        pairs of its kernel relation: none."""

    @abstractmethod
    def stages(self, state, body, running: Running) -> list:
        """The passes (Stage) of one force evaluation over `body`'s owned points of `state`
        (state.RankState), reading what changes while the run goes from `running`."""

    def moved(self, state, body) -> np.ndarray:
        """Positions of the body's owned points of its own set in the current configuration
        (the Eulerian kernel's update); only a family with such points has them."""
        raise NotImplementedError(f"formulation '{self.type}' has no points of its own")

    def trial_functions(self) -> tuple:
        """(ptr, idx, Phi) of its trial functions from the owned particles to the particles,
        for collocated constraints (collocates)."""
        raise NotImplementedError(f"formulation '{self.type}' does not collocate its constraints")

    @abstractmethod
    def quadrature(self, state, body) -> list:
        """[(X, F, w)] of the body's owned integration points: reference positions,
        deformation gradients, quadrature weights."""

    @abstractmethod
    def integrated(self, state, body, density) -> np.ndarray:
        """w_q q_q over the body's owned integration points, q = density(arrays) per row of a
        point set's arrays (a density per unit reference volume: psi, plastic work)."""

    def stable_step(self, state, body, omega2: np.ndarray, step_limit: np.ndarray, scale: float,
                    dampers: bool = True) -> tuple:
        """(stable step, largest incremental log strain, the row that sets the step or -1)
        over the body's owned particles, with its hourglass springs (none: HOURGLASS_OFF), its
        hourglass dampers' rates (unless not `dampers`), the interactions' springs' squared
        frequencies `omega2` and the motion's `step_limit` (each empty: none), the body's own
        frequencies times `scale` (formulations.tlsph.stable_time_step)."""
        from parsph.formulations import tlsph  # which imports this module
        ref = body.relation.ref
        return tlsph.stable_time_step(
            body.lo, body.hi, state.fs if self.updated else state.F, state.F, state.J, ref.min_spacing,
            ref.stiffening, body.constants.wave_speed, body.law.law_id, body.constants.values, state.dim,
            state.broken, state.omega_hg2, self.hourglass_form,
            state.damper_rate2 if dampers else state.damper_rate2[:0], omega2, step_limit, scale, state.scratch33)


class Running:
    """What a body's stages read while the run goes, kept current by the loop
    (simulation.Simulation): the steps taken and the time (for error messages), the size of
    the last step (it brought F from the committed state: rate-dependent laws), the ledger
    (ledger.Ledger: what stages book) and the stable step (stability.StableStep: the advice in
    error messages)."""

    def __init__(self, ledger, stable, t: float = 0.0):
        self.ledger, self.stable = ledger, stable
        self.t = t
        self.step = 0
        self.dt = 0.0


class CompiledOnce:
    """A compiled stage kernel whose first call in a process (where Numba compiles it, or
    loads it from its on-disk cache) holds an exclusive file lock named after the kernel's
    variant. Processes that need the same variant at the same time, the ranks of an MPI job
    or the workers of the test suite, then compile it once: the others wait for the lock and
    load the compiled code from the cache. Later calls go straight to the kernel."""

    def __init__(self, kernel, variant: str):
        self.kernel = kernel
        self.lock_path = os.path.join(tempfile.gettempdir(), "parsph-compile-" + hashlib.sha256(
            f"{kernel.py_func.__qualname__} {variant}".encode()).hexdigest()[:32] + ".lock")
        self.first = True

    def __call__(self, *args):
        if not self.first:
            return self.kernel(*args)
        with _locked(self.lock_path):
            out = self.kernel(*args)
        self.first = False
        return out


@contextlib.contextmanager
def _locked(path: str):
    """An exclusive flock on `path` (released however the process ends); without one (the
    folder is not writable) the block runs unlocked."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


@dataclass(frozen=True)
class Stage:
    """One compiled pass over a body's owned particles."""

    name: str  # label of its time in the per-stage report
    run: Callable[[], None]
    reads: tuple = ()  # fields read at neighbours: their ghost values must be current
    writes: tuple = ()  # fields written on owned particles (ghost values become stale)
    # a pass of the force row, which needs the state (F, stress) only: an Eulerian kernel
    # moves its reference to the current configuration before the first one
    force_row: bool = False


def bound(state, fields: dict) -> dict:
    """The rank's arrays a stage's kernel parameters are bound to: `fields` maps each
    parameter to the field it takes, named as Stage.reads names the particles' fields (a
    carried field or a work array of state.RankState), so that a stage declares as read at
    neighbours the very arrays its kernel reads there."""
    arrays = state.particles.arrays
    return {p: arrays[name] if name in arrays else getattr(state, name) for p, name in fields.items()}


def check_shared_keys(path: str, form: dict, kind: str, moves_reference: bool) -> None:
    """The rules every formulation family applies to a formulation table of type `kind`
    (InputError naming the key at `path`), after its own defaults: the update triggers
    are ulsph's, the force form corrected SPH's, Hessian stabilisation [V]'s; MACHDYN's
    viscous hourglass force needs the paper's hourglass force, hourglass control a
    Lagrangian kernel; search_every and skin apply where the reference moves (they and the
    kernel are dropped when not given, as in scenes written before the keys existed)."""
    if kind != "ulsph" and (form["update_every"] or form["update_strain"]):
        raise InputError(f"{path}.update_every/update_strain apply to {path}.type = 'ulsph' only")
    if kind not in ("tlsph", "ulsph") and form["force_form"] != "pair":
        raise InputError(f"{path}.force_form applies to tlsph and ulsph; {kind} has its own force row")
    if kind not in ("tlsph", "ulsph") and form["hessian"] > 0:
        raise InputError(f"{path}.hessian (Hessian's-difference stabilisation [V]) applies to tlsph and ulsph, "
                         f"not to {kind}")
    if form["plastic_hourglass"] == "viscous" and not (form["hourglass"] > 0 and form["hourglass_form"] == "paper"):
        raise InputError(f"{path}.plastic_hourglass = 'viscous' (LAMMPS MACHDYN's) needs the paper's hourglass "
                         f"force: {path}.hourglass > 0 and {path}.hourglass_form = 'paper'")
    if form["kernel"] == "eulerian" and form["hourglass"] > 0:
        raise InputError(f"{path}.hourglass applies to a Lagrangian kernel: with kernel = 'eulerian' the reference "
                         "is the current configuration, where F explains every separation (give 0 or leave it out)")
    for key in ("search_every", "skin"):
        if form[key] is not None and not moves_reference:
            raise InputError(f"{path}.{key} applies to kernel = 'eulerian' and type = 'ulsph'")
        if form[key] is None:
            del form[key]
    if form["kernel"] != "eulerian":
        del form["kernel"]
