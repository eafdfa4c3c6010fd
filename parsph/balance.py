"""The terms of the energy balance, declared once: each term's key (what the ledger sums
for it: parsph.ledger), its history column (J), its sign in the total energy and whether a
scene has it. The balance: kinetic + strain + plastic + damage + viscous + hourglass +
contact + contact work + damping work - external work is constant.
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
    Term("contact", "contact_energy", present=lambda sim: sim.contact is not None),
    Term("contact_work", "contact_work", present=lambda sim: sim.contact is not None and sim.contact.dissipative),
    Term("damping", "damping_work", present=lambda sim: sim.damping > 0),
)
