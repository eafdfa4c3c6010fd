"""Particle geometry: part generators (`count` particles, `rows(start, stop)` ->
(positions (n, D), volumes (n,))) and whole-set functions, kernel support radii and
particle group selection."""

from .fill import Fill, fill
from .groups import select
from .lattice import MAX_PARTICLES, Box, box
from .shapes import Cylinder, Disk, PolarRing, Ring, close_pairs, cylinder, disk, ring, shadowed, union
from .smoothing import support_for_neighbours, support_from_spacing
from .voronoi import RandomPatch, random_box, random_patch

__all__ = [
    "MAX_PARTICLES",
    "Box",
    "Cylinder",
    "Disk",
    "Fill",
    "PolarRing",
    "RandomPatch",
    "Ring",
    "box",
    "close_pairs",
    "cylinder",
    "disk",
    "fill",
    "random_box",
    "random_patch",
    "ring",
    "select",
    "shadowed",
    "support_for_neighbours",
    "support_from_spacing",
    "union",
]
