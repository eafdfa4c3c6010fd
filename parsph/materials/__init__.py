"""Material laws: what a scene's `material.model` names, the constants each takes, the
per-point state it carries (registered fields, parsph.fields) and the id of its compiled
update (materials.update), which the formulations call without knowing which law it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Law:
    name: str
    law_id: int  # the compiled update's id (materials.update)
    takes: tuple  # the material keys it needs (the others of ELASTIC_KEYS are refused)
    state: tuple = ()  # names of the registered fields it carries per point
    doc: str = ""


ELASTIC_KEYS = ("youngs_modulus", "poisson_ratio", "shear_modulus", "bulk_modulus")
LAWS = {law.name: law for law in (
    Law("saint_venant_kirchhoff", 0, ("youngs_modulus", "poisson_ratio"), doc="[G eq. 19]"),
    Law("neo_hookean", 1, ("youngs_modulus", "poisson_ratio"), doc="[G eq. 44]"),
    Law("neo_hookean_nearly_incompressible", 2, ("shear_modulus", "bulk_modulus"), doc="[V §2.4.1]"),
)}


@dataclass(frozen=True)
class Constants:
    """A law's constants as its compiled update reads them, and the moduli the formulation
    and the time step need."""

    values: np.ndarray  # (lam, mu, bulk) for the hyperelastic laws
    youngs: float  # Young's modulus (hourglass forces)
    wave_speed: float  # reference P-wave speed sqrt((lam + 2 mu) / rho)

    @property
    def lam(self) -> float:
        return float(self.values[0])

    @property
    def mu(self) -> float:
        return float(self.values[1])

    @property
    def bulk(self) -> float:
        return float(self.values[2])


def constants(material: dict) -> Constants:
    """The constants of a resolved `material` table."""
    rho = material["density"]
    if material["model"] == "neo_hookean_nearly_incompressible":
        mu, k = material["shear_modulus"], material["bulk_modulus"]
        lam = k - 2.0 * mu / 3.0
        youngs = 9.0 * k * mu / (3.0 * k + mu)
    else:
        youngs, nu = material["youngs_modulus"], material["poisson_ratio"]
        lam = youngs * nu / ((1 + nu) * (1 - 2 * nu))
        mu = youngs / (2 * (1 + nu))
        k = lam + 2.0 * mu / 3.0
    return Constants(values=np.array([lam, mu, k]), youngs=youngs,
                     wave_speed=math.sqrt((lam + 2 * mu) / rho))
