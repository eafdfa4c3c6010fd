#!/usr/bin/env python3
"""Bytes per particle and per pair, by field, of a scene's simulation on one rank.

Sets up runs/SCENE.toml (with --set overrides) on one rank, takes one step, then walks
every numpy array the simulation holds (its own, the reference data's, the neighbour
search's, the point sets', the bodies' material and damage state) and sorts each by its
first dimension: per particle (owned or owned + ghosts), per pair, or other. Prints a
markdown table (bytes per particle, per pair, and in all) and the process's peak resident
memory. An array seen under two names (a view, or the total-Lagrangian d = u) is counted
once, under the first.

usage: tools/memory.py [SCENE | PATH.toml] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import os
import resource

from mpi4py import MPI

from parsph import config
from parsph.build import build_local
from parsph.profile import arrays_held
from parsph.simulation import Simulation

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scene", nargs="?", default="cylinder_bending")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    path = args.scene if args.scene.endswith(".toml") else os.path.join(ROOT, "runs", f"{args.scene}.toml")
    scene = config.load(path, args.set)
    sim = Simulation(scene, build_local(scene, MPI.COMM_SELF), MPI.COMM_SELF)
    sim.step()
    n, rows, pairs = sim.state.n_owned, len(sim.state.X), sim.topology.pair_count()
    found = arrays_held(sim)
    table = {"particle": [], "pair": [], "other": []}
    for name, a in found:
        first = a.shape[0] if a.ndim else 0
        kind = "pair" if first == pairs and pairs not in (n, rows) else \
            "particle" if first in (n, rows) or first == n + 1 else "other"
        table[kind].append((name, a))
    print(f"scene {args.scene}: {n} particles ({rows} with ghosts), {pairs} pairs "
          f"({pairs / n:.1f} per particle), dimension {sim.state.dim}\n")
    print("| field | kind | shape | dtype | bytes per particle | bytes per pair | MB |")
    print("|---|---|---|---|---|---|---|")
    totals = {}
    for kind, items in table.items():
        for name, a in sorted(items, key=lambda item: -item[1].nbytes):
            per_particle = f"{a.nbytes / n:.0f}" if kind == "particle" else ""
            per_pair = f"{a.nbytes / pairs:.0f}" if kind == "pair" else ""
            print(f"| {name} | {kind} | {a.shape} | {a.dtype} | {per_particle} | {per_pair} | {a.nbytes / 1e6:.2f} |")
            totals[kind] = totals.get(kind, 0) + a.nbytes
    print()
    for kind, total in totals.items():
        unit = {"particle": n, "pair": pairs}.get(kind)
        per = f", {total / unit:.0f} B per {kind}" if unit else ""
        print(f"{kind}: {total / 1e6:.1f} MB{per}")
    print(f"arrays in all: {sum(totals.values()) / 1e6:.1f} MB, {sum(totals.values()) / n:.0f} B per particle; "
          f"peak resident memory of the process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3:.0f} MB")


if __name__ == "__main__":
    main()
