"""The compressible Mooney-Rivlin law of [R eq. 18] (materials/elastic.py,
`material.model = "mooney_rivlin"`): its stress against the printed formula, the energy it
derives from, its small-strain moduli, frame indifference, and energy conservation in a run.
Constants of [R §9.6]: c1 = 1.265e5, c2 = 1.012e4, lambda = 1.012e7 Pa."""

from __future__ import annotations

import numpy as np
import pytest

from parsph.materials import constants
from parsph.materials.elastic import MOONEY_RIVLIN, TAIT_FLUID
from parsph.materials.update import stresses
from physics import block_2d, run_until, simulation

C1, C2, LAMBDA = 1.265e5, 1.012e4, 1.012e7


def piola(F: np.ndarray) -> np.ndarray:
    dim = F.shape[-1]
    P = np.empty((1, dim, dim))
    none = np.zeros((1, 0))
    stresses(MOONEY_RIVLIN, np.ascontiguousarray(F[None]), dim, np.array([LAMBDA, C1, C2]), none, none, P,
             np.empty(1))
    return P[0]


def energy(F: np.ndarray) -> float:
    """psi from the compiled law (through a one-point stack)."""
    dim = F.shape[-1]
    none, psi = np.zeros((1, 0)), np.empty(1)
    stresses(MOONEY_RIVLIN, np.ascontiguousarray(F[None]), dim, np.array([LAMBDA, C1, C2]), none, none,
             np.empty((1, dim, dim)), psi)
    return psi[0]


def printed_cauchy(F3: np.ndarray) -> np.ndarray:
    """[R eq. 18] as printed, on a 3 x 3 F: sigma = I3^(-1/2) [(c1 + c2 I1) B - c2 B^2 -
    (c1 I3^(1/3) + 2 c2 I3^(2/3) - lambda ln I3) I]."""
    B = F3 @ F3.T
    i1, i3 = np.trace(B), np.linalg.det(B)
    return i3 ** -0.5 * ((C1 + C2 * i1) * B - C2 * B @ B
                         - (C1 * i3 ** (1 / 3) + 2 * C2 * i3 ** (2 / 3) - LAMBDA * np.log(i3)) * np.eye(3))


def embed(F: np.ndarray) -> np.ndarray:
    """F of a model in d < 3 dimensions as the 3 x 3 F with unit stretch out of it."""
    F3 = np.eye(3)
    F3[: F.shape[0], : F.shape[0]] = F
    return F3


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_stress_is_the_printed_formula_and_the_energy_gradient(dim):
    """At a large random deformation (J = 0.52 to 1.07): J sigma F^-T of the printed eq. 18
    equals the compiled P to 1e-12, and P = d psi / d F by central differences to 1e-7;
    the undeformed state is stress- and energy-free."""
    rng = np.random.default_rng(dim)
    F = np.eye(dim) + 0.2 * rng.standard_normal((dim, dim))
    assert 0.5 < np.linalg.det(F) < 1.5
    P = piola(F)
    sigma = printed_cauchy(embed(F))
    expected = (np.linalg.det(F) * sigma @ np.linalg.inv(embed(F)).T)[:dim, :dim]
    assert np.abs(P - expected).max() < 1e-12 * np.abs(expected).max()
    h = 1e-6
    numeric = np.empty((dim, dim))
    for a in range(dim):
        for b in range(dim):
            step = np.zeros((dim, dim))
            step[a, b] = h
            numeric[a, b] = (energy(F + step) - energy(F - step)) / (2 * h)
    assert np.abs(numeric - P).max() < 1e-7 * np.abs(P).max()
    assert np.abs(piola(np.eye(dim))).max() == 0.0 and energy(np.eye(dim)) == 0.0


def test_small_strain_moduli_are_mu_c1_plus_c2_and_k_two_lambda():
    """For a small strain eps (1e-7) the law is linear elastic with mu = c1 + c2 =
    1.3662e5 Pa and K = 2 lambda = 2.024e7 Pa, the moduli parsph uses for
    the wave speed (403.6 m/s at [R]'s density)."""
    c = constants({"model": "mooney_rivlin", "density": 125.4, "c1": C1, "c2": C2, "lambda": LAMBDA})
    assert c.mu == pytest.approx(1.3662e5, rel=1e-12) and c.bulk == pytest.approx(2.024e7, rel=1e-12)
    assert c.wave_speed == pytest.approx(403.6, rel=1e-3)
    rng = np.random.default_rng(7)
    H = 1e-7 * rng.standard_normal((3, 3))
    eps = 0.5 * (H + H.T)
    linear = c.lam * np.trace(eps) * np.eye(3) + 2 * c.mu * eps
    assert np.abs(piola(np.eye(3) + H) - linear).max() < 1e-5 * np.abs(linear).max()


def test_frame_indifference():
    """psi(Q F) = psi(F) and P(Q F) = Q P(F) for a rotation Q."""
    rng = np.random.default_rng(3)
    F = np.eye(3) + 0.2 * rng.standard_normal((3, 3))
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    assert energy(Q @ F) == pytest.approx(energy(F), rel=1e-12)
    assert np.abs(piola(Q @ F) - Q @ piola(F)).max() < 1e-11 * np.abs(piola(F)).max()


