"""The energy ledger: what each rank sums for every term of the energy balance
(parsph.balance.TERMS) for the history (diagnostics.global_parts), and the work
accumulated step by step (running totals per body, exact: exact_sum). The works are
integrated by the trapezoidal rule over each step's displacement, as the kick-drift-kick
scheme moves the particles.

Beside the energies, each particle accumulates the impulse and the angular impulse of the
forces between particles (formulations, hourglass control, viscosity, contact): over a
kick-drift-kick step they are dt/2 (f_n + f_(n+1)) and dt/2 (x_n x f_n + x_(n+1) x f_(n+1)),
exactly what those forces change the momenta by. Summed over all particles they vanish for
forces that are equal, opposite and collinear in pairs; what is left is the momenta's
change that no external force explains (parsph.balance_check).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from parsph.exact_sum import Accumulator, Exact, allsum, totals
from parsph.fields import MOMENT_COMPONENTS, Field, register
from parsph.interactions import RUNNING as INTERACTION_RUNNING, TERMS
from parsph.materials import damage

RUNNING = ("hourglass_work",  # absorbed by the "paper" hourglass forces
           "viscous_work",  # absorbed by the artificial viscosity
           "damping_work",  # taken by the mass-proportional damping (time.damping)
           "hourglass_released",  # penalty dropped at reference updates, broken pairs and falling moduli
           "damage_released",  # strain energy and plastic work broken pairs release from intact particles
           "external_work") + INTERACTION_RUNNING  # contact's and the ties' works, the ties' released energy


register(Field("viscous_heat", "scalar", owner="viscosity",
               doc="heat the artificial viscosity gave the particle in the last step, for its material [J]"),
         Field("internal_impulse", "vector", doc="impulse of the forces between particles on the particle [N s]"),
         Field("internal_angular_impulse", "moment",
               doc="angular impulse (about the origin) of the forces between particles on the particle [N m s]"))


@njit(cache=True, _nrt=False)
def add_impulses(dt, f_old, f_new, X, u_old, u_new, impulse, angular):
    """impulse += dt/2 (f_old + f_new), angular += dt/2 (x_old x f_old + x_new x f_new),
    x = X + u, row by row (angular (n, 1) in 2D: the out-of-plane component; (n, 0) in 1D)."""
    n, dim = f_new.shape
    for i in range(n):
        for a in range(dim):
            impulse[i, a] += 0.5 * dt * (f_old[i, a] + f_new[i, a])
        if dim == 2:
            x0, y0 = X[i, 0] + u_old[i, 0], X[i, 1] + u_old[i, 1]
            x1, y1 = X[i, 0] + u_new[i, 0], X[i, 1] + u_new[i, 1]
            angular[i, 0] += 0.5 * dt * ((x0 * f_old[i, 1] - y0 * f_old[i, 0]) + (x1 * f_new[i, 1] - y1 * f_new[i, 0]))
        elif dim == 3:
            for a in range(3):
                b, c = (a + 1) % 3, (a + 2) % 3
                angular[i, a] += 0.5 * dt * (((X[i, b] + u_old[i, b]) * f_old[i, c] - (X[i, c] + u_old[i, c]) * f_old[i, b])
                                             + ((X[i, b] + u_new[i, b]) * f_new[i, c]
                                                - (X[i, c] + u_new[i, c]) * f_new[i, b]))


@njit(cache=True, _nrt=False)
def step_work(c, f_old, f_new, du, out):
    """out = c (f_old + f_new) du per particle and component: the trapezoidal work of a force
    f over the step's displacement du (c = 1/2; -1/2 for the work a force absorbs)."""
    n, dim = out.shape
    for i in range(n):
        for a in range(dim):
            out[i, a] = c * (f_old[i, a] + f_new[i, a]) * du[i, a]


