#!/usr/bin/env python3
"""The Taylor bar of [G §4.5] (runs/taylor_impact.toml) at three lattice spacings (0.35,
0.175, 0.1167 mm), and at the base spacing without hourglass control and with E in the
hourglass force ([G Fig. 9]'s contrasts). Prints a table: particles, final length (the
shortest top position, when the bar has stopped) over the initial one, foot width (at the
end, twice the largest |x|), largest plastic strain, energy balance error
(max |total - initial| / initial), disorder (mass-weighted RMS of the hourglass error at the
end) and wall time; draws the final plastic strain of every case side by side into
OUT/taylor_impact.png.

usage: tools/taylor_study.py [--ranks N] [--out DIR]
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from launch import ROOT, run_scene

from parsph.io import read_history, read_snapshots

CASES = (  # label, overrides
    ("0.35 mm", []),
    ("0.175 mm", ["parameters.spacing=1.75e-4"]),
    ("0.117 mm", ["parameters.spacing=1.1666666666666667e-4"]),
    ("0.35 mm, alpha = 0", ["formulation.hourglass=0"]),
    ("0.35 mm, E in hourglass", ["formulation.plastic_hourglass=elastic"]),
)


def measure(out: str) -> dict:
    series = read_history(out)
    first_snapshot, last = read_snapshots(out, ("position", "plastic_strain"), which=[0, -1])
    first, x, strain = first_snapshot["position"], last["position"], last["plastic_strain"]
    initial = series["kinetic_energy"][0]
    return {"particles": len(x), "length": series["length"].min() / first[:, 1].max(),
            "width": 2 * np.abs(x[:, 0]).max() * 1e3, "strain": strain.max(),
            "energy": np.abs(series["total_energy"] - initial).max() / initial,
            "disorder": series["disorder"][-1], "x": x, "plastic": strain}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, default=2)
    parser.add_argument("--out", default=os.path.join(ROOT, "results", "taylor_study"))
    args = parser.parse_args()
    rows = []
    for k, (label, overrides) in enumerate(CASES):
        out = os.path.join(args.out, f"case{k}")
        seconds = run_scene("taylor_impact", out, overrides, args.ranks, ["position", "plastic_strain"])
        rows.append((label, measure(out), seconds))
    print(f"{'case':26s} {'particles':>9s} {'L/L0':>7s} {'foot [mm]':>9s} {'max eps_p':>9s} {'energy':>8s} "
          f"{'disorder':>8s} {'wall [s]':>8s}")
    for label, m, seconds in rows:
        print(f"{label:26s} {m['particles']:9d} {m['length']:7.4f} {m['width']:9.3f} {m['strain']:9.3f} "
              f"{m['energy']:8.1e} {m['disorder']:8.4f} {seconds:8.1f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(rows), figsize=(2.1 * len(rows) + 1.2, 5.0))
    for ax, (label, m, _) in zip(axes, rows):
        size = 60.0 / np.sqrt(m["particles"])
        sc = ax.scatter(m["x"][:, 0] * 1e3, m["x"][:, 1] * 1e3, c=m["plastic"], s=size, vmin=0, vmax=1.5,
                        cmap="viridis")
        ax.set_xlim(-5.5, 5.5)
        ax.set_ylim(-0.5, 23.5)
        ax.set_aspect("equal")
        ax.set_title(label, fontsize=8)
        ax.set_xlabel("x [mm]", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel("y [mm] (the wall at y = 0.175 mm)", fontsize=8)
    fig.colorbar(sc, ax=list(axes), label="equivalent plastic strain", shrink=0.8)
    path = os.path.join(args.out, "taylor_impact.png")
    fig.savefig(path, dpi=120)
    print(path)


if __name__ == "__main__":
    main()
