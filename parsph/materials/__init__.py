"""Material laws, the registry: what a scene's `material.model` names. Each law family's
module declares its laws (materials.law.Law: scene keys, constants, per-point state, the
id of its branch of the compiled update in materials.update); a new law is its module, its
line here and its line in materials.update.
"""

from __future__ import annotations

from parsph.fields import Field, register
from parsph.materials import damage, elastic, elastoplastic, johnson_cook
from parsph.materials.law import Constants, Law

__all__ = ["LAWS", "LAW_KEYS", "Constants", "Law", "constants"]

LAWS = {law.name: law for law in (
    *elastic.LAWS,
    elastoplastic.LAW,
    johnson_cook.LAW,
)}
LAW_KEYS = {k: key for law in LAWS.values() for k, key in law.keys.items()}  # every law's material keys
# tensile damage over any solid law (materials.damage), at the particles
register(Field("damage", "state", owner="damage", columns=damage.COLUMNS,
               initial=lambda X, gid: damage.initial_state(len(X)),
               doc="committed damage, largest principal strain, work taken, last P and F"))


def constants(material: dict) -> Constants:
    """The constants of a resolved `material` table."""
    return LAWS[material["model"]].constants(material)
