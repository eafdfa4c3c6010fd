"""The topology: the kernel relations of the bodies (parsph.kernel_relation), in order, and
for those whose reference moves (ulsph, the Eulerian kernel) when it is updated and how, with
the neighbour lists and ghost layers it needs.

An update makes the current configuration the reference [V §3.1]: X^r = x, F^r = F,
V^r = J V^0 (Remark 1), for the bodies of the relations that are due; the others keep their
reference. It searches (new ownership if the work is out of balance, migration, ghosts and
neighbours in X^r: every relation built anew) at most every search_every updates of a due
relation, with lists and ghost layers a skin wider, and in between rebuilds the due
relations' reference data on their kept lists: the same result as a search at every update
(relations.Skin).
"""

from __future__ import annotations

import contextlib

import numpy as np

from parsph import fields
from parsph.errors import InputError, ParsphError
from parsph.kernel_relation import Configuration, KernelRelation, groups, reach
from parsph.parallel.decomposition import LocalBody, add_ghosts, localize, partition
from parsph.parallel.runtime import collective
from parsph.relations import Relation


class Topology:
    """The kernel relations of the bodies, each with its own kernel, stabilisation, update
    schedule, list rule and updates so far (kernel_relation.KernelRelation)."""

    def __init__(self, scene, bodies: list, local, comm):
        length = reach(local.fields["support"][: local.n_owned], comm)
        self.relations = [KernelRelation(k, group, bodies, scene, length, comm)
                          for k, group in enumerate(groups(bodies, scene))]
        self.rebalance = scene.parallel.rebalance  # the work imbalance that repartitions
        self.builds = 0  # the builds of the relations' reference data so far (a self-contact's cue)

    @property
    def count(self) -> int:
        """Reference updates so far, of all relations."""
        return sum(r.count for r in self.relations)

    @property
    def skin(self) -> float:
        """The widest skin of the current lists (the ghost layers': a relation's lists may be
        searched wider than its own skin)."""
        return max(r.skin for r in self.relations)

    @property
    def keeps(self) -> bool:
        """Whether some relation keeps its lists between searches."""
        return any(r.rule.every > 1 for r in self.relations)

    @property
    def adaptive(self) -> bool:
        """Whether some relation updates its reference by strain."""
        return any(r.moves and r.strain > 0 for r in self.relations)

    def clock(self) -> dict:
        """The updates so far, for a checkpoint: each relation's (count, since) beyond the
        first's, which a scene of one relation writes alone."""
        first = self.relations[0]
        out = {"updates": first.count, "since_update": first.since}
        if len(self.relations) > 1:
            out["relation_updates"] = [[r.count, r.since] for r in self.relations]
        return out

    def restore(self, clock: dict) -> None:
        counts = clock.get("relation_updates", [[clock.get("updates", 0), clock.get("since_update", 0)]])
        for r, (count, since) in zip(self.relations, counts):
            r.count, r.since = count, since

    def stepped(self) -> None:
        for r in self.relations:
            r.since += 1

    def due(self, strains=None) -> list:
        """The relations whose reference update is due between steps: by count, or also (given
        each relation's largest incremental log strain) by strain."""
        if strains is None:
            return [r for r in self.relations if r.due()]
        return [r for r, strain in zip(self.relations, strains) if r.due() or r.due(strain)]

    def by_strain(self, due: list) -> bool:
        """Whether a relation not in `due` may be due by strain."""
        return any(r.moves and not r.eulerian and r.strain and r not in due for r in self.relations)

    def build(self, at: Configuration, **how) -> np.ndarray:
        """Every relation's reference data in configuration `at` (KernelRelation.build);
        returns the singular rows (with `tolerant`)."""
        self.builds += 1
        return np.concatenate([r.build(at, **how).bad for r in self.relations])

    def kernel_pairs(self) -> Relation:
        """The pairs of all relations (CSR rows of the owned particles)."""
        if len(self.relations) == 1:
            return self.relations[0].ref
        refs = [r.ref for r in self.relations]
        rows = np.concatenate([np.repeat(np.arange(len(ref.ptr) - 1), np.diff(ref.ptr)) for ref in refs])
        order = np.argsort(rows, kind="stable")  # rows are disjoint: each row's pairs from one relation
        ptr = np.zeros(len(refs[0].ptr), np.int64)
        np.cumsum(np.bincount(rows, minlength=len(ptr) - 1), out=ptr[1:])
        return Relation(ptr, np.concatenate([ref.idx for ref in refs])[order])

    def pair_count(self) -> int:
        return sum(len(r.ref.idx) for r in self.relations)

    def move(self, state, ledger, due: list) -> LocalBody | None:
        """Make the current configuration the reference [V §3.1] of the `due` relations'
        bodies: X^r = x, F^r = F, V^r = J V^0 (Remark 1); re-decide ownership (parallel RCB
        of X^r) if the work is out of balance, migrate the particles with their state and find
        ghosts in X^r: returns them (a LocalBody) for the simulation to adopt. A relation
        that keeps its lists searches at most every search_every of its updates, with lists
        and ghost layers a skin wider, and in between rebuilds its reference on the kept
        lists (_recommit, returns None): the same result as a search every time. `moved`
        ends the update."""
        bodies = [b for r in due for b in r.bodies if b.moves]
        for b in bodies:  # the penalty restarts at 0
            ledger.totals["hourglass_released"][b.index].add(state.hg_psi[b.lo:b.hi])
        # the rows whose reference moves now: those of every moving body (the mask adopt made), or fewer
        moving = state.moves if len(bodies) == sum(b.moves for b in state.bodies) else \
            np.isin(state.body, [b.index for b in bodies])
        n = state.n_owned
        moved = {name: self._moved(state, name, bodies) for name in state.sets}  # stress points at x
        x = state.X[:n] + state.u[:n] if moving.all() else \
            np.where(moving[:n, None], state.X[:n] + state.u[:n], state.Xr[:n])  # the new reference
        points = np.concatenate([x, *moved.values()])
        if any(r.rule.every == 1 or r.rule.due(points, r.rows(state)) for r in due):
            return self._search(state, ledger, moved, moving)
        self._recommit(state, moved, moving, due)
        return None

    def moved(self, state, due: list, searched: bool) -> None:
        """The end of a reference update of the `due` relations (after the simulation adopted
        the particles of a search)."""
        if searched:
            points = np.concatenate([state.Xr[: state.n_owned], *(p.owned("Xr") for p in state.sets.values())])
            for r in self.relations:
                r.rule.searched(points, r.rows(state))
        for r in due:
            r.rule.stepped()
            r.count += 1
            r.since = 0

    def _search(self, state, ledger, moved: dict, moving: np.ndarray) -> LocalBody:
        """The reference update with a new decomposition: ownership and ghosts in X^r
        (`moved`: the owned points of the other sets at their new reference, _moved; `moving`:
        the rows whose reference moves); every relation searches when they are adopted."""
        comm, n = state.comm, state.n_owned
        owned = dict(state.particles.migrating(), **self._new_reference(state, moving), **ledger.in_flight(state))
        # stress points of an Eulerian kernel: moved with the particles, repartitioned with them
        sets = {name: dict(points.migrating(), Xr=moved[name], Fr=points.owned("F").copy())
                for name, points in state.sets.items()}
        if comm.size > 1 and not sets:
            work = np.array(comm.allgather(self.pair_count() + n), float)
            if work.max() > (1.0 + self.rebalance) * work.mean():
                owned = partition(owned, "Xr", comm)
        for r in self.relations:  # the new numbering of the rows: every relation searches
            r.skin = r.rule.length if r.rule.every > 1 else 0.0
        with collective(comm):
            local = localize(owned, sets, "Xr", comm, self.skin) if sets else \
                add_ghosts(owned, "Xr", comm, skin=self.skin)
        ledger.land(local.fields, local.n_owned)  # the step's start, with its particles
        return local

    def _recommit(self, state, moved: dict, moving: np.ndarray, due: list) -> None:
        """The reference update between searches: X^r = x, F^r = F, V^r = J V^0 on the owned
        particles whose reference moves (`moving`, and their moved stress points), every
        carried field refreshed on both ghost layers, then the `due` relations' reference
        data and their bodies' Galerkin relations rebuilt on the kept neighbour lists: the
        same as _search gives, without repartitioning or finding neighbours. F, the stress
        and VP (formed for the current configuration) stand; the motion from the new
        reference is the identity."""
        n = state.n_owned
        eye = np.eye(state.dim)
        everything = bool(moving.all())
        for name, points in state.sets.items():
            A = points.arrays
            A["Xr"][: points.n_owned] = moved[name]
            A["Fr"][: points.n_owned] = A["F"][: points.n_owned]
            A["fs"][:] = eye
            points.refresh("Xr", "Fr")
        for name, value in self._new_reference(state, moving).items():
            getattr(state, name)[:n] = value
        state.particles.refresh_all(*(name for name in fields.migrating(state.carried) if name != "gid"))
        if state.eulerian and everything:
            state.shift[:] = state.u  # d = 0 exactly (state.RankState.reference_shift)
        else:
            np.subtract(state.Xr, state.X, out=state.shift)
            if state.eulerian:
                np.copyto(state.shift, state.u, where=moving[:, None])
        if everything:
            state.d[:] = 0.0
        else:  # the bodies that keep their reference: d = u - (X^r - X)
            np.subtract(state.u, state.shift, out=state.d)
            state.d[moving] = 0.0
        state.fs[:] = eye
        state.hg_psi[moving[: len(state.hg_psi)]] = 0.0
        at = Configuration(state.Xr, state.measure_r, state.volume_r, state.support, state.gid, state.body, n,
                           state.decomp.n_rows)
        with collective(state.comm):
            for r in due:
                r.build(at, search=False)
            self.builds += 1
            for r in due:
                for b in r.bodies:
                    b.formulation.build(state, b, r.kernel, self.skin, search=False)

    @staticmethod
    def _new_reference(state, moving: np.ndarray) -> dict:
        """The owned particles' new updated reference: X^r = x, F^r = F, V^r = J V^0 (Remark 1)
        where it moves (`moving`); the other rows keep theirs."""
        n = state.n_owned
        new = dict(Xr=state.X[:n] + state.u[:n], Fr=state.F[:n].copy(), measure_r=state.J[:n] * state.measure[:n],
                   volume_r=state.J[:n] * state.volume[:n])
        if not moving.all():
            still = ~moving[:n]
            for name, value in new.items():
                value[still] = getattr(state, name)[:n][still]
        return new

    @staticmethod
    def _moved(state, name: str, bodies: list) -> np.ndarray:
        """The owned points of set `name` at their new updated reference, those of `bodies`
        moved with their particles (formulations.galerkin.GalerkinFormulation.moved)."""
        Xr = state.sets[name].owned("Xr").copy()
        for b in bodies:
            lo, hi = b.set_rows[name]
            if hi > lo:
                Xr[lo:hi] = b.formulation.moved(state, b)
        return Xr

    @contextlib.contextmanager
    def failing(self, step: int, t: float):
        """A reference update (at `step`, time t) that fails on the configuration (not the
        input) says so."""
        try:
            yield
        except InputError as exc:
            error = ParsphError(
                f"reference update {self.count + 1} at step {step}, t = {t:.6g} failed: "
                f"{str(exc).rstrip('.')}. The particles are too disordered for a new reference: update "
                "earlier (formulation.update_strain), raise the stabilisation or refine the particles")
            error.agreed = getattr(exc, "agreed", False)
            raise error from None
