"""Analytic solutions the tests and benchmarks compare against."""

from __future__ import annotations

import numpy as np


def bar_tip_displacement(t, length, wave_speed, v0, start=0.75, modes=2000):
    """Free-end displacement of a fixed-free elastic bar whose part x > start*L starts at v0.

    u(x, t) = sum_n b_n sin(w_n t) sin(k_n x), k_n = (2n - 1) pi / (2L), w_n = c k_n, with
    b_n = 2 v0 cos(k_n start L) / (L k_n w_n) from the initial velocity; at x = L,
    sin(k_n L) = (-1)^(n+1). (Linear wave equation, [V §3.3.1] problem.)
    """
    t = np.asarray(t, dtype=float)
    n = np.arange(1, modes + 1)
    k = (2 * n - 1) * np.pi / (2 * length)
    w = wave_speed * k
    b = 2 * v0 * np.cos(k * start * length) / (length * k * w)
    sign = np.where(n % 2 == 1, 1.0, -1.0)
    return np.sin(np.multiply.outer(t, w)) @ (b * sign)


def cantilever_stiffness(youngs, poisson, length, height, thickness, plane_strain=True):
    """Tip stiffness F/u = 3 E I / L^3 of a cantilever (Euler-Bernoulli), [G §4.2]:
    with E/(1 - nu^2) in plane strain this is the paper's C = 0.053657 kN/mm for the
    8 mm x 1 mm beam of E = 100 GPa, nu = 0.3, 1 mm thick."""
    e = youngs / (1 - poisson ** 2) if plane_strain else youngs
    return 3 * e * thickness * height ** 3 / 12 / length ** 3


def free_rod_velocity(x, t, length, wave_speed, initial):
    """Axial velocity of an elastic rod with free ends on [0, length] that starts at rest in
    its natural length with velocity `initial(x)` (a function on arrays): d'Alembert,
    v = (V(x - c t) + V(x + c t)) / 2 with V the even, 2L-periodic extension of the
    initial velocity (zero stress at both ends). [R §9.2]'s rod with nu = 0 is one."""
    def extended(s):
        s = np.mod(s, 2.0 * length)
        return initial(np.where(s > length, 2.0 * length - s, s))

    x = np.asarray(x, dtype=float)
    return 0.5 * (extended(x - wave_speed * t) + extended(x + wave_speed * t))


def driven_rod_velocity(x, t, length, wave_speed, speed, duration):
    """Axial velocity of an elastic rod on [0, length], at rest at first, whose end x = 0
    moves at `speed` for 0 < t < duration and is free after, the end x = L free throughout
    ([R §9.2], the rectangular pulse): the pulse g(s) = speed for 0 < s < duration, else 0,
    runs along the rod and each free end reflects it with its velocity unchanged (zero
    stress), so
        v(x, t) = sum over k >= 0 of g(t - (2kL + x)/c) + g(t - (2(k+1)L - x)/c).
    This holds only if the pulse has left x = 0 when its reflection returns there,
    2L/c > duration (the end still driven would reflect it otherwise): refused if not."""
    if 2.0 * length / wave_speed <= duration:
        raise ValueError(f"the pulse ({duration:g} s) outlasts the round trip 2L/c = "
                         f"{2.0 * length / wave_speed:g} s: its reflection would meet the driven end")
    x = np.asarray(x, dtype=float)

    def g(s):
        return np.where((s > 0) & (s < duration), speed, 0.0)

    v = np.zeros(np.broadcast(x, t).shape)
    for k in range(int(np.max(t) * wave_speed / (2.0 * length)) + 1):  # the terms that have started
        v += g(t - (2 * k * length + x) / wave_speed) + g(t - (2 * (k + 1) * length - x) / wave_speed)
    return v


def timoshenko_cantilever(X, length, depth, youngs, poisson, load, plane_strain=True):
    """Displacement (n, 2) and small strain (n, 2, 2) of Timoshenko & Goodier's cantilever
    on [0, L] x [-D/2, D/2] (unit thickness) clamped at x = 0 as the solution prescribes and
    loaded at x = L by the parabolic shear traction t_y = P / (2 I) (D^2/4 - y^2), total P:
        u_x = -P y / (6 E I) [(6L - 3x) x + (2 + nu)(y^2 - D^2/4)]
        u_y =  P / (6 E I) [3 nu y^2 (L - x) + (4 + 5 nu) D^2 x / 4 + (3L - x) x^2]
    (plane stress; in plane strain with E / (1 - nu^2) and nu / (1 - nu)), I = D^3 / 12."""
    X = np.asarray(X, dtype=float)
    E, nu = (youngs / (1 - poisson ** 2), poisson / (1 - poisson)) if plane_strain else (youngs, poisson)
    x, y = X[:, 0], X[:, 1]
    L, D, P = length, depth, load
    inertia = D ** 3 / 12.0
    c = P / (6.0 * E * inertia)
    u = np.column_stack([-c * y * ((6 * L - 3 * x) * x + (2 + nu) * (y ** 2 - D ** 2 / 4)),
                         c * (3 * nu * y ** 2 * (L - x) + (4 + 5 * nu) * D ** 2 * x / 4 + (3 * L - x) * x ** 2)])
    # strains of the stresses sigma_xx = -P (L - x) y / I, sigma_yy = 0, sigma_xy = P (D^2/4 - y^2) / (2 I)
    sxx = -P * (L - x) * y / inertia
    sxy = P * (D ** 2 / 4 - y ** 2) / (2 * inertia)
    strain = np.zeros((len(X), 2, 2))
    strain[:, 0, 0] = sxx / E
    strain[:, 1, 1] = -nu * sxx / E
    strain[:, 0, 1] = strain[:, 1, 0] = (1 + nu) / E * sxy
    return u, strain
