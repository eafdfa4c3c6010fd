"""Tensile damage [G §4.6, eq. 45-46] on top of any solid law (`material.failure_strain`).

While the largest principal logarithmic strain of a point exceeds the failure strain, its
damage grows at  d(D^(1/3))/dt = 0.4 c0 / h  (c0 the reference P-wave speed, h the kernel
support radius of the particle; [G] leaves the strain measure and the sound speed open),
irreversibly, capped at 1. The Cauchy stress of the law is scaled in its principal axes:
positive principal stresses by (1 - D), negative ones are kept: a damaged point still
carries compression. Its pairs stay; its hourglass modulus is (1 - D) E
(formulations.nodal), so the penalty does not hold a crack shut.

A fully failed point (D = 1) carries no stress at all, not even compression (kept, it was
crushed by its neighbours until the stable step collapsed); its law is no longer evaluated.

The degraded stress derives from no energy, so the loop keeps the work each point has
taken, W = int P : dF (trapezoidal rule, per unit reference volume), and reports the
difference to the law's strain energy (and plastic work), W - psi, as damage work (all of
W once the point has failed: its strain energy is then reported as 0); strain energy +
damage work is the work the point has taken, and the balance of the run stays checkable.
W starts at psi when the point is first damaged (parsph.ledger.start_damage_work): an
intact point takes no damage work, whatever the trapezoidal rule's difference from the
law's energy.

The state row (committed; the stress evaluation writes the trial row): D, the failure
index (here the largest principal strain at the last evaluation; Johnson-Cook's D:
materials.johnson_cook_failure), W, and P and F of the last evaluation (3 x 3 each,
row-major, the model's dim x dim block used).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.keys import Key, positive
from parsph.materials.elastic import det, inverse, right_cauchy_green
from parsph.materials.elastoplastic import symmetric_eigen
from parsph.materials.law import FailureModel

TENSILE = 1  # the failure model's id (materials.johnson_cook_failure is another)
COLUMNS = 21
DAMAGE, STRAIN, WORK, STRESS, PREVIOUS = 0, 1, 2, 3, 12
RATE = 0.4  # damage front speed over the sound speed [G eq. 45]


def initial_state(n: int) -> np.ndarray:
    out = np.zeros((n, COLUMNS))
    out[:, PREVIOUS + 0] = out[:, PREVIOUS + 4] = out[:, PREVIOUS + 8] = 1.0  # F = I
    return out


@njit(cache=True, _nrt=False)  # not inlined: stages without damage do not compile it
def degrade(P, F, dim, state, trial, i, work):
    """Scale the positive principal Cauchy stresses of P (at F, point i) by 1 - D from the
    committed state[i]; write trial[i] (the strain, W, P, F). `work`: 3x3 scratch matrices
    (at least 5)."""
    D = state[i, DAMAGE]
    C, N, sigma, Finv = work[0], work[1], work[2], work[3]
    values = work[4][0]
    for a in range(3):
        for b in range(3):
            C[a, b] = 1.0 if a == b else 0.0
            sigma[a, b] = 0.0
    right_cauchy_green(F, dim, C)
    symmetric_eigen(C, values, N)
    largest = max(values[0], values[1], values[2])
    trial[i, STRAIN] = 0.5 * math.log(largest) if largest > 0.0 else 0.0
    J = det(F, dim)
    inverse(F, dim, Finv)
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(dim):
                s += P[a, k] * F[b, k]
            sigma[a, b] = s / J
    symmetric_eigen(sigma, values, N)
    for k in range(3):
        values[k] *= (1.0 - D) if values[k] > 0.0 else 1.0
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(3):
                for m in range(dim):
                    s += N[a, k] * values[k] * N[m, k] * Finv[b, m]
            P[a, b] = J * s
    record(P, F, dim, state, trial, i)


@njit(cache=True, _nrt=False)
def failed(F, dim, state, trial, i, P):
    """A failed point (D = 1): P = 0, W completed for the step; returns its reported
    strain energy, 0."""
    for a in range(dim):
        for b in range(dim):
            P[a, b] = 0.0
    record(P, F, dim, state, trial, i)
    trial[i, STRAIN] = state[i, STRAIN]
    return 0.0


@njit(cache=True, inline="always")
def record(P, F, dim, state, trial, i):
    """trial[i]: D, W += (P_n + P) : (F - F_n) / 2, P and F of this evaluation."""
    work_done = 0.0
    for a in range(dim):
        for b in range(dim):
            column = 3 * a + b
            work_done += (P[a, b] + state[i, STRESS + column]) * (F[a, b] - state[i, PREVIOUS + column])
            trial[i, STRESS + column] = P[a, b]
            trial[i, PREVIOUS + column] = F[a, b]
    trial[i, DAMAGE] = state[i, DAMAGE]
    trial[i, WORK] = state[i, WORK] + 0.5 * work_done


@njit(cache=True)
def _degraded(P, F, dim, state, work):
    trial = state.copy()
    for n in range(F.shape[0]):
        if state[n, DAMAGE] >= 1.0:
            failed(F[n], dim, state, trial, n, P[n])
        else:
            degrade(P[n], F[n], dim, state, trial, n, work)


def grow(state: np.ndarray, failure_strain: float, speed: float, support: np.ndarray, dt: float) -> None:
    """Damage growth over a step dt from the committed state (in place, rows of `state`,
    each point's support radius in `support`): D^(1/3) += 0.4 c0 dt / h where the strain
    of the last evaluation exceeds the failure strain, capped at 1."""
    loaded = state[:, STRAIN] > failure_strain
    if loaded.any():
        root = np.cbrt(state[loaded, DAMAGE]) + RATE * speed * dt / support[loaded]
        state[loaded, DAMAGE] = np.minimum(root, 1.0) ** 3


def hourglass_factor(state: np.ndarray) -> np.ndarray:
    """1 - D: the share of E a damaged point keeps in its hourglass force."""
    return 1.0 - state[:, DAMAGE]


def degraded_stresses(P: np.ndarray, F: np.ndarray, dim: int, state: np.ndarray) -> None:
    """The damaged stress of every row of a stack (in place): degrade, or 0 for failed rows."""
    _degraded(P, F, dim, state, np.empty((5, 3, 3)))


KEYS = dict(failure_strain=Key("float", None, positive,
                               "tensile damage [G eq. 45-46]: damage grows while the largest principal log strain "
                               "exceeds this (default: no damage; solids, particle formulations)"))


def _advance(state: np.ndarray, body, support: np.ndarray, dt: float) -> None:
    grow(state, body.failure_strain, body.constants.wave_speed, support, dt)


def _index(state: np.ndarray, body) -> np.ndarray:
    return state[:, STRAIN] / body.failure_strain


MODEL = FailureModel("tensile", TENSILE, KEYS, _advance, degraded_stresses, _index)
