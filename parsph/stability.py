"""The step size and the run's instabilities: the stable time step of all bodies
(their formulations' stable_step, rigid.stable_step) with time.cfl or a fixed
time.dt, its floor, and the errors that name the particle or point where a run broke down
with what to change.
"""

from __future__ import annotations

import math

import numpy as np
from mpi4py import MPI

from parsph import rigid
from parsph.errors import InputError, ParsphError
from parsph.parallel.runtime import collective
from parsph.relations import BLOCK_PAIRS, row_blocks


class StableStep:
    """The size of the next step and what bounds it: the first stable step (for
    time.step_floor), with a fixed time.dt the CFL step at set-up (for messages), and
    whether the hourglass frequencies must be formed at each force evaluation."""

    def __init__(self, settings: dict):
        self.settings = settings  # the scene's [time]
        self.dt = 0.0
        self.first = 0.0  # the first stable step
        self.floor = 0.0  # the smallest stable step allowed (time.step_floor), set by start
        self.cfl_at = None  # with a fixed time.dt: (CFL step, step) at set-up
        self.bound_hourglass = True  # whether the stable step is due after each force evaluation
        self.measured = 0  # the step at which the bodies' step factors were last measured (calibrate)

    def start(self, state, topology, interactions, step: int, t: float, clock: dict | None) -> None:
        """The first step's size, or the checkpoint's `clock` (collective); the arguments as
        for limit."""
        settings = self.settings
        if settings.dt > 0:
            self.cfl_at = (settings.cfl * self.limit(state, topology, interactions, step, t)[0], step)
        self.dt = clock["dt"] if clock else self.next_step(state, topology, interactions, step, t)[0]
        self.first = clock.get("first_stable", 0.0) if clock else self.limit(state, topology, interactions, step, t)[0]
        self.floor = settings.step_floor * self.first if self.first < math.inf else 0.0
        # a fixed time.dt needs no stable step after the set-up (unless for the adaptive update's strain)
        self.bound_hourglass = settings.dt == 0 or (state.updated and topology.adaptive)

    def calibrate(self, state, squared: np.ndarray, tighten: bool = False) -> None:
        """Set each deformable body's step_factor k so that its part of the estimate at set-up,
        max_i sqrt(omega_el^2 + omega_hg^2) over its particles (without contact or the
        motion's limits), equals sqrt(`squared`), the largest frequency of its discrete force
        operator (operator_frequency.largest_frequencies) on `state` (collective). The
        estimate is conservative by up to 2 where corrected SPH's operator decouples odd and
        even particles (1D bars) and where the hourglass bound's triangle inequality is loose;
        it is optimistic where Hessian stabilisation stiffens more than its power law says:
        the factor corrects both, and the estimate keeps tracking stretch, stiffening,
        yielding and contact as the run goes. A body with no stable step (all failed, or
        flattened) keeps its k. With `tighten` (a measurement during the run) k only grows:
        a deformed state's operator may be stiffer than the estimate follows (the
        Hessian-stabilised updated cylinder's), but a softer one is not taken up, as the
        operator knows nothing of the contact and disorder of a compressed body (the updated
        punch, given the larger step, pairs up its particles under the tool)."""
        sizes = np.full(len(state.bodies), np.inf)
        none = np.zeros(0)
        for b in state.bodies:
            if not b.rigid:
                sizes[b.index] = b.formulation.stable_step(state, b, none, none, 1.0, dampers=False)[0]
        if state.comm.size > 1:
            state.comm.Allreduce(MPI.IN_PLACE, sizes, op=MPI.MIN)
        for b in state.bodies:
            if not b.rigid and 0.0 < sizes[b.index] < math.inf:
                factor = 0.5 * math.sqrt(float(squared[b.index])) * float(sizes[b.index])
                b.step_factor = max(factor, b.step_factor) if tighten else factor

    def next_step(self, state, topology, interactions, step: int, t: float) -> tuple:
        """(size of the next step, each kernel relation's largest incremental log strain):
        time.dt if fixed, else time.cfl times the stable step; the strains for the adaptive
        reference update (0 unless it is enabled); the arguments as for limit. Collective."""
        settings = self.settings
        adaptive = state.updated and topology.adaptive
        if settings.dt > 0:
            return settings.dt, self.limit(state, topology, interactions, step, t)[1] if adaptive else \
                np.zeros(len(topology.relations))
        size, strains = self.limit(state, topology, interactions, step, t)
        return settings.cfl * size, strains

    def limit(self, state, topology, interactions, step: int, t: float) -> tuple:
        """(stable step, each kernel relation's largest incremental log strain) over all
        ranks of the rank's particles (`state`: state.RankState) in their kernel relations
        (`topology`) and interactions (their springs: interactions.Interactions), from
        their formulations' stable_step (collective). A step of zero, or below
        time.step_floor times the first one, raises the error naming the particle with the
        smallest step on any rank, at `step` and time t."""
        dt, smallest = np.inf, -1
        strains = np.zeros(len(topology.relations))
        for b in state.bodies:  # in row order: the first particle with the smallest step
            if b.rigid:
                size, worst, first = rigid.stable_step(b, interactions.omega2, state.step_limit, state.v, interactions.contact)
            else:
                size, worst, first = b.formulation.stable_step(state, b, interactions.omega2, state.step_limit,
                                                               b.step_factor)
            if b.moves:  # the strain since a reference that moves
                strains[b.relation.index] = max(strains[b.relation.index], worst)
            if size < dt or (first >= 0 and not size > 0.0):
                dt, smallest = size, first
            if not size > 0.0:
                break
        reduced = np.array([-dt, *strains])
        if state.comm.size > 1:
            state.comm.Allreduce(MPI.IN_PLACE, reduced, op=MPI.MAX)
        if -reduced[0] == math.inf and self.settings.dt > 0:  # nothing bounds a fixed step: it is the user's
            return math.inf, reduced[1:]
        if -reduced[0] == math.inf:
            why = ("every body is rigid and none touches another: give time.dt" if all(b.rigid for b in state.bodies)
                   else "every particle has failed completely (damage 1) and carries no stress; the run is stopped, "
                        "as nothing is left to integrate")
            error = ParsphError(f"no particle sets the stable time step at step {step}, t = {t:.6g} s: "
                                f"{why}")
            error.agreed = True  # the same reduction on every rank
            raise error
        if not -reduced[0] > self.floor:
            raise self.collapsed(state, interactions, step, t, -reduced[0], dt, smallest)
        return -reduced[0], reduced[1:]

    def standstill(self, step: int, t: float) -> ParsphError:
        """The error for a step too small to advance the clock (below its rounding) at
        `step`, time t."""
        error = ParsphError(f"the time step {self.dt:.3g} s no longer advances the time t = {t:.6g} s (step "
                            f"{step}): the run would stand still; {self.advice()}")
        error.agreed = True  # the same clock on every rank
        return error

    def collapsed(self, state, interactions, step: int, t: float, size: float, dt: float,
                  smallest: int) -> ParsphError:
        """The error for a step that has collapsed (below the floor, or zero: `size`; this
        rank's smallest `dt` at its row `smallest`) at `step`, time t, naming the particle
        that sets it and, if it touches another body, both bodies (collective)."""
        touching, speed = None, None
        if smallest >= 0 and interactions.contact is not None:
            touching = interactions.contact.partner(smallest)
        if smallest >= 0 and len(state.step_limit) and not state.step_limit[smallest] > dt:  # its motion sets it
            v = state.v[smallest]
            top = float(np.abs(v).max())
            speed = top * float(np.sqrt(np.sum((v / top) ** 2))) if 0.0 < top < np.inf else top  # no overflow
        mine = [] if smallest < 0 else [(dt, int(state.gid[smallest]),
                                         tuple((state.X[smallest] + state.u[smallest]).tolist()),
                                         int(state.body[smallest]), touching, speed)]
        _, gid, x, body, touching, speed = min(c for part in state.comm.allgather(mine) for c in part)
        where = ", ".join(f"{c:.6g}" for c in x)
        if not size > 0.0:
            what = "collapsed to zero"
        else:
            what = (f"fell to {size:.3g} s, below time.step_floor = {self.settings.step_floor:g} of the first "
                    f"one ({self.first:.3g} s),")
        names = [b.name for b in state.bodies]
        if speed is not None:
            why = (f"of body '{names[body]}' moves at {speed:.3g} m/s, and the step in which it closes in on another "
                   f"body or moves a quarter of the contact skin has collapsed: check the initial velocities and "
                   f"loads")
        elif touching is not None:
            other, other_body, ratio = touching
            why = (f"of body '{names[body]}' is at {ratio:.3g} of the contact distance from particle {other} of body "
                   f"'{names[other_body]}': the contact between '{names[body]}' and '{names[other_body]}' has "
                   f"failed (the bodies are pressed into each other faster than their contact springs can part "
                   f"them); raise contact.stiffness, refine the particles, or slow the impact")
        else:
            why = (("is flattened (a principal stretch near zero)" if not size > 0.0 else
                    "is the most flattened (its smallest principal stretch sets the step)")
                   + f"; the run is unstable: {self.advice()}")
        error = ParsphError(f"the stable time step {what} at step {step}, t = {t:.6g}: "
                            f"particle {gid} at ({where}) {why}")
        error.agreed = True  # every rank found the same particle and raises this
        return error

    def advice(self) -> str:
        """What to change when the run has become unstable."""
        dt = self.settings.dt
        if dt == 0:
            return "reduce time.cfl, raise formulation.hourglass or refine the particles"
        cfl = "" if self.cfl_at is None or self.cfl_at[0] == math.inf else \
            " (the CFL step, time.cfl times the stable step, was {:.3g} s at step {})".format(*self.cfl_at)
        return f"reduce time.dt = {dt:.3g} s{cfl}, raise formulation.hourglass or refine the particles"


