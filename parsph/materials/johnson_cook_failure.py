"""Johnson-Cook failure (G. R. Johnson, W. H. Cook, Fracture characteristics of three
metals subjected to various strains, strain rates, temperatures and pressures, Engineering
Fracture Mechanics 21 (1985) 31-48) over a plastic law (`material.jc_d1` ... `jc_d5`):
the strain to fracture

    eps_f = (D1 + D2 exp(D3 sigma*)) (1 + D4 ln max(eps_dot / eps_dot_0, 1)) (1 + D5 T*),

sigma* = sigma_m / sigma_eq the stress triaxiality (mean over von Mises stress), with the
law's reference strain rate eps_dot_0 and homologous temperature T* (materials.law.Plastic:
the Johnson-Cook laws heat adiabatically, J2 does not), and the damage index
D = sum d_eps / eps_f over the plastic strain increments, at the stress and rate of each
step. A point fails when D reaches 1: its damage (materials.damage) becomes 1, it carries
no stress from then on, and, with material.break_pairs, loses its pairs. Before that its
stress is the law's: the model does not soften.

The constants must keep eps_f positive wherever a yielding point can be: at any
triaxiality (its mean stress over its flow stress, unbounded under high pressure or
tension), any rate from eps_dot_0 on and T* in [0, 1]; else every point that yields there
fails at once. So D2 >= 0, D4 >= 0, D5 > -1, D1 + D2 > 0 and, unless D3 = 0, D1 >= 0
(Johnson & Cook's Armco iron, D1 = -2.20, D3 = -0.47, is refused: its eps_f is negative
beyond sigma* = 1.92, which a spalling plate reaches).

The index is kept in the damage state's STRAIN column (the tensile model's largest
principal strain): the evaluation writes D + d_eps / eps_f to the trial row, the commit
fails the points whose committed index has reached 1 (`fail`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.keys import Key, greater_than, non_negative
from parsph.materials import damage
from parsph.materials.elastoplastic import PLASTIC_STRAIN, PLASTIC_WORK
from parsph.materials.law import FailureModel

JOHNSON_COOK_FAILURE = 2  # the failure model's id (materials.damage.TENSILE is 1)
INDEX = damage.STRAIN  # the damage state's column of the index D
D1, D2, D3, D4, D5, RATE0, HOMOLOGOUS, HOMOLOGOUS_HEAT, HEAT = range(9)  # the constants appended to the law's
SIZE = 9
KIRCHHOFF = 5  # the scratch matrix where the plastic laws leave their full Kirchhoff stress

KEYS = dict(
    jc_d1=Key("float", None, None, "Johnson-Cook failure (1985): D1 of the strain to fracture; giving it enables "
              "the model (plastic laws: j2, johnson_cook, mie_gruneisen); D1 + D2 > 0, and D1 >= 0 unless D3 = 0"),
    jc_d2=Key("float", None, non_negative, "Johnson-Cook failure: D2 (default 0)"),
    jc_d3=Key("float", None, None, "Johnson-Cook failure: D3, of the triaxiality (default 0)"),
    jc_d4=Key("float", None, non_negative, "Johnson-Cook failure: D4, of the strain rate (default 0; >= 0: "
              "1 + D4 ln(rate) stays positive at every rate)"),
    jc_d5=Key("float", None, greater_than(-1.0), "Johnson-Cook failure: D5, of the temperature (default 0; > -1: "
              "1 + D5 T* stays positive up to the melting point)"),
)


def values(material: dict, law, law_values: np.ndarray) -> np.ndarray:
    """The constants the compiled update reads after the law's: D1..D5, the law's eps_dot_0
    and T* per unit plastic work and per unit heat (materials.law.Plastic.failure_terms; 1/s
    and none without), and its state's column of the heat."""
    terms = law.plastic.failure_terms(law_values) if law.plastic.failure_terms else (1.0, 0.0, 0.0)
    return np.array([material[k] or 0.0 for k in KEYS] + list(terms) + [law.plastic.heat])


@njit(cache=True)
def strain_to_fracture(c, o, triaxiality, rate, temperature):
    """eps_f at the triaxiality sigma*, the plastic strain rate over eps_dot_0 and T*
    (the module's equation; the constants from c[o])."""
    rate_factor = 1.0 + c[o + D4] * math.log(rate) if rate > 1.0 else 1.0
    return (c[o + D1] + c[o + D2] * math.exp(c[o + D3] * triaxiality)) * rate_factor * \
        (1.0 + c[o + D5] * temperature)


