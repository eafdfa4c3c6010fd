"""The terms of the energy balance, declared once: each term's key (what the ledger sums
for it: parsph.ledger), its history column (J), its sign in the total energy and whether a
scene has it. The balance: kinetic + strain + plastic + damage + viscous + hourglass +
damping work - external work + the interactions' terms (parsph.interactions: contact,
contact work, tie energy, released and work) is constant.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


@dataclass(frozen=True)
class Term:
    """A term of the balance: its key in ledger.Ledger.items, its history column, its sign in the
    total energy and whether the scene has it (a predicate of the simulation)."""

    key: str
    column: str
    sign: float = 1.0
    present: Callable | None = None

    def shown(self, sim) -> bool:
        return self.present is None or self.present(sim)


TERMS = (
    Term("strain", "strain_energy"),
    Term("plastic", "plastic_work"),
    Term("damage", "damage_work"),
    Term("viscous", "viscous_work"),
    Term("hourglass", "hourglass_energy"),
    Term("external", "external_work", -1.0),
    Term("damping", "damping_work", present=lambda sim: sim.conditions.damping > 0),
)
