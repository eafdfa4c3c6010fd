#!/usr/bin/env python3
"""How far the updated formulation's stored deformation drifts from its particle positions.

Runs an updated-Lagrangian scene (formulation.type = "ulsph") in one process and, every
--every steps, evaluates the total-Lagrangian gradient of the same positions (a twin
simulation of the scene with formulation.type = "tlsph", the same kernel and
stabilisation, given the UL displacements). In exact arithmetic F = f F^r [V §3.1] equals
that gradient for any smooth motion; the gap is what the reference updates have frozen
into F^r. Prints per report: time, updates so far, strain energy of UL and of the TL
gradient of the UL positions (and their ratio), J_UL - J_TL (mean, 1st and 99th
percentile) and where it is largest.
The total-Lagrangian gradient means something only while the initial neighbours are still
neighbours, i.e. before the distortion this formulation exists for: read it early on.
It measured the README's Known gap on the updated reference's consistency.

usage: tools/ul_consistency.py runs/punch_ul.toml [--set KEY=VALUE ...] [--until T] [--every N]
"""

from __future__ import annotations

import argparse
import os

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def main() -> None:
    from mpi4py import MPI

    from parsph import config
    from parsph.build import build_local
    from parsph.simulation import Simulation

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--until", type=float, help="end time [s] (default: the scene's)")
    parser.add_argument("--every", type=int, default=100, help="steps between reports")
    args = parser.parse_args()

    scene = config.load(args.scene, args.set)
    if scene.formulation.type != "ulsph":
        parser.error("the scene must use formulation.type = 'ulsph'")
    total = config.load(args.scene, args.set + ["formulation.type=tlsph", "formulation.update_every=0",
                                                 "formulation.update_strain=0"])
    comm = MPI.COMM_SELF
    ul = Simulation(scene, build_local(scene, comm), comm)
    tl = Simulation(total, build_local(total, comm), comm)
    n = ul.state.n_owned
    end = args.until or scene.time.end
    print("t [s]       updates  W_UL [J]     W_TL(x) [J]  ratio   dJ mean    dJ p1     dJ p99    "
          "largest |dJ| at X")
    while ul.t < end * (1 - 1e-12):
        ul.step()
        if ul.step_count % args.every and ul.t < end * (1 - 1e-12):
            continue
        tl.state.u[:n] = ul.state.u[:n]
        tl.compute_forces()
        dJ = ul.state.J[:n] - tl.state.J[:n]
        k = int(np.argmax(np.abs(dJ)))
        w_ul, w_tl = ul.ledger.local(ul, "strain"), tl.ledger.local(tl, "strain")
        where = ", ".join(f"{c:.4g}" for c in ul.state.X[k])
        print(f"{ul.t:<11.5g} {ul.topology.count:<8d} {w_ul:<12.5g} {w_tl:<12.5g} {w_tl / w_ul:<7.4f} "
              f"{dJ.mean():+.2e} {np.percentile(dJ, 1):+.2e} {np.percentile(dJ, 99):+.2e} ({where})",
              flush=True)


if __name__ == "__main__":
    main()