@njit(cache=True, _nrt=False)
def add_obstacle_work(out, dt, mass, v_half, dv, moved, force_old, force):
    """out += the obstacles' work in the step per particle and component, as the
    kick-drift-kick scheme sees it: the kinetic energy m dv (2 v_half + dv) / 2 their
    velocity change dv takes from the mid-step velocity v_half, with the second half kick's
    share dt/2 f_(n+1) . dv, and the work -(f_n + f_(n+1))/2 . moved of the step's forces
    (force_old, force) over the displacement `moved` by which they put particles back on
    their surfaces (zero where there was no contact); for a particle held at rest on a wall
    it is zero. Each value is rounded as the expressions read, left to right."""
    n, dim = out.shape
    for i in range(n):
        for a in range(dim):
            kinetic = 0.5 * mass[i] * dv[i, a] * (2.0 * v_half[i, a] + dv[i, a])
            out[i, a] = out[i, a] + (kinetic + 0.5 * dt * force[i, a] * dv[i, a]
                                     - 0.5 * (force_old[i, a] + force[i, a]) * moved[i, a])


class Ledger:
    """The running totals of the work done on this rank's particles of each body, and the
    forces of the step's start that the trapezoidal rule needs."""

    def __init__(self, bodies: list):
        self.bodies = bodies
        self.totals = {name: [Accumulator() for _ in bodies] for name in RUNNING}
        self.external = None  # body force, tractions and reactions at the current state
        self._start = None
        self.share = None  # each owned particle's share in the part modelled (parallel.mirrors.on_planes; None: 1)

    def add(self, name: str, values: np.ndarray) -> None:
        """Add each body's rows of per-particle `values` (owned rows) to running total `name`."""
        for b in self.bodies:
            self.totals[name][b.index].add(self.part(b, values[b.lo:b.hi]))

    def part(self, b, values: np.ndarray) -> np.ndarray:
        """Per-particle `values` of body `b`'s owned rows, each weighted by the particle's
        share in the part modelled (1/2 on a symmetry plane: parallel.mirrors.on_planes).
        Arrays of other points (an empty penalty; KBM's and EFG's integration points, which
        take no planes) are as given."""
        if self.share is None or len(values) != b.hi - b.lo:
            return values
        share = self.share[b.lo:b.hi]
        return values * (share if values.ndim == 1 else share.reshape((-1,) + (1,) * (values.ndim - 1)))

    def masses(self, state) -> np.ndarray:
        """The particles' masses as the sums of the balance count them (by their share)."""
        return state.mass if self.share is None else state.mass[: state.n_owned] * self.share

    def restore(self, carried: dict) -> None:
        """The global totals of a checkpoint (rank 0 carries them); a total the checkpoint
        predates starts at zero."""
        for name, accs in self.totals.items():
            if name in carried:
                saved = carried[name] if len(accs) > 1 else [carried[name]]
                for acc, value in zip(accs, saved):
                    acc.set([Exact.from_json(value)])

    def checkpoint(self, comm) -> dict:
        """The totals over all ranks, exact (exact_sum.Exact.to_json) (collective)."""
        count = len(self.bodies)
        sums = allsum(comm, [acc.sums()[0] for accs in self.totals.values() for acc in accs])
        per_body = [sums[k: k + count] for k in range(0, len(sums), count)]
        return {name: [s.to_json() for s in values] if count > 1 else values[0].to_json()
                for name, values in zip(self.totals, per_body)}

    def damp(self, state, bcs, factor: float) -> None:
        """Scale the owned velocities by `factor` (time.damping over a half step) and add the
        kinetic energy it takes to the damping work; prescribed components are left out (the
        constraints set them again)."""
        n = state.n_owned
        v = state.v[:n]
        before = v * v
        v *= factor
        self.add("damping_work", np.where(bcs.mask, 0.0, 0.5 * state.mass[:n, None] * (before - v * v)))

    @staticmethod
    def give_heat(state) -> None:
        """The heat the artificial viscosity dissipated in the last step (trapezoidal in its
        power) into the committed state of each particle whose law keeps one (the heat column
        of the plastic laws: materials.law.Plastic), per unit reference volume. It is not a term of the
        balance: the viscous work already counts it, as the plastic work counts its heat.
        After the commit, so that the stress evaluation depends on the committed state alone
        (a restart from a checkpoint evaluates the same)."""
        if not state.viscous:
            return
        heat = state.particles.owned("viscous_heat")
        for b in state.bodies:
            if b.law.plastic is not None:
                held = state.material_state(b)[0]
                held[b.lo:b.hi, b.law.plastic.heat] += heat[b.lo:b.hi] / state.volume[b.lo:b.hi]
        heat[:] = 0.0

    def begin(self, state, conditions, interactions) -> None:
        """Keep what the step's works need from its start (after the commit, before the kick)."""
        n = state.n_owned
        self._start = dict(u=state.u[:n].copy(), v=state.v[:n].copy() if conditions.bcs.moving or conditions.collocation else None,
                           **{f.name: getattr(state, f.name).copy() for f in state.forces if f.work},
                           force=state.force,
                           dissipation={i.name: i.dissipation.copy() for i in interactions if i.dissipative},
                           external=self.external,
                           obstacles=None, internal=state.internal_force, heating=state.viscous_heating.copy())

    def in_flight(self, state) -> dict:
        """The step's start values of the owned particles (begin, obstacles_moved), named
        "ledger.KEY", to travel with them when a reference update inside the step (an
        Eulerian kernel's search) repartitions them; {} between steps."""
        if self._start is None:
            return {}
        per_particle = {"u", "force", "external", "internal"} | {f.name for f in state.forces if f.work} | (
            {"heating"} if state.viscous else set())
        out = {}
        for key, value in self._start.items():
            if key == "obstacles" and value is not None:
                out.update({f"ledger.obstacles.{k}": part for k, part in enumerate(value)})
            elif key == "dissipation":
                out.update({f"ledger.dissipation.{name}": part for name, part in value.items()})
            elif key in per_particle or (key == "v" and value is not None):
                out[f"ledger.{key}"] = value
        return out

    def land(self, fields: dict, n: int) -> None:
        """Take back the step's start values (in_flight) from the repartitioned `fields` (the
        owned rows first, n of them), removing them from it."""
        names = [name for name in fields if name.startswith("ledger.")]
        parts = {}
        for name in names:
            key, values = name[len("ledger."):], fields.pop(name)[:n]
            if key.startswith("obstacles."):
                parts[int(key.split(".")[1])] = values
            elif key.startswith("dissipation."):
                self._start["dissipation"][key.split(".", 1)[1]] = values
            else:
                self._start[key] = values
        if parts:
            self._start["obstacles"] = tuple(parts[k] for k in sorted(parts))

    def obstacles_moved(self, state, v_half: np.ndarray, u_drift: np.ndarray) -> None:
        """Keep the changes the obstacles made to the mid-step velocity v_half and the
        drifted displacement u_drift (parsph.walls)."""
        n = state.n_owned
        self._start["obstacles"] = (v_half, state.v[:n] - v_half, state.u[:n] - u_drift)

    def end(self, state, conditions, interactions, t: float, dt: float) -> None:
        """Add the step's works (after the second kick): the absorbed forces' (state.FORCES:
        the paper hourglass forces', the viscous forces'), contact damping's and friction's,
        the external forces' and obstacles', and the work that changes the kinetic energy of
        a prescribed motion."""
        n, start = state.n_owned, self._start
        du = state.u[:n] - start["u"]
        for force in (f for f in state.forces if f.work):  # forces without a potential
            now = getattr(state, force.name)
            for b in (b for b in state.bodies if force.absorbs(b.formulation)):
                work = np.empty((b.hi - b.lo, state.dim))
                step_work(-0.5, start[force.name][b.lo:b.hi], now[b.lo:b.hi], du[b.lo:b.hi], work)
                self.totals[force.work][b.index].add(self.part(b, work))
        if state.viscous:
            state.particles.owned("viscous_heat")[:] += 0.5 * dt * (start["heating"] + state.viscous_heating)
        for interaction in interactions:  # contact damping's and friction's, the ties' dashpots'
            if interaction.name in start["dissipation"]:
                self.add(interaction.work, -0.5 * (start["dissipation"][interaction.name] + interaction.dissipation)
                         * du)
        self.external = conditions.external_force(state, t)
        work = np.empty_like(du)
        step_work(0.5, start["external"], self.external, du, work)
        if start["obstacles"] is not None:
            add_obstacle_work(work, dt, state.mass[:n], *start["obstacles"], start["force"], state.force)
        self.add("external_work", work)
        if start["v"] is not None:
            v, v_old = state.v[:n], start["v"]
            self.add("external_work", np.where(conditions.bcs.mask, 0.5 * state.mass[:n, None] * (v * v - v_old * v_old), 0.0))
        A = state.particles.arrays
        add_impulses(dt, start["internal"], state.internal_force, state.X, start["u"], state.u,
                     A["internal_impulse"], A["internal_angular_impulse"].reshape(len(state.X), MOMENT_COMPONENTS[state.dim]))
        self._start = None

    def items(self, sim) -> dict:
        """What this rank sums for each term of each body (arrays, or exact_sum.Exact running
        totals): strain (V^0 psi of the owned integration points), plastic work (V^0 w_p),
        damage work (the work the damaged particles have taken beyond their strain energy
        and plastic work, V^0 (W - psi - w_p): materials.damage, and what broken pairs
        released from the intact ones), viscous work, hourglass (the
        particles' penalty, the work absorbed on this rank by the paper form, the penalty
        released since), damping work, external work and the interactions' terms
        (interactions.Interactions.energies: contact's, each particle's half of its pairs' potential, its
        work; the ties')."""
        out = {term.key: [] for term in TERMS}
        for b in sim.state.bodies:
            lo, hi = b.lo, b.hi
            acc = {name: accs[b.index].sums()[0] for name, accs in self.totals.items()}
            out["strain"].append([self.part(b, b.formulation.integrated(sim.state, b, lambda A: A["psi"]))])
            out["plastic"].append([] if not b.law.plastic else [self.part(b, b.formulation.integrated(
                sim.state, b, lambda A, b=b: A[b.law.state + "_trial"][:, b.law.plastic.work]))])
            out["damage"].append([] if not b.failure else [self.part(b, sim.state.volume[lo:hi] * _damage_work(sim.state, b)),
                                                           acc["damage_released"]])
            out["viscous"].append([acc["viscous_work"]])
            out["hourglass"].append([self.part(b, sim.state.hg_psi[lo:hi]), acc["hourglass_work"], acc["hourglass_released"]])
            out["damping"].append([acc["damping_work"]])
            out["external"].append([acc["external_work"]])
            for key, parts in sim.interactions.energies(sim, b).items():
                out[key].append(parts)
        return out

    def local(self, sim, key: str) -> float:
        """This rank's part of term `key`, all bodies together."""
        return float(sum((sum(totals(body), Exact(0)) for body in self.items(sim)[key]), Exact(0)))


