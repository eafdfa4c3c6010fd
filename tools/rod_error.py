#!/usr/bin/env python3
"""Error of a rod run against d'Alembert's solution, [R eq. 75]: ||v_h - v|| / ||v|| over the
particles at every snapshot, with v the exact velocity (axial; zero across) of a free rod
along x whose initial velocity is the scene's `velocity_field` (runs/rod.toml).

usage: tools/rod_error.py OUT [OUT ...]
"""

from __future__ import annotations

import json
import math
import os
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from parsph.analytic import free_rod_velocity  # noqa: E402
from parsph.config import bodies  # noqa: E402
from parsph.expressions import Field  # noqa: E402

# [R] Table 3: error at 0.0116 ms / 0.0231 ms
PAPER = {"sph": (0.05026, 0.04999), "rlm": (0.01301, 0.01297), "kbm": (0.00813, 0.00842),
         "efg_nodal": (0.008322, 0.008232), "efg_cells": (0.006817, 0.006834)}


def rod_errors(out: str) -> list:
    """[(time, particles, error)] for each snapshot of the run in `out`."""
    with open(os.path.join(out, "scene.json")) as fh:
        scene = json.load(fh)
    [body] = bodies(scene)
    [part] = body["parts"]
    length = part["upper"][0] - part["lower"][0]
    material = body["material"]
    c = math.sqrt(material["youngs_modulus"] / material["density"])
    [initial] = [ic for ic in scene["initial"] if ic["type"] == "velocity_field"]
    dim = scene["scene"]["dimension"]
    v0 = Field("initial.expression[0]", initial["expression"][0], scene["parameters"], dim)
    rows = []
    with h5py.File(os.path.join(out, "snapshots.h5"), "r") as f:
        for name in sorted(k for k in f if k.startswith("step_")):
            g = f[name]
            X = g["position"][:, :dim] - g["displacement"][()]
            t = float(g.attrs["time"])
            exact = np.zeros_like(X)  # and the velocity across is zero
            exact[:, 0] = free_rod_velocity(X[:, 0] - part["lower"][0], t, length, c,
                                            lambda s: v0(np.column_stack([s + part["lower"][0]] + [X[:, 1:]]),
                                                         g["gid"][()]))
            error = np.linalg.norm(g["velocity"][()] - exact) / np.linalg.norm(exact)
            rows.append((t, len(X), float(error)))
    return rows


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for out in sys.argv[1:]:
        with open(os.path.join(out, "scene.json")) as fh:
            form = bodies(json.load(fh))[0]["formulation"]
        method = form["type"] + (f"_{form['integration']}" if form["type"] == "efg" else "")
        paper = PAPER.get(method)
        rows = [row for row in rod_errors(out) if row[0] > 0]
        for k, (t, n, error) in enumerate(rows):
            ref = f"   [R] {paper[k]:.4f}" if paper and k < 2 else ""
            print(f"{out}: {method:9s} t = {t * 1e3:.5f} ms  {n} particles  error {error:.5f}{ref}")


if __name__ == "__main__":
    main()