def breakdown(J: float) -> str:
    """What went wrong at a point whose stress evaluation failed, from its volume ratio J."""
    if J <= 0.0:
        return f"is inverted (J = {J:.4g})"
    if not math.isfinite(J):
        return f"has a deformation that is not finite (J = {J})"
    return f"has a stress that is not finite (J = {J:.4g})"


def unstable_particle(running, state, i: int) -> ParsphError:
    """The error for owned particle i of `state` (state.RankState), inverted or with a stress
    that is not finite, in the step after `running`'s (formulations.base.Running)."""
    where = ", ".join(f"{c:.6g}" for c in state.X[i] + state.u[i])
    return ParsphError(
        f"particle {int(state.gid[i])} at ({where}) {breakdown(state.J[i])} at step {running.step + 1}, "
        f"t = {running.t:.6g}; the run is unstable: {running.stable.advice()}")


def unstable_point(running, state, points: str, q: int) -> ParsphError:
    """The error for owned point q of set `points`, inverted or with a stress that is
    not finite (the arguments as for unstable_particle)."""
    A = state.sets[points].arrays
    where = ", ".join(f"{c:.6g}" for c in A["X"][q])
    what = points[:-1].replace("_", " ")
    return ParsphError(
        f"{what} {int(A['gid'][q])} at reference ({where}) {breakdown(A['J'][q])} at step "
        f"{running.step + 1}, t = {running.t:.6g}; the run is unstable: {running.stable.advice()}")


