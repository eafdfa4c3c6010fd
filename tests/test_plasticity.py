"""The J2 return mapping in principal logarithmic stretches (materials/elastoplastic.py,
`material.model = "j2_plasticity"`), driven point by point through the compiled update with
a commit after each increment, as the loop does: uniaxial stress and pure shear against the
closed-form elastic-plastic responses (Hencky's law in log strains is small-strain J2 for
proportional loading), consistency, objectivity, plastic work, softening to zero, plane
strain as 3D with F33 = 1."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from parsph.materials import constants, elastoplastic, update

E, NU, RHO, YIELD = 78.2e9, 0.3, 2700.0, 1.0e9  # the aluminium of [G §4.5]
MU = E / (2 * (1 + NU))


def law(hardening: float = 0.0) -> np.ndarray:
    return constants(dict(model="j2_plasticity", density=RHO, youngs_modulus=E, poisson_ratio=NU,
                          yield_stress=YIELD, hardening_modulus=hardening)).values


def evaluate(c: np.ndarray, F: np.ndarray, state: np.ndarray) -> tuple:
    """(P, psi, new state) at one point."""
    dim = F.shape[-1]
    P, psi, trial = np.empty((1, dim, dim)), np.empty(1), state.copy()
    update.stresses(update.J2_PLASTICITY, np.ascontiguousarray(F[None]), dim, c, state, trial, P, psi)
    return P[0], psi[0], trial


def kirchhoff(F: np.ndarray, P: np.ndarray) -> np.ndarray:
    return P @ F.T


def uniaxial(c: np.ndarray, strain: float, state: np.ndarray) -> tuple:
    """(tau_11, new state) at axial log strain `strain` with the lateral stretch that frees
    the lateral stress (3D)."""
    def lateral(s):
        F = np.diag([math.exp(strain), math.exp(s), math.exp(s)])
        P, _, _ = evaluate(c, F, state)
        return kirchhoff(F, P)[1, 1]

    s = brentq(lateral, -strain, strain, xtol=1e-16, rtol=4 * np.finfo(float).eps, maxiter=200)
    F = np.diag([math.exp(strain), math.exp(s), math.exp(s)])
    P, _, trial = evaluate(c, F, state)
    return kirchhoff(F, P)[0, 0], trial


@pytest.mark.parametrize("hardening", [0.0, 0.05 * E, -0.02 * E])
def test_uniaxial_stress_matches_the_closed_form(hardening):
    """tau = E eps up to yield, then sigma_Y0 + E H / (E + H) (eps - sigma_Y0 / E), to 1e-10,
    at every increment of a monotonic loading to 20 times the yield strain."""
    c = law(hardening)
    state = elastoplastic.initial_state(1)
    yield_strain = YIELD / E
    for strain in np.linspace(0.0, 20 * yield_strain, 41)[1:]:
        tau, state = uniaxial(c, strain, state)
        expected = E * strain if strain <= yield_strain else \
            YIELD + E * hardening / (E + hardening) * (strain - yield_strain)
        assert tau == pytest.approx(expected, rel=1e-10)
        plastic = 0.0 if strain <= yield_strain else (strain - yield_strain) * E / (E + hardening)
        assert state[0, elastoplastic.PLASTIC_STRAIN] == pytest.approx(plastic, rel=1e-9, abs=1e-15)


def rotation(angle: float, dim: int = 3) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    Q = np.eye(dim)
    Q[:2, :2] = [[c, -s], [s, c]]
    return Q


@pytest.mark.parametrize("hardening", [0.0, 0.1 * E])
def test_pure_shear_matches_the_closed_form(hardening):
    """Plane strain F = R diag(e^s, e^-s) R^T with R at 45 degrees (the stretch of simple
    shear): the shear stress is 2 mu s up to k = sigma_Y / sqrt(3), then
    2 mu s - sqrt(3) mu eps_bar with eps_bar = (2 sqrt(3) mu s - sigma_Y0) / (3 mu + H)."""
    c = law(hardening)
    R = rotation(math.pi / 4, 2)
    state = elastoplastic.initial_state(1)
    for s in np.linspace(0.0, 0.1, 51)[1:]:
        F = R @ np.diag([math.exp(s), math.exp(-s)]) @ R.T
        P, _, state = evaluate(c, F, state)
        eps_bar = max(0.0, (2 * math.sqrt(3) * MU * s - YIELD) / (3 * MU + hardening))
        assert kirchhoff(F, P)[0, 1] == pytest.approx(2 * MU * s - math.sqrt(3) * MU * eps_bar, rel=1e-10)
        assert state[0, elastoplastic.PLASTIC_STRAIN] == pytest.approx(eps_bar, rel=1e-9, abs=1e-15)


def equivalent_stress(F: np.ndarray, P: np.ndarray) -> float:
    dim = F.shape[-1]
    tau = np.zeros((3, 3))
    tau[:dim, :dim] = kirchhoff(F, P)
    dev = tau - np.trace(tau) / 3 * np.eye(3)
    return math.sqrt(1.5 * np.sum(dev * dev))


def smooth_path(count: int, dim: int = 3):
    """count deformation gradients along one smooth loading path, s in (0, 1]: strains of
    about 0.1, eight times the yield strain, with a turn of the principal axes."""
    rng = np.random.default_rng(7)
    A, B, C = (0.08 * rng.standard_normal((dim, dim)) for _ in range(3))
    for s in np.linspace(0.0, 1.0, count + 1)[1:]:
        yield np.eye(dim) + s * A + s * s * B + 0.3 * math.sin(3 * s) * C


def stress_work(c: np.ndarray, count: int, check=None) -> tuple:
    """(sum of P_mid : dF, psi^e + w_p, w_p at the end) along smooth_path(count); `check(F, P,
    state, trial)` after each increment."""
    state = elastoplastic.initial_state(1)
    F_old, P_old, work, psi = np.eye(3), np.zeros((3, 3)), 0.0, 0.0
    for F in smooth_path(count):
        P, psi, trial = evaluate(c, F, state)
        if check:
            check(F, P, state, trial)
        work += np.sum(0.5 * (P + P_old) * (F - F_old))
        F_old, P_old, state = F, P, trial
    return work, psi + state[0, elastoplastic.PLASTIC_WORK], state[0, elastoplastic.PLASTIC_WORK]


@pytest.mark.parametrize("hardening", [0.0, 0.05 * E, -0.05 * E])
def test_consistency_and_plastic_work(hardening):
    """After every plastic increment the stress is on the yield surface (below it after an
    elastic one); the plastic work never decreases; the stress work sum P_mid : dF matches
    psi^e + w_p to 1e-4 of the plastic work, better with smaller increments."""
    c = law(hardening)
    plastic_steps = []

    def check(F, P, state, trial):
        step = trial[0, elastoplastic.PLASTIC_STRAIN] - state[0, elastoplastic.PLASTIC_STRAIN]
        yield_stress = max(YIELD + hardening * trial[0, elastoplastic.PLASTIC_STRAIN], 0.0)
        if step > 0:
            plastic_steps.append(step)
            assert equivalent_stress(F, P) == pytest.approx(yield_stress, rel=1e-10, abs=1e-6 * YIELD)
        else:
            assert equivalent_stress(F, P) <= yield_stress * (1 + 1e-12)
        assert trial[0, elastoplastic.PLASTIC_WORK] >= state[0, elastoplastic.PLASTIC_WORK]

    errors = []
    for count in (200, 800):
        work, stored, plastic = stress_work(c, count, check)
        errors.append(abs(stored - work) / plastic)
    assert len(plastic_steps) > 700
    assert errors[1] < errors[0] < 1e-4


def reference_return(c: np.ndarray, F: np.ndarray, plastic_inverse: np.ndarray, eps_bar: float) -> tuple:
    """A second implementation of the return (numpy, LAPACK's eigh): (P, (C^p)^-1, eps_bar)."""
    _, mu, bulk, yield0, hardening = c
    values, N = np.linalg.eigh(F @ plastic_inverse @ F.T)
    eps = 0.5 * np.log(values)
    theta = eps.sum()
    dev = eps - theta / 3
    norm = 2 * mu * np.linalg.norm(dev)
    excess = math.sqrt(1.5) * norm - max(yield0 + hardening * eps_bar, 0.0)
    step = 0.0
    if excess > 0:
        step = excess / (3 * mu + hardening)
        if yield0 + hardening * (eps_bar + step) < 0:
            step = math.sqrt(1.5) * norm / (3 * mu)
        dev = dev * (1 - math.sqrt(6) * mu * step / norm)
    Finv = np.linalg.inv(F)
    tau = N @ np.diag(2 * mu * dev + bulk * theta) @ N.T
    elastic = N @ np.diag(np.exp(2 * (dev + theta / 3))) @ N.T
    return tau @ Finv.T, Finv @ elastic @ Finv.T, eps_bar + step


@pytest.mark.parametrize("hardening", [0.0, -0.05 * E])
def test_compiled_return_matches_a_second_implementation(hardening):
    """Stress, (C^p)^-1 and eps_bar along a path that turns the principal axes, against the
    numpy implementation above, to 1e-12."""
    c = law(hardening)
    state = elastoplastic.initial_state(1)
    plastic_inverse, eps_bar = np.eye(3), 0.0
    for F in smooth_path(200):
        P, _, state = evaluate(c, F, state)
        P_ref, plastic_inverse, eps_bar = reference_return(c, F, plastic_inverse, eps_bar)
        np.testing.assert_allclose(P, P_ref, rtol=0, atol=1e-12 * np.abs(P_ref).max())
        k = [0, 1, 2, 0, 1, 0], [0, 1, 2, 1, 2, 2]
        np.testing.assert_allclose(state[0, :6], plastic_inverse[k], rtol=0, atol=1e-12)
        assert state[0, elastoplastic.PLASTIC_STRAIN] == pytest.approx(eps_bar, rel=1e-12)
    assert eps_bar > 0.1


def test_objective_under_a_superposed_rotation():
    """P(Q F) = Q P(F), the same psi and the same new state (C^p is a material tensor),
    after a plastic history."""
    c = law(0.05 * E)
    state = elastoplastic.initial_state(1)
    for F in smooth_path(60):
        P, psi, trial = evaluate(c, F, state)
        Q = rotation(0.7) @ rotation(1.3).T[[2, 0, 1]][:, [2, 0, 1]]
        Pq, psi_q, trial_q = evaluate(c, Q @ F, state)
        np.testing.assert_allclose(Pq, Q @ P, rtol=0, atol=1e-11 * np.abs(P).max())
        assert psi_q == pytest.approx(psi, rel=1e-10)
        np.testing.assert_allclose(trial_q, trial, rtol=1e-10, atol=1e-13)
        state = trial
    assert state[0, elastoplastic.PLASTIC_STRAIN] > 0


def test_plane_strain_is_3d_with_unit_out_of_plane_stretch():
    """The 2D update (F33 = 1 held) equals the 3D one, and flows out of plane: (C^p)^-1_zz
    departs from 1."""
    c = law(0.02 * E)
    s2 = s3 = elastoplastic.initial_state(1)
    for F in smooth_path(80, dim=2):
        F3 = np.eye(3)
        F3[:2, :2] = F
        P2, psi2, s2 = evaluate(c, F, s2)
        P3, psi3, s3 = evaluate(c, F3, s3)
        np.testing.assert_allclose(P2, P3[:2, :2], rtol=0, atol=1e-12 * np.abs(P3).max())
        assert psi2 == pytest.approx(psi3, rel=1e-12)
    np.testing.assert_allclose(s2, s3, rtol=1e-12, atol=1e-15)
    assert abs(s2[0, 2] - 1.0) > 1e-4


def test_softening_to_zero_leaves_no_deviatoric_stress():
    """[R §9.5]'s softening (H = -E/10): once eps_bar passes sigma_Y0 / |H| the yield stress
    is zero and so is the deviatoric stress; the pressure remains."""
    c = law(-0.1 * E)
    state = elastoplastic.initial_state(1)
    for s in np.linspace(0.0, 0.5, 26)[1:]:  # pure shear in plane strain, with a dilation
        F = np.diag([math.exp(s + 0.001), math.exp(-s + 0.001), 1.0])
        P, _, state = evaluate(c, F, state)
    assert state[0, elastoplastic.PLASTIC_STRAIN] > YIELD / (0.1 * E)
    assert equivalent_stress(F, P) < 1e-6 * YIELD
    tau = kirchhoff(F, P)
    assert np.trace(tau) / 3 == pytest.approx(constants(dict(
        model="j2_plasticity", density=RHO, youngs_modulus=E, poisson_ratio=NU, yield_stress=YIELD)).bulk * 0.002,
        rel=1e-9)


def test_inverted_point_gives_nan():
    c = law()
    _, psi, _ = evaluate(c, np.diag([1.0, -1.0, 1.0]), elastoplastic.initial_state(1))
    assert math.isnan(psi)


def test_scene_keys_of_plasticity_and_damage_are_checked():
    """A softening faster than 3 mu, damage on a fluid or on stress points, a yield stress on
    an elastic law: each refused with a message naming the key."""
    from parsph.errors import InputError
    from physics import scene_from

    taylor = ["material.failure_strain=0.1"]
    assert scene_from("taylor_impact", taylor).material.failure_strain == 0.1
    with pytest.raises(InputError, match=r"material.hardening_modulus = -1e\+11 softens faster"):
        scene_from("taylor_impact", ["material.hardening_modulus=-1e11"])
    with pytest.raises(InputError, match="material.yield_stress does not apply to model 'neo_hookean'"):
        scene_from("taylor_impact", ["material.model='neo_hookean'"])
    with pytest.raises(InputError, match="material.failure_strain: damage is for solids computed at the particles"):
        scene_from("rubber_ring", ["material.failure_strain=0.1"])


@pytest.mark.parametrize("dim", [2, 3])
def test_a_jump_of_F_without_motion_keeps_the_elastic_state(dim):
    """elastoplastic.keep_elastic_state (a particle's pairs broke, its F jumped): the plastic
    metric takes the change, so b^e = F (C^p)^-1 F^T, and with it the stress, is unchanged."""
    from parsph.materials.elastoplastic import SYMMETRIC_PAIRS, keep_elastic_state

    rng = np.random.default_rng(dim)
    n = 5
    F_old = np.eye(dim) + 0.2 * rng.standard_normal((n, dim, dim))
    F_new = F_old + 0.1 * rng.standard_normal((n, dim, dim))
    G = np.eye(3) + 0.1 * rng.standard_normal((n, 3, 3))
    metric = np.einsum("nab,ncb->nac", G, G)  # symmetric positive definite (C^p)^-1
    state = np.zeros((n, 8))
    for k, (a, b) in enumerate(SYMMETRIC_PAIRS):
        state[:, k] = metric[:, a, b]
    state[:, 6:] = [0.3, 1e6]  # plastic strain and work: untouched

    def elastic(F):
        full = np.tile(np.eye(3), (n, 1, 1))
        full[:, :dim, :dim] = F
        M = np.empty((n, 3, 3))
        for k, (a, b) in enumerate(SYMMETRIC_PAIRS):
            M[:, a, b] = M[:, b, a] = state[:, k]
        return np.einsum("nab,nbc,ndc->nad", full, M, full)

    before = elastic(F_old)
    keep_elastic_state(state, F_old, F_new)
    assert np.allclose(elastic(F_new), before, rtol=1e-12, atol=1e-12)
    assert np.all(state[:, 6:] == [0.3, 1e6])
