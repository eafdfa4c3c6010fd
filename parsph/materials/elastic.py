"""Hyperelastic laws evaluated per particle inside the compiled kernels.

Each law takes F (dim x dim), writes the first Piola-Kirchhoff stress P and returns
the strain-energy density psi per unit reference volume. Missing dimensions (plane strain
in 2D, uniaxial strain in 1D) are held at unit stretch, so 3D invariants such as tr C get
(3 - dim) added. A law returns NaN for J <= 0 (an inverted particle), which the caller
reports.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.keys import Key, in_range, non_negative, positive
from parsph.materials.law import Constants, Law, moduli

SAINT_VENANT_KIRCHHOFF = 0
NEO_HOOKEAN = 1
NEO_HOOKEAN_NEARLY_INCOMPRESSIBLE = 2
MOONEY_RIVLIN = 3
TAIT_FLUID = 4


@njit(cache=True, inline="always")
def det(A, dim):
    if dim == 1:
        return A[0, 0]
    if dim == 2:
        return A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    return (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
            - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
            + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))


@njit(cache=True, inline="always")
def inverse(A, dim, out):
    """out = A^-1 for dim <= 3 (A not singular)."""
    d = det(A, dim)
    if dim == 1:
        out[0, 0] = 1.0 / d
    elif dim == 2:
        out[0, 0] = A[1, 1] / d
        out[0, 1] = -A[0, 1] / d
        out[1, 0] = -A[1, 0] / d
        out[1, 1] = A[0, 0] / d
    else:
        out[0, 0] = (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]) / d
        out[0, 1] = (A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]) / d
        out[0, 2] = (A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]) / d
        out[1, 0] = (A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]) / d
        out[1, 1] = (A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]) / d
        out[1, 2] = (A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]) / d
        out[2, 0] = (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]) / d
        out[2, 1] = (A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]) / d
        out[2, 2] = (A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]) / d


@njit(cache=True, inline="always")
def right_cauchy_green(F, dim, C):
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(dim):
                s += F[k, a] * F[k, b]
            C[a, b] = s


@njit(cache=True, inline="always")
def first_piola(F, S, dim, P):
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(dim):
                s += F[a, k] * S[k, b]
            P[a, b] = s


@njit(cache=True, _nrt=False)  # not inlined: compiled once, shared by every stage that calls it
def stress(model, F, dim, lam, mu, bulk, P, S, C, Cinv):
    """P for the law `model` with its three constants (lam, mu, bulk); returns psi (NaN if
    J <= 0). Mooney-Rivlin and Tait's fluid are functions of their own (`mooney_rivlin`,
    `tait`), so that a stage of one of these laws compiles none of the others.

    Saint Venant-Kirchhoff [G eq. 19] (with the standard lam tr(E) I term):
        S = lam tr(E) I + 2 mu E,  psi = lam/2 tr(E)^2 + mu E:E,  E = (C - I)/2.
    Compressible neo-Hookean [G eq. 44]:
        S = mu (I - C^-1) + lam ln(J) C^-1,  psi = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2.
    Nearly incompressible neo-Hookean [V §2.4.1] (Bonet & Wood):
        S = mu J^(-2/3) (I - I1/3 C^-1) + bulk J (J - 1) C^-1,
        psi = mu/2 (J^(-2/3) I1 - 3) + bulk/2 (J - 1)^2.
    """
    right_cauchy_green(F, dim, C)
    if model == SAINT_VENANT_KIRCHHOFF:
        tr = 0.0
        for a in range(dim):
            tr += 0.5 * (C[a, a] - 1.0)
        ee = 0.0
        for a in range(dim):
            for b in range(dim):
                e = 0.5 * (C[a, b] - (1.0 if a == b else 0.0))
                ee += e * e
                S[a, b] = 2.0 * mu * e + (lam * tr if a == b else 0.0)
        first_piola(F, S, dim, P)
        return 0.5 * lam * tr * tr + mu * ee
    J = det(F, dim)
    if not J > 0.0:
        return math.nan
    inverse(C, dim, Cinv)
    i1 = float(3 - dim)
    for a in range(dim):
        i1 += C[a, a]
    if model == NEO_HOOKEAN:
        lnj = math.log(J)
        for a in range(dim):
            for b in range(dim):
                S[a, b] = (mu * (1.0 if a == b else 0.0)) + (lam * lnj - mu) * Cinv[a, b]
        first_piola(F, S, dim, P)
        return 0.5 * mu * (i1 - 3.0) - mu * lnj + 0.5 * lam * lnj * lnj
    jm23 = J ** (-2.0 / 3.0)
    vol = bulk * J * (J - 1.0)
    for a in range(dim):
        for b in range(dim):
            S[a, b] = mu * jm23 * ((1.0 if a == b else 0.0) - i1 / 3.0 * Cinv[a, b]) + vol * Cinv[a, b]
    first_piola(F, S, dim, P)
    return 0.5 * mu * (jm23 * i1 - 3.0) + 0.5 * bulk * (J - 1.0) ** 2


@njit(cache=True, _nrt=False)  # not inlined: the stages of the other laws do not compile it
def mooney_rivlin(F, dim, lam, c1, c2, P, B, B2, Finv):
    """Compressible Mooney-Rivlin [R eq. 18], Kirchhoff stress from B = F F^T:
        tau = (c1 + c2 I1) B - c2 B^2 - (c1 I3^(1/3) + 2 c2 I3^(2/3) - lambda ln I3) I,
        psi = c1/2 (I1 - 3 I3^(1/3)) + c2/2 (I2 - 3 I3^(2/3)) + lambda/4 (ln I3)^2
    (the energy whose derivative is [R]'s stress: 2 dpsi/dI1 = c1, 2 dpsi/dI2 = c2);
    P = tau F^-T, psi returned (NaN if J <= 0); out of the model's dimensions B is 1."""
    J = det(F, dim)
    if not J > 0.0:
        return math.nan
    right_cauchy_green(F.T, dim, B)  # B = F F^T
    first_piola(B, B, dim, B2)  # B^2
    i1 = float(3 - dim)
    trace_b2 = float(3 - dim)
    for a in range(dim):
        i1 += B[a, a]
        trace_b2 += B2[a, a]
    i2 = 0.5 * (i1 * i1 - trace_b2)
    i3 = J * J
    ln_i3 = math.log(i3)
    cube = i3 ** (1.0 / 3.0)
    q = c1 * cube + 2.0 * c2 * cube * cube - lam * ln_i3
    inverse(F, dim, Finv)
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(dim):
                tau = (c1 + c2 * i1) * B[a, k] - c2 * B2[a, k] - (q if a == k else 0.0)
                s += tau * Finv[b, k]
            P[a, b] = s
    return 0.5 * c1 * (i1 - 3.0 * cube) + 0.5 * c2 * (i2 - 3.0 * cube * cube) + 0.25 * lam * ln_i3 * ln_i3


@njit(cache=True, _nrt=False)  # not inlined, as mooney_rivlin
def tait(F, dim, b, gamma, P, Finv):
    """Tait's fluid [R eq. 77], rho / rho0 = 1 / J:
        p = B (J^-gamma - 1),  P = -p J F^-T,  psi = B ((J^(1-gamma) - 1) / (gamma - 1) + J - 1)
    (dpsi/dJ = -p; no shear stiffness: an isochoric motion is stress-free); psi returned
    (NaN if J <= 0)."""
    J = det(F, dim)
    if not J > 0.0:
        return math.nan
    p = b * (J ** -gamma - 1.0)
    inverse(F, dim, Finv)
    for a in range(dim):
        for k in range(dim):
            P[a, k] = -p * J * Finv[k, a]
    if gamma == 1.0:
        return b * (J - 1.0 - math.log(J))
    return b * ((J ** (1.0 - gamma) - 1.0) / (gamma - 1.0) + J - 1.0)


@njit(cache=True, _nrt=False)
def symmetric_extremes(C, dim):
    """(smallest, largest) eigenvalue of the symmetric positive semi-definite dim x dim
    block of C (a 3x3 array; in 3D its diagonal is overwritten), in closed form."""
    if dim == 1:
        return C[0, 0], C[0, 0]
    if dim == 2:
        half = 0.5 * (C[0, 0] + C[1, 1])
        root = math.sqrt(max(half * half - (C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]), 0.0))
        return half - root, half + root
    q = (C[0, 0] + C[1, 1] + C[2, 2]) / 3.0
    off = C[0, 1] ** 2 + C[0, 2] ** 2 + C[1, 2] ** 2
    p = math.sqrt(((C[0, 0] - q) ** 2 + (C[1, 1] - q) ** 2 + (C[2, 2] - q) ** 2 + 2.0 * off) / 6.0)
    if p <= 1e-14 * q:  # (nearly) isotropic or zero: also keeps p**3 from underflowing to zero
        return q, q
    for a in range(3):
        C[a, a] -= q
    r = max(-1.0, min(1.0, det(C, 3) / (2.0 * p ** 3)))
    phi = math.acos(r) / 3.0
    return q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0), q + 2.0 * p * math.cos(phi)


