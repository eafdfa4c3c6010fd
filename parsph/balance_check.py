"""The run's check of its own balance, after every history row ([balance] keys):

- energy: the drift of the total energy (parsph.balance: every term booked) since the
  first row, over the largest energy the run has held (the largest term of any row so far);
- momentum: the momentum that the forces between particles have changed (parsph.ledger:
  the impulses they leave, which vanish for equal, opposite and collinear pair forces), over
  sqrt(2 M E), the momentum the largest energy would give the whole mass M; components
  normal to a symmetry plane are left out (the plane's reaction is a force between a
  particle and its image);
- angular momentum: the same for the angular impulse, over sqrt(2 M E) times the radius of
  gyration (not checked with symmetry planes).

Each ratio is a history series (energy_error, momentum_error, angular_momentum_error).
Past its tolerance a check warns once, naming the term that changed most since the last
row within tolerance, the step and the time, and the history file keeps the warning; a
strict check stops the run instead (exit 1, after a checkpoint). Every rank sees the same
global row, so every rank decides alike.
"""

from __future__ import annotations

import math

from parsph.interactions import TERMS
from parsph.errors import ParsphError

DEFAULT_ENERGY = 0.05  # balance.energy where the formulations conserve energy
DEFAULT_ENERGY_LOOSE = 0.25  # where one does not (kbm, rlm): their energy swings by a few per cent


class BalanceCheck:
    """The reference values of the checks (the first row's total energy, the largest energy
    and radius of gyration so far, the last row within tolerance, the warnings given) and the
    check of each history row."""

    def __init__(self, settings: dict, dim: int, mass: float, free_axes: list, momentum: bool, energy: bool,
                 restored: dict | None = None):
        """`settings`: the scene's [balance]; `mass`: the total mass; `free_axes`: the axes
        whose momentum is checked (none normal to a symmetry plane); `momentum`, `energy`:
        whether the formulations conserve them (RLM's force row does neither, KBM's is not
        its energy's gradient: their energy is checked at a looser default, their momentum
        not at all if not conserved);
        `restored`: state() of a checkpoint."""
        self.settings, self.dim, self.mass = settings, dim, mass
        given = settings.energy
        self.energy_limit = given if given is not None else (DEFAULT_ENERGY if energy else DEFAULT_ENERGY_LOOSE)
        self.free_axes = free_axes
        self.momentum = momentum
        self.angular = momentum and dim > 1 and len(free_axes) == dim
        restored = restored or {}
        self.first_total = restored.get("first_total")
        self.energy = restored.get("energy", 0.0)  # the largest energy term so far
        self.radius = restored.get("radius", 0.0)  # the largest radius of gyration so far
        self.clean = restored.get("clean")  # the last row within every tolerance
        self.warned = list(restored.get("warned", []))  # the checks that have warned
        self.messages = list(restored.get("messages", []))  # their warnings

    def state(self) -> dict:
        """What a checkpoint keeps (JSON: floats round-trip exactly)."""
        return dict(first_total=self.first_total, energy=self.energy, radius=self.radius, clean=self.clean,
                    warned=self.warned, messages=self.messages)

    def errors(self, row: dict) -> dict:
        """The row's relative errors (energy_error, momentum_error, angular_momentum_error),
        updating the scales with the row."""
        if self.first_total is None:
            self.first_total = row["total_energy"]
        columns = ["kinetic_energy"] + [t.column for t in TERMS if t.column in row]
        self.energy = max([self.energy] + [abs(row[c]) for c in columns])
        self.radius = max(self.radius, row["radius_of_gyration"])
        p_scale = math.sqrt(2.0 * self.mass * self.energy)
        out = {"energy_error": (row["total_energy"] - self.first_total) / self.energy if self.energy > 0 else 0.0}
        if self.momentum:
            defect = math.sqrt(sum(row[f"momentum_defect_{'xyz'[a]}"] ** 2 for a in self.free_axes))
            out["momentum_error"] = defect / p_scale if p_scale > 0 else 0.0
        if self.angular:
            names = ["angular_momentum_defect"] if self.dim == 2 else [f"angular_momentum_defect_{a}" for a in "xyz"]
            defect = math.sqrt(sum(row[name] ** 2 for name in names))
            scale = p_scale * self.radius
            out["angular_momentum_error"] = defect / scale if scale > 0 else 0.0
        return out

    def check(self, row: dict) -> list:
        """The row's errors added to it; returns the warnings it gives (each check warns
        once), or raises ParsphError for a strict check."""
        errors = self.errors(row)
        row.update(errors)
        limits = {"energy_error": self.energy_limit, "momentum_error": self.settings.momentum,
                  "angular_momentum_error": self.settings.momentum}
        tripped = [name for name, value in errors.items() if limits[name] > 0 and abs(value) > limits[name]]
        if not tripped:
            self.clean = {k: row[k] for k in self._tracked(row)}
            return []
        out = []
        for name in tripped:
            if name in self.warned and not self.settings.strict:
                continue
            self.warned.append(name)
            out.append(self._message(name, errors[name], limits[name], row))
        self.messages.extend(out)
        if self.settings.strict and out:
            error = ParsphError(f"{out[0]}; the run is stopped (balance.strict)")
            error.agreed = True  # the same global row on every rank
            raise error
        return out

    def _tracked(self, row: dict) -> list:
        energy = ["time", "step", "kinetic_energy"] + [t.column for t in TERMS if t.column in row]
        defects = [k for k in row if k.startswith(("momentum_defect", "angular_momentum_defect"))]
        return energy + defects

    def _message(self, name: str, value: float, limit: float, row: dict) -> str:
        """The warning for check `name`: how far it is off, since when, and the term that
        changed most since the last row within tolerance."""
        where = f"at step {int(row['step'])}, t = {row['time']:.6g} s"
        since = self.clean or {}
        since_at = (f" since step {int(since['step'])} (t = {since['time']:.6g} s)" if since else "")
        if name == "energy_error":
            columns = ["kinetic_energy"] + [t.column for t in TERMS if t.column in row]
            changes = {c: row[c] - since.get(c, 0.0) for c in columns}
            term = max(changes, key=lambda c: abs(changes[c]))
            drift = row["total_energy"] - self.first_total
            return (f"the energy balance is off by {100 * value:+.3g} % of the largest energy ({drift:+.4g} J of "
                    f"{self.energy:.4g} J; balance.energy = {limit:g}) {where}: {term} changed by "
                    f"{changes[term]:+.4g} J{since_at}, more than any other term; an energy that grows is a "
                    "sign of an unstable or unresolved run (a smaller time.cfl, a finer spacing)")
        prefix = "momentum_defect" if name == "momentum_error" else "angular_momentum_defect"
        parts = {k: row[k] - since.get(k, 0.0) for k in row if k.startswith(prefix)}
        comp = max(parts, key=lambda k: abs(parts[k]))
        what = "momentum" if name == "momentum_error" else "angular momentum"
        units = "N s" if name == "momentum_error" else "N m s"
        return (f"the {what} is off by {100 * value:.3g} % of its scale (balance.momentum = {limit:g}) {where}: "
                f"the forces between particles changed it by {parts[comp]:+.4g} {units} in {comp}{since_at}, "
                "which no external force explains")