def check_hourglass_stiffness(state, topology) -> None:
    """InputError if 2 sum_j c_ij (E_i + E_j) / m_i, the scale of a particle's hourglass
    frequency squared, overflows (an absurd formulation.hourglass), on the rank's particles
    (`state`) in their kernel relations (`topology`). At set-up."""
    n = state.n_owned
    if not state.hourglass:
        return
    out = np.zeros(n)
    for ref in (r.ref for r in topology.relations if len(r.ref.hgc)):  # the rows of a relation's bodies
        for r0, r1 in row_blocks(ref.ptr, BLOCK_PAIRS):
            p0, p1 = ref.ptr[r0], ref.ptr[r1]
            rows = np.repeat(np.arange(r0, r1), np.diff(ref.ptr[r0:r1 + 1]))
            with np.errstate(over="ignore", invalid="ignore"):
                k = ref.hgc[p0:p1] * (state.youngs[rows] + state.youngs[ref.idx[p0:p1]])
                out += 2.0 * np.bincount(rows, weights=k, minlength=n) / state.mass[:n]
    with collective(state.comm):
        bad = np.flatnonzero(~np.isfinite(out))
        if len(bad):
            i = bad[np.argmin(state.gid[bad])]
            alpha = state.bodies[state.body[i]].formulation.alpha
            raise InputError(f"formulation.hourglass = {alpha:g}: the hourglass stiffness of particle "
                             f"{state.gid[i]} over its mass, {out[i]:g} 1/s^2, overflows the range of double "
                             "precision ([G] recommends 50)")
