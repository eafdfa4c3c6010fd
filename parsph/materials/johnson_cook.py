"""Johnson-Cook plasticity (G. R. Johnson, W. H. Cook, A constitutive model and data for
metals subjected to large strains, high strain rates and high temperatures, 7th
International Symposium on Ballistics, The Hague, 1983): the finite-strain J2 law of
materials.elastoplastic (Hencky's law in the elastic log stretches, radial return) with
the flow stress

    sigma_Y = (A + B eps_bar^n) (1 + C ln max(eps_dot / eps_dot_0, 1)) (1 - T*^m),
    T* = (T - T_room) / (T_melt - T_room),   T = T_room + (beta w_p + Q) / (rho0 c_p),

the plastic strain rate eps_dot = d_eps / dt of the step and the temperature from the
plastic work per unit reference volume w_p converted to heat with the Taylor-Quinney
fraction beta, and the heat Q of other dissipation (the artificial viscosity's work in a
shock), adiabatic: no conduction. The return mapping solves
sqrt(3/2) |dev tau^trial| - 3 mu d_eps = sigma_Y(eps_bar_n + d_eps, d_eps / dt, T_n) for
d_eps (Newton's method kept inside a bracket that bisection shrinks), with T from the
committed state (explicit in the temperature, as the impact codes integrate it). The
plastic work grows by d_eps (q_n + q_(n+1)) / 2, the trapezoidal rule over the von Mises
stress at the step's ends (kept in the state): the time integration's stress work is
trapezoidal too, so elastic energy + plastic work keep to it even where the flow stress
drops within a step. A melted point (T* >= 1) has no flow stress and keeps no deviatoric
stress: the step that melts it books the deviatoric energy it held as plastic work. The
state is materials.elastoplastic's.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.keys import Key, in_range, non_negative, positive
from parsph.materials.elastic import ISOTROPIC_KEYS, isotropic
from parsph.materials.elastoplastic import (FLOW, HEAT, PLASTIC_STRAIN, PLASTIC_WORK, READOUTS, corrector, keep_elastic_state,
                                            predictor)
from parsph.materials.law import Law, Plastic, Readout

JOHNSON_COOK = 6
_SQRT_3_2 = math.sqrt(1.5)
# constants values: lam, mu, K, then from BASE on (another law may put them elsewhere)
A, B, N, C, M, RATE0, ROOM, MELT, PLASTIC_HEAT, CAPACITY = range(10)  # beta / (rho0 c_p), 1 / (rho0 c_p)
BASE = 3


@njit(cache=True, inline="always")
def heating(c, o, plastic_work, heat):
    """T - T_room of the plastic work w_p and the heat Q (the constants from c[o])."""
    return c[o + PLASTIC_HEAT] * plastic_work + c[o + CAPACITY] * heat


@njit(cache=True, inline="always")
def _thermal(c, o, plastic_work, heat):
    """1 - T*^m at the temperature the plastic work w_p and the heat Q have raised (0 once
    melted); the constants from c[o]."""
    t_star = heating(c, o, plastic_work, heat) / (c[o + MELT] - c[o + ROOM])
    if t_star <= 0.0:
        return 1.0
    if t_star >= 1.0:
        return 0.0
    return 1.0 - t_star ** c[o + M]


@njit(cache=True, inline="always")
def _flow(c, o, eps_bar, step, dt, thermal):
    """(sigma_Y, d sigma_Y / d step) at the plastic strain eps_bar + step over the step dt."""
    eps = eps_bar + step
    hardening = c[o + A] + c[o + B] * eps ** c[o + N]
    slope = c[o + N] * c[o + B] * eps ** (c[o + N] - 1.0) if eps > 0.0 else math.inf
    rate, rate_slope = 1.0, 0.0
    if dt > 0.0 and step > c[o + RATE0] * dt:
        rate = 1.0 + c[o + C] * math.log(step / (c[o + RATE0] * dt))
        rate_slope = c[o + C] / step
    return hardening * rate * thermal, (slope * rate + hardening * rate_slope) * thermal


@njit(cache=True, inline="always")
def return_step(c, o, q, mu, eps_bar, plastic_work, heat, dt):
    """(d_eps, sigma_Y at its end) of the radial return from the trial von Mises stress q
    (the module's equation; the constants from c[o], the temperature of `plastic_work` and
    `heat`)."""
    thermal = _thermal(c, o, plastic_work, heat)
    step = 0.0
    if q > _flow(c, o, eps_bar, 0.0, dt, thermal)[0]:
        lo, hi = 0.0, q / (3.0 * mu)  # g(lo) > 0 >= g(hi), g = q - 3 mu step - sigma_Y
        step = 0.5 * hi
        for _ in range(100):
            sigma, slope = _flow(c, o, eps_bar, step, dt, thermal)
            g = q - 3.0 * mu * step - sigma
            if g > 0.0:
                lo = step
            else:
                hi = step
            if abs(g) <= 1e-13 * q or hi - lo <= 1e-15 * hi:
                break
            guess = step + g / (3.0 * mu + slope)
            step = guess if lo < guess < hi else 0.5 * (lo + hi)
    return step, _flow(c, o, eps_bar, step, dt, thermal)[0]


@njit(cache=True, _nrt=False)  # not inlined: the stages of the other laws do not compile it
def update(F, dim, c, state, trial, i, P, work, dt):
    """The return mapping at point i (see the module): reads the committed state[i], writes
    trial[i] and P; returns psi^e (NaN if J <= 0)."""
    mu, bulk = c[1], c[2]
    admissible, theta, norm = predictor(F, dim, mu, state, i, work)
    if not admissible:
        return math.nan
    q = _SQRT_3_2 * norm
    step = return_step(c, BASE, q, mu, state[i, PLASTIC_STRAIN], state[i, PLASTIC_WORK], state[i, HEAT], dt)[0]
    trial[i, HEAT] = state[i, HEAT]
    trial[i, FLOW] = q - 3.0 * mu * step
    return corrector(F, dim, mu, bulk, state, trial, i, P, work, theta, norm, step,
                     state[i, PLASTIC_WORK] + 0.5 * step * (state[i, FLOW] + trial[i, FLOW]))


def yield_stress(c: np.ndarray, state: np.ndarray, o: int = BASE, heat: int = HEAT) -> np.ndarray:
    """The quasi-static flow stress of each row of `state` at its temperature (the heat in
    column `heat`)."""
    t_star = np.clip(heating(c, o, state[:, PLASTIC_WORK], state[:, heat]) / (c[o + MELT] - c[o + ROOM]), 0.0, 1.0)
    return (c[o + A] + c[o + B] * state[:, PLASTIC_STRAIN] ** c[o + N]) * (1.0 - t_star ** c[o + M])


def temperature(c: np.ndarray, state: np.ndarray, o: int = BASE, heat: int = HEAT) -> np.ndarray:
    """T = T_room + (beta w_p + Q) / (rho0 c_p) of each row of `state` (Q in column `heat`)."""
    return c[o + ROOM] + heating(c, o, state[:, PLASTIC_WORK], state[:, heat])


def failure_terms(c: np.ndarray, o: int = BASE) -> tuple:
    """(eps_dot_0, T* per unit plastic work, T* per unit heat): the rate and temperature the
    failure models read (materials.johnson_cook_failure)."""
    span = c[o + MELT] - c[o + ROOM]
    return c[o + RATE0], c[o + PLASTIC_HEAT] / span, c[o + CAPACITY] / span


def values(m: dict) -> tuple:
    """(A, B, n, C, m, eps_dot_0, T_room, T_melt, beta / (rho0 c_p), 1 / (rho0 c_p)) of a
    material table."""
    beta = 0.9 if m["taylor_quinney"] is None else m["taylor_quinney"]
    capacity = m["density"] * m["specific_heat"]
    return (m["jc_a"], m["jc_b"], m["jc_n"], m["jc_c"] or 0.0, m["jc_m"] or 1.0, m["reference_strain_rate"] or 1.0,
            m["room_temperature"], m["melting_temperature"], beta / capacity, 1.0 / capacity)


def _constants(m: dict):
    """(lam, mu, K, A, B, n, C, m, eps_dot_0, T_room, T_melt, beta / (rho0 c_p), 1 / (rho0 c_p))."""
    return isotropic(m, values(m))


def check(path: str, m: dict) -> None:
    """The melting point above the room's."""
    if not m["melting_temperature"] > m["room_temperature"]:
        raise InputError(f"{path}.melting_temperature = {m['melting_temperature']:g} K must be above "
                         f"{path}.room_temperature = {m['room_temperature']:g} K")


