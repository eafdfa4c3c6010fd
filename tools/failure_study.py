#!/usr/bin/env python3
"""The 3D tensile specimen of [G §4.6] (runs/tensile_failure.toml) with (alpha = 50) and
without (alpha = 0) hourglass control, at lattice spacings 1.25 and 0.833 mm. Prints, per
run: particles, peak force, elongation at failure (the pulled end's displacement when the
force has fallen below half its peak), where the crack is (the median and the range of the
reference x of the failed particles, D = 1, at the end; the neck spans |x| < 2.5 mm) and
the energy balance error; draws the failed particles of every run into OUT/tensile_failure.png.

usage: tools/failure_study.py [--ranks N] [--out DIR]
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from launch import ROOT, run_scene

from parsph.io import read_history, read_snapshots

SPEED, RAMP = 10.0, 1.0e-5  # the scene's pull speed and ramp
CASES = (  # label, overrides
    ("1.25 mm, alpha = 50", []),
    ("1.25 mm, alpha = 0", ["formulation.hourglass=0"]),
    ("0.833 mm, alpha = 50", ["parameters.s=8.333333333333333e-4"]),
    ("0.833 mm, alpha = 0", ["parameters.s=8.333333333333333e-4", "formulation.hourglass=0"]),
)


def measure(out: str) -> dict:
    h = read_history(out)
    t, force = h["time"], h["force"]
    balance = np.abs(h["total_energy"]).max() / h["external_work"].max()
    peak = int(np.argmax(force))
    after = np.flatnonzero(force[peak:] < 0.5 * force[peak])
    failed_at = t[peak + after[0]] if len(after) else np.nan
    last = read_snapshots(out, ("position", "displacement", "damage"), which=-1)[0]
    x, u, D = last["position"], last["displacement"], last["damage"]
    X = x - u
    failed = X[D >= 1.0, 0] * 1e3
    return {"particles": len(x), "peak": force[peak], "elongation": SPEED * (failed_at - 0.5 * RAMP) * 1e3,
            "crack": (np.median(failed), failed.min(), failed.max()) if len(failed) else (np.nan,) * 3,
            "balance": balance, "X": X, "D": D}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(ROOT, "results", "failure_study"))
    args = parser.parse_args()
    rows = []
    for k, (label, overrides) in enumerate(CASES):
        out = os.path.join(args.out, f"case{k}")
        seconds = run_scene("tensile_failure", out, overrides, args.ranks, ["position", "displacement", "damage"])
        rows.append((label, measure(out), seconds))
    print(f"{'case':22s} {'particles':>9s} {'peak [kN]':>9s} {'elong. [mm]':>11s} "
          f"{'crack x [mm]: median (range)':>30s} {'energy':>8s} {'wall [s]':>8s}")
    for label, m, seconds in rows:
        median, lo, hi = m["crack"]
        print(f"{label:22s} {m['particles']:9d} {m['peak'] / 1e3:9.1f} {m['elongation']:11.3f} "
              f"{median:12.2f} ({lo:6.2f} .. {hi:6.2f}) {m['balance']:8.1e} {seconds:8.1f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(8, 6.4), sharex=True, sharey=True)
    for ax, (label, m, _) in zip(axes.T.ravel(), rows):
        order = np.argsort(m["D"])  # the most damaged drawn last, on top
        X, D = m["X"][order] * 1e3, m["D"][order]
        ax.scatter(X[:, 0], X[:, 1], c=D, s=3, vmin=0, vmax=1, cmap="inferno_r")
        ax.set_aspect("equal")
        ax.set_title(label, fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("x [mm]", fontsize=8)
    fig.suptitle("damage at the end (black: failed), over the reference positions, all z", fontsize=9)
    fig.tight_layout()
    path = os.path.join(args.out, "tensile_failure.png")
    fig.savefig(path, dpi=120)
    print(path)


if __name__ == "__main__":
    main()
