#!/usr/bin/env python3
"""Measurements on the scenes from a run's snapshots and history.

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
  tools/measure.py kirsch OUT  the stress concentration at the hole of runs/plate_hole.toml (its
                               parameters W, d, n): at the last snapshot, sigma_yy at the particle
                               nearest the hole's edge (a, 0), and at the edge from Michell's
                               solution around a traction-free hole fitted to the stresses of the
                               particles FIT_BAND spacings from the edge, over the net-section
                               stress, against Roark's K_tn; the far field's sigma_yy against the
                               traction and the kinetic energy left (static state).
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
  tools/measure.py punch_stl OUT_STL OUT_TOOL
                               the punch as a surface file (runs/punch_stl.toml) against the
                               tool (runs/punch.toml): the two forces at the history rows of
                               both, the largest relative difference over the rows where the
                               tool's force exceeds a tenth of its last value, and at the end.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import scipy.sparse as sparse
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from parsph import config
from parsph.bc import Tractions
from parsph.geometry import select
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


FIT_BAND = (1.0, 6.0)  # the edge fit takes the particles this many spacings from the hole's edge
FIT_HARMONICS = 6  # and Michell's terms cos n theta up to this n
FAR_BAND = (3.0, 5.0)  # the far field: the particles this many spacings below the loaded edge


def roark_ktn(ratio: float) -> float:
    """Net-section stress concentration factor of a finite-width plate with a central circular
    hole in tension, d/W = ratio (Roark's Formulas for Stress and Strain, 7th ed., Table 17.1,
    case 1a)."""
    return 3.0 - 3.13 * ratio + 3.66 * ratio ** 2 - 1.53 * ratio ** 3


def heywood_ktn(ratio: float) -> float:
    """Heywood's approximation of the same factor, 2 + (1 - d/W)^3."""
    return 2.0 + (1.0 - ratio) ** 3


def kirsch_polar(rho, theta):
    """Kirsch's (sigma_rr, sigma_tt, sigma_rt) around a hole of radius a in an infinite plate
    under a remote stress 1 along y, at rho = r / a and the angle theta from the x axis."""
    q = rho ** -2.0
    c, s = np.cos(2.0 * theta), np.sin(2.0 * theta)
    return np.array([0.5 * (1 - q) - 0.5 * (1 - 4 * q + 3 * q * q) * c, 0.5 * (1 + q) + 0.5 * (1 + 3 * q * q) * c,
                     0.5 * (1 + 2 * q - 3 * q * q) * s])


def michell_terms(rho, theta, harmonics: int = FIT_HARMONICS) -> list:
    """The stresses (sigma_rr, sigma_tt, sigma_rt), each (3, len(rho)), of Michell's solution
    around a traction-free hole, symmetric about both axes, term by term: the Airy functions
    phi = f(r) cos n theta, n = 0, 2, ..., harmonics (f = r^2, ln r for n = 0; r^(n+2), r^n,
    r^(2-n), r^-n otherwise), combined so that sigma_rr = sigma_rt = 0 at r = a (rho = 1)."""
    terms = [np.array([2 * (1 - rho ** -2.0), 2 * (1 + rho ** -2.0), 0 * rho])]
    for n in range(2, harmonics + 1, 2):
        m = np.array([n + 2, n, 2 - n, -n], dtype=float)
        for c in np.linalg.svd(np.array([m - n * n, m - 1]))[2][2:]:  # free of traction at rho = 1
            power = [ci * rho ** (mi - 2) for ci, mi in zip(c, m)]
            terms.append(np.array([sum(p * (mi - n * n) for p, mi in zip(power, m)) * np.cos(n * theta),
                                   sum(p * mi * (mi - 1) for p, mi in zip(power, m)) * np.cos(n * theta),
                                   sum(p * n * (mi - 1) for p, mi in zip(power, m)) * np.sin(n * theta)]))
    return terms


def edge_fit(rho, theta, polar, harmonics: int = FIT_HARMONICS) -> float:
    """sigma_tt at the hole's edge on the x axis (rho = 1, theta = 0) of the least-squares fit
    of Michell's terms to the stresses `polar` = (sigma_rr, sigma_tt, sigma_rt) at (rho, theta)."""
    A = np.column_stack([t.ravel() for t in michell_terms(rho, theta, harmonics)])
    c = np.linalg.lstsq(A, np.ravel(polar), rcond=None)[0]
    return float(sum(ci * t[1, 0] for ci, t in zip(c, michell_terms(np.ones(1), np.zeros(1), harmonics))))


