#!/usr/bin/env python3
"""Write the notched flat tensile specimen of runs/specimen_mesh.toml as a structured
hexahedral mesh (Gmsh 2.2 ASCII, with meshio): 50 mm long along z, 14 mm wide grips (x) for
|z| >= 16 mm, a gauge 8 mm wide for |z| <= 12 mm with cosine shoulders between, and a
U-notch of radius 1.5 mm (1.5 mm deep) on both edges at mid-length (net width 5 mm); 3 mm
thick (y), so that the x-z plane shows the outline. 16 x 100 x 6 elements (width, length,
thickness): the width is divided evenly at every z (0.5 mm cubes in the gauge). Physical
groups (3D): "grip_bottom" (z < -16 mm), "grip_top" (z > 16 mm), "gauge" (the rest).
Coordinates in mm (the scene scales by 1e-3).

  tools/specimen_mesh.py [OUT]   (default runs/parts/specimen.msh)
"""

from __future__ import annotations

import sys
from pathlib import Path

import meshio
import numpy as np

LENGTH, THICKNESS = 50.0, 3.0
GRIP_WIDTH, GAUGE_WIDTH = 14.0, 8.0
GAUGE_END, GRIP_START = 12.0, 16.0  # |y| where the shoulders begin and end
NOTCH_RADIUS = 1.5
CELLS = (16, 100, 6)  # across the width (x), along the length (y), through the thickness (z)
GROUPS = {"grip_bottom": 1, "gauge": 2, "grip_top": 3}
DEFAULT = Path(__file__).resolve().parent.parent / "runs" / "parts" / "specimen.msh"


def width(y: np.ndarray) -> np.ndarray:
    """The specimen's width at the axial positions y (the z coordinate): grip, cosine
    shoulder, gauge, notch."""
    s = np.clip((np.abs(y) - GAUGE_END) / (GRIP_START - GAUGE_END), 0.0, 1.0)
    w = GAUGE_WIDTH + 0.5 * (GRIP_WIDTH - GAUGE_WIDTH) * (1.0 - np.cos(np.pi * s))
    return w - 2.0 * np.sqrt(np.maximum(NOTCH_RADIUS ** 2 - y ** 2, 0.0))


def specimen() -> meshio.Mesh:
    nx, ny, nz = CELLS
    u, y, v = np.meshgrid(np.linspace(-0.5, 0.5, nx + 1), np.linspace(-0.5 * LENGTH, 0.5 * LENGTH, ny + 1),
                          np.linspace(-0.5, 0.5, nz + 1), indexing="ij")
    # (width, length, thickness) turned by a right angle about x: length along z, thickness along -y
    points = np.column_stack([(u * width(y)).ravel(), (-v * THICKNESS).ravel(), y.ravel()])
    node = np.arange(points.shape[0]).reshape(nx + 1, ny + 1, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    hexes = np.column_stack([node[i + a, j + b, k + c] for c in (0, 1) for a, b in ((0, 0), (1, 0), (1, 1), (0, 1))])
    centre = points[hexes, 2].mean(axis=1)
    tag = np.where(centre < -GRIP_START, GROUPS["grip_bottom"],
                   np.where(centre > GRIP_START, GROUPS["grip_top"], GROUPS["gauge"]))
    return meshio.Mesh(np.round(points, 9) + 0.0, [("hexahedron", hexes)],  # + 0.0: no -0.0
                       cell_data={"gmsh:physical": [tag], "gmsh:geometrical": [tag]},
                       field_data={name: np.array([t, 3]) for name, t in GROUPS.items()})


def main(out: str | Path = DEFAULT) -> None:
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    meshio.write(out, specimen(), file_format="gmsh22", binary=False)


if __name__ == "__main__":
    if len(sys.argv) > 2:
        sys.exit(__doc__)
    main(*sys.argv[1:])
