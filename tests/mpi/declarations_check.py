"""Run under mpiexec: with other values in the ghost rows of every field a stage does not
declare to read while it runs (physics.poison_undeclared), the forces of the cantilever
are the same bit for bit, for each formulation. Prints OK and exits 0, or the first case
whose forces changed and exits 1.

usage: mpiexec -n P python declarations_check.py
"""

import sys

import numpy as np
from mpi4py import MPI

sys.path.insert(0, __file__.rsplit("/", 2)[0])
from physics import poison_undeclared, simulation  # noqa: E402

CASES = {
    "tlsph hessian": ["formulation.hessian=1.0", "formulation.hourglass=0.0"],
    "tlsph paper": ["formulation.hourglass_form='paper'"],
    "ulsph": ["formulation.type='ulsph'", "formulation.update_every=5", "formulation.hessian=0.5"],
    "sph": ["formulation.type='sph'"],
    "rlm": ["formulation.type='rlm'"],
    "rlm eulerian": ["formulation.type='rlm'", "formulation.kernel='eulerian'"],
    "kbm": ["formulation.type='kbm'"],
    "efg": ["formulation.type='efg'"],
    "efg eulerian": ["formulation.type='efg'", "formulation.kernel='eulerian'"],
}

comm = MPI.COMM_WORLD
for name, overrides in CASES.items():
    sim = simulation("cantilever", ["time.end=1e-3", *overrides], comm)
    ghosts = comm.allreduce(sum(p.decomp.n_rows - p.n_owned for p in sim.state.point_sets()))
    for _ in range(20):
        sim.step()
    sim.compute_forces()
    force = sim.quantity("force")
    poison_undeclared(sim)
    sim.compute_forces()
    same = bool(np.array_equal(sim.quantity("force"), force))
    if not comm.allreduce(same and ghosts > 0, op=MPI.LAND):
        if comm.rank == 0:
            print(f"{name}: the forces changed with other values in undeclared ghost rows (ghost rows {ghosts})")
        sys.exit(1)
if comm.rank == 0:
    print("OK")