@njit(cache=True, _nrt=False)  # not inlined: the stages without it do not compile it
def accumulate(P, F, dim, c, state, trial, damaged, damaged_trial, i, work, dt):
    """After the law's update at point i: the index D + d_eps / eps_f into damaged_trial[i]
    (d_eps the law's plastic strain increment, the triaxiality from the law's Kirchhoff
    stress in work[KIRCHHOFF]), and the work the point has taken, P and F
    (materials.damage)."""
    damage.record(P, F, dim, damaged, damaged_trial, i)
    step = trial[i, PLASTIC_STRAIN] - state[i, PLASTIC_STRAIN]
    index = damaged[i, INDEX]
    if step > 0.0:
        o = c.shape[0] - SIZE
        tau = work[KIRCHHOFF]
        mean = (tau[0, 0] + tau[1, 1] + tau[2, 2]) / 3.0
        s = 0.0
        for a in range(3):
            for b in range(3):
                dev = tau[a, b] - (mean if a == b else 0.0)
                s += dev * dev
        equivalent = math.sqrt(1.5 * s)
        triaxiality = mean / equivalent if equivalent > 0.0 else 0.0
        rate = step / (dt * c[o + RATE0]) if dt > 0.0 else 0.0
        heating = c[o + HOMOLOGOUS] * trial[i, PLASTIC_WORK] + c[o + HOMOLOGOUS_HEAT] * trial[i, int(c[o + HEAT])]
        temperature = min(max(heating, 0.0), 1.0)
        fracture = strain_to_fracture(c, o, triaxiality, rate, temperature)
        index += step / fracture if fracture > 0.0 else math.inf
    damaged_trial[i, INDEX] = index


def fail(state: np.ndarray) -> None:
    """The points (committed rows of the damage `state`) whose index has reached 1 fail."""
    state[state[:, INDEX] >= 1.0, damage.DAMAGE] = 1.0


def _advance(state: np.ndarray, body, support: np.ndarray, dt: float) -> None:
    fail(state)


def stresses(P: np.ndarray, F: np.ndarray, dim: int, state: np.ndarray) -> None:
    """The law's stress (in place) until a point fails, then none."""
    P[state[:, damage.DAMAGE] >= 1.0] = 0.0


def check(path: str, material: dict, law) -> None:
    """Over a plastic law, whose state holds the plastic strain and work where the
    elasto-plastic laws keep them; D1 + D2 exp(D3 sigma*) positive at every triaxiality
    (the module's rule; the keys' checks hold the other constants to it)."""
    if law.plastic is None or (law.plastic.strain, law.plastic.work) != (PLASTIC_STRAIN, PLASTIC_WORK):
        raise InputError(f"{path}.jc_d1: Johnson-Cook failure accumulates plastic strain and applies to the "
                         f"plastic laws, not to model '{law.name}' (it has no plastic strain)")
    d1, d2, d3 = (material[k] or 0.0 for k in ("jc_d1", "jc_d2", "jc_d3"))
    if d1 + d2 <= 0.0:
        raise InputError(f"{path}.jc_d1 + jc_d2 = {d1 + d2:g} must be > 0: it is the strain to fracture at "
                         "triaxiality 0, where every point that yields would fail at once")
    if d1 < 0.0 and d3 != 0.0:
        edge = math.log(-d1 / d2) / d3
        raise InputError(f"{path}.jc_d1 = {d1:g} must be >= 0 with jc_d3 = {d3:g}: the strain to fracture "
                         f"D1 + D2 exp(D3 sigma*) is not positive at triaxialities sigma* {'above' if d3 < 0 else 'below'} "
                         f"{edge:.3g} (a yielding point's mean stress over its flow stress, unbounded under pressure "
                         "or tension), where every point that yields would fail at once")


def _index(state: np.ndarray, body) -> np.ndarray:
    return state[:, INDEX]


MODEL = FailureModel("johnson_cook", JOHNSON_COOK_FAILURE, KEYS, _advance, stresses, _index, check, values)