def _damage_work(state, b) -> np.ndarray:
    """W - psi - w_p at `b`'s owned particles that are damaged (0 at the others): the work
    they have taken (materials.damage) beyond their strain energy and, with a plastic law,
    their plastic work (counted as such), since they were first damaged (start_damage_work)."""
    lo, hi = b.lo, b.hi
    trial = state.damage_state(b)[1]
    rows = np.arange(lo, hi)
    return np.where(trial[lo:hi, damage.DAMAGE] > 0.0, trial[lo:hi, damage.WORK] - law_work(state, b, rows, 1), 0.0)


def law_work(state, b, rows: np.ndarray, which: int = 0) -> np.ndarray:
    """psi + w_p at the owned `rows` of body `b`: its law's strain energy of the last
    evaluation and its plastic work (committed, `which` 0, or trial, 1)."""
    out = state.psi[rows]
    if b.law.plastic:
        out = out + state.material_state(b)[which][rows, b.law.plastic.work]
    return out


def intact_law_work(state) -> np.ndarray:
    """V^0 (psi + w_p) (trial) at the owned particles of the bodies with a failure model
    whose committed damage is 0 (0 at the others): what a break of pairs can release from
    them (failure.Failure.break_pairs)."""
    out = np.zeros(state.n_owned)
    for b in (b for b in state.bodies if b.failure):
        rows = np.arange(b.lo, b.hi)
        intact = state.damage_state(b)[0][rows, damage.DAMAGE] == 0.0
        out[rows[intact]] = state.volume[rows[intact]] * law_work(state, b, rows[intact], 1)
    return out


def start_damage_work(state, b, rows: np.ndarray) -> None:
    """The owned `rows` of body `b` have just been damaged (at a step's start, after the
    commit): their work taken W (committed damage state) becomes psi + w_p, so that their
    damage work starts at zero and counts only what the damaged stress does differently;
    the integration error of W against the law's energies before (trapezoidal rule against
    the law's own increments) does not enter the balance, as for a body without damage."""
    state.damage_state(b)[0][rows, damage.WORK] = law_work(state, b, rows)
