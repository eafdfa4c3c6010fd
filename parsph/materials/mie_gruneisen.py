"""The Mie-Grüneisen equation of state with a linear shock-velocity relation U_s = c0 + s u_p
(M. A. Meyers, Dynamic Behavior of Materials, Wiley 1994, ch. 4), for shock-loaded solids,
with a perfectly plastic von Mises strength (or none):

    p = p_H(eta) (1 - Gamma0 eta / 2) + Gamma0 E,   eta = 1 - J = 1 - rho0 / rho,
    p_H = rho0 c0^2 eta / (1 - s eta)^2 in compression, rho0 c0^2 eta in tension,

the pressure of the Hugoniot p_H, whose energy is p_H eta / 2 per reference volume, moved
off it by the internal energy E per unit reference volume with Gamma rho = Gamma0 rho0. E
is the work of the pressure, dE = -p dJ (by the trapezoidal rule over the step, solved with
p in closed form: p is linear in E), plus the plastic work and the heat of other dissipation
(the artificial viscosity's work, which carries a shock's entropy: with it the shocked
state is on the Hugoniot, E = p eta / 2, not on the isentrope). The deviatoric part is
materials.elastoplastic's Hencky law and radial return with the shear modulus and a
constant yield stress (none: no shear strength once it flows, a fluid) or Johnson-Cook's
flow stress (materials.johnson_cook, given its constants: the impact codes' pairing). The
strain energy the balance counts is the deviatoric elastic energy plus the pressure's work.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.fields import Field, register
from parsph.keys import Key, in_range, non_negative, positive
from parsph.materials import johnson_cook
from parsph.materials.elastic import SHEAR_MODULUS
from parsph.materials.elastoplastic import (COLUMNS, PLASTIC_STRAIN, PLASTIC_WORK, READOUTS, YIELD_STRESS, corrector,
                                            initial_state, keep_elastic_state, predictor)
from parsph.materials.law import Law, Plastic, Readout, moduli

MIE_GRUNEISEN = 7
_SQRT_3_2 = math.sqrt(1.5)
# state: the elasto-plastic columns, then the pressure's work, J and p of the last evaluation, the heat
# and the von Mises Kirchhoff stress of the last evaluation
ENERGY, LAST_J, PRESSURE, HEAT, FLOW = COLUMNS, COLUMNS + 1, COLUMNS + 2, COLUMNS + 3, COLUMNS + 4
# constants values: lam, mu, K, then (Johnson-Cook's from STRENGTH + 1 when STRENGTH is 1)
YIELD, RHO_C2, SLOPE, GAMMA, STRENGTH = 3, 4, 5, 6, 7


@njit(cache=True, inline="always")
def hugoniot(c, eta):
    """The pressure of the reference curve at eta = 1 - J, and its tangent over rho0 c0^2."""
    if eta <= 0.0:
        return c[RHO_C2] * eta, 1.0
    d = 1.0 - c[SLOPE] * eta
    return c[RHO_C2] * eta / (d * d), (1.0 + c[SLOPE] * eta) / (d * d * d)


@njit(cache=True, _nrt=False)  # not inlined: the stages of the other laws do not compile it
def update(F, dim, c, state, trial, i, P, work, dt):
    """The pressure, the deviatoric return mapping and the new state at point i (see the
    module); returns the strain energy (NaN if J <= 0)."""
    mu, yield_stress = c[1], c[YIELD]
    admissible, theta, norm = predictor(F, dim, mu, state, i, work)
    if not admissible:
        return math.nan
    step = 0.0
    heat = state[i, HEAT]
    q = _SQRT_3_2 * norm
    if c[STRENGTH] > 0.0:  # the plastic work as Johnson-Cook's (trapezoidal in the flow stress)
        step = johnson_cook.return_step(c, STRENGTH + 1, q, mu, state[i, PLASTIC_STRAIN], state[i, PLASTIC_WORK],
                                        heat, dt)[0]
        trial[i, FLOW] = q - 3.0 * mu * step
        plastic_work = state[i, PLASTIC_WORK] + 0.5 * step * (state[i, FLOW] + trial[i, FLOW])
    else:
        if q > yield_stress:  # perfectly plastic: back to the yield surface
            step = (q - yield_stress) / (3.0 * mu)
        plastic_work = state[i, PLASTIC_WORK] + yield_stress * step
    psi = corrector(F, dim, mu, 0.0, state, trial, i, P, work, theta, norm, step, plastic_work)  # deviatoric
    J = math.exp(theta)
    eta = 1.0 - J
    p_h = hugoniot(c, eta)[0]
    reference = p_h * (1.0 - 0.5 * c[GAMMA] * eta) if eta > 0.0 else p_h
    dJ = J - state[i, LAST_J]
    p = (reference + c[GAMMA] * (state[i, ENERGY] - 0.5 * state[i, PRESSURE] * dJ + plastic_work + heat)) / (
        1.0 + 0.5 * c[GAMMA] * dJ)
    energy = state[i, ENERGY] - 0.5 * (state[i, PRESSURE] + p) * dJ
    trial[i, ENERGY], trial[i, LAST_J], trial[i, PRESSURE], trial[i, HEAT] = energy, J, p, heat
    Finv, tau = work[1], work[5]
    for a in range(dim):
        for b in range(dim):
            P[a, b] -= p * J * Finv[b, a]
    for a in range(3):  # the whole Kirchhoff stress, as the plastic laws leave it (failure models)
        tau[a, a] -= p * J
    return psi + energy


def _initial(n: int) -> np.ndarray:
    out = initial_state(n, FLOW + 1)
    out[:, LAST_J] = 1.0
    return out



def _johnson_cook(c: np.ndarray) -> bool:
    return c[STRENGTH] > 0.0


def yield_stress(c: np.ndarray, state: np.ndarray) -> np.ndarray:
    if _johnson_cook(c):
        return johnson_cook.yield_stress(c, state, STRENGTH + 1, HEAT)
    return np.full(len(state), c[YIELD])


def temperature(c: np.ndarray, state: np.ndarray) -> np.ndarray:
    """Johnson-Cook's temperature of the plastic work's and the other dissipation's heat (0
    without its strength)."""
    if _johnson_cook(c):
        return johnson_cook.temperature(c, state, STRENGTH + 1, HEAT)
    return np.zeros(len(state))


def failure_terms(c: np.ndarray) -> tuple:
    """Johnson-Cook's rate and heating with its strength (materials.johnson_cook.failure_terms)."""
    return johnson_cook.failure_terms(c, STRENGTH + 1) if _johnson_cook(c) else (1.0, 0.0, 0.0)


