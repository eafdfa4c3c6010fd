"""Rigid frictionless walls: planes that particles of a group cannot cross.

A wall is the plane through p(t) = point + velocity t with unit normal n pointing into the
material, optionally limited to a box of current positions (a tool of finite width). After
each drift a particle found behind the plane (gap (x - p) . n < 0) is put back on it and
loses the part of its normal velocity that moves into the wall (relative to the wall): a
perfectly plastic, frictionless contact, as of a rigid tool with prescribed motion
([V §2.4.3]) or a symmetry plane that two colliding bodies press against ([V §2.4.2]).
The impulse the wall gives per step, over the step, is its contact force.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Wall:
    index: np.ndarray  # owned particles that can touch it
    point: np.ndarray
    normal: np.ndarray  # unit, into the material
    velocity: np.ndarray
    lower: np.ndarray | None
    upper: np.ndarray | None


class Walls:
    """The scene's walls acting on this rank's owned particles."""

    def __init__(self, specs: list, masks: dict):
        self.items = []
        for spec in specs:
            normal = np.asarray(spec["normal"], float)
            self.items.append(Wall(
                index=np.flatnonzero(masks[spec["group"]]), point=np.asarray(spec["point"], float),
                normal=normal / np.linalg.norm(normal), velocity=np.asarray(spec["velocity"], float),
                lower=None if spec["lower"] is None else np.asarray(spec["lower"], float),
                upper=None if spec["upper"] is None else np.asarray(spec["upper"], float)))
        self.force = np.zeros((len(self.items), len(specs[0]["point"]) if specs else 0))

    def enforce(self, X: np.ndarray, u: np.ndarray, v: np.ndarray, mass: np.ndarray, t: float,
                dt: float) -> None:
        """Project owned particles behind a wall back onto it; record each wall's force."""
        for k, w in enumerate(self.items):
            self.force[k] = 0.0
            sel = w.index
            x = X[sel] + u[sel]
            gap = (x - (w.point + w.velocity * t)) @ w.normal
            hit = gap < 0.0
            if w.lower is not None:
                hit &= np.all((x >= w.lower) & (x <= w.upper), axis=1)
            if not hit.any():
                continue
            sel = sel[hit]
            u[sel] -= gap[hit, None] * w.normal
            approach = np.minimum((v[sel] - w.velocity) @ w.normal, 0.0)
            v[sel] -= approach[:, None] * w.normal
            self.force[k] = -np.sum(mass[sel] * approach) * w.normal / dt
