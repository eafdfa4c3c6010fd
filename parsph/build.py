"""Turn a resolved scene into the reference particle set: positions, volumes, masses,
kernel supports, global ids and named groups."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsph import geometry
from parsph.errors import InputError


@dataclass
class Body:
    """Reference configuration of all particles, in global-id order (gid = row index)."""

    X: np.ndarray  # (n, d) reference positions [m]
    measure: np.ndarray  # (n,) d-dimensional volume: length (1D), area (2D), volume (3D)
    volume: np.ndarray  # (n,) physical volume [m^3]: measure x area (1D) or x thickness (2D)
    mass: np.ndarray  # (n,) [kg]
    support: np.ndarray  # (n,) kernel support radius h [m]
    groups: dict  # name -> bool mask (n,)

    @property
    def count(self) -> int:
        return len(self.X)


def _part(part: dict):
    shape = part["shape"]
    args = {k: v for k, v in part.items() if k != "shape"}
    maker = {
        "box": geometry.box, "random_patch": geometry.random_patch, "cylinder": geometry.cylinder,
        "ring": geometry.ring, "disk": geometry.disk,
    }[shape]
    return maker(**args)


def _spacing(parts: list, X: np.ndarray, measure: np.ndarray, dim: int) -> np.ndarray:
    """Particle spacing: the lattice spacing of the part a particle came from, or
    measure^(1/d) for random particle sets (boundary particles of a node lattice keep the
    lattice spacing although their lumped volume is smaller)."""
    lattice = [p["spacing"] for p in parts if "spacing" in p]
    if len(lattice) == len(parts):
        return np.full(len(X), min(lattice))
    return measure ** (1.0 / dim)


def build_body(scene: dict) -> Body:
    """Generate the particles of `scene`; raises InputError for an empty or degenerate set."""
    dim = scene["scene"]["dimension"]
    parts = []
    for i, part in enumerate(scene["geometry"]["parts"]):
        try:
            parts.append(_part(part))
        except ValueError as exc:
            raise InputError(f"geometry.parts[{i}]: {exc}") from None
    try:
        if len(parts) == 1:
            X, measure = parts[0]
        else:
            spacing = min(float(np.min(m)) ** (1.0 / dim) for _, m in parts)
            X, measure = geometry.union(*parts, tol=1e-6 * spacing)
    except ValueError as exc:
        raise InputError(f"geometry.parts: {exc}") from None
    X = np.ascontiguousarray(X, dtype=np.float64).reshape(len(X), dim)
    if len(X) == 0:
        raise InputError("geometry.parts produce zero particles; check the shapes' sizes and spacing")
    factor = {1: scene["geometry"]["area"], 2: scene["geometry"]["thickness"], 3: 1.0}[dim]
    volume = measure * factor
    mass = volume * scene["material"]["density"]
    kernel = scene["kernel"]
    if kernel["neighbours"] > 0:
        if kernel["neighbours"] >= len(X):
            raise InputError(f"kernel.neighbours = {kernel['neighbours']} needs more than {len(X)} particles")
        support = geometry.support_for_neighbours(X, kernel["neighbours"])
    else:
        support = kernel["support"] * _spacing(scene["geometry"]["parts"], X, measure, dim)
    groups = {}
    for name, spec in scene["groups"].items():
        try:
            groups[name] = geometry.select(spec, X, measure)
        except ValueError as exc:
            raise InputError(f"groups.{name}: {exc}") from None
    used = {item["group"] for key in ("bc", "walls", "initial", "probes") for item in scene[key]}
    for name in sorted(used):
        if not groups[name].any():
            raise InputError(f"group '{name}' selects no particles; check groups.{name}")
    return Body(X=X, measure=np.asarray(measure, float), volume=volume, mass=mass,
                support=np.asarray(support, float), groups=groups)