# ------------------------------------------------------------------ the laws' declarations

ISOTROPIC_KEYS = {"youngs_modulus": Key("float", None, positive, "Young's modulus E [Pa]"),
                  "poisson_ratio": Key("float", None, in_range(-1.0, 0.5, True, True), "Poisson's ratio nu")}
SHEAR_MODULUS = Key("float", None, positive, "shear modulus mu [Pa]")


def isotropic(material: dict, extra: tuple = ()) -> Constants:
    """Constants (lambda, mu, K, *extra) from Young's modulus and Poisson's ratio."""
    youngs, nu = material["youngs_modulus"], material["poisson_ratio"]
    lam = youngs * nu / ((1 + nu) * (1 - 2 * nu))
    mu = youngs / (2 * (1 + nu))
    k = lam + 2.0 * mu / 3.0
    return Constants(values=np.array((lam, mu, k) + extra), lam=lam, mu=mu, bulk=k, youngs=youngs,
                     wave_speed=math.sqrt((lam + 2 * mu) / material["density"]))


def _nearly_incompressible_constants(m: dict) -> Constants:
    mu, k = m["shear_modulus"], m["bulk_modulus"]
    return moduli((k - 2.0 * mu / 3.0, mu, k), mu, k, m["density"])


def _mooney_rivlin_constants(m: dict) -> Constants:  # psi = lambda (ln J)^2 under dilation: K = 2 lambda
    return moduli((m["lambda"], m["c1"], m["c2"]), m["c1"] + m["c2"], 2.0 * m["lambda"], m["density"])


