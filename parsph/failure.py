"""Failure: each body's failure model advanced at the start of a step (materials.FAILURES:
tensile damage grows, a Johnson-Cook index of 1 fails its point), the failed particles,
and for the bodies whose failed particles lose their pairs (material.break_pairs) the
pairs they cut, with the reference data built again without them: cracks open.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsph import conditions
from parsph.kernel_relation import Configuration
from parsph import materials
from parsph.ledger import intact_law_work, start_damage_work
from parsph.materials import damage
from parsph.neighbors import crossing, find_pairs
from parsph.parallel.runtime import collective


class Failure:
    """The bodies' failure models and which local particles have lost their pairs."""

    def __init__(self, bodies: list, dim: int, comm):
        self.bodies, self.dim, self.comm = bodies, dim, comm
        self.breaking = any(b.breaks_pairs for b in bodies)  # some body's failed particles lose their pairs
        self.detached = None  # per local row: failed and without pairs (None if no body breaks pairs)

    def advance(self, sim, dt: float) -> None:
        """Each body's failure model advances from the committed state over the coming step dt
        (materials.FAILURES: tensile damage grows, a Johnson-Cook index of 1 fails its point)."""
        for b in self.bodies:
            if b.failure:
                state = sim.damage_state(b)[0][b.lo:b.hi]
                intact = state[:, damage.DAMAGE] == 0.0
                materials.FAILURES[b.failure].advance(state, b, sim.support[b.lo:b.hi], dt)
                start_damage_work(sim, b, b.lo + np.flatnonzero(intact & (state[:, damage.DAMAGE] > 0.0)))
        self.find_broken(sim)

    def find_broken(self, sim) -> None:
        """Mark the owned particles that have failed (committed damage 1)."""
        for b in sim.bodies:
            if b.failure:
                sim.broken[b.lo:b.hi] = sim.damage_state(b)[0][b.lo:b.hi, damage.DAMAGE] >= 1.0

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

    def crack(self, searched, X: np.ndarray, measure: np.ndarray, gid: np.ndarray, n: int,
               detached) -> np.ndarray | None:
        """The keys of the pairs the failed particles cut (neighbors.crossing), over all ranks:
        each owned failed particle's from its neighbours in the reference X (`searched`:
        neighbors.find_pairs of the owned rows, needed where one has failed) (collective)."""
        if detached is None:
            return None
        failed = np.flatnonzero(detached[:n])
        keys = np.zeros(0, np.int64)
        if len(failed):
            keys = crossing(searched, X, gid, measure ** (1.0 / self.dim), failed)
        return np.unique(np.concatenate(self.comm.allgather(keys)))

    def break_pairs(self, sim) -> None:
        """Particles that have failed since the last call lose their pairs (collective): the
        reference data is built again without them (materials.damage: cracks open), and
        again while it leaves a particle with a singular correction matrix (a particle cut
        off from its body: it fails too). The forces are evaluated on the new pairs; the
        change of F this makes does no work (the particles do not move): an elasto-plastic
        particle keeps its elastic state (its plastic metric takes the change), an elastic
        one's stress changes, and the strain energy it releases counts as damage work (a
        damaged particle's work W is kept; an intact one's release is added to the ledger's
        damage_released), and the hourglass penalty it drops as released (the balance
        stays closed)."""
        n = sim.n_owned
        state, trial = sim.particles.arrays["damage"], sim.particles.arrays["damage_trial"]
        new = self.failed(state[:n], sim.body) & ~self.detached[:n]
        if not sim.comm.allreduce(bool(new.any()), op=MPI.LOR):
            return
        searched = find_pairs(sim.X, sim.support, sim.gid, n)  # in the reference: once for every round
        while True:
            sim.decomp.refresh_all(state)
            detached = self.failed(state, sim.body)
            with collective(sim.comm):
                cut = self.crack(searched, sim.X, sim.measure, sim.gid, n, detached)
                bad = sim.topology.build(Configuration(sim.X, sim.measure, sim.volume, sim.support, sim.gid,
                                                       sim.body, n, sim.decomp.n_rows),
                                         detached=detached, cut=cut, tolerant=True)
            if not sim.comm.allreduce(len(bad)):
                break
            for b in (b for b in self.bodies if b.failure):  # cut off from their bodies: they fail too
                cut_off = bad[(bad >= b.lo) & (bad < b.hi)]
                start_damage_work(sim, b, cut_off[state[cut_off, damage.DAMAGE] == 0.0])
            state[bad, damage.DAMAGE] = trial[bad, damage.DAMAGE] = 1.0
        self.detached = detached  # the stages read their relation's reference data when they run
        sim.exclude_kernel_pairs()
        penalty = sim.hg_psi.copy()
        held = intact_law_work(sim)
        work = state[:, damage.WORK].copy()
        F_old = sim.F[:n].copy()
        sim.compute_forces()
        plastic = [b for b in sim.bodies if b.law.plastic and not b.rigid]
        for b in plastic:  # their elastic state (stress) is kept: the plastic metric takes the change of F
            b.law.plastic.keep_elastic(sim.material_state(b)[0][b.lo:b.hi], F_old[b.lo:b.hi], sim.F[b.lo:b.hi])
        if plastic:
            sim.compute_forces()
        sim.ledger.add("hourglass_released", penalty[:n] - sim.hg_psi[:n])
        sim.ledger.add("damage_released", held - intact_law_work(sim))
        trial[:, damage.WORK] = work
        for points in sim.point_sets():
            points.commit()
        self.find_broken(sim)
        sim.ledger.external = conditions.external_force(sim)
