"""Write runs/parts/punch_tool.csv: the outline of the punch of runs/punch.toml (a box of
half-width 1 cm and height 2 cm, its corners rounded with a radius of 1 mm) for
runs/punch_stl.toml, its lower face at y = 0, counter-clockwise, with SEGMENTS segments
on each quarter circle.

    python tools/punch_tool_outline.py [--segments 16] [--out runs/parts/punch_tool.csv]
"""

import argparse
import os

import numpy as np

HALF_WIDTH, HEIGHT, RADIUS = 0.01, 0.02, 1.0e-3


def outline(segments: int) -> np.ndarray:
    """The rounded rectangle's vertices, counter-clockwise from the lower face."""
    corners = [((HALF_WIDTH - RADIUS, RADIUS), -0.5 * np.pi), ((HALF_WIDTH - RADIUS, HEIGHT - RADIUS), 0.0),
               ((-HALF_WIDTH + RADIUS, HEIGHT - RADIUS), 0.5 * np.pi), ((-HALF_WIDTH + RADIUS, RADIUS), np.pi)]
    points = []
    for (cx, cy), start in corners:
        angle = start + np.linspace(0.0, 0.5 * np.pi, segments + 1)
        points.append(np.column_stack([cx + RADIUS * np.cos(angle), cy + RADIUS * np.sin(angle)]))
    return np.concatenate(points)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--segments", type=int, default=256, help="segments per quarter circle")
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "runs", "parts",
                                                      "punch_tool.csv"))
    args = parser.parse_args()
    np.savetxt(args.out, outline(args.segments), delimiter=",", fmt="%.17g",
               header="x [m], y [m]: the punch of runs/punch.toml (tools/punch_tool_outline.py)")


if __name__ == "__main__":
    main()