KEYS = dict(  # the flow stress's (besides the elastic constants)
    jc_a=Key("float", None, positive, "johnson_cook: A, the yield stress [Pa]"),
    jc_b=Key("float", None, non_negative, "johnson_cook: B, the strain hardening modulus [Pa]"),
    jc_n=Key("float", None, positive, "johnson_cook: n, the strain hardening exponent"),
    jc_c=Key("float", None, non_negative, "johnson_cook: C, the strain rate coefficient (default 0)"),
    jc_m=Key("float", None, positive, "johnson_cook: m, the thermal softening exponent (default 1)"),
    reference_strain_rate=Key("float", None, positive, "johnson_cook: eps_dot_0 (default 1) [1/s]"),
    room_temperature=Key("float", None, positive, "johnson_cook: T_room, the initial temperature [K]"),
    melting_temperature=Key("float", None, positive, "johnson_cook: T_melt [K]"),
    specific_heat=Key("float", None, in_range(10.0, 1.0e5), "johnson_cook: c_p [J/(kg K)] (solids and liquids: "
                      "about 100 to 4200; outside [10, 1e5] a unit is wrong)"),
    taylor_quinney=Key("float", None, in_range(0.0, 1.0), "johnson_cook: beta, the share of plastic "
                       "work turned to heat (Taylor-Quinney; default 0.9)"))
OPTIONAL = ("jc_c", "jc_m", "reference_strain_rate", "taylor_quinney")
TEMPERATURE = Readout("K", "temperature (johnson_cook; 0 for the other laws)", temperature)
LAW = Law(
    "johnson_cook", JOHNSON_COOK, dict(ISOTROPIC_KEYS, **KEYS), _constants, optional=OPTIONAL,
    state="plastic_state", check=check, doc="Johnson & Cook 1983",
    plastic=Plastic(PLASTIC_STRAIN, PLASTIC_WORK, HEAT, yield_stress, keep_elastic_state, failure_terms),
    readouts=dict(READOUTS, temperature=TEMPERATURE))
