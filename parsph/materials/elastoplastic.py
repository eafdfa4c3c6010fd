"""Finite-strain J2 elasto-plasticity with a multiplicative split F = F^e F^p (Simo; Bonet &
Wood, Nonlinear Continuum Mechanics, ch. 7), as [G §4.5] uses it for the Taylor bar.

Hencky's elastic law in the principal logarithmic elastic stretches eps_a of the elastic
left Cauchy-Green tensor b^e = F (C^p)^-1 F^T:
    tau_a = 2 mu dev(eps)_a + K theta,   psi^e = mu |dev eps|^2 + K/2 theta^2,  theta = ln J,
von Mises yield f = sqrt(3/2) |dev tau| - sigma_Y(eps_bar) with linear isotropic hardening
or softening sigma_Y = max(sigma_Y0 + H eps_bar, 0), and the radial return from the
trial state (C^p)^-1_n:  dev eps = (1 - sqrt(6) mu d_eps / |dev tau^trial|) dev eps^trial,
d_eps = f^trial / (3 mu + H) (once sigma_Y reaches zero: the whole excess), then
(C^p)^-1_(n+1) = F^-1 b^e F^-T. The first Piola-Kirchhoff stress is P = tau F^-T.

The state of a point, in the columns of its row: (C^p)^-1 (xx, yy, zz, xy, yz, xz), the
equivalent plastic strain eps_bar, the plastic work per unit reference volume
w_p = int sigma_Y d eps_bar (the dissipation of J2 flow, tau : d^p = sigma_Y d eps_bar / dt),
exact for the increment d_eps: strain energy + plastic work then match the stress work to
the accuracy of the time integration, and the heat per unit reference volume that other
dissipation (the artificial viscosity) has left there (read by the laws with a temperature
or a thermal pressure). Missing dimensions (plane strain in 2D, 1D) are held
at unit stretch; the state is always 3D (plane strain still flows out of plane).

For [R §9.5] (printed as a Jaumann rate of Kirchhoff stress, eq. 76) the same law is used:
it is objective exactly, needs no rate integration and keeps the energy balance, and for
small elastic strains it is the hyperelastic counterpart of the printed hypoelastic one.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.fields import Field, register
from parsph.keys import Key, positive
from parsph.materials.elastic import ISOTROPIC_KEYS, det, inverse, isotropic
from parsph.materials.law import Law, Plastic, Readout

COLUMNS = 8  # (C^p)^-1 in 6 columns, eps_bar, w_p: what every plastic law's state begins with
WORK = 7  # scratch 3x3 matrices of the update
PLASTIC_STRAIN, PLASTIC_WORK = 6, 7
HEAT = 8  # the heat of other dissipation per unit reference volume, after COLUMNS (J2, Johnson-Cook)
FLOW = 9  # Johnson-Cook's von Mises Kirchhoff stress of the last evaluation
_SQRT_3_2 = math.sqrt(1.5)
_SQRT_6 = math.sqrt(6.0)
SYMMETRIC_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (0, 2))  # a symmetric tensor in 6 columns


def initial_state(n: int, columns: int = FLOW + 1) -> np.ndarray:
    """The virgin state: (C^p)^-1 = I, no plastic strain, work, heat or stress (`columns` wide)."""
    out = np.zeros((n, columns))
    out[:, :3] = 1.0
    return out


@njit(cache=True, _nrt=False)
def symmetric_eigen(A, w, V):
    """Eigenvalues w and unit eigenvectors (the columns of V) of the symmetric 3x3 matrix A
    (overwritten), by cyclic Jacobi rotations (deterministic, to rounding)."""
    for a in range(3):
        for b in range(3):
            V[a, b] = 1.0 if a == b else 0.0
    for _ in range(50):
        off = A[0, 1] * A[0, 1] + A[0, 2] * A[0, 2] + A[1, 2] * A[1, 2]
        scale = A[0, 0] * A[0, 0] + A[1, 1] * A[1, 1] + A[2, 2] * A[2, 2]
        if off <= 1e-36 * scale:
            break
        for p, q, r in ((0, 1, 2), (0, 2, 1), (1, 2, 0)):
            apq = A[p, q]
            if apq == 0.0:
                continue
            theta = (A[q, q] - A[p, p]) / (2.0 * apq)
            if abs(theta) > 1e150:
                t = 0.5 / theta
            else:
                t = (1.0 if theta >= 0.0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1.0))
            c = 1.0 / math.sqrt(t * t + 1.0)
            s = t * c
            A[p, p] -= t * apq
            A[q, q] += t * apq
            A[p, q] = A[q, p] = 0.0
            arp, arq = A[r, p], A[r, q]
            A[r, p] = A[p, r] = c * arp - s * arq
            A[r, q] = A[q, r] = s * arp + c * arq
            for k in range(3):
                vkp, vkq = V[k, p], V[k, q]
                V[k, p] = c * vkp - s * vkq
                V[k, q] = s * vkp + c * vkq
    for a in range(3):
        w[a] = A[a, a]


@njit(cache=True, inline="always")
def _yield_integral(yield0, hardening, start, step):
    """int sigma_Y d eps_bar from start to start + step, sigma_Y = max(yield0 + H eps_bar, 0)."""
    if step == 0.0:
        return 0.0
    end = start + step
    if hardening < 0.0:  # no dissipation once the yield stress is exhausted
        end = min(end, -yield0 / hardening)
        if end <= start:
            return 0.0
    return (end - start) * (yield0 + 0.5 * hardening * (start + end))


@njit(cache=True, inline="always")
def _sandwich(A, B, out):
    """out = A B A^T (3x3, B symmetric: so is out)."""
    for a in range(3):
        ab0 = A[a, 0] * B[0, 0] + A[a, 1] * B[1, 0] + A[a, 2] * B[2, 0]
        ab1 = A[a, 0] * B[0, 1] + A[a, 1] * B[1, 1] + A[a, 2] * B[2, 1]
        ab2 = A[a, 0] * B[0, 2] + A[a, 1] * B[1, 2] + A[a, 2] * B[2, 2]
        for b in range(a + 1):
            out[a, b] = out[b, a] = ab0 * A[b, 0] + ab1 * A[b, 1] + ab2 * A[b, 2]


@njit(cache=True, inline="always")
def predictor(F, dim, mu, state, i, work):
    """The elastic trial state at point i from its committed (C^p)^-1: b^e = F (C^p)^-1 F^T,
    its principal directions N (work[4]) and log stretches, the deviatoric part dev
    (work[6][2]) and F^-1 (work[1]); returns (whether J > 0 and b^e is positive definite,
    theta = ln J, |dev tau^trial| = 2 mu |dev|)."""
    F3, Finv, cp, be, N, vectors = work[0], work[1], work[2], work[3], work[4], work[6]
    w, eps, dev = vectors[0], vectors[1], vectors[2]
    for a in range(3):
        for b in range(3):
            F3[a, b] = F[a, b] if a < dim and b < dim else (1.0 if a == b else 0.0)
    J = det(F3, 3)
    if not J > 0.0:
        return False, 0.0, 0.0
    inverse(F3, 3, Finv)
    for k in range(6):
        a, b = SYMMETRIC_PAIRS[k]
        cp[a, b] = cp[b, a] = state[i, k]
    _sandwich(F3, cp, be)  # b^e trial = F (C^p)^-1 F^T
    symmetric_eigen(be, w, N)
    for a in range(3):
        if not w[a] > 0.0:
            return False, 0.0, 0.0
        eps[a] = 0.5 * math.log(w[a])
    theta = eps[0] + eps[1] + eps[2]
    for a in range(3):
        dev[a] = eps[a] - theta / 3.0
    return True, theta, 2.0 * mu * math.sqrt(dev[0] * dev[0] + dev[1] * dev[1] + dev[2] * dev[2])


@njit(cache=True, inline="always")
def corrector(F, dim, mu, bulk, state, trial, i, P, work, theta, norm, step, plastic_work):
    """The radial return by the plastic strain increment `step` from the predictor's trial
    state: dev scaled by 1 - sqrt(6) mu step / |dev tau^trial|, tau, the new (C^p)^-1 (an
    elastic step keeps it), the state's plastic strain and work (`plastic_work`) into
    trial[i], P = tau F^-T; returns psi^e."""
    Finv, cp, be, N, tau, vectors = work[1], work[2], work[3], work[4], work[5], work[6]
    eps, dev = vectors[1], vectors[2]
    if step > 0.0:
        scale = 1.0 - _SQRT_6 * mu * step / norm
        for a in range(3):
            dev[a] *= scale
    psi = mu * (dev[0] * dev[0] + dev[1] * dev[1] + dev[2] * dev[2]) + 0.5 * bulk * theta * theta
    for a in range(3):
        for b in range(a + 1):
            s = 0.0
            for k in range(3):
                s += (2.0 * mu * dev[k] + bulk * theta) * N[a, k] * N[b, k]
            tau[a, b] = tau[b, a] = s
    if step > 0.0:  # the flow changes (C^p)^-1 = F^-1 b^e F^-T; an elastic step keeps it
        for k in range(3):
            eps[k] = math.exp(2.0 * (dev[k] + theta / 3.0))  # the elastic stretches squared
        for a in range(3):
            for b in range(a + 1):
                s = 0.0
                for k in range(3):
                    s += eps[k] * N[a, k] * N[b, k]
                be[a, b] = be[b, a] = s
        _sandwich(Finv, be, cp)
        for k in range(6):
            a, b = SYMMETRIC_PAIRS[k]
            trial[i, k] = cp[a, b]
    else:
        for k in range(6):
            trial[i, k] = state[i, k]
    trial[i, PLASTIC_STRAIN] = state[i, PLASTIC_STRAIN] + step
    trial[i, PLASTIC_WORK] = plastic_work
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(dim):
                s += tau[a, k] * Finv[b, k]
            P[a, b] = s
    return psi


@njit(cache=True, _nrt=False)  # not inlined: the stages of the other laws do not compile it
def j2(F, dim, c, state, trial, i, P, work):
    """The return mapping at point i (see the module): reads the committed state[i], writes
    trial[i] and P; returns psi^e (NaN if J <= 0). `work`: (WORK, 3, 3) scratch."""
    mu, bulk, yield0, hardening = c[1], c[2], c[3], c[4]
    admissible, theta, norm = predictor(F, dim, mu, state, i, work)
    if not admissible:
        return math.nan
    eps_bar = state[i, PLASTIC_STRAIN]
    excess = _SQRT_3_2 * norm - max(yield0 + hardening * eps_bar, 0.0)
    step = 0.0
    if excess > 0.0:
        step = excess / (3.0 * mu + hardening)
        if yield0 + hardening * (eps_bar + step) < 0.0:  # the yield stress is exhausted
            step = _SQRT_3_2 * norm / (3.0 * mu)
    trial[i, HEAT] = state[i, HEAT]
    return corrector(F, dim, mu, bulk, state, trial, i, P, work, theta, norm, step,
                     state[i, PLASTIC_WORK] + _yield_integral(yield0, hardening, eps_bar, step))


def yield_stress(c: np.ndarray, state: np.ndarray) -> np.ndarray:
    """The current yield stress of each row of `state` (committed or trial)."""
    return np.maximum(c[3] + c[4] * state[:, PLASTIC_STRAIN], 0.0)


def keep_elastic_state(state: np.ndarray, F_old: np.ndarray, F_new: np.ndarray) -> None:
    """When F jumps from F_old to F_new (dim x dim, rows of `state`) without the particle
    moving (its pairs changed: materials.damage, break_pairs), carry the plastic metric so
    that the elastic state b^e = F (C^p)^-1 F^T, and with it the stress, stays as it was:
    (C^p)^-1 <- A (C^p)^-1 A^T with A = F_new^-1 F_old (in place)."""
    n, dim = F_old.shape[0], F_old.shape[1]
    old, new = np.tile(np.eye(3), (n, 1, 1)), np.tile(np.eye(3), (n, 1, 1))
    old[:, :dim, :dim], new[:, :dim, :dim] = F_old, F_new
    A = np.linalg.solve(new, old)
    M = np.empty((n, 3, 3))
    for k, (a, b) in enumerate(SYMMETRIC_PAIRS):
        M[:, a, b] = M[:, b, a] = state[:, k]
    M = np.einsum("nab,nbc,ndc->nad", A, M, A)
    for k, (a, b) in enumerate(SYMMETRIC_PAIRS):
        state[:, k] = M[:, a, b]


def _check(path: str, material: dict) -> None:
    """A softening slower than the elastic shear stiffness (3 mu + H > 0, else the return
    mapping has no unique solution)."""
    if material["hardening_modulus"] is not None:
        mu = material["youngs_modulus"] / (2.0 * (1.0 + material["poisson_ratio"]))
        if not 3.0 * mu + material["hardening_modulus"] > 0.0:
            raise InputError(f"{path}.hardening_modulus = {material['hardening_modulus']:g} softens faster than "
                             f"the elastic shear stiffness allows: it must be > -3 mu = {-3.0 * mu:g} Pa")


J2_PLASTICITY = 5
YIELD_STRESS = Key("float", None, positive, "j2_plasticity: initial von Mises yield stress [Pa]")
READOUTS = {  # of the laws with this state
    "plastic_strain": Readout("1", "equivalent plastic strain (0 for elastic laws)",
                              lambda c, state: state[:, PLASTIC_STRAIN]),
    "plastic_work": Readout("J/m^3", "plastic work per unit reference volume", lambda c, state: state[:, PLASTIC_WORK]),
}
LAW = Law(
    "j2_plasticity", J2_PLASTICITY,
    dict(ISOTROPIC_KEYS,
         yield_stress=YIELD_STRESS,
         hardening_modulus=Key("float", None, None, "j2_plasticity: H = d sigma_Y / d eps_bar, negative for "
                               "softening (default 0: perfectly plastic) [Pa]")),
    lambda m: isotropic(m, (m["yield_stress"], m.get("hardening_modulus") or 0.0)),
    optional=("hardening_modulus",), state="plastic_state", check=_check, doc="[G §4.5], [R §9.5]",
    plastic=Plastic(PLASTIC_STRAIN, PLASTIC_WORK, HEAT, yield_stress, keep_elastic_state), readouts=READOUTS)
# the elasto-plastic state, wherever the law's stress is evaluated (carried where a law names it)
for _points in ("particles", "stress_points", "gauss_points"):
    register(Field("plastic_state", "state", owner="plastic_state", points=_points, columns=FLOW + 1,
                   initial=lambda X, gid: initial_state(len(X)),
                   doc="committed (C^p)^-1, equivalent plastic strain, plastic work and heat per volume, "
                       "von Mises stress"))
