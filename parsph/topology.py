"""The topology of the bodies whose reference moves (ulsph, the Eulerian kernel): when
their reference is updated and how, with the neighbour lists and ghost layers it needs.

An update makes the current configuration the reference [V §3.1]: X^r = x, F^r = F,
V^r = J V^0 (Remark 1). It searches (new ownership if the work is out of balance,
migration, ghosts and neighbours in X^r) at most every search_every updates, with lists
and ghost layers a skin wider, and in between rebuilds the reference data on the kept
lists: the same result as a search at every update (relations.Skin).
"""

from __future__ import annotations

import contextlib
import time

import numpy as np
from mpi4py import MPI

from parsph import conditions, config, fields, state
from parsph.collocation import BoundaryCollocation
from parsph.errors import InputError, ParsphError
from parsph.formulations import reference
from parsph.parallel.decomposition import add_ghosts, localize, partition
from parsph.parallel.runtime import collective
from parsph.relations import Skin


class Topology:
    """The update schedule of the moving bodies (they share it: config), the search rule
    and skin of the current lists, and the updates so far."""

    def __init__(self, scene: dict, bodies: list, local, comm):
        forms = [b.formulation for b in bodies]
        schedule = ([b.formulation for b in bodies if b.moves] or forms)[0]
        self.every, self.strain = schedule.update_every, schedule.update_strain  # by steps, by log strain
        # the neighbour lists and ghost layers of an updated reference: searched at most every
        # search_every updates, kept while no particle has moved half the skin since
        supports = local.fields["support"][: local.n_owned]
        kept = config.moving_formulation(scene) or config.bodies(scene)[0]["formulation"]
        self.rule = Skin(config.skin(kept) * comm.allreduce(
            float(supports.max()) if len(supports) else 0.0, op=MPI.MAX), comm,
            config.search_every(kept))
        self.skin = 0.0  # the skin of the current lists (none at set-up: the first update searches)
        self.count = 0  # reference updates so far
        self.since = 0  # steps since the last one

    def restore(self, clock: dict) -> None:
        self.count, self.since = clock.get("updates", 0), clock.get("since_update", 0)

    def due(self, sim, strain: float | None = None) -> bool:
        """Whether an update is due between steps: by count, or (given the largest
        incremental log strain) by strain. The Eulerian kernel moves inside its steps."""
        if not sim.updated or sim.eulerian:
            return False
        if strain is None:
            return bool(self.every) and self.since >= self.every
        return bool(self.strain) and strain > self.strain

    def update(self, sim) -> None:
        """Make the current configuration the reference [V §3.1] between steps
        (move) and evaluate the forces in it."""
        self.move(sim)
        sim.compute_forces()
        sim.ledger.external = conditions.external_force(sim)

    def move(self, sim) -> bool:
        """Make the current configuration the reference [V §3.1]: X^r = x, F^r = F,
        V^r = J V^0 (Remark 1); re-decide ownership (parallel RCB of X^r) if the work is
        out of balance, migrate the particles with their state, find ghosts and neighbours
        in X^r and rebuild the corrections. An Eulerian kernel (a move inside every step)
        searches at most every search_every steps, with lists and ghost layers a skin wider,
        and in between rebuilds the reference on the kept lists (_recommit): the same result
        as a search every step. Returns whether it searched (the arrays are new)."""
        start = time.perf_counter()
        for b in sim.bodies:  # the penalty restarts at 0
            if b.moves:
                sim.ledger.totals["hourglass_released"][b.index].add(sim.hg_psi[b.lo:b.hi])
        n = sim.n_owned
        moved = {name: self._moved(sim, name) for name in sim.sets}  # stress points at the current configuration
        x = sim.X[:n] + sim.u[:n] if sim.all_move else \
            np.where(sim.moves[:n, None], sim.X[:n] + sim.u[:n], sim.Xr[:n])  # the new reference
        searching = self.rule.every == 1 or self.rule.due(np.concatenate([x, *moved.values()]))
        if searching:
            self._search(sim, moved)
        else:
            self._recommit(sim, moved)
        self.rule.stepped()
        sim.stage_seconds["reference update"] += time.perf_counter() - start
        self.count += 1
        self.since = 0
        return searching

    def _search(self, sim, moved: dict) -> None:
        """The reference update with a new decomposition: ownership, ghosts, neighbours
        (`moved`: the owned points of the other sets at their new reference, _moved)."""
        n = sim.n_owned
        owned = dict(sim.particles.migrating(), **self._new_reference(sim), **sim.ledger.in_flight(sim))
        # stress points of an Eulerian kernel: moved with the particles, repartitioned with them
        sets = {name: dict(points.migrating(), Xr=moved[name], Fr=points.owned("F").copy())
                for name, points in sim.sets.items()}
        if sim.comm.size > 1 and not sets:
            work = np.array(sim.comm.allgather(len(sim.ref.idx) + n), float)
            if work.max() > (1.0 + sim.rebalance) * work.mean():
                owned = partition(owned, "Xr", sim.comm)
        self.skin = self.rule.length if self.rule.every > 1 else 0.0
        with collective(sim.comm):
            local = localize(owned, sets, "Xr", sim.comm, self.skin) if sets else \
                add_ghosts(owned, "Xr", sim.comm, skin=self.skin)
        sim.ledger.land(local.fields, local.n_owned)  # the step's start, with its particles
        with self._failure(sim):
            state.adopt(sim, local)
        self.rule.searched(np.concatenate([sim.Xr[: sim.n_owned],
                                           *(points.owned("Xr") for points in sim.sets.values())]))

    def _recommit(self, sim, moved: dict) -> None:
        """The reference update between searches (Eulerian kernel): X^r = x, F^r = F,
        V^r = J V^0 on the owned particles (and their moved stress points), every carried
        field refreshed on both ghost layers, then the reference data and the Galerkin
        relations rebuilt on the kept neighbour lists: the same as _search gives, without
        repartitioning or finding neighbours. F, the stress and VP (formed for the current
        configuration) stand; the motion from the new reference is the identity."""
        n = sim.n_owned
        eye = np.eye(sim.dim)
        for name, points in sim.sets.items():
            A = points.arrays
            A["Xr"][: points.n_owned] = moved[name]
            A["Fr"][: points.n_owned] = A["F"][: points.n_owned]
            A["fs"][:] = eye
            points.refresh("Xr", "Fr")
        for name, value in self._new_reference(sim).items():
            getattr(sim, name)[:n] = value
        sim.particles.refresh_all(*(name for name in fields.migrating(sim.carried) if name != "gid"))
        if sim.eulerian and sim.all_move:
            sim.shift[:] = sim.u  # d = 0 exactly (state.reference_shift)
        else:
            np.subtract(sim.Xr, sim.X, out=sim.shift)
            if sim.eulerian:
                np.copyto(sim.shift, sim.u, where=sim.moves[:, None])
        if sim.all_move:
            sim.d[:] = 0.0
        else:  # the bodies that keep their initial reference: d = u
            np.subtract(sim.u, sim.shift, out=sim.d)
            sim.d[sim.moves] = 0.0
        sim.fs[:] = eye
        sim.hg_psi[sim.moves[: len(sim.hg_psi)]] = 0.0
        with self._failure(sim), collective(sim.comm):
            sim.ref = reference.build(
                sim.Xr, sim.measure_r, sim.volume_r, sim.support, sim.gid, n, sim.decomp.n_rows,
                sim.scene["kernel"]["type"], sim.body, [b.formulation.pair_options for b in sim.bodies],
                sim.eta, sim.weighted_hessian, kept=sim.ref.kept)
            sim.exclude_kernel_pairs()
            for b in sim.bodies:
                b.formulation.build(sim, b, sim.scene["kernel"]["type"], search=False)
        if sim.collocation:
            sim.collocation = BoundaryCollocation(sim)
        for b in sim.bodies:
            b.stages = b.formulation.stages(sim, b)

    @staticmethod
    def _new_reference(sim) -> dict:
        """The owned particles' new updated reference: X^r = x, F^r = F, V^r = J V^0 (Remark 1)
        where it moves; the bodies that keep their initial reference keep it."""
        n = sim.n_owned
        new = dict(Xr=sim.X[:n] + sim.u[:n], Fr=sim.F[:n].copy(), measure_r=sim.J[:n] * sim.measure[:n],
                   volume_r=sim.J[:n] * sim.volume[:n])
        if not sim.all_move:
            still = ~sim.moves[:n]
            for name, value in new.items():
                value[still] = getattr(sim, name)[:n][still]
        return new

    @staticmethod
    def _moved(sim, name: str) -> np.ndarray:
        """The owned points of set `name` at their new updated reference, each body's moved
        with its particles (formulations.galerkin.GalerkinFormulation.moved)."""
        Xr = sim.sets[name].owned("Xr").copy()
        for b in sim.bodies:
            lo, hi = b.set_rows[name]
            if hi > lo and b.moves:
                Xr[lo:hi] = b.formulation.moved(sim, b)
        return Xr

    @contextlib.contextmanager
    def _failure(self, sim):
        """A reference update that fails on the configuration (not the input) says so."""
        try:
            yield
        except InputError as exc:
            error = ParsphError(
                f"reference update {self.count + 1} at step {sim.step_count}, t = {sim.t:.6g} failed: "
                f"{str(exc).rstrip('.')}. The particles are too disordered for a new reference: update "
                "earlier (formulation.update_strain), raise the stabilisation or refine the particles")
            error.agreed = getattr(exc, "agreed", False)
            raise error from None
