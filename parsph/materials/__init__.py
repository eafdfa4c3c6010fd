"""Material laws: what a scene's `material.model` names, the constants each takes, the
per-point state it carries (registered fields, parsph.fields) and the id of its compiled
update (materials.update), which the formulations call without knowing which law it is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parsph.fields import Field, register
from parsph.materials import damage, elastoplastic, update


@dataclass(frozen=True)
class Law:
    name: str
    law_id: int  # the compiled update's id (materials.update)
    takes: tuple  # the material keys it needs (the others of LAW_KEYS are refused)
    state: str | None = None  # the registered "state" field of its per-point state, if any
    optional: tuple = ()  # keys it also takes, 0 if not given
    doc: str = ""


LAW_KEYS = ("youngs_modulus", "poisson_ratio", "shear_modulus", "bulk_modulus", "c1", "c2", "lambda", "tait_b",
            "tait_gamma", "yield_stress", "hardening_modulus")
LAWS = {law.name: law for law in (
    Law("saint_venant_kirchhoff", 0, ("youngs_modulus", "poisson_ratio"), doc="[G eq. 19]"),
    Law("neo_hookean", 1, ("youngs_modulus", "poisson_ratio"), doc="[G eq. 44]"),
    Law("neo_hookean_nearly_incompressible", 2, ("shear_modulus", "bulk_modulus"), doc="[V §2.4.1]"),
    Law("mooney_rivlin", 3, ("c1", "c2", "lambda"), doc="[R eq. 18]"),
    Law("tait_fluid", 4, ("tait_b", "tait_gamma"), doc="[R eq. 77]"),
    Law("j2_plasticity", update.J2_PLASTICITY, ("youngs_modulus", "poisson_ratio", "yield_stress"),
        state="plastic_state", optional=("hardening_modulus",), doc="[G §4.5], [R §9.5]"),
)}
# tensile damage over any solid law (materials.damage), at the particles
register(Field("damage", "state", owner="damage", columns=damage.COLUMNS,
               initial=lambda X, gid: damage.initial_state(len(X)),
               doc="committed damage, largest principal strain, work taken, last P and F"))
# the elasto-plastic state (materials.elastoplastic), wherever the law's stress is evaluated
for _points in ("particles", "stress_points", "gauss_points"):
    register(Field("plastic_state", "state", owner="j2_plasticity", points=_points, columns=elastoplastic.COLUMNS,
                   initial=lambda X, gid: elastoplastic.initial_state(len(X)),
                   doc="committed (C^p)^-1, equivalent plastic strain and plastic work per volume"))


@dataclass(frozen=True)
class Constants:
    """A law's constants as its compiled update reads them, and its small-strain moduli,
    which the formulation and the time step need."""

    values: np.ndarray  # (lam, mu, bulk); (lambda, c1, c2) for Mooney-Rivlin; (B, gamma, 0) for Tait;
    #                     (lam, mu, bulk, yield stress, hardening modulus) for J2 plasticity
    lam: float  # small-strain Lame constants and bulk modulus
    mu: float
    bulk: float
    youngs: float  # Young's modulus (hourglass forces)
    wave_speed: float  # reference P-wave speed sqrt((lam + 2 mu) / rho)


def constants(material: dict) -> Constants:
    """The constants of a resolved `material` table."""
    rho, model = material["density"], material["model"]
    if model in ("saint_venant_kirchhoff", "neo_hookean", "j2_plasticity"):
        youngs, nu = material["youngs_modulus"], material["poisson_ratio"]
        lam = youngs * nu / ((1 + nu) * (1 - 2 * nu))
        mu = youngs / (2 * (1 + nu))
        k = lam + 2.0 * mu / 3.0
        values = (lam, mu, k)
        if model == "j2_plasticity":
            values += (material["yield_stress"], material.get("hardening_modulus") or 0.0)
    else:
        if model == "mooney_rivlin":  # psi = lambda (ln J)^2 under dilation: K = 2 lambda
            mu, k = material["c1"] + material["c2"], 2.0 * material["lambda"]
            values = (material["lambda"], material["c1"], material["c2"])
        elif model == "tait_fluid":  # dp / d(rho / rho0) = gamma B at rest; no shear stiffness
            mu, k = 0.0, material["tait_gamma"] * material["tait_b"]
            values = (material["tait_b"], material["tait_gamma"], 0.0)
        else:
            mu, k = material["shear_modulus"], material["bulk_modulus"]
            values = (k - 2.0 * mu / 3.0, mu, k)
        lam = k - 2.0 * mu / 3.0
        youngs = 9.0 * k * mu / (3.0 * k + mu)
    return Constants(values=np.array(values), lam=lam, mu=mu, bulk=k, youngs=youngs,
                     wave_speed=math.sqrt((lam + 2 * mu) / rho))
