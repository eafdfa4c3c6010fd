"""Write runs/parts/sphere.stl: the projectile of runs/sphere_plate.toml, an icosphere of
radius 1 (scaled to 2 mm in the scene), 1280 triangles (trimesh.creation.icosphere, 3
subdivisions).

    python tools/sphere_part.py [--subdivisions 3] [--out runs/parts/sphere.stl]
"""

import argparse
import os

import trimesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--subdivisions", type=int, default=3)
    parser.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "..", "runs", "parts", "sphere.stl"))
    args = parser.parse_args()
    trimesh.creation.icosphere(subdivisions=args.subdivisions, radius=1.0).export(args.out)


if __name__ == "__main__":
    main()
