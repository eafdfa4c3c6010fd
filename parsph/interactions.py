"""The interactions between particles beyond the bodies' kernels, registered once: each kind
is the scene's array of tables that makes it, the function that builds it on a rank's
particles, and the terms it adds to the energy balance (parsph.balance) and the ledger's
running totals (parsph.ledger). The simulation sums their forces in this order after the
bodies' stages (Simulation.compute_forces). A new kind of interaction is one module and one
line of KINDS.

An interaction has `name`, `reads` (the particle fields whose ghost values it needs: the
halo refreshes the stale ones first), `evaluate(x, v, step_limit)` (x, v: the owned
particles' current positions and velocities; it may lower step_limit), after which `force`
(owned particles) is its force, `omega2` its springs' bound on the squared frequency (the
stable step) and, if `dissipative`, `dissipation` the force's non-conservative part, whose
work the ledger books as its `work` total; `checkpoint()` and `restore(totals)` carry what
a restart needs beyond the particles.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from parsph import balance, ties
from parsph.balance import Term
from parsph.contact import Contact


@dataclass(frozen=True)
class Kind:
    """A kind of interaction: its scene key, builder (the adopted state -> the interaction or
    None), the balance terms it adds (first its energy, the interaction's `energy` per owned
    particle; then running totals of the ledger of the same keys), the running totals the
    ledger keeps for it and its history series beyond them (contact's are
    diagnostics.contact_parts)."""

    key: str
    build: Callable  # (scene, state.RankState, ledger.Ledger, topology.Topology) -> the interaction or None
    terms: tuple = ()
    running: tuple = ()
    columns: Callable | None = None  # (it, state, diagnostics.RowReduction) -> () -> its history series


def _contact(scene, state, ledger, topology):
    """parsph.contact's bodies in contact, or None."""
    if not scene.contact:
        return None
    from parsph import config  # config imports the interactions' keys
    return Contact(scene.contact, state.bodies, state.body, state.measure, state.mass, state.gid, state.n_owned,
                   state.dim, config.thickness(scene), state.comm, scene.symmetry, topology)


KINDS = (
    Kind("contact", _contact,
         (Term("contact", "contact_energy", present=lambda sim: sim.interactions.contact is not None),
          Term("contact_work", "contact_work",
               present=lambda sim: sim.interactions.contact is not None and sim.interactions.contact.dissipative)),
         ("contact_work",)),
    Kind("ties", ties.build, ties.TERMS, ties.RUNNING, ties.columns),
)

TERMS = balance.TERMS + tuple(term for kind in KINDS for term in kind.terms)  # every term of the balance
RUNNING = tuple(name for kind in KINDS for name in kind.running)


class Interactions:
    """The scene's interactions on a rank's particles: by kind (`contact`, `ties`: None where
    the scene has none); iterating gives the present ones in KINDS' order, in which their
    forces are summed. `omega2` is their springs' bound on the squared frequency of the owned
    particles (the stable step)."""

    def __init__(self, scene, state, ledger, topology):
        self.by_kind = {kind.key: kind.build(scene, state, ledger, topology) for kind in KINDS}
        self.contact, self.ties = self.by_kind["contact"], self.by_kind["ties"]
        self.present = [i for i in self.by_kind.values() if i is not None]
        self.omega2 = self.present[0].omega2 if len(self.present) == 1 else \
            np.zeros(state.n_owned if self.present else 0)

    def __iter__(self):
        return iter(self.present)

    def add_frequencies(self) -> None:
        """omega2 = the sum of the present interactions' bounds (after their evaluation), for
        more than one."""
        if len(self.present) > 1:
            self.omega2[:] = self.present[0].omega2
            for interaction in self.present[1:]:
                self.omega2 += interaction.omega2

    def energies(self, sim, b) -> dict:
        """Each interaction term's parts on body `b`'s owned particles (parsph.ledger.items):
        the interaction's energy (half of each pair's) for its first term, its running totals
        for the others; [] where the scene does not have it."""
        out = {}
        for kind in KINDS:
            interaction = self.by_kind[kind.key]
            for k, term in enumerate(kind.terms):
                if interaction is None or not term.shown(sim):
                    out[term.key] = []
                elif k == 0:
                    out[term.key] = [sim.ledger.part(b, interaction.energy[b.lo:b.hi])]
                else:
                    out[term.key] = [sim.ledger.totals[term.key][b.index].sums()[0]]
        return out

    def columns(self, state, reduction) -> list:
        """The present interactions' history series (Kind.columns), as functions that give
        them once `reduction` is reduced."""
        return [kind.columns(self.by_kind[kind.key], state, reduction) for kind in KINDS
                if kind.columns and self.by_kind[kind.key] is not None]

    def checkpoint(self) -> dict:
        """What the present interactions keep in a checkpoint's totals (collective)."""
        return {k: v for interaction in self.present for k, v in interaction.checkpoint().items()}
