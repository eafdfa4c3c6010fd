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
    build: Callable
    terms: tuple = ()
    running: tuple = ()
    columns: Callable | None = None  # (sim, diagnostics.RowReduction) -> () -> its history series


def _contact(sim):
    """parsph.contact's bodies in contact, or None."""
    if not sim.scene.contact:
        return None
    from parsph import config  # config imports the interactions' keys
    contact = Contact(sim.scene.contact, sim.bodies, sim.body, sim.measure, sim.mass, sim.gid, sim.n_owned, sim.dim,
                      config.thickness(sim.scene), sim.comm, sim.scene.symmetry)
    return contact


KINDS = (
    Kind("contact", _contact,
         (Term("contact", "contact_energy", present=lambda sim: sim.contact is not None),
          Term("contact_work", "contact_work",
               present=lambda sim: sim.contact is not None and sim.contact.dissipative)),
         ("contact_work",)),
    Kind("ties", ties.build, ties.TERMS, ties.RUNNING, ties.columns),
)

TERMS = balance.TERMS + tuple(term for kind in KINDS for term in kind.terms)  # every term of the balance
RUNNING = tuple(name for kind in KINDS for name in kind.running)


def build(sim) -> dict:
    """The scene's interactions on the adopted state `sim`, by kind (None where the scene has
    none)."""
    return {kind.key: kind.build(sim) for kind in KINDS}


def energies(sim, b) -> dict:
    """Each interaction term's parts on body `b`'s owned particles (parsph.ledger.items): the
    interaction's energy (half of each pair's) for its first term, its running totals for
    the others; [] where the scene does not have it."""
    out = {}
    for kind in KINDS:
        interaction = sim.interaction[kind.key]
        for k, term in enumerate(kind.terms):
            if interaction is None or not term.shown(sim):
                out[term.key] = []
            elif k == 0:
                out[term.key] = [sim.ledger.part(b, interaction.energy[b.lo:b.hi])]
            else:
                out[term.key] = [sim.ledger.totals[term.key][b.index].sums()[0]]
    return out


def frequency_bound(present: list, n: int) -> np.ndarray:
    """The array of the owned particles' bound on the squared frequency from the present
    interactions (`present`, in order): the one interaction's own, a sum that
    add_frequencies keeps for several, empty for none."""
    if len(present) == 1:
        return present[0].omega2
    return np.zeros(n if present else 0)


def add_frequencies(present: list, into: np.ndarray) -> None:
    """into = the sum of the present interactions' bounds (after their evaluation), for more
    than one."""
    if len(present) > 1:
        into[:] = present[0].omega2
        for interaction in present[1:]:
            into += interaction.omega2


def columns(sim, reduction) -> list:
    """The present interactions' history series (Kind.columns), as functions that give them
    once `reduction` is reduced."""
    return [kind.columns(sim, reduction) for kind in KINDS if kind.columns and sim.interaction[kind.key] is not None]


def checkpoint(present: list) -> dict:
    """What the present interactions keep in a checkpoint's totals (collective)."""
    return {k: v for interaction in present for k, v in interaction.checkpoint().items()}
