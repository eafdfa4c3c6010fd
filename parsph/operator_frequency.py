"""The largest frequency of each deformable body's discrete force operator, by power
iteration on M^-1 K with K v = -(f(u + eps v) - f(u)) / eps (finite differences of the
bodies' internal force, their stages alone: no contact, ties or loads), the frequency
squared as the Rayleigh quotient v.K v / v.M v of the last iterate (a lower bound that
converges to the top of the spectrum for a symmetric K; Golub & Van Loan, Matrix
Computations, §7.3.1 and §8.2.1).

The start vector comes from a fixed seed and the particles' global ids, the sums over a
body's particles are exact (exact_sum) and the maxima are reductions of exact values, so the
frequencies are the same bit for bit on any number of ranks. Every rank takes part in every
reduction for every body, whether or not it owns particles of it.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from parsph import exact_sum
from parsph.errors import ParsphError

ITERATIONS = 30  # power iterations of a measurement (each one evaluation of the bodies' forces)
# the least steps between measurements where a reference moves (simulation.Simulation.step): the
# iterations then cost at most a tenth of the run's force evaluations
EVERY = 10 * ITERATIONS
DELTA = 1.0e-6  # the perturbation's largest displacement, of the body's smallest reference spacing
SEED = 0x5EED5EED  # of the start vector
# the iteration is on M^-1 K - sigma I, sigma = SHIFT times the last frequency squared: with
# the spectrum in [0, lambda_max] and sigma < lambda_max / 2, the top converges as
# ((lambda_2 - sigma) / (lambda_max - sigma))^k, faster than (lambda_2 / lambda_max)^k
SHIFT = 0.45


def start_vector(gid: np.ndarray, dim: int) -> np.ndarray:
    """(len(gid), dim) values in [-1, 1) from the particles' global ids and SEED alone
    (splitmix64, Steele, Lea & Flood 2014): the same vector however the particles are split."""
    with np.errstate(over="ignore"):
        z = (gid.astype(np.uint64)[:, None] * np.uint64(dim) + np.arange(dim, dtype=np.uint64)
             + np.uint64(SEED)) * np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z ^= z >> np.uint64(31)
    return (z >> np.uint64(11)).astype(np.float64) * 2.0 ** -52 - 1.0


def largest_frequencies(state, evaluate, iterations: int = ITERATIONS) -> np.ndarray:
    """Squared largest frequency [1/s^2] of each body's force operator at the current
    displacement of `state` (state.RankState; 0 for a rigid body), from `evaluate()`, the
    bodies' internal force on the owned rows at state.u. The displacement is restored on
    return; the arrays the evaluations wrote are those of the last perturbed one (the caller
    evaluates the forces again). A frequency that is not finite, or a body whose forces do
    not change with its displacement, raises ParsphError (collective: every rank raises it)."""
    n, comm, bodies = state.n_owned, state.comm, state.bodies
    deformable = [b for b in bodies if not b.rigid]
    u0 = state.u[:n].copy()
    rows = np.zeros(n, bool)
    length = np.full(len(bodies), np.inf)
    for b in deformable:
        rows[b.lo:b.hi] = True
        if b.hi > b.lo:
            length[b.index] = b.relation.ref.min_spacing[b.lo:b.hi].min()
    comm.Allreduce(MPI.IN_PLACE, length, op=MPI.MIN)
    eps = DELTA * np.where(np.isfinite(length), length, 0.0)[state.body[:n], None]
    v = np.where(rows[:, None], start_vector(state.gid[:n], state.dim), 0.0)
    mass = state.mass[:n, None]
    squared = np.zeros(len(bodies))
    try:
        f0 = evaluate().copy()
        for _ in range(iterations):
            top = np.zeros(len(bodies))
            for b in deformable:
                if b.hi > b.lo:
                    top[b.index] = np.abs(v[b.lo:b.hi]).max()
            comm.Allreduce(MPI.IN_PLACE, top, op=MPI.MAX)
            with np.errstate(all="ignore"):
                v /= np.where(top > 0.0, top, 1.0)[state.body[:n], None]  # the largest component 1
                state.u[:n] = u0 + eps * v
                kv = np.where(rows[:, None], -(evaluate() - f0) / np.where(eps > 0.0, eps, 1.0), 0.0)
            parts = [x for b in deformable for x in (np.sum(v[b.lo:b.hi] * kv[b.lo:b.hi], axis=1),
                                                     np.sum(mass[b.lo:b.hi] * v[b.lo:b.hi] ** 2, axis=1))]
            sums = [float(s) for s in exact_sum.allsum(comm, exact_sum.totals(parts))]
            for k, b in enumerate(deformable):
                vkv, vmv = sums[2 * k], sums[2 * k + 1]
                squared[b.index] = vkv / vmv if vmv != 0.0 else 0.0  # nan stays nan
            with np.errstate(all="ignore"):  # the next iterate: (M^-1 K - sigma) v
                v = kv / mass - (SHIFT * squared[state.body[:n]])[:, None] * v
    finally:
        state.u[:n] = u0
    for b in deformable:
        if not np.isfinite(squared[b.index]):
            error = ParsphError(f"body '{b.name}': its internal force is not finite at a small change of its "
                                f"displacement (the largest frequency of its force operator is "
                                f"{squared[b.index]}): check its material constants and particles")
        elif not squared[b.index] > 0.0:
            error = ParsphError(f"body '{b.name}': its internal force does not grow with its displacement "
                                f"(its force operator is singular: the largest frequency squared is "
                                f"{squared[b.index]:.3g} 1/s^2); its particles have no stiffness or no "
                                f"neighbours: check its material constants, particle spacing and kernel support")
        else:
            continue
        error.agreed = True  # the same exact sums on every rank
        raise error
    return squared
