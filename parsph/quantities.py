"""Output quantities: what snapshots and probes can show, with shapes, units and how each
is computed from the state, and the units of the history's series, declared once.
Snapshot field validation, probe and history units, snapshot sizes and
`Simulation.quantity` derive from this registry. A module that knows a quantity registers
it (`register`: the material laws their read-outs); every registered field
(parsph.fields) that declares units is a quantity too, under its own name, read directly
from the point set.
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from typing import Callable

import numpy as np

from parsph import fields
from parsph.interactions import TERMS


@dataclass(frozen=True)
class Quantity:
    name: str
    kind: str  # "scalar" | "vector" | "tensor" | "point" | "rank"
    units: str
    probe: bool = True  # probes may reduce it over a group
    doc: str = ""
    compute: Callable | None = None  # (simulation, owned rows sel) -> its values there


def _read(path: str, every: bool = False) -> Callable:
    """Compute with the function MODULE.NAME of parsph (of the owned rows, or with `every`
    of all owned particles, then selected), looked up when called: parsph.readouts
    imports the material laws, which register their quantities here."""
    def compute(sim, sel):
        module, _, name = path.rpartition(".")
        function = getattr(importlib.import_module("parsph." + module), name)
        return function(sim)[sel] if every else function(sim, sel)
    return compute


def _zeros_without_contact(sim, sel):
    return sim.interactions.contact.force[sel] if sim.interactions.contact else np.zeros((len(sel), sim.state.dim))


_BUILT_IN = (
    Quantity("displacement", "vector", "m", compute=lambda sim, sel: sim.state.u[sel]),
    Quantity("velocity", "vector", "m/s", compute=lambda sim, sel: sim.state.v[sel]),
    Quantity("position", "point", "m", compute=lambda sim, sel: sim.state.X[sel] + sim.state.u[sel]),
    Quantity("reaction", "vector", "N", doc="force the constraints exert",
             compute=lambda sim, sel: sim.conditions.reaction(sim.state)[sel]),
    Quantity("force", "vector", "N", doc="internal, hourglass and body force",
             compute=lambda sim, sel: sim.state.force[sel]),
    Quantity("J", "scalar", "1", doc="volume ratio det F", compute=lambda sim, sel: sim.state.J[sel]),
    Quantity("von_mises", "scalar", "Pa", compute=_read("readouts.von_mises")),
    Quantity("disorder", "scalar", "1", doc="hourglass error [G eq. 26]",
             compute=_read("readouts.disorder", every=True)),
    Quantity("spacing_ratio", "scalar", "1", doc="nearest current neighbour against the smooth spacing",
             compute=_read("readouts.spacing_ratio", every=True)),
    Quantity("rank", "rank", "1", probe=False, doc="owner rank",
             compute=lambda sim, sel: np.full(len(sel), sim.comm.rank, np.int32)),
    Quantity("reference_position", "point", "m", probe=False, compute=lambda sim, sel: sim.state.X[sel]),
    Quantity("cauchy_stress", "tensor", "Pa", probe=False, compute=_read("readouts.cauchy_stress")),
    Quantity("contact_force", "vector", "N", doc="force from other bodies' particles (parsph.contact)",
             compute=_zeros_without_contact),
    Quantity("body", "scalar", "1", probe=False, doc="index of the particle's body, in the scene's order",
             compute=lambda sim, sel: sim.state.body[sel].astype(float)),
    Quantity("deformation_gradient", "tensor", "1", probe=False, doc="F, from the initial configuration",
             compute=lambda sim, sel: sim.state.F[sel]),
    Quantity("mass", "scalar", "kg", compute=lambda sim, sel: sim.state.mass[sel]),
    Quantity("volume", "scalar", "m^3", doc="reference volume V^0", compute=lambda sim, sel: sim.state.volume[sel]),
)
BUILT_IN = {q.name: q for q in _BUILT_IN}


def register(*quantities: Quantity) -> None:
    """Declare quantities computed by the module that knows them."""
    for q in quantities:
        if q.name in BUILT_IN and BUILT_IN[q.name] != q:
            raise ValueError(f"quantity '{q.name}' is declared twice, differently")
        BUILT_IN[q.name] = q


def registry() -> dict:
    """Every quantity by name: the built-in and registered ones, then the registered fields
    with units."""
    out = dict(BUILT_IN)
    for f in fields.REGISTRY["particles"].values():
        if f.units is not None and f.name not in out:
            out[f.name] = Quantity(f.name, f.kind, f.units, probe=f.kind in ("scalar", "vector"), doc=f.doc)
    return out


def snapshot_names() -> tuple:
    return tuple(registry())


def probe_names() -> tuple:
    return tuple(name for name, q in registry().items() if q.probe)


def units(name: str) -> str:
    return registry()[name].units


def bytes_per_point(name: str, dim: int) -> int:
    """Bytes one point's value takes in a snapshot (positions are padded to 3D)."""
    kind = registry()[name].kind
    return {"rank": 4, "point": 24, "tensor": 8 * dim * dim, "vector": 8 * dim}.get(kind, 8)


# The history's series (diagnostics.history_row, the energies of balance.TERMS): units by
# name, by pattern, and NAME.BODY for a body's energies
HISTORY = {
    "time": "s", "step": "1", "dt": "s", "reference_updates": "1", "kinetic_energy": "J",
    **{term.column: "J" for term in TERMS}, "total_energy": "J", "contact_closest": "1",
    "disorder": "1", "disorder_max": "1", "angular_momentum": "kg m^2/s", "angular_momentum_defect": "kg m^2/s",
    "radius_of_gyration": "m", "energy_error": "1", "momentum_error": "1", "angular_momentum_error": "1",
}
HISTORY_PATTERNS = ((r"momentum_(defect_)?[xyz]", "kg m/s"), (r"angular_momentum_(defect_)?[xyz]", "kg m^2/s"),
                    (r"(wall|tool|surface)[0-9]+_force_[xyz]", "N"),
                    (r"surface[0-9]+_torque_[xyz]", "N m"), (r"contact_force_[xyz]\..*", "N"),
                    (r"tie_force_[xyz]\..*", "N"), (r"ties_broken\..*", "1"),
                    (r"rigid_force_[xyz]\..*", "N"), (r"rigid_torque(_[xyz])?\..*", "N m"))


def is_history_series(name: str) -> bool:
    """Is `name` one of the history's own series (a probe of that name would replace it)?"""
    return bool(history_units(name))


def history_units(name: str) -> str:
    """Units of a history series other than a probe ("" if unknown)."""
    if name in HISTORY:
        return HISTORY[name]
    if name.split(".")[0] in HISTORY:  # a body's energy
        return HISTORY[name.split(".")[0]]
    return next((u for pattern, u in HISTORY_PATTERNS if re.fullmatch(pattern, name)), "")
