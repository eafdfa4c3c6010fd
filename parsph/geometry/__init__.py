"""Particle geometry: generators returning (positions (n, D), volumes (n,)), kernel
support radii and particle group selection."""

from .groups import select
from .lattice import box
from .shapes import cylinder, disk, ring, union
from .smoothing import support_for_neighbours, support_from_spacing
from .voronoi import random_box, random_patch

__all__ = [
    "box",
    "cylinder",
    "disk",
    "random_box",
    "random_patch",
    "ring",
    "select",
    "support_for_neighbours",
    "support_from_spacing",
    "union",
]