def _constants(m: dict):
    """(lam, mu, K, yield stress, rho0 c0^2, s, Gamma0, 0 or 1: Johnson-Cook's strength, and
    then its constants), K = rho0 c0^2."""
    bulk = m["density"] * m["sound_speed"] ** 2
    strength = (1.0, *johnson_cook.values(m)) if m.get("jc_a") is not None else (0.0,)
    return moduli((bulk - 2.0 * m["shear_modulus"] / 3.0, m["shear_modulus"], bulk, m["yield_stress"] or 0.0, bulk,
                   m["hugoniot_slope"], m["gruneisen_gamma"], *strength), m["shear_modulus"], bulk, m["density"])


def _check(path: str, m: dict) -> None:
    """One strength: a yield stress or Johnson-Cook's constants, whole."""
    given = [k for k in johnson_cook.KEYS if m[k] is not None]
    if not given:
        return
    if m["yield_stress"] is not None:
        raise InputError(f"{path}.yield_stress and {path}.{given[0]}: give one strength, a constant yield stress "
                         "or Johnson-Cook's constants")
    missing = [k for k in johnson_cook.KEYS if k not in johnson_cook.OPTIONAL and m[k] is None]
    if missing:
        raise InputError(f"missing required key '{path}.{missing[0]}' for Johnson-Cook's strength under model "
                         f"'mie_gruneisen'")
    johnson_cook.check(path, m)


LAW = Law(
    "mie_gruneisen", MIE_GRUNEISEN,
    {"shear_modulus": SHEAR_MODULUS,
     "sound_speed": Key("float", None, positive, "mie_gruneisen: c0 of U_s = c0 + s u_p, the bulk sound speed [m/s]"),
     "hugoniot_slope": Key("float", None, in_range(0.0, 5.0), "mie_gruneisen: s of U_s = c0 + s u_p (solids and "
                           "liquids: about 0.5 to 3, K' = 4 s - 1; the Hugoniot's pole is at 1 - J = 1 / s)"),
     "gruneisen_gamma": Key("float", None, non_negative, "mie_gruneisen: Gamma0, Grüneisen's coefficient"),
     "yield_stress": YIELD_STRESS,
     **johnson_cook.KEYS},
    _constants, optional=("yield_stress", *johnson_cook.KEYS), state="shock_state", check=_check,
    doc="Meyers 1994, ch. 4", plastic=Plastic(PLASTIC_STRAIN, PLASTIC_WORK, HEAT, yield_stress, keep_elastic_state,
                                                 failure_terms),
    readouts=dict(READOUTS, temperature=Readout("K", johnson_cook.TEMPERATURE.doc, temperature)))
for _points in ("particles", "stress_points", "gauss_points"):
    register(Field("shock_state", "state", owner="shock_state", points=_points, columns=FLOW + 1,
                   initial=lambda X, gid: _initial(len(X)),
                   doc="the elasto-plastic state, the pressure's work per reference volume, J, p, the heat and "
                       "the von Mises stress"))
