"""Run under mpiexec: every owned particle's neighbour set, weighted kernel gradients and its
neighbours' inverse correction matrices must equal the single-rank result. Prints OK and exits 0, or prints the first difference and exits 1.

usage: mpiexec -n P python halo_check.py DIM CELLS
"""

import sys

import numpy as np
from mpi4py import MPI

sys.path.insert(0, __file__.rsplit("/", 2)[0])
from physics import simulation  # noqa: E402

dim, cells = int(sys.argv[1]), int(sys.argv[2])
comm = MPI.COMM_WORLD
upper = ", ".join(["1.0"] * dim)
scene = f"""
[scene]
name = "halo"
dimension = {dim}
[[geometry.parts]]
shape = "box"
lower = [{", ".join(["0.0"] * dim)}]
upper = [{upper}]
spacing = {1.0 / cells!r}
[kernel]
type = "cubic_spline"
support = 2.6
[material]
model = "saint_venant_kirchhoff"
density = 1.0
youngs_modulus = 1.0
poisson_ratio = 0.25
[time]
end = 1.0
"""


def rows(sim):
    """gid -> (sorted neighbour gids, gw, the neighbours' L^-1) for the owned particles."""
    out = {}
    ref = sim.topology.relations[0].ref
    for i in range(sim.state.n_owned):
        p = slice(ref.ptr[i], ref.ptr[i + 1])
        out[int(sim.state.gid[i])] = (sim.state.gid[ref.idx[p]], ref.gw[p], ref.Linv[ref.idx[p]])
    return out


sim = simulation(scene, comm=comm)
owner = {int(g): comm.rank for g in sim.state.gid[: sim.state.n_owned]}
gathered = comm.gather((rows(sim), owner), root=0)
status = 0
if comm.rank == 0:
    serial = rows(simulation(scene, comm=MPI.COMM_SELF))
    parallel, owners = {}, {}
    for r, o in gathered:
        parallel.update(r)
        owners.update(o)
    assert sorted(parallel) == sorted(serial), "particles lost or duplicated"
    max_ranks = 0
    for gid, (nbr, gw, Linv) in serial.items():
        p_nbr, p_gw, p_Linv = parallel[gid]
        if not (np.array_equal(nbr, p_nbr) and np.array_equal(gw, p_gw) and np.array_equal(Linv, p_Linv)):
            print(f"particle {gid}: neighbours or gradients differ on rank {owners[gid]}")
            status = 1
            break
        max_ranks = max(max_ranks, len({owners[int(j)] for j in nbr} | {owners[gid]}))
    if status == 0 and max_ranks < comm.size:
        print(f"no neighbourhood spans all {comm.size} ranks (max {max_ranks}): test is too weak")
        status = 1
    if status == 0:
        print(f"OK: {len(serial)} particles, neighbourhoods spanning up to {max_ranks} ranks")
status = comm.bcast(status, root=0)
sys.exit(status)
