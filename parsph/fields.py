"""The field registry: every per-point array is declared once, here or by the formulation or
material that needs it, and everything that moves, stores, mirrors or shows point data
derives from the declarations.

A `Field` says what an array is (its kind: scalar, vector, tensor, point, flags, id, moment
(an axial vector: a scalar in 2D), or state: a material law's `columns` numbers per point,
read at the point only),
whether it travels with its point when ownership changes (`migrate`, which also makes it
part of the ghost copies sent at set-up), whether checkpoints store it (`checkpoint`), and
whether snapshots and probes may show it (`units`, None if not). How a field reflects at a
symmetry plane follows from its kind. Which stage refreshes a field's ghost values is not
declared here: stages declare the fields they read at neighbours (formulations.base), and
the halo refreshes are derived from that.

Fields belong to a point set (`points`): "particles" (mass and degrees of freedom), or a
set of integration points without mass, such as "stress_points". `register` adds a field.
A point set carries every field of that set owned by "all" (the base fields below, and any
other declared so) plus the fields owned by the formulations and material laws the scene's
bodies use (`carried`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KINDS = ("scalar", "vector", "tensor", "point", "flags", "id", "state", "moment")
MOMENT_COMPONENTS = {1: 0, 2: 1, 3: 3}  # of an axial vector (a moment) in 1D, 2D, 3D


@dataclass(frozen=True)
class Field:
    """One per-point array."""

    name: str
    kind: str
    migrate: bool = True  # travels with its point (partition, migration, ghosts at set-up)
    checkpoint: bool = True  # stored in checkpoints (implies migrate)
    units: str | None = None  # snapshots and probes may show it, in these units
    doc: str = ""
    owner: str = "all"  # "all": every point of the set carries it; else the formulation or
    #                    material law that declares it (carried where a body uses it)
    initial: object = None  # optional: (X, gid) -> initial values (else zeros; u, v: conditions)
    points: str = "particles"  # the point set that carries it
    columns: int = 0  # of a "state" field

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"field {self.name}: kind must be one of {KINDS}")
        if self.checkpoint and not self.migrate:
            raise ValueError(f"field {self.name}: a checkpointed field must migrate with its point")

    def shape(self, dim: int) -> tuple:
        """Shape of one point's value ("flags" columns vary; not given here)."""
        if self.kind == "moment":  # an axial vector: none in 1D, out of plane in 2D
            return () if dim == 2 else (MOMENT_COMPONENTS[dim],)
        return {"scalar": (), "id": (), "vector": (dim,), "point": (dim,), "tensor": (dim, dim),
                "state": (self.columns,)}[self.kind]

    def reflect(self, value: np.ndarray, sign: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Values of mirror images: points reflect as positions (sign x + offset), vectors
        and tensors by `sign` per component (tensors on both indices); the rest is copied (a
        material state is only read at its own point: an image never evaluates stress)."""
        if self.kind == "point":
            return sign * value + offset
        if self.kind == "vector":
            return value * sign
        if self.kind == "tensor":
            return value * sign[:, :, None] * sign[:, None, :]
        return value


REGISTRY: dict[str, dict[str, Field]] = {}  # point set -> field name -> Field


def register(*fields: Field) -> None:
    """Declare fields; a name may be declared again in its set only with the same declaration."""
    for field in fields:
        known = REGISTRY.setdefault(field.points, {}).get(field.name)
        if known is not None and known != field:
            raise ValueError(f"field '{field.name}' of the {field.points} is declared twice, differently")
        REGISTRY[field.points][field.name] = field


# The particles: reference configuration, kinematic state, and the data every particle carries.
PARTICLE_FIELDS = (
    Field("gid", "id", doc="global id"),
    Field("X", "point", doc="reference position [m]"),
    Field("measure", "scalar", doc="d-dimensional reference measure (length, area, volume)"),
    Field("volume", "scalar", doc="reference volume V^0 [m^3]"),
    Field("mass", "scalar", doc="mass [kg]"),
    Field("support", "scalar", doc="kernel support radius [m]"),
    Field("groups", "flags", doc="membership of the scene's groups, one column per group"),
    Field("u", "vector", doc="displacement [m]"),
    Field("v", "vector", doc="velocity [m/s]"),
)
register(*PARTICLE_FIELDS)


def carried(owners, points: str = "particles") -> list:
    """Names of the fields the point set `points` carries when the scene uses the
    formulations and laws named in `owners`, in declaration order."""
    return [f.name for f in REGISTRY.get(points, {}).values() if f.owner == "all" or f.owner in owners]


def get(name: str, points: str = "particles") -> Field:
    return REGISTRY[points][name]


def known(name: str, points: str = "particles") -> bool:
    return name in REGISTRY.get(points, {})


def migrating(names, points: str = "particles") -> list:
    """The names among `names` whose fields travel with their points."""
    return [n for n in names if REGISTRY[points][n].migrate]


def checkpointed(names, points: str = "particles") -> list:
    return [n for n in names if REGISTRY[points][n].checkpoint]
