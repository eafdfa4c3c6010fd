"""Failure: each body's failure model advanced at the start of a step (materials.FAILURES:
tensile damage grows, a Johnson-Cook index of 1 fails its point), the failed particles,
and for the bodies whose failed particles lose their pairs (material.break_pairs) the
pairs they cut, with the reference data built again without them: cracks open.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from parsph.kernel_relation import Configuration
from parsph import materials
from parsph.ledger import intact_law_work, start_damage_work
from parsph.materials import damage
from parsph.neighbors import crossing, find_pairs
from parsph.parallel.mirrors import reflected_pairs
from parsph.parallel.runtime import collective


@dataclass
class Broken:
    """What the state held before pairs broke: the hourglass penalty, the intact laws' work,
    the damage work column and the owned particles' F."""

    penalty: np.ndarray
    held: np.ndarray
    work: np.ndarray
    F: np.ndarray


class Failure:
    """The bodies' failure models, which local particles have lost their pairs and which
    pairs cracks have cut (`cut`: from a checkpoint, io.checkpoint)."""

    def __init__(self, bodies: list, dim: int, comm, cut: np.ndarray | None = None):
        self.bodies, self.dim, self.comm = bodies, dim, comm
        self.breaking = any(b.breaks_pairs for b in bodies)  # some body's failed particles lose their pairs
        self.detached = None  # per local row: failed and without pairs (None if no body breaks pairs)
        self.cut = cut  # the pair_keys of the pairs cracks have cut (crack), on every rank; None: not known

    def advance(self, state, dt: float) -> None:
        """Each body's failure model advances from the committed state over the coming step dt
        (materials.FAILURES: tensile damage grows, a Johnson-Cook index of 1 fails its point)."""
        for b in self.bodies:
            if b.failure:
                held = state.damage_state(b)[0][b.lo:b.hi]
                intact = held[:, damage.DAMAGE] == 0.0
                materials.FAILURES[b.failure].advance(held, b, state.support[b.lo:b.hi], dt)
                start_damage_work(state, b, b.lo + np.flatnonzero(intact & (held[:, damage.DAMAGE] > 0.0)))
        self.find_broken(state)

    def find_broken(self, state) -> None:
        """Mark the owned particles that have failed (committed damage 1)."""
        for b in state.bodies:
            if b.failure:
                state.broken[b.lo:b.hi] = state.damage_state(b)[0][b.lo:b.hi, damage.DAMAGE] >= 1.0

    def failed(self, state: np.ndarray | None, body: np.ndarray) -> np.ndarray | None:
        """Which local particles of bodies whose failed particles lose their pairs have
        failed (damage 1 in the damage `state` of every local row; none without one), or
        None if no body's do."""
        if not self.breaking:
            return None
        if state is None:
            return np.zeros(len(body), bool)
        breaking = np.array([b.breaks_pairs for b in self.bodies])
        return breaking[body[: len(state)]] & (state[:, damage.DAMAGE] >= 1.0)

    def crack(self, searched, X: np.ndarray, measure: np.ndarray, gid: np.ndarray, n: int, fresh: np.ndarray,
              planes: int = 0, total: int = 0) -> np.ndarray:
        """The keys of the pairs cut so far (remembered by global ids, on every rank: a cut
        pair stays cut through reference updates, migration and searches) with those the
        crack through each owned particle of `fresh` cuts (neighbors.crossing; `searched`:
        neighbors.find_pairs of the owned rows, needed where one is fresh), and with
        `planes` symmetry planes their mirror images' (mirrors.reflected_pairs: `total`
        particles) (collective). The crossing test runs in the configuration the pairs are
        built in: X of a total-Lagrangian body, the current updated reference X^r of an
        updated or Eulerian one (the crack goes through a particle where it is when it
        fails; a detached particle that has since moved cuts nothing more)."""
        rows = np.flatnonzero(fresh[:n])
        keys = np.zeros(0, np.int64)
        if len(rows):
            keys = crossing(searched, X, gid, measure ** (1.0 / self.dim), rows)
        known = [] if self.cut is None else [self.cut]
        self.cut = np.unique(np.concatenate(known + self.comm.allgather(keys)))
        if planes:
            self.cut = reflected_pairs(self.cut, total, planes)
        return self.cut

    def known_cut(self, X: np.ndarray, measure: np.ndarray, support: np.ndarray, gid: np.ndarray, n: int,
                  detached, planes: int, total: int) -> np.ndarray | None:
        """The pairs cut at a set-up or a search (collective): those remembered (crack) or
        restored from a checkpoint, else (a first set-up) those the detached particles cut
        in the reference `X` the pairs are built in."""
        if detached is None:
            return None
        if self.cut is not None:
            return self.cut
        searched = find_pairs(X, support, gid, n) if detached[:n].any() else None
        return self.crack(searched, X, measure, gid, n, detached, planes, total)

    @staticmethod
    def refresh(decomp, held: np.ndarray) -> None:
        """The damage state `held` of the ghosts of both layers and of the mirror images
        (decomp: the halo plan) (collective)."""
        decomp.refresh_all(held)
        if decomp.mirrors is not None:
            decomp.mirrors.copy_all(held)

    def break_pairs(self, state, topology, planes: int) -> Broken | None:
        """Particles that have failed since the last call lose their pairs (collective): the
        reference data is built again without them (materials.damage: cracks open), in the
        reference it is built in (X, or X^r when updated; on the kept lists if any), and
        again while it leaves a particle with a singular correction matrix (a particle cut
        off from its body: it fails too). Returns what the state held before (None: no pair
        broke), for keep_elastic and settle once the loop has evaluated the forces on the
        new pairs (`topology`: the kernel relations; `planes`: the symmetry planes)."""
        n = state.n_owned
        held, trial = state.particles.arrays["damage"], state.particles.arrays["damage_trial"]
        new = self.failed(held[:n], state.body) & ~self.detached[:n]
        if not state.comm.allreduce(bool(new.any()), op=MPI.LOR):
            return
        # the configuration the reference data is built in (X, or X^r when updated)
        X, measure, volume = (state.Xr, state.measure_r, state.volume_r) if state.updated else \
            (state.X, state.measure, state.volume)
        searched = find_pairs(X, state.support, state.gid, n)  # in the reference: once for every round
        while True:
            self.refresh(state.decomp, held)
            detached = self.failed(held, state.body)
            with collective(state.comm):
                cut = self.crack(searched, X, measure, state.gid, n, detached[:n] & ~self.detached[:n], planes,
                                 state.decomp.total)
                bad = topology.build(Configuration(X, measure, volume, state.support, state.gid, state.body, n,
                                                   state.decomp.n_rows),
                                     search=False, detached=detached, cut=cut, tolerant=True)
            if not state.comm.allreduce(len(bad)):
                break
            for b in (b for b in self.bodies if b.failure):  # cut off from their bodies: they fail too
                cut_off = bad[(bad >= b.lo) & (bad < b.hi)]
                start_damage_work(state, b, cut_off[held[cut_off, damage.DAMAGE] == 0.0])
            held[bad, damage.DAMAGE] = trial[bad, damage.DAMAGE] = 1.0
        self.detached = detached  # the stages read their relation's reference data when they run
        return Broken(state.hg_psi.copy(), intact_law_work(state), held[:, damage.WORK].copy(), state.F[:n].copy())

    @staticmethod
    def keep_elastic(state, broken: Broken) -> bool:
        """After the forces on the new pairs: an elasto-plastic particle keeps its elastic
        state (stress), its plastic metric taking the change of F; returns whether a body
        did (the forces are then evaluated again)."""
        plastic = [b for b in state.bodies if b.law.plastic and not b.rigid]
        for b in plastic:
            b.law.plastic.keep_elastic(state.material_state(b)[0][b.lo:b.hi], broken.F[b.lo:b.hi], state.F[b.lo:b.hi])
        return bool(plastic)

    def settle(self, state, ledger, broken: Broken) -> None:
        """The change of F the broken pairs made does no work (the particles do not move): an
        elastic particle's released strain energy counts as damage work (a damaged particle's
        work W is kept; an intact one's release is added to the ledger's damage_released),
        the hourglass penalty it drops as released (the balance stays closed) in the
        `ledger`; the state is committed."""
        n = state.n_owned
        ledger.add("hourglass_released", broken.penalty[:n] - state.hg_psi[:n])
        ledger.add("damage_released", broken.held - intact_law_work(state))
        state.particles.arrays["damage_trial"][:, damage.WORK] = broken.work
        for points in state.point_sets():
            points.commit()
        self.find_broken(state)
