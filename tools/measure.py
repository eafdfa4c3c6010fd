#!/usr/bin/env python3
"""Measurements on [R]'s scenes from a run's snapshots.

  tools/measure.py bands OUT   shear bands (runs/ring_shear_bands.toml): at each snapshot, the
                               particles (not the loaded inner row) whose plastic strain is in
                               the top 15 %, grouped into connected clusters (particles within
                               1.5 lattice spacings); a cluster that spans at least 40 % of the
                               wall is a band, its direction the principal axis of its current
                               positions; prints the number of bands and the mean and spread of
                               their angle to the radius through their centre.
  tools/measure.py hoop OUT    hoop stress (runs/rubber_ring.toml): at each snapshot, the hoop
                               Cauchy stress of the particles of the middle row, its mean and
                               its spread (standard deviation over |mean|) around the ring.
  tools/measure.py drained OUT the funnel (runs/funnel.toml): at each snapshot, the share of
                               the fluid's mass below y = 0, through the opening.
  tools/measure.py punch_stl OUT_STL OUT_TOOL
                               the punch as a surface file (runs/punch_stl.toml) against the
                               tool (runs/punch.toml): the two forces at the history rows of
                               both, the largest relative difference over the rows where the
                               tool's force exceeds a tenth of its last value, and at the end.
"""

from __future__ import annotations

import sys

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from parsph.io import read_history, read_snapshots


def snapshots(out: str):
    for snapshot in read_snapshots(out):
        yield snapshot.time, snapshot.fields


def rows(X: np.ndarray) -> tuple:
    """(row index of each particle by reference radius, the radial spacing)."""
    radius = np.hypot(*X.T)
    radii = np.unique(np.round(radius, 12))
    spacing = radii[1] - radii[0]
    return np.round((radius - radii[0]) / spacing).astype(int), spacing


def bands(out: str) -> None:
    for t, s in snapshots(out):
        x, X, strain = s["position"], s["reference_position"], s["plastic_strain"]
        row, spacing = rows(X)
        wall = row.max() * spacing
        hot = np.flatnonzero((row > 0) & (strain > np.percentile(strain[row > 0], 85)) & (strain > 0))
        pairs = cKDTree(x[hot]).query_pairs(1.5 * spacing, output_type="ndarray")
        graph = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(hot),) * 2)
        _, label = connected_components(graph, directed=False)
        angles = []
        for c in np.unique(label):
            members = hot[label == c]
            if np.ptp(row[members]) * spacing < 0.4 * wall:
                continue
            p = x[members]
            centre = p.mean(axis=0)
            axis = np.linalg.svd(p - centre)[2][0]
            angles.append(np.degrees(np.arccos(min(1.0, abs(axis @ centre) / np.linalg.norm(centre)))))
        summary = f"{np.mean(angles):5.1f} deg to the radius (spread {np.std(angles):4.1f})" if angles else ""
        print(f"t = {t:.4g} s: {len(angles):3d} bands {summary}")


def hoop(out: str) -> None:
    for t, s in snapshots(out):
        x, X, sigma = s["position"], s["reference_position"], s["cauchy_stress"]
        row, _ = rows(X)
        mid = row == row.max() // 2
        theta = np.arctan2(x[mid, 1], x[mid, 0])
        tangent = np.column_stack([-np.sin(theta), np.cos(theta)])
        value = np.einsum("na,nab,nb->n", tangent, sigma[mid][:, :2, :2], tangent)
        spread = value.std() / abs(value.mean()) if value.mean() else 0.0
        print(f"t = {t:.4g} s: hoop stress at mid-radius {value.mean():.4g} Pa, spread {spread:.2e}")


def drained(out: str) -> None:
    for t, s in snapshots(out):
        below = s["position"][:, 1] < 0.0
        print(f"t = {t:.4g} s: {below.mean():.3f} of the fluid below the opening")


def stroke_difference(a: dict, b: dict) -> tuple:
    """(times, surface force, tool force, largest relative difference where the tool's force
    exceeds a tenth of its last value, relative difference at the last row) of the punch's
    force, surface0_force_y of the history `a` against tool0_force_y of `b`, at the rows of
    `a` (the tool's force interpolated linearly to their times, which differ by the stable
    steps)."""
    times = a["time"][a["time"] <= b["time"][-1]]
    fa, fb = a["surface0_force_y"][: len(times)], np.interp(times, b["time"], b["tool0_force_y"])
    loaded = np.abs(fb) > 0.1 * abs(fb[-1])
    relative = np.divide(np.abs(fa - fb), np.abs(fb), out=np.zeros_like(fb), where=fb != 0.0)
    return times, fa, fb, float(relative[loaded].max()), float(relative[-1])


def punch_stl(surface_out: str, tool_out: str) -> None:
    times, fa, fb, worst, end = stroke_difference(read_history(surface_out), read_history(tool_out))
    print("   t [ms]  surface [N/m]     tool [N/m]   difference")
    for t, x, y in zip(times, fa, fb):
        print(f"{1e3 * t:9.3f}  {x:13.6g}  {y:13.6g}  {abs(x - y) / abs(y) if y else 0.0:11.2e}")
    print(f"{len(times)} rows; largest relative difference where the tool's force exceeds a tenth of its last "
          f"value: {worst:.2e}; at t = {1e3 * times[-1]:.3f} ms: {end:.2e}")


COMMANDS = {"bands": bands, "hoop": hoop, "drained": drained, "punch_stl": punch_stl}

if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] not in COMMANDS:
        sys.exit(__doc__)
    COMMANDS[sys.argv[1]](*sys.argv[2:])
