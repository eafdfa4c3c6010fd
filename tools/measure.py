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
  tools/measure.py specimen OUT a specimen from a mesh pulled by its grips to failure
                               (runs/specimen_mesh.toml: the mesh sets grip_top, grip_bottom,
                               pulled apart along the axis that joins their centres; probes
                               top and bottom, the grips' displacements along it, and
                               max_damage): the first failure (history: time, elongation
                               top - bottom in mm and in per cent of the grips' distance; the
                               failed particles' reference box at the next snapshot), and the
                               through-crack: the first snapshot where no chain of intact
                               elements sharing faces joins the grips (time, elongation, the
                               failed elements' axial reference position: median, quartiles).
"""

from __future__ import annotations

import sys

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from parsph.geometry.mesh_parts import MeshPart
from parsph.io import read_history, read_snapshots
from parsph.io.output_dir import held_scene


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


def face_graph(part: MeshPart) -> sparse.csr_matrix:
    """Adjacency of the part's particles (elements, in its order) that share a face (at
    least as many nodes as the dimension)."""
    rows, cols = [], []
    for b, start, _ in part.blocks:
        data = np.asarray(part.mesh.cells[b].data)
        rows.append(np.repeat(np.arange(start, start + len(data)), data.shape[1]))
        cols.append(data.ravel())
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    incidence = sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(part.total, len(part.mesh.points)))
    shared = (incidence @ incidence.T).tocsr()[part.selected][:, part.selected]
    shared.data = (shared.data >= part.dim).astype(np.float64)
    shared.setdiag(0.0)
    shared.eliminate_zeros()
    return shared


def specimen(out: str) -> None:
    scene = held_scene(out)
    mesh = scene["geometry"]["parts"][0]
    part = MeshPart(mesh["file"], mesh["scale"], mesh["translate"], mesh["cells"], scene["scene"]["dimension"])
    top, bottom = part.set_mask("grip_top"), part.set_mask("grip_bottom")
    axis = int(np.argmax(np.abs(part.centroid[top].mean(axis=0) - part.centroid[bottom].mean(axis=0))))
    corners = np.concatenate([c for _, _, c in part.blocks])[part.selected]
    gap = part.points[corners[top], axis].min() - part.points[corners[bottom], axis].max()
    h = read_history(out)
    elongation = h["top"] - h["bottom"]

    def at(t):
        e = float(np.interp(t, h["time"], elongation))
        return f"elongation {1e3 * e:.3f} mm ({100 * e / gap:.2f} % of the {1e3 * gap:.1f} mm between the grips)"

    peak = h["time"][np.argmax(h["force"])]
    print(f"peak force {h['force'].max():.4g} N at t = {peak:.4g} s, {at(peak)}")
    failed_rows = np.flatnonzero(h["max_damage"] >= 1.0)
    if not failed_rows.size:
        print("no particle fails")
        return
    t_first = h["time"][failed_rows[0]]
    print(f"first failure at t = {t_first:.4g} s, {at(t_first)}")
    graph = face_graph(part)
    reported = False
    for t, s in snapshots(out):
        order = np.argsort(s["gid"])
        failed = s["damage"][order] >= 1.0
        if not failed.any():
            continue
        X = 1e3 * (s["position"] - s["displacement"])[order]
        if not reported:
            box = ", ".join(f"{'xyz'[k]} {X[failed, k].min():.2f} to {X[failed, k].max():.2f}"
                            for k in range(X.shape[1]))
            print(f"  failed particles at t = {t:.4g} s: {failed.sum()}, reference {box} mm")
            reported = True
        intact = np.flatnonzero(~failed)
        _, label = connected_components(graph[intact][:, intact], directed=False)
        joined = np.intersect1d(label[top[intact]], label[bottom[intact]])
        if not joined.size:
            q = np.percentile(X[failed, axis], [25, 50, 75])
            print(f"through-crack at t = {t:.4g} s (first snapshot with the grips apart), {at(t)}; "
                  f"{failed.sum()} failed particles, reference {'xyz'[axis]} median {q[1]:.2f} mm (quartiles "
                  f"{q[0]:.2f}, {q[2]:.2f})")
            return
    print("no through-crack by the last snapshot")


COMMANDS = {"bands": bands, "hoop": hoop, "drained": drained, "specimen": specimen}

if __name__ == "__main__":
    if len(sys.argv) != 3 or sys.argv[1] not in COMMANDS:
        sys.exit(__doc__)
    COMMANDS[sys.argv[1]](sys.argv[2])