def kirsch_figures(scene, X: np.ndarray, sigma: np.ndarray, measure: np.ndarray, kinetic: float,
                   strain: float) -> dict:
    """The figures of a run of runs/plate_hole.toml at rest: reference positions X, Cauchy
    stresses sigma and measures (volume / thickness) of the particles, the kinetic and strain
    energy; `scene` resolved (config.Scene)."""
    p = scene.parameters
    W, a, h = p["W"], p["d"] / 2, p["d"] / p["n"]
    thickness = scene.geometry.thickness
    masks = {name: select(spec, X, measure) for name, spec in scene.groups.items()}
    force = np.zeros_like(X)
    Tractions(scene.tractions, masks, X, np.arange(len(X)), measure, thickness, p).add(force, np.inf)
    load = force[:, 1].sum()
    nominal = load / (thickness * (W / 2 - a))
    rho, theta = np.hypot(*X.T) / a, np.arctan2(X[:, 1], X[:, 0])
    radial = np.column_stack([np.cos(theta), np.sin(theta)])
    tangent = np.column_stack([-np.sin(theta), np.cos(theta)])
    polar = np.array([np.einsum("na,nab,nb->n", u, sigma[:, :2, :2], v) for u, v in
                      ((radial, radial), (tangent, tangent), (radial, tangent))]) / nominal

    def fit(band, harmonics=FIT_HARMONICS, field=polar):
        k = (rho >= 1 + band[0] * h / a) & (rho < 1 + band[1] * h / a)
        return edge_fit(rho[k], theta[k], field[:, k], harmonics), int(k.sum())

    nearest = int(np.argmin(np.hypot(X[:, 0] - a, X[:, 1])))
    top = X[:, 1].max() + h / 2
    far = (X[:, 1] > top - FAR_BAND[1] * h) & (X[:, 1] < top - FAR_BAND[0] * h)
    far_mean = np.sum(sigma[far, 1, 1] * measure[far]) / np.sum(measure[far])
    traction = load / (thickness * W / 2)
    ratio = p["d"] / W
    edge, count = fit(FIT_BAND)
    return {
        "ratio": ratio, "load": load, "nominal": nominal, "traction": traction,
        "kinetic_ratio": kinetic / strain,
        "far": far_mean / traction,
        "far_spread": (sigma[far, 1, 1].min() / far_mean, sigma[far, 1, 1].max() / far_mean),
        "nearest": sigma[nearest, 1, 1] / nominal, "nearest_rho": rho[nearest],
        "nearest_theta": np.degrees(theta[nearest]),
        "nearest_kirsch": kirsch_polar(rho[nearest], 0.0)[1] / 3.0,
        "fit": edge, "fit_count": count,
        "fit_on_kirsch": fit(FIT_BAND, field=kirsch_polar(rho, theta))[0] / 3.0 - 1.0,
        "fit_variants": [fit(band, harmonics)[0] for band in ((0.0, 4.0), (1.0, 6.0), (1.0, 10.0), (2.0, 8.0))
                         for harmonics in (4, 6, 8)],
        "ktn": roark_ktn(ratio), "heywood": heywood_ktn(ratio),
    }


def kirsch(out: str) -> None:
    with open(os.path.join(out, "scene.json")) as fh:
        scene = config.validate(json.load(fh))  # a resolved scene resolves to itself
    last = read_snapshots(out)[-1]
    history = read_history(out)
    thickness = scene.geometry.thickness
    dim = scene.scene.dimension
    f = kirsch_figures(scene, last["reference_position"][:, :dim], last["cauchy_stress"], last["volume"] / thickness,
                       history["kinetic_energy"][-1], history["strain_energy"][-1])
    ktn = f["ktn"]
    print(f"plate with a hole, d/W = {f['ratio']:.3g}, spacing d/{scene.parameters['n']:g}, "
          f"t = {last.time:.4g} s")
    print(f"static state: kinetic / strain energy {f['kinetic_ratio']:.2e}")
    print(f"load {f['load']:.6g} N on the quarter: traction {f['traction']:.6g} Pa, net-section stress "
          f"{f['nominal']:.6g} Pa")
    print(f"far field ({FAR_BAND[0]:g} to {FAR_BAND[1]:g} spacings below the loaded edge): mean sigma_yy / "
          f"traction {f['far']:.5f} (particles {f['far_spread'][0]:.4f} to {f['far_spread'][1]:.4f} of the mean)")
    print(f"nearest particle to the edge (r = {f['nearest_rho']:.4f} a, {f['nearest_theta']:.2f} deg): "
          f"sigma_yy / net stress {f['nearest']:.4f} ({100 * (f['nearest'] / ktn - 1):+.2f} % from K_tn; Kirsch's "
          f"sigma_yy at that radius is {f['nearest_kirsch']:.3f} of its edge value)")
    print(f"edge fit (Michell's terms to cos {FIT_HARMONICS} theta, traction-free hole, to the {f['fit_count']} "
          f"particles {FIT_BAND[0]:g} to {FIT_BAND[1]:g} spacings from the edge): K = {f['fit']:.4f} "
          f"({100 * (f['fit'] / ktn - 1):+.2f} % from K_tn); of Kirsch's field at these particles it errs by "
          f"{f['fit_on_kirsch']:+.1e}; other bands and harmonics {min(f['fit_variants']):.4f} to "
          f"{max(f['fit_variants']):.4f}")
    print(f"Roark's K_tn = {ktn:.4f} (Heywood's {f['heywood']:.4f}); gross K_tg = {f['fit'] / (1 - f['ratio']):.4f}"
          f" (Roark's {ktn / (1 - f['ratio']):.4f})")


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


COMMANDS = {"bands": bands, "hoop": hoop, "drained": drained, "kirsch": kirsch, "specimen": specimen,
            "punch_stl": punch_stl}

if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] not in COMMANDS:
        sys.exit(__doc__)
    COMMANDS[sys.argv[1]](*sys.argv[2:])
