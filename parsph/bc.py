"""Initial conditions and kinematic boundary conditions on particle groups.

Boundary conditions constrain chosen components of a group's motion:
  fixed         u = 0, v = 0
  velocity      v(t) = value * min(t / ramp, 1)            (u follows by integration)
  displacement  u(t) = value * s(t / ramp), s(x) = x - sin(2 pi x) / (2 pi) for x < 1, else 1
                (smooth start and stop: zero velocity at both ends of the ramp)
The constrained components are excluded from the free update; the force the constraint
exerts (the reaction) is minus the sum of the other forces on those components.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parsph import expressions


@dataclass
class Constraint:
    kind: str
    index: np.ndarray  # local particle indices
    components: np.ndarray
    value: np.ndarray  # (d,)
    ramp: float

    def __post_init__(self):
        # flat (particle, component) pairs of the constrained entries
        self.rows = np.repeat(self.index, len(self.components))
        self.cols = np.tile(self.components, len(self.index))

    def velocity(self, t: float) -> np.ndarray:
        if self.kind == "fixed":
            return np.zeros_like(self.value)
        if self.kind == "velocity":
            return self.value * (1.0 if self.ramp <= 0 else min(t / self.ramp, 1.0))
        if self.ramp <= 0 or t >= self.ramp:
            return np.zeros_like(self.value)
        x = t / self.ramp
        return self.value * (1.0 - math.cos(2 * math.pi * x)) / self.ramp

    def displacement(self, t: float) -> np.ndarray | None:
        """Prescribed displacement at t, or None when u follows from the velocity."""
        if self.kind == "fixed":
            return np.zeros_like(self.value)
        if self.kind == "velocity":
            return None
        if self.ramp <= 0 or t >= self.ramp:
            return self.value
        x = t / self.ramp
        return self.value * (x - math.sin(2 * math.pi * x) / (2 * math.pi))


class BoundaryConditions:
    """The scene's constraints on this rank's owned particles."""

    def __init__(self, specs: list, masks: dict, dim: int):
        """masks: group name -> bool mask over the owned particles."""
        self.items = []
        self.mask = np.zeros((len(masks["all"]), dim), bool)
        for spec in specs:
            index = np.flatnonzero(masks[spec["group"]])
            comps = np.asarray(spec["components"], np.int64)
            self.items.append(Constraint(spec["type"], index, comps, np.asarray(spec["value"], float),
                                         spec["ramp"]))
            item = self.items[-1]
            self.mask[item.rows, item.cols] = True
        # a prescribed velocity or displacement can change the kinetic energy
        self.moving = any(c.kind != "fixed" for c in self.items)

    def set_velocity(self, v: np.ndarray, t: float) -> None:
        for c in self.items:
            v[c.rows, c.cols] = c.velocity(t)[c.cols]

    def set_displacement(self, u: np.ndarray, t: float) -> None:
        for c in self.items:
            d = c.displacement(t)
            if d is not None:
                u[c.rows, c.cols] = d[c.cols]


def apply_initial_conditions(specs: list, masks: dict, X, gid, u, v, parameters: dict) -> None:
    """Initial velocities and displacements on groups [scene 'initial']: uniform, a rigid
    rotation, a displacement gradient, or fields given as expressions of the reference
    position (parsph.expressions, over the scene's `parameters`); masks and arrays cover
    the owned particles (global ids `gid`)."""
    dim = X.shape[1]
    for i, spec in enumerate(specs):
        sel = np.flatnonzero(masks[spec["group"]])
        rel = X[sel] - np.asarray(spec["center"])
        if spec["type"].endswith("_field"):
            target = v if spec["type"] == "velocity_field" else u
            for k, text in enumerate(spec["expression"]):
                field = expressions.Field(f"initial[{i}].expression[{k}]", text, parameters, dim)
                target[sel, k] = field(X[sel], gid[sel])
        elif spec["type"] == "velocity":
            v[sel] = spec["value"]
        elif spec["type"] == "angular_velocity":
            omega = np.asarray(spec["omega"])
            if X.shape[1] == 2:
                v[sel] += omega[0] * np.stack([-rel[:, 1], rel[:, 0]], axis=1)
            else:
                v[sel] += np.cross(omega, rel)
        else:
            u[sel] += rel @ np.asarray(spec["gradient"]).T
