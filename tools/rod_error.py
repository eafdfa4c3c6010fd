#!/usr/bin/env python3
"""Error of a rod run against the exact solution, [R eq. 75]: ||v_h - v|| / ||v|| over the
particles at every snapshot after t = 0, with v the exact velocity (axial; zero across) of
the run's rod, told from its resolved scene:
  runs/rod.toml        free rod whose initial velocity is the scene's `velocity_field`
                       (d'Alembert), beside [R] Table 3;
  runs/rod_pulse.toml  rod at rest driven at its left end by a velocity [[bc]] with a
                       `duration` (the rectangular pulse; [R] gives only its figures 8-9).
--plot: also draw v_x along the rod's mid-line (the row of particles nearest it) against the
exact velocity, a panel per snapshot, into OUT/rod_velocity.png.

usage: tools/rod_error.py [--plot] OUT [OUT ...]
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

from parsph.analytic import driven_rod_velocity, free_rod_velocity
from parsph import config
from parsph.expressions import Field
from parsph.io import read_snapshots

# [R] Table 3 (the Gaussian): error at 0.0116 ms / 0.0231 ms
PAPER = {"sph": (0.05026, 0.04999), "rlm": (0.01301, 0.01297), "kbm": (0.00813, 0.00842),
         "efg_nodal": (0.008322, 0.008232), "efg_cells": (0.006817, 0.006834)}


def exact_axial(scene: config.Scene):
    """(axial velocity function (X, gid, t) -> (n,), whether the case is the Gaussian)."""
    [body] = scene.bodies
    [part] = body.parts
    lower, upper = part["lower"][0], part["upper"][0]
    material = body.material
    c = math.sqrt(material.youngs_modulus / material.density)
    fields = [ic for ic in scene.initial if ic.type == "velocity_field"]
    if fields:
        v0 = Field("initial.expression[0]", fields[0].expression[0], scene.parameters, scene.scene.dimension)

        def gaussian(X, gid, t):
            return free_rod_velocity(X[:, 0] - lower, t, upper - lower, c,
                                     lambda s: v0(np.column_stack([s + lower, X[:, 1:]]), gid))
        return gaussian, True
    [drive] = [bc for bc in scene.bc if bc.type == "velocity" and bc.duration is not None]

    def pulse(X, gid, t):
        x0 = X[:, 0].min()  # the driven column of particles, where the pulse starts
        return driven_rod_velocity(X[:, 0] - x0, t, upper - x0, c, drive.value[0], drive.duration)
    return pulse, False


def snapshots(out: str) -> list:
    """[(time, reference positions, computed velocity, exact velocity)] for each snapshot of
    the run in `out` after t = 0."""
    with open(os.path.join(out, "scene.json")) as fh:
        scene = config.validate(json.load(fh))  # a resolved scene resolves to itself
    axial, _ = exact_axial(scene)
    dim = scene.scene.dimension
    rows = []
    for snapshot in read_snapshots(out, ("position", "displacement", "gid", "velocity")):
        if snapshot.time > 0:
            X = snapshot["position"][:, :dim] - snapshot["displacement"]
            exact = np.zeros_like(X)  # and the velocity across is zero
            exact[:, 0] = axial(X, snapshot["gid"], snapshot.time)
            rows.append((snapshot.time, X, snapshot["velocity"], exact))
    return rows


def rod_errors(out: str) -> list:
    """[(time, particles, error)] for each snapshot of the run in `out` after t = 0."""
    return [(t, len(X), float(np.linalg.norm(v - exact) / np.linalg.norm(exact)))
            for t, X, v, exact in snapshots(out)]


def plot(out: str) -> str:
    """v_x of the row of particles nearest the mid-line and the exact one, a panel per
    snapshot, into OUT/rod_velocity.png."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = snapshots(out)
    fig, axes = plt.subplots(len(rows), 1, figsize=(9, 2.6 * len(rows)), sharex=True, squeeze=False)
    for ax, (t, X, v, exact) in zip(axes[:, 0], rows):
        across = np.linalg.norm(X[:, 1:] - 0.5 * (X[:, 1:].min(0) + X[:, 1:].max(0)), axis=1)
        row = np.flatnonzero(np.isclose(X[:, 1:], X[np.argmin(across), 1:]).all(axis=1))
        row = row[np.argsort(X[row, 0])]
        ax.plot(1e3 * X[row, 0], exact[row, 0], "k-", lw=1, label="exact")
        ax.plot(1e3 * X[row, 0], v[row, 0], ".", ms=2.5, label="computed")
        ax.set_title(f"t = {t * 1e3:.5f} ms", fontsize=9)
        ax.set_ylabel("v_x [m/s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("x [mm] (reference)")
    fig.tight_layout()
    path = os.path.join(out, "rod_velocity.png")
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def main():
    args = sys.argv[1:]
    draw = "--plot" in args
    outs = [a for a in args if a != "--plot"]
    if not outs:
        sys.exit(__doc__)
    for out in outs:
        with open(os.path.join(out, "scene.json")) as fh:
            scene = config.validate(json.load(fh))
        form = scene.bodies[0].formulation
        method = form.type + (f"_{form.integration}" if form.type == "efg" else "")
        paper = PAPER.get(method) if exact_axial(scene)[1] else None
        for k, (t, n, error) in enumerate(rod_errors(out)):
            ref = f"   [R] {paper[k]:.4f}" if paper and k < 2 else ""
            print(f"{out}: {method:9s} t = {t * 1e3:.5f} ms  {n} particles  error {error:.5f}{ref}")
        if draw:
            print(f"{out}: plot {plot(out)}")


if __name__ == "__main__":
    main()
