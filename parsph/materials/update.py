"""The compiled material update the formulations call at every integration point:

    psi = update(law, F, dim, c, state, trial, i, P, work, dt)

writes the first Piola-Kirchhoff stress P for the deformation gradient F and returns the
(elastic) strain-energy density per unit reference volume (NaN for an inverted point); `c`
are the law's constants (materials.Constants.values). A law with per-point state reads
point i's committed state, row i of `state` (points, k), and writes its new state to row i
of `trial`; the loop commits trial to state at the start of the next step, so evaluating
the stress again at the same F (a restart, a reference update) gives the same result.
`work` is scratch space, (WORK, 3, 3), allocated once per stage; dt is the step over
which F came from the committed state (0 at set-up), for the laws whose stress depends
on the rate. `stiffening` is the factor on the reference P-wave speed squared that the
stable time step uses. `law` is a compile-time constant of the calling stage, so the
branch below is folded away and a stage calls only its law's code. Each law family is a
function of its own, not inlined: Numba compiles it once and every stage variant that
uses it links it from the on-disk cache, where an inlined body was copied and typed
again in each variant (most of a stage's compile time). A new law family adds one branch
here and its line in materials.LAWS.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from parsph.materials import damage, elastic, elastoplastic, johnson_cook, johnson_cook_failure, mie_gruneisen

WORK = elastoplastic.WORK  # the most scratch matrices a law uses
J2_PLASTICITY = elastoplastic.J2_PLASTICITY
JOHNSON_COOK = johnson_cook.JOHNSON_COOK
MIE_GRUNEISEN = mie_gruneisen.MIE_GRUNEISEN
MOONEY_RIVLIN = elastic.MOONEY_RIVLIN
TAIT_FLUID = elastic.TAIT_FLUID
# the failure models as plain globals: a branch on a module's attribute is not folded away
TENSILE = damage.TENSILE
JOHNSON_COOK_FAILURE = johnson_cook_failure.JOHNSON_COOK_FAILURE


@njit(cache=True, inline="always")
def runtime(n):
    """n as a run-time integer: passed as a literal (a stage's closure constant), it would
    compile the callee again for each value. The plastic laws take the dimension at run time,
    so one compiled law serves every dimension and the output's 3 x 3 stresses (their stage
    time is the same: the return map outweighs the loops); the hyperelastic stress, a few
    loops over the components, is compiled for each dimension, whose unrolled loops save a
    tenth of the 3D block's stress stage."""
    return max(n, 0)


@njit(cache=True, inline="always")
def update(law, F, dim, c, state, trial, i, P, work, dt):
    """One branch per law family (the hyperelastic laws share one)."""
    d = runtime(dim)
    if law == J2_PLASTICITY:
        return elastoplastic.j2(F, d, c, state, trial, i, P, work)
    if law == JOHNSON_COOK:
        return johnson_cook.update(F, d, c, state, trial, i, P, work, dt)
    if law == MIE_GRUNEISEN:
        return mie_gruneisen.update(F, d, c, state, trial, i, P, work, dt)
    if law == MOONEY_RIVLIN:
        return elastic.mooney_rivlin(F, dim, c[0], c[1], c[2], P, work[0], work[1], work[2])
    if law == TAIT_FLUID:
        return elastic.tait(F, dim, c[0], c[1], P, work[2])
    return elastic.stress(law, F, dim, c[0], c[1], c[2], P, work[0], work[1], work[2])


@njit(cache=True, inline="always")
def has_failed(failure, damaged, i):
    """Whether point i has failed (damage 1) under the failure model `failure` (0: none)."""
    broken = False
    if failure:
        broken = damaged[i, damage.DAMAGE] >= 1.0
    return broken


@njit(cache=True, inline="always")
def update_failing(law, failure, F, dim, c, state, trial, damaged, damaged_trial, i, P, work, dt):
    """update() under the point's failure model `failure` (0: none, damage.TENSILE,
    johnson_cook_failure.JOHNSON_COOK_FAILURE; a compile-time constant too), its state in row
    i of `damaged` (new: `damaged_trial`): a failed point (damage 1) carries no stress and
    its law is not evaluated; otherwise tensile damage degrades the law's stress, or the
    Johnson-Cook index accumulates."""
    d = runtime(dim)
    if has_failed(failure, damaged, i):
        return damage.failed(F, d, damaged, damaged_trial, i, P)
    e = update(law, F, dim, c, state, trial, i, P, work, dt)
    if failure == TENSILE:
        damage.degrade(P, F, d, damaged, damaged_trial, i, work)
    elif failure == JOHNSON_COOK_FAILURE:
        johnson_cook_failure.accumulate(P, F, d, c, state, trial, damaged, damaged_trial, i, work, dt)
    return e


@njit(cache=True, inline="always")
def stiffening(law, s_max, J, c):
    """Tangent stiffening of the law under the total deformation (>= 1): (3 s_max^2 - 1)/2
    under stretch for Saint Venant-Kirchhoff, J^(1 - gamma) under compression for Tait's
    fluid (its sound speed squared, c[1] = gamma), 1 - ln J under compression for the
    neo-Hookean, Mooney-Rivlin and Hencky elasto-plastic laws (their bulk terms, which set
    the wave speed; plastic flow only softens the elasto-plastic one), the Hugoniot's
    tangent under compression for Mie-Grüneisen; inf for an inverted point."""
    if law == elastic.SAINT_VENANT_KIRCHHOFF:
        return max(1.0, 0.5 * (3.0 * s_max * s_max - 1.0))
    if law == MIE_GRUNEISEN:  # the Hugoniot's tangent and its pressure's share through Gamma0
        eta = 1.0 - J
        return max(1.0, mie_gruneisen.hugoniot(c, eta)[1] + c[mie_gruneisen.GAMMA] * max(eta, 0.0)) \
            if J > 0 else math.inf
    if law == elastic.TAIT_FLUID:
        return max(1.0, J ** (1.0 - c[1])) if J > 0 else math.inf
    return max(1.0, 1.0 - math.log(J)) if J > 0 else math.inf


def stresses(law, F, dim, c, state, trial, P, psi, dt=0.0) -> None:
    """P[n], psi[n] and trial[n] for a stack of deformation gradients F[n] from the
    committed states state[n] (output, material tests; state and trial have no columns
    for a law without state)."""
    _stack_update(int(law), int(dim))(F, c, state, trial, P, psi, float(dt))


@functools.lru_cache(maxsize=None)
def _stack_update(law: int, dim: int):
    """`stresses`' kernel for one law and dimension, closure constants as in the stages, so
    that it compiles only that law's code and links the law's function the stages use."""
    @njit(cache=True)
    def kernel(F, c, state, trial, P, psi, dt):
        work = np.empty((WORK, 3, 3))
        for n in range(F.shape[0]):
            psi[n] = update(law, F[n], dim, c, state, trial, n, P[n], work, dt)
    return kernel
