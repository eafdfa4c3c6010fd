#!/usr/bin/env python3
"""Time the lattice fill of a surface part (geometry.fill) on the ranks it runs with: an
icosphere STL (written to a temporary directory) filled with about N particles, without a
run. Reports the fill (counting shared by the ranks, then each rank's block of rows) and
the whole particle build (build.build_bodies: the fill, the ranks' exchange of particles by
RCB and the kernel supports), wall time and microseconds per particle.

usage: mpiexec -n P python tools/bench_fill.py [--count 10000000] [--subdivisions 4]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
import trimesh
from mpi4py import MPI

from parsph import build, config
from parsph.geometry import fill


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=float, default=1e7, help="particles wanted (about)")
    parser.add_argument("--subdivisions", type=int, default=4, help="icosphere subdivisions (4: 5120 triangles)")
    args = parser.parse_args()
    comm = MPI.COMM_WORLD
    folder = comm.bcast(tempfile.mkdtemp() if comm.rank == 0 else None)
    path = os.path.join(folder, "ball.stl")
    if comm.rank == 0:
        trimesh.creation.icosphere(subdivisions=args.subdivisions, radius=0.05).export(path)
    comm.Barrier()
    volume = trimesh.load_mesh(path).volume
    spacing = (volume / args.count) ** (1.0 / 3.0)
    part = {"shape": "surface", "file": path, "spacing": spacing}

    comm.Barrier()
    start = time.perf_counter()
    g = fill(part, "geometry.parts[0]", 3, comm)
    cuts = np.linspace(0, g.count, comm.size + 1).round().astype(np.int64)
    X, _ = g.rows(int(cuts[comm.rank]), int(cuts[comm.rank + 1]))
    comm.Barrier()
    filled = time.perf_counter() - start

    scene = config.validate({
        "scene": {"name": "bench_fill", "dimension": 3},
        "geometry": {"parts": [dict(part, shape="surface")]},
        "material": {"model": "saint_venant_kirchhoff", "density": 1.0, "youngs_modulus": 1.0, "poisson_ratio": 0.3},
        "time": {"end": 1.0},
    })
    comm.Barrier()
    start = time.perf_counter()
    owned, _ = build.build_bodies(scene, comm)
    comm.Barrier()
    built = time.perf_counter() - start
    largest = comm.allreduce(len(owned["gid"]), op=MPI.MAX)
    if comm.rank == 0:
        n = g.count
        print(f"bench_fill: {n} particles (spacing {spacing:.4g} m, {20 * 4 ** args.subdivisions} "
              f"triangles) on {comm.size} rank(s); {g.report()}")
        print(f"  fill (count + rows):       {filled:8.2f} s  {1e6 * filled / n:6.2f} us/particle")
        print(f"  build_bodies (fill, RCB, supports): {built:8.2f} s  {1e6 * built / n:6.2f} us/particle; "
              f"largest rank holds {largest} ({100 * largest * comm.size / n:.0f} % of an even share)")
        os.remove(path)
        os.rmdir(folder)


if __name__ == "__main__":
    main()
