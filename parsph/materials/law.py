"""What a material law declares to the rest of parsph: its name and scene keys, how its
constants follow from them, its per-point state, what a plastic law's state holds, and the
id of its branch of the compiled update (materials.update). Each law family's module
declares its laws; materials.LAWS lists them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class Constants:
    """A law's constants as its compiled update reads them, and its small-strain moduli,
    which the formulation and the time step need."""

    values: np.ndarray  # the compiled update's constants (the law's own layout)
    lam: float  # small-strain Lame constants and bulk modulus
    mu: float
    bulk: float
    youngs: float  # Young's modulus (hourglass forces)
    wave_speed: float  # reference P-wave speed sqrt((lam + 2 mu) / rho)


def moduli(values, mu: float, bulk: float, density: float) -> Constants:
    """Constants with the given update constants from the small-strain shear and bulk moduli."""
    lam = bulk - 2.0 * mu / 3.0
    youngs = 9.0 * bulk * mu / (3.0 * bulk + mu)
    return Constants(values=np.array(values), lam=lam, mu=mu, bulk=bulk, youngs=youngs,
                     wave_speed=math.sqrt((lam + 2 * mu) / density))


@dataclass(frozen=True)
class Plastic:
    """What the loop, the read-outs and the hourglass force read of a plastic law's state."""

    strain: int  # the state's column of the equivalent plastic strain
    work: int  # the state's column of the plastic work per unit reference volume
    heat: int  # the state's column of the heat of other dissipation per unit reference volume
    yield_stress: Callable  # (constants values, state rows) -> current yield stress per row
    keep_elastic: Callable  # (state rows, F_old, F_new): the elastic state kept when F jumps (in place)
    # (constants values) -> (reference strain rate, homologous temperature T* per unit plastic work and per
    # unit heat) of the failure models (materials.johnson_cook_failure); None: 1/s and no heating
    failure_terms: Callable | None = None


@dataclass(frozen=True)
class Readout:
    """A scalar a law computes from its per-point state, for snapshots and probes."""

    units: str
    doc: str
    compute: Callable  # (constants values, state rows) -> values


@dataclass(frozen=True)
class Law:
    """A material law: `material.model = name`, the scene keys it takes (`keys`: their Key
    declarations; `optional` ones may be left out), its constants, its registered per-point
    state field (if any) and its branch of the compiled update (`law_id`)."""

    name: str
    law_id: int
    keys: dict  # {key: Key} of the material table it takes
    constants: Callable  # (resolved material table) -> Constants
    optional: tuple = ()
    state: str | None = None
    plastic: Plastic | None = None
    fluid: bool = False  # no shear strength: no tensile damage
    check: Callable | None = None  # (path, material table) -> None: raises InputError
    readouts: dict = field(default_factory=dict)  # {quantity name: Readout}
    doc: str = ""
    takes: tuple = field(init=False)  # the keys it requires

    def __post_init__(self):
        object.__setattr__(self, "takes", tuple(k for k in self.keys if k not in self.optional))


@dataclass(frozen=True)
class FailureModel:
    """A failure model over the laws: damage at the particles (materials.damage's state row),
    enabled by its first key, with the id of its branch of the compiled stress update
    (formulations.tlsph.stress_at)."""

    name: str
    failure_id: int
    keys: dict  # {key: Key} of the material table it takes; the first enables it
    advance: Callable  # (committed state rows, body, support rows, dt): failure at the step's start, in place
    stresses: Callable  # (P, F, dim, committed state rows): the stress the model leaves of the law's, in place
    index: Callable  # (committed state rows, body) -> its failure index per row (1: failing)
    check: Callable | None = None  # (path, material table, its law) -> None: raises InputError
    constants: Callable | None = None  # (material table, its law, the law's values) -> values appended to them

    @property
    def key(self) -> str:
        """The material key that enables it."""
        return next(iter(self.keys))
