"""Material laws, the registry: what a scene's `material.model` names. Each law family's
module declares its laws (materials.law.Law: scene keys, constants, per-point state, the
id of its branch of the compiled update in materials.update); a new law is its module, its
line here and its line in materials.update.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from parsph import quantities
from parsph.fields import Field, register
from parsph.errors import InputError
from parsph.materials import damage, elastic, elastoplastic, johnson_cook, johnson_cook_failure, mie_gruneisen
from parsph.materials.law import Constants, Law

__all__ = ["FAILURES", "FAILURE_KEYS", "LAWS", "LAW_KEYS", "Constants", "Law", "check_failure", "constants",
           "failure_of"]

LAWS = {law.name: law for law in (
    *elastic.LAWS,
    elastoplastic.LAW,
    johnson_cook.LAW,
    mie_gruneisen.LAW,
)}
LAW_KEYS = {k: key for law in LAWS.values() for k, key in law.keys.items()}  # every law's material keys
FAILURES = {model.failure_id: model for model in (  # the failure models over the laws, at the particles
    damage.MODEL,
    johnson_cook_failure.MODEL,
)}
FAILURE_KEYS = {k: key for model in FAILURES.values() for k, key in model.keys.items()}
register(Field("damage", "state", owner="damage", columns=damage.COLUMNS,
               initial=lambda X, gid: damage.initial_state(len(X)),
               doc="committed damage, failure index (largest principal strain, or D of Johnson-Cook's), work "
                   "taken, last P and F"))


def failure_of(material: dict):
    """A resolved material's failure model (FAILURES: the one whose key is given), or None."""
    return next((model for model in FAILURES.values() if material.get(model.key) is not None), None)


def check_failure(path: str, material: dict) -> None:
    """One failure model, whole, over a law it applies to."""
    given = [model.key for model in FAILURES.values() if material.get(model.key) is not None]
    if len(given) > 1:
        raise InputError(f"{path}.{given[0]} and {path}.{given[1]}: give one failure model")
    for model in FAILURES.values():
        extra = [k for k in model.keys if k != model.key and material.get(k) is not None]
        if extra and material.get(model.key) is None:
            raise InputError(f"{path}.{extra[0]} needs {path}.{model.key}, which enables the {model.name} failure "
                             "model")
        if material.get(model.key) is not None and model.check:
            model.check(path, material, LAWS[material["model"]])


def _damage(sim, sel):
    """The committed damage D at the owned particles `sel` (0 without damage)."""
    out = np.zeros(len(sel))
    for b in sim.state.bodies:
        if b.failure:
            rows = np.flatnonzero(sim.state.body[sel] == b.index)
            out[rows] = sim.state.damage_state(b)[0][sel[rows], damage.DAMAGE]
    return out


def _failure_index(sim, sel):
    """The failure model's index at the owned particles `sel`: Johnson-Cook's D, or the
    largest principal strain over failure_strain; 1 is where a point fails or its damage
    grows (0 without a failure model)."""
    out = np.zeros(len(sel))
    for b in sim.state.bodies:
        if b.failure:
            rows = np.flatnonzero(sim.state.body[sel] == b.index)
            out[rows] = FAILURES[b.failure].index(sim.state.damage_state(b)[0][sel[rows]], b)
    return out


def law_readout(sim, sel: np.ndarray, name: str) -> np.ndarray:
    """The material laws' read-out `name` (materials.law.Readout) of their last stress
    evaluation's state at the owned particles `sel` (0 for the laws without it)."""
    out = np.zeros(len(sel))
    for b in sim.state.bodies:
        readout = b.law.readouts.get(name)
        if readout is not None:
            rows = np.flatnonzero(sim.state.body[sel] == b.index)
            out[rows] = readout.compute(b.constants.values, sim.state.material_state(b)[1][sel[rows]])
    return out


# the laws' read-outs (the first law that declares a name gives its units), damage and failure index
quantities.register(
    *{name: quantities.Quantity(name, "scalar", readout.units, doc=readout.doc,
                                compute=lambda sim, sel, name=name: law_readout(sim, sel, name))
      for law in reversed(LAWS.values()) for name, readout in law.readouts.items()}.values(),
    quantities.Quantity("damage", "scalar", "1", doc="damage D (0 without a failure model; 1: failed)",
                        compute=_damage),
    quantities.Quantity("failure_index", "scalar", "1", doc="the failure model's index: >= 1 where a point fails "
                        "(Johnson-Cook) or its damage grows (tensile)", compute=_failure_index))


def constants(material: dict) -> Constants:
    """The constants of a resolved `material` table: its law's, then its failure model's."""
    law = LAWS[material["model"]]
    out = law.constants(material)
    model = failure_of(material)
    if model and model.constants:
        out = dataclasses.replace(out, values=np.concatenate([out.values, model.constants(material, law, out.values)]))
    return out
