"""Initial conditions and kinematic boundary conditions on particle groups.

Boundary conditions constrain chosen components of a group's motion:
  fixed         u = 0, v = 0
  velocity      v(t) = value * min(t / ramp, 1)            (u follows by integration)
  displacement  u(t) = value * s(t / ramp), s(x) = x - sin(2 pi x) / (2 pi) for x < 1, else 1
                (smooth start and stop: zero velocity at both ends of the ramp)
The value is one vector for the group, or each particle's from expressions of its reference
position (`expression`, parsph.expressions). A condition with a `duration` acts for
t < duration and then releases the group, which moves freely after (the rectangular velocity
pulse on a rod's end, [R §9.2]); without one it acts for ever. The components constrained
at t (`BoundaryConditions.mask`) are excluded from the free update; the force the
constraint exerts (the reaction) is minus the sum of the other forces on them. Tractions
are forces per unit area on a group's particles, each taking its share of the surface,
measure^((d-1)/d) (its face on a lattice) times the thickness in 2D [R eq. 61], ramped as
min(t / ramp, 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from parsph import expressions


def values(spec: dict, path: str, X: np.ndarray, gid: np.ndarray, parameters: dict) -> np.ndarray:
    """A condition's value at the particles X (rows): its `value` vector for all of them, or
    its `expression` per component evaluated at each."""
    dim = X.shape[1]
    if spec.expression is None:
        return np.broadcast_to(np.asarray(spec.value, float), (len(X), dim))
    out = np.empty((len(X), dim))
    for k, text in enumerate(spec.expression):
        out[:, k] = expressions.Field(f"{path}.expression[{k}]", text, parameters, dim)(X, gid)
    return out


@dataclass
class Constraint:
    kind: str
    index: np.ndarray  # local particle indices
    components: np.ndarray
    value: np.ndarray  # (particles, d)
    ramp: float
    duration: float = math.inf  # released at t >= duration

    def __post_init__(self):
        # flat (particle, component) pairs of the constrained entries, and their values
        self.rows = np.repeat(self.index, len(self.components))
        self.cols = np.tile(self.components, len(self.index))
        self.value = np.ascontiguousarray(self.value[:, self.components]).ravel()

    def active(self, t: float) -> bool:
        """Whether the constraint holds at t (it is released at t >= duration)."""
        return t < self.duration

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
    """The scene's constraints on this rank's owned particles; `mask` (owned particles, d)
    marks the entries constrained at the time of the last set_velocity / set_displacement
    (at the time t given to the constructor before the first)."""

    def __init__(self, specs: list, masks: dict, X: np.ndarray, gid: np.ndarray, parameters: dict,
                 t: float = 0.0):
        """masks: group name -> bool mask over the owned particles, at reference positions
        X with global ids gid; `mask` starts as the entries constrained at time t."""
        dim = X.shape[1]
        self.items = []
        for i, spec in enumerate(specs):
            index = np.flatnonzero(masks[spec.group])
            comps = np.asarray(spec.components, np.int64)
            value = values(spec, f"bc[{i}]", X[index], gid[index], parameters)
            self.items.append(Constraint(spec.type, index, comps, value, spec.ramp,
                                         math.inf if spec.duration is None else spec.duration))
        self.mask = np.zeros((len(X), dim), bool)
        self._active = None  # the items self.mask marks
        self._activate(t)
        # a prescribed velocity or displacement can change the kinetic energy
        self.moving = any(c.kind != "fixed" for c in self.items)

    def active_items(self, t: float) -> tuple:
        """Indices of the items in force at t."""
        return tuple(i for i, c in enumerate(self.items) if c.active(t))

    def _activate(self, t: float) -> list:
        """The items in force at t, with `mask` set to the entries they constrain."""
        active = self.active_items(t)
        if active != self._active:
            self._active = active
            self.mask[:] = False
            for i in active:
                self.mask[self.items[i].rows, self.items[i].cols] = True
        return [self.items[i] for i in active]

    def set_velocity(self, v: np.ndarray, t: float) -> None:
        for c in self._activate(t):
            v[c.rows, c.cols] = c.velocity(t)

    def set_displacement(self, u: np.ndarray, t: float) -> None:
        for c in self._activate(t):
            d = c.displacement(t)
            if d is not None:
                u[c.rows, c.cols] = d


class Tractions:
    """The scene's surface tractions on this rank's owned particles, as forces."""

    def __init__(self, specs: list, masks: dict, X: np.ndarray, gid: np.ndarray, measure: np.ndarray,
                 thickness: float, parameters: dict):
        dim = X.shape[1]
        share = measure ** ((dim - 1) / dim) * thickness  # each particle's part of the surface
        self.items = []
        for i, spec in enumerate(specs):
            index = np.flatnonzero(masks[spec.group])
            area = share[index, None] if spec.area is None else spec.area
            force = values(spec, f"tractions[{i}]", X[index], gid[index], parameters) * area
            self.items.append((index, force, spec))

    def __bool__(self) -> bool:
        return bool(self.items)

    def add(self, force: np.ndarray, t: float) -> None:
        """Add the traction forces at time t to `force` (owned particles): ramped up over
        `ramp`, zero from `duration` on, times exp(-t / decay)."""
        for index, f, spec in self.items:
            factor = 1.0 if spec.ramp <= 0 else min(t / spec.ramp, 1.0)
            if spec.duration is not None and t >= spec.duration:
                factor = 0.0
            if spec.decay is not None:
                factor *= math.exp(-t / spec.decay)
            force[index] += f * factor


def apply_initial_conditions(specs: list, masks: dict, X, gid, u, v, parameters: dict) -> None:
    """Initial velocities and displacements on groups [scene 'initial']: uniform, a rigid
    rotation, a displacement gradient, or fields given as expressions of the reference
    position (parsph.expressions, over the scene's `parameters`); masks and arrays cover
    the owned particles (global ids `gid`)."""
    for i, spec in enumerate(specs):
        sel = np.flatnonzero(masks[spec.group])
        rel = X[sel] - np.asarray(spec.center)
        if spec.type.endswith("_field"):
            target = v if spec.type == "velocity_field" else u
            target[sel] = values(spec, f"initial[{i}]", X[sel], gid[sel], parameters)
        elif spec.type == "velocity":
            v[sel] = spec.value
        elif spec.type == "angular_velocity":
            omega = np.asarray(spec.omega)
            if X.shape[1] == 2:
                v[sel] += omega[0] * np.stack([-rel[:, 1], rel[:, 0]], axis=1)
            else:
                v[sel] += np.cross(omega, rel)
        else:
            u[sel] += rel @ np.asarray(spec.gradient).T