def test_a_free_block_keeps_its_energy():
    """A free block (corrected SPH, variational hourglass control) set spinning and
    stretched by an initial velocity field: over 0.2 s (ten wave transits) kinetic + strain +
    hourglass energy stays within the leapfrog's fluctuation, which falls as dt^2 (measured
    1.5e-3 at time.cfl 0.3, 3.7e-4 at 0.15; 1.3e-2 at the default 0.85)."""
    drift = []
    for cfl in (0.3, 0.15):
        sim = simulation(block_2d(model="mooney_rivlin", hourglass=50.0, extra="""
[[initial]]
type = "velocity_field"
group = "all"
expression = ["2*(x - 0.5) - (y - 0.3)", "(x - 0.5)"]
"""), [f"time.cfl={cfl}"])
        energy_total = run_until(sim, 0.2, every=20)["total_energy"]
        drift.append(np.abs(energy_total - energy_total[0]).max() / energy_total[0])
    assert drift[0] < 3e-3 and 3.5 < drift[0] / drift[1] < 4.5


def test_the_law_takes_its_three_constants_and_no_other():
    from parsph.errors import InputError
    from physics import scene_from

    text = block_2d(model="mooney_rivlin")
    assert scene_from(text).material.lambda_ == 1.0e6
    with pytest.raises(InputError, match=r"material.youngs_modulus does not apply to model 'mooney_rivlin' "
                                         r"\(it takes c1, c2 and lambda\)"):
        scene_from(text, ["material.youngs_modulus=1e6"])
    with pytest.raises(InputError, match="missing required key 'material.c2'"):
        scene_from(text.replace("c2 = 5.0e4\n", ""))
    with pytest.raises(InputError, match="material.c1 must be > 0"):
        scene_from(text, ["material.c1=-1.0"])


# Tait's fluid [R eq. 77]: water of [R §9.7], B = 4.704e5 Pa, gamma = 7, rho0 = 1000 kg/m^3
B, GAMMA = 4.704e5, 7.0


def tait_piola(F: np.ndarray) -> np.ndarray:
    dim = F.shape[-1]
    P = np.empty((1, dim, dim))
    none = np.zeros((1, 0))
    stresses(TAIT_FLUID, np.ascontiguousarray(F[None]), dim, np.array([B, GAMMA, 0.0]), none, none, P, np.empty(1))
    return P[0]


def tait_energy(F: np.ndarray) -> float:
    dim = F.shape[-1]
    none, psi = np.zeros((1, 0)), np.empty(1)
    stresses(TAIT_FLUID, np.ascontiguousarray(F[None]), dim, np.array([B, GAMMA, 0.0]), none, none,
             np.empty((1, dim, dim)), psi)
    return psi[0]


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_tait_pressure_is_the_equation_of_state_and_the_energy_gradient(dim):
    """P = -p J F^-T with p = B ((rho/rho0)^gamma - 1), rho/rho0 = 1/J, to 1e-12; P = dpsi/dF
    by central differences to 1e-7; an isochoric shear is stress-free; at rest p = 0."""
    rng = np.random.default_rng(10 + dim)
    F = np.eye(dim) + 0.05 * rng.standard_normal((dim, dim))
    J = np.linalg.det(F)
    p = B * (J ** -GAMMA - 1.0)
    expected = -p * J * np.linalg.inv(F).T
    assert np.abs(tait_piola(F) - expected).max() < 1e-12 * np.abs(expected).max()
    h = 1e-7
    numeric = np.array([[(tait_energy(F + h * np.eye(dim)[:, [a]] @ np.eye(dim)[[b]])
                          - tait_energy(F - h * np.eye(dim)[:, [a]] @ np.eye(dim)[[b]])) / (2 * h)
                         for b in range(dim)] for a in range(dim)])
    assert np.abs(numeric - tait_piola(F)).max() < 1e-6 * np.abs(expected).max()
    if dim > 1:
        shear = np.eye(dim)
        shear[0, 1] = 0.3
        assert np.abs(tait_piola(shear)).max() < 1e-9 * B
    assert np.abs(tait_piola(np.eye(dim))).max() == 0.0 and tait_energy(np.eye(dim)) == 0.0


def test_tait_sound_speed_and_its_growth_under_compression():
    """c0 = sqrt(gamma B / rho0) = 57.4 m/s ([R §9.7]'s water); under compression the stable
    step uses c^2 = c0^2 (rho/rho0)^(gamma - 1): a factor J^(1 - gamma) (1.88 at J = 0.9)."""
    from parsph.materials.elastic import TAIT_FLUID as law
    from parsph.materials.update import stiffening

    c = constants({"model": "tait_fluid", "density": 1000.0, "tait_b": B, "tait_gamma": GAMMA})
    assert c.wave_speed == pytest.approx(57.4, rel=1e-3) and c.mu == 0.0 and c.youngs == 0.0
    assert stiffening(law, 1.0, 0.9, c.values) == pytest.approx(0.9 ** -6, rel=1e-14)
    assert stiffening(law, 1.2, 1.1, c.values) == 1.0


def test_a_fluid_block_breathes_and_its_energy_error_is_the_integrators():
    """A free block of Tait fluid (corrected SPH, no hourglass control) given a radial
    velocity: it expands by 0.1 % and the negative pressure pulls it back. The change of
    kinetic + strain energy over 0.05 s is the leapfrog's: it falls as dt^2 (measured 6.9e-3
    at CFL 0.3, 1.7e-3 at 0.15, 4.4e-4 at 0.075 of the initial energy)."""
    drift = []
    for cfl in (0.3, 0.15):
        sim = simulation(block_2d(model="tait_fluid") + """
[[initial]]
type = "velocity_field"
group = "all"
expression = ["0.5*(x - 0.5)", "0.5*(y - 0.3)"]
""", [f"time.cfl={cfl}"])
        energy_total = run_until(sim, 0.05, every=10)["total_energy"]
        drift.append(np.abs(energy_total - energy_total[0]).max() / energy_total[0])
    assert drift[0] < 0.01 and 3.5 < drift[0] / drift[1] < 4.5
