"""The compiled material update the formulations call at every integration point:

    psi = update(law, F, dim, c, state, i, P, S, C, Cinv)

writes the first Piola-Kirchhoff stress P for the deformation gradient F and returns the
strain-energy density per unit reference volume (NaN for an inverted point); `c` are the
law's constants (materials.Constants.values), `state` the (points, k) array of its per-point
state, row i. `stiffening` is the factor on the reference P-wave speed squared that the
stable time step uses. `law` is a compile-time constant of the calling stage, so the branch
below is folded away: each stage holds only its law's code. A new law family adds one
branch here and its entry in materials.LAWS.
"""

from __future__ import annotations

import math

from numba import njit

from parsph.materials import elastic


@njit(cache=True, inline="always")
def update(law, F, dim, c, state, i, P, S, C, Cinv):
    return elastic.stress(law, F, dim, c[0], c[1], c[2], P, S, C, Cinv)


@njit(cache=True, inline="always")
def stiffening(law, s_max, J, c):
    """Tangent stiffening of the law under the total deformation (>= 1): (3 s_max^2 - 1)/2
    under stretch for Saint Venant-Kirchhoff, J^(1 - gamma) under compression for Tait's
    fluid (its sound speed squared, c[1] = gamma), 1 - ln J under compression for the
    neo-Hookean and Mooney-Rivlin laws (their bulk terms, which set the wave speed); inf
    for an inverted point."""
    if law == elastic.SAINT_VENANT_KIRCHHOFF:
        return max(1.0, 0.5 * (3.0 * s_max * s_max - 1.0))
    if law == elastic.TAIT_FLUID:
        return max(1.0, J ** (1.0 - c[1])) if J > 0 else math.inf
    return max(1.0, 1.0 - math.log(J)) if J > 0 else math.inf
