"""Material laws, the registry: what a scene's `material.model` names. Each law family's
module declares its laws (materials.law.Law: scene keys, constants, per-point state, the
id of its branch of the compiled update in materials.update); a new law is its module, its
line here and its line in materials.update.
"""

from __future__ import annotations

import numpy as np

from parsph import quantities, readouts
from parsph.fields import Field, register
from parsph.materials import damage, elastic, elastoplastic, johnson_cook, mie_gruneisen
from parsph.materials.law import Constants, Law

__all__ = ["LAWS", "LAW_KEYS", "Constants", "Law", "constants"]

LAWS = {law.name: law for law in (
    *elastic.LAWS,
    elastoplastic.LAW,
    johnson_cook.LAW,
    mie_gruneisen.LAW,
)}
LAW_KEYS = {k: key for law in LAWS.values() for k, key in law.keys.items()}  # every law's material keys
# tensile damage over any solid law (materials.damage), at the particles
register(Field("damage", "state", owner="damage", columns=damage.COLUMNS,
               initial=lambda X, gid: damage.initial_state(len(X)),
               doc="committed damage, largest principal strain, work taken, last P and F"))


def _damage(sim, sel):
    """The committed damage D at the owned particles `sel` (0 without damage)."""
    out = np.zeros(len(sel))
    for b in sim.bodies:
        if b.failure_strain is not None:
            rows = np.flatnonzero(sim.body[sel] == b.index)
            out[rows] = sim.damage_state(b)[0][sel[rows], damage.DAMAGE]
    return out


# the laws' read-outs (the first law that declares a name gives its units) and the damage
quantities.register(
    *{name: quantities.Quantity(name, "scalar", readout.units, doc=readout.doc,
                                compute=lambda sim, sel, name=name: readouts.law_readout(sim, sel, name))
      for law in reversed(LAWS.values()) for name, readout in law.readouts.items()}.values(),
    quantities.Quantity("damage", "scalar", "1", doc="tensile damage D (0 without damage)", compute=_damage))


def constants(material: dict) -> Constants:
    """The constants of a resolved `material` table."""
    return LAWS[material["model"]].constants(material)
