"""Run under mpiexec (or alone): set up runs/SCENE.toml and print, on rank 0, each body's
step factor (stability.StableStep.calibrate) and the first step as exact hexadecimal floats,
for a comparison across rank counts.

usage: mpiexec -n P python step_factor_check.py SCENE [KEY=VALUE ...]
"""

import sys

from mpi4py import MPI

sys.path.insert(0, __file__.rsplit("/", 2)[0])
from physics import simulation  # noqa: E402

sim = simulation(sys.argv[1], sys.argv[2:], comm=MPI.COMM_WORLD)
if MPI.COMM_WORLD.rank == 0:
    print(" ".join(float(b.step_factor).hex() for b in sim.state.bodies), float(sim.dt).hex())