def _tait_constants(m: dict) -> Constants:  # dp / d(rho / rho0) = gamma B at rest; no shear stiffness
    return moduli((m["tait_b"], m["tait_gamma"], 0.0), 0.0, m["tait_gamma"] * m["tait_b"], m["density"])


LAWS = (
    Law("saint_venant_kirchhoff", SAINT_VENANT_KIRCHHOFF, ISOTROPIC_KEYS, isotropic, doc="[G eq. 19]"),
    Law("neo_hookean", NEO_HOOKEAN, ISOTROPIC_KEYS, isotropic, doc="[G eq. 44]"),
    Law("neo_hookean_nearly_incompressible", NEO_HOOKEAN_NEARLY_INCOMPRESSIBLE,
        {"shear_modulus": SHEAR_MODULUS, "bulk_modulus": Key("float", None, positive, "bulk modulus K [Pa]")},
        _nearly_incompressible_constants, doc="[V §2.4.1]"),
    Law("mooney_rivlin", MOONEY_RIVLIN,
        {"c1": Key("float", None, positive, "mooney_rivlin: c1 of [R eq. 18] [Pa]"),
         "c2": Key("float", None, non_negative, "mooney_rivlin: c2 of [R eq. 18] [Pa]"),
         "lambda": Key("float", None, positive, "mooney_rivlin: lambda of [R eq. 18] [Pa]")},
        _mooney_rivlin_constants, doc="[R eq. 18]"),
    Law("tait_fluid", TAIT_FLUID,
        {"tait_b": Key("float", None, positive, "tait_fluid: B of p = B ((rho/rho0)^gamma - 1) [R eq. 77] [Pa]"),
         "tait_gamma": Key("float", None, positive, "tait_fluid: gamma of [R eq. 77]")},
        _tait_constants, fluid=True, doc="[R eq. 77]"),
)
