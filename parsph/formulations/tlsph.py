"""Lagrangian corrected SPH [G §2], [V §2.3, §3]: the compiled stages of a step.

Quantities are measured from the reference configuration X^r: the initial one in the
total-Lagrangian formulation (F^r = I), the last updated one in the updated formulation
[V §3.1]; d = x - X^r is the displacement since the reference.

The corrected gradient g_ij = V_j L_i^-1 w_ij (kernels.correction) enters as the stored
gw_ij = V_j w_ij with L_i^-1 applied per particle: w_ij is antisymmetric, so
g_ji = -(V_i / V_j) L_j^-1 gw_ij (V the reference measures), and no reverse is stored.

Stage 1, `kinematics_stress`: for each owned particle
    f_i = I + sum_j (d_j - d_i) (x) g_ij = I + (sum_j (d_j - d_i) (x) gw_ij) L_i^-T
                                                              [G eq. 17], [V eq. 12]
    optionally stabilised by Hessian's difference [V eq. 17, 21]:
    f_i^s = f_i + eta sum_j [(d_j - d_i) (x) Hc_ij h - (f_j - f_i) (g_ij . h)]
    (f of the neighbours comes from the extra pass `gradient` and a halo refresh)
    F_i = f_i^s F^r_i,  P_i = P(F_i), psi_i                   (materials.update)
and the stored product VP_i = V^0_i P_i F^rT_i [V eq. 14]; with an Eulerian kernel, whose
reference moves to the current configuration between the stages, VP_i = V^0_i P_i F_i^T =
V_i sigma_i, the same product in the new reference. Stage 2 reads it through
S_i = VP_i L_i^-1 / V_i (with Hessian stabilisation (VP_i - B_i) L_i^-1 / V_i).

Stage 2, `forces`: the internal force in one of two forms,
    pair form [G eq. 24]:   f_i = sum_j (V_i P_i g_ij - V_j P_j g_ji) = V_i sum_j (S_i + S_j) gw_ij
    virtual work [V eq. 11]: f_i = -sum_{j in S_i + {i}} V_j P_j G_i(X_j)
                                 = V_i (S_i sum_j gw_ij + sum_j S_j gw_ij),
        with G_i(X_j) = g_ji and the self coefficient G_i(X_i) = -sum_k g_ik,
which agree in exact arithmetic (they differ by summation order only); both conserve
linear momentum. With Hessian stabilisation the forces are the exact transpose of f^s:
V P - B with g plus V P with eta Hc h, B from `hessian_transpose` (so energy is conserved
between updates).

Hourglass control penalises the error e^i_ij = F_i X_ij - x_ij, the part of the neighbour
separation that F does not explain [G eq. 25-26]:
  "paper" [G eq. 27-32]: per pair, antisymmetric and along x_ij,
      delta^i_ij = e^i_ij . x_ij / (|x_ij| + 0.1 h_ij),
      f_i^HG = -sum_j c_ij (E_i delta^i_ij + E_j delta^j_ji) x_ij / |x_ij|,
      c_ij = alpha/4 V_i V_j W_ij / (|X_ij|^2 + 0.01 h_ij^2).
    This is eq. 32 as its author implemented it in LAMMPS MACHDYN (smd/tlsph): half the
    printed magnitude and two regularised denominators. With it alpha = 50 is the best
    coefficient for the beam of [G Table 1], as the paper reports, and alpha means what it
    means in MACHDYN. It is not the gradient of a potential and can feed energy into a
    long undamped run.
  "variational": the forces are minus the gradient of the penalty energy
      Phi = sum_i sum_j c_ij E_i |e^i_ij|^2 / 2,  c_ij = s alpha/2 V_i V_j W_ij / |X_ij|^2,
    (s = VARIATIONAL_SCALE) including its dependence on F_i: a direct pair part -sum_j c_ij (E_i e^i_ij + E_j e^j_ij)
    and the hourglass stress A_i = dPhi/dF_i = sum_j c_ij E_i e^i_ij (x) X_ij, which enters
    the internal force exactly like V_i P_i. Energy (with Phi) and linear and angular
    momentum are conserved.
`compile_stages` makes the stages for one body's switches (dimension, material law, force
row, hourglass form, updated reference, Hessian stabilisation), captured as compile-time
constants: a body's machine code holds only the terms it uses. Compiled code is cached on
disk per combination. The same kernels serve symmetrised SPH (plain kernel gradients, pair
form) and RLM (its own force row) of formulations.nodal.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from parsph import COMPILED_SOURCE
from parsph.formulations.base import CompiledOnce
from parsph.kernels.functions import value, value_and_slope
from parsph.materials import update
from parsph.materials.elastic import det, right_cauchy_green, symmetric_extremes
from parsph.pair_lanes import LANES, lane_block, lanes_used, quotient
from parsph.small_vectors import added, component, replaced, separation

HOURGLASS_OFF, HOURGLASS_PAPER, HOURGLASS_VARIATIONAL = 0, 1, 2
# the reference of F: the initial configuration, an updated one [V §3.1], or the current
# one (an Eulerian kernel [R eq. 16]: VP is formed for the reference the forces will use)
REFERENCE_INITIAL, REFERENCE_UPDATED, REFERENCE_CURRENT = 0, 1, 2
# force rows: [G eq. 24] pair form, [V eq. 11] virtual work, and RLM [R Table 1]
FORCE_PAIR, FORCE_VIRTUAL_WORK, FORCE_RLM = 0, 1, 2
FORCE_FORMS = {"pair": FORCE_PAIR, "virtual_work": FORCE_VIRTUAL_WORK, "rlm": FORCE_RLM}
HOURGLASS_FORMS = {"paper": HOURGLASS_PAPER, "variational": HOURGLASS_VARIATIONAL}
# The variational penalty acts on the whole error vector, the paper's on its projection;
# with this factor both stiffen the beam of [G §4.2] alike at the same alpha (compliance
# error +4 % / +1.6 % at n = 8, about 0 / -0.2 % at n = 16, variational / paper form).
VARIATIONAL_SCALE = 0.2
# LAMMPS MACHDYN's switch to its viscous hourglass force: a pair of which a particle's
# equivalent plastic strain exceeds this
VISCOUS_ONSET = 1.0e-3
# The two stages' floating-point licence: without signed zeros ("nsz") the compiler may drop
# the additions of 0.0 that start each sum (x + 0.0 is x except for x = -0.0): the same values,
# the force row about 10 % faster, the variational form's kinematics 3 %. Not fused
# multiply-adds ("contract"), though another 10 %: with them a run that compiles the kernels
# and a run that loads them from the cache differ in the last bit
# (docs/notes/2026-12-05-pair-data-memory.md).
STAGE_MATH = {"nsz"}
# the rows of the stages' blocks of a row's pairs (pair_lanes). Gathered for both hourglass
# forms: X_ij, d_j and the pair's coefficient c_ij. The paper springs', in the force stage:
# gathered, fs_j (row by row), E_j and h_j; formed, x_ij, |x_ij|^2, |x_ij| and the spring's
# coefficient. The variational penalty's, in stage 1: formed, the pair's terms of the
# hourglass stress (row by row) and of the penalty energy.
REF, NEIGHBOUR_D, HGC = 0, 3, 6
GRADIENT, YOUNGS, SUPPORT, SEP, R2, DISTANCE, COEFFICIENT = 7, 16, 17, 18, 21, 22, 23
FORCE_ROWS = 24
STRESS_TERMS, ENERGY_TERM = 7, 16
PENALTY_ROWS = 17


def compile_stages(dim: int, law: int, force_form: int, hourglass: int, reference: int = REFERENCE_INITIAL,
                   hessian: bool = False, failure: int = 0, viscous: bool = False):
    """(gradient, kinematics_stress, hessian_transpose, forces) for one body's switches:
    dimension, material law (materials.update), force row, hourglass form, reference
    (REFERENCE_*), Hessian stabilisation, the failure model (0: none, materials.damage.TENSILE or
    materials.johnson_cook_failure.JOHNSON_COOK_FAILURE), and with the paper's hourglass form
    LAMMPS MACHDYN's viscous hourglass force for yielded pairs (`viscous`). Each stage works
    on the owned rows lo..hi-1.

    The switches are closure constants, so branches on them are folded away by the
    compiler. Each stage is compiled for the switches it reads only (`_hessian_passes`,
    `_stress_stage`, `_force_stage`), so bodies that differ in the others share it. The
    stage bodies are written out rather than inlined from module-level functions: Numba
    inlines a function by copying its IR (per block, with its whole scope), and for bodies
    this size that copy took about a third of each variant's compile time; the material
    laws, the largest part, are functions of their own (materials.update).
    `gradient` and `hessian_transpose` are the extra passes of Hessian's-difference
    stabilisation.
    """
    gradient, hessian_transpose = _hessian_passes(dim)
    kinematics_stress = _stress_stage(dim, law, hourglass == HOURGLASS_VARIATIONAL, reference, hessian, failure,
                                      stage_one_corrects(force_form, hessian, reference))
    forces = _force_stage(dim, force_form, hourglass, hessian, viscous)
    return gradient, kinematics_stress, hessian_transpose, forces


def stage_one_corrects(force_form: int, hessian: bool, reference: int) -> bool:
    """Whether stage 1 forms the force row's S = V P L^-1 / V with the stress: not for RLM's
    row (it reads V P), nor where the stabilisation's B enters S (`hessian_transpose` forms
    it) or the reference moves between the stages (an Eulerian kernel: `corrected_stresses`
    forms it once the reference has moved)."""
    return force_form != FORCE_RLM and not hessian and reference != REFERENCE_CURRENT


@functools.lru_cache(maxsize=None)
def _hessian_passes(dim: int):
    """(gradient, hessian_transpose): the extra passes of Hessian's-difference stabilisation."""
    @njit(cache=True, _nrt=False)
    def gradient(lo, hi, ptr, idx, gw, Linv, d, f):
        """f_i = I + sum_j (d_j - d_i) (x) g_ij for particles lo..hi-1 [V eq. 12]."""
        for i in range(lo, hi):
            corrected_gradient_row(dim, i, ptr, idx, gw, Linv, d, f)

    @njit(cache=True, _nrt=False)
    def hessian_transpose(lo, hi, ptr, idx, gh, gh_rev, VP, B, Linv, measure, S):
        """B_i = sum_j (V P_j gh_ji - V P_i gh_ij): what the gradient-of-gradient term of
        [V eq. 21] feeds back into the forces; and S_i = (VP_i - B_i) L_i^-1 / V_i, which
        the force row reads."""
        for i in range(lo, hi):
            for a in range(dim):
                for b in range(dim):
                    B[i, a, b] = 0.0
            for p in range(ptr[i], ptr[i + 1]):
                j = idx[p]
                for a in range(dim):
                    for b in range(dim):
                        B[i, a, b] += VP[j, a, b] * gh_rev[p] - VP[i, a, b] * gh[p]
            corrected_stress(dim, i, VP, B, True, Linv, measure, S)

    variant = f"{COMPILED_SOURCE} {dim}"
    return CompiledOnce(gradient, variant), CompiledOnce(hessian_transpose, variant)


@functools.lru_cache(maxsize=None)
def _stress_stage(dim: int, law: int, variational: bool, reference: int, hessian: bool, failure: int,
                  corrects: bool):
    """kinematics_stress, stage 1, for its switches (`variational`: the variational hourglass
    form's penalty and hourglass stress; `corrects`: it forms the force row's S)."""
    @njit(cache=True, _nrt=False, fastmath=STAGE_MATH)
    def kinematics_stress(lo, hi, ptr, idx, gw, Linv, measure, q, gh, X, hgc, d, volume, youngs, c, state, trial,
                          damage_state, damage_trial, f, fs, F, Fr, VP, S, J, psi, hg_psi, P, work, dt):
        """Stage 1 for particles lo..hi-1, with each particle's strain energy density psi,
        new material and damage state (trial, damage_trial), (variational form) hourglass
        penalty hg_psi and (`corrects`) S_i = VP_i L_i^-1 / V_i; returns the first inverted
        particle or -1."""
        first_bad = -1
        lanes = lane_block(PENALTY_ROWS)  # the variational penalty's pairs (pair_lanes)
        held = lane_block(1)[0]  # its sums of V P_i
        mine = lane_block(1)[0]  # particle i's fs (row by row) and d
        for i in range(lo, hi):
            # fs: gradient of the motion from the reference, stabilised [V eq. 17, 21] if enabled
            if hessian:  # a row of fs at a time, summed in locals
                for a in range(dim):
                    s0 = f[i, a, 0]
                    s1 = f[i, a, 1] if dim > 1 else 0.0
                    s2 = f[i, a, 2] if dim > 2 else 0.0
                    for p in range(ptr[i], ptr[i + 1]):
                        j = idx[p]
                        dd = d[j, a] - d[i, a]
                        for b in range(dim):
                            s0, s1, s2 = added(b, dd * q[p, b] - (f[j, a, b] - f[i, a, b]) * gh[p], s0, s1, s2)
                    for b in range(dim):
                        fs[i, a, b] = component(b, s0, s1, s2)
            else:
                corrected_gradient_row(dim, i, ptr, idx, gw, Linv, d, fs)
            if stress_at(dim, law, reference, failure, i, fs, Fr, volume[i], c, state, trial, damage_state,
                         damage_trial, P, work, F, VP, J, psi, dt) and first_bad < 0:
                first_bad = i
            if variational:
                # hourglass "stress" A_i = dPhi/dfs_i = sum_j c_ij E_i e_ij (x) X_ij, added to V P;
                # the pairs' terms formed lane by lane (penalty_stress_lanes), summed in row
                # order into `held`, on the stack: the compiler keeps the sums in registers
                for a in range(dim):
                    for b in range(dim):
                        held[3 * a + b] = VP[i, a, b]
                particle_block(dim, i, fs, d, mine)
                phi = 0.0
                start = ptr[i]
                while start < ptr[i + 1]:
                    stop = min(start + LANES, ptr[i + 1])
                    for p in range(start, stop):
                        gather_separation(dim, lanes, p - start, X, i, idx[p], d, hgc[p])
                    penalty_stress_lanes(dim, lanes, lanes_used(stop - start), mine, youngs[i])
                    for lane in range(stop - start):
                        phi += lanes[ENERGY_TERM, lane]
                        for a in range(dim):
                            for b in range(dim):
                                held[3 * a + b] += lanes[STRESS_TERMS + 3 * a + b, lane]
                    start = stop
                for a in range(dim):
                    for b in range(dim):
                        VP[i, a, b] = held[3 * a + b]
                hg_psi[i] = phi
            if corrects:
                corrected_stress(dim, i, VP, VP, False, Linv, measure, S)
        return first_bad

    return CompiledOnce(kinematics_stress,
                        f"{COMPILED_SOURCE} {dim} {law} {variational} {reference} {hessian} {failure} {corrects}")


@functools.lru_cache(maxsize=None)
def _force_stage(dim: int, force_form: int, hourglass: int, hessian: bool, viscous: bool):
    """forces, stage 2, for its switches."""
    @njit(cache=True, _nrt=False, fastmath=STAGE_MATH)
    def forces(lo, hi, ptr, idx, gw, gw_sum, Linv, measure, q, q_rev, q_sum, X, hgc, d, fs, VP, S, youngs,
               volume, mass, f_int, f_hg, bound, omega_hg2, damper_rate2, tensor, v, plastic, support, kind, vc):
        """Stage 2 for particles lo..hi-1: internal force f_int and, if enabled, f_hg and (if
        `bound`: the stable step is due) the bound omega_hg2 on the hourglass springs'
        frequency and, with `viscous`, damper_rate2 on the dampers' rate (see
        `stable_time_step`). With `viscous`, a pair of which a particle's equivalent plastic
        strain (column vc[4] of `plastic`, the state just computed) exceeds VISCOUS_ONSET
        takes LAMMPS MACHDYN's viscous hourglass force instead of the spring: with
        gamma = (F_i + F_j) X_ij / 2 - x_ij, r = |x_ij|, h the mean support,
        v = x_ij . v_ij / (r + h/10) limited to 1 % of the wave speed c0, when
        v gamma . x_ij < 0,
            f_i += m_i m_j (-e alpha c0 mu / rho0) W'(|X_ij|) x_ij / (r + h/100),
            mu = h v / (r + h/10),  e = max(|gamma| / |X_ij|, 0.05),
        an artificial viscosity on the hourglass mode's closing (vc = alpha, c0, rho0, E,
        column; scaled by E_i E_j / E^2, the damage's factors). Its dampers bound the stable step
        as the springs do (an explicit damper is stable for dt < 2 / rate): the damping matrix
        is a Laplacian of pair coefficients k_ij along n_ij (the force per unit closing
        speed), whose largest rate is at most max_i 2 lambda_max(sum_j k_ij n_ij n_ij^T) / m_i
        (the springs' argument); its square goes to damper_rate2. Pairs not yet past the onset
        count too (their e at least its floor): a damper that switches on within a step is then
        stable in it (at an impact the first yield comes in the first step, sized before it). With
        Hessian stabilisation the force is the standard one for V P - B with g (through S)
        plus the standard one for V P with q (the transpose of [V eq. 21]). The RLM row
        [R Table 1, its printed sign corrected] is f_i = V_i sum_j (P_i + P_j) g_ij: with the
        corrected g_ij it uses particle i's correction for both terms and does not conserve
        linear momentum."""
        pair_form = force_form == FORCE_PAIR
        lanes = lane_block(FORCE_ROWS)  # a row's pairs for the hourglass force (pair_lanes)
        mine = lane_block(1)[0]  # particle i's fs (row by row) and d
        for i in range(lo, hi):
            # the row's sums are kept in locals, (f0, f1, f2) of f_int, (h0, h1, h2) of f_hg and
            # the spring and damper tensors (k*, c*: xx, yy, zz, xy, yz, xz), and stored once:
            # the pair loop stores only to its own block of lanes, so the compiler keeps them
            # and particle i's data in registers (the sums are the same, term by term in row
            # order). (f0, f1, f2): the S terms, times V_i when stored; (t0, t1, t2): the q
            # terms. The paper hourglass force's terms are formed lane by lane (spring_lanes)
            # and summed after each block of the row.
            f0 = f1 = f2 = h0 = h1 = h2 = t0 = t1 = t2 = 0.0
            k0 = k1 = k2 = k3 = k4 = k5 = 0.0
            c0 = c1 = c2 = c3 = c4 = c5 = 0.0
            damped = False
            if force_form == FORCE_VIRTUAL_WORK:
                for a in range(dim):
                    s = t = 0.0
                    for b in range(dim):
                        s += S[i, a, b] * gw_sum[i, b]
                        if hessian:
                            t += VP[i, a, b] * q_sum[i, b]
                    f0, f1, f2 = replaced(a, s, f0, f1, f2)
                    t0, t1, t2 = replaced(a, t, t0, t1, t2)
            if hourglass == HOURGLASS_PAPER:
                particle_block(dim, i, fs, d, mine)
            start = ptr[i]
            while start < ptr[i + 1]:  # the row LANES pairs at a time (pair_lanes)
                stop = min(start + LANES, ptr[i + 1])
                for p in range(start, stop):
                    j = idx[p]
                    if force_form == FORCE_RLM:
                        ratio = volume[i] / volume[j]
                        g0, g1, g2 = corrected_gradient(dim, Linv, i, gw, p)
                        for a in range(dim):
                            s = 0.0
                            for b in range(dim):
                                s += (VP[i, a, b] + ratio * VP[j, a, b]) * component(b, g0, g1, g2)
                            f0, f1, f2 = added(a, s, f0, f1, f2)
                    else:
                        for a in range(dim):
                            s = t = 0.0
                            for b in range(dim):
                                if pair_form:
                                    s += (S[i, a, b] + S[j, a, b]) * gw[p, b]
                                else:
                                    s += S[j, a, b] * gw[p, b]
                                if hessian:
                                    t -= VP[j, a, b] * q_rev[p, b]
                                    if pair_form:
                                        t += VP[i, a, b] * q[p, b]
                            f0, f1, f2 = added(a, s, f0, f1, f2)
                            if hessian:
                                t0, t1, t2 = added(a, t, t0, t1, t2)
                    if hourglass == HOURGLASS_PAPER:
                        gather_pair(dim, lanes, p - start, X, i, j, d, fs, youngs, support, hgc[p])
                    elif hourglass == HOURGLASS_VARIATIONAL:
                        # direct part of -dPhi/dx_i: -sum_j c_ij (E_i e^i_ij + E_j e^j_ij)
                        # (formed pair by pair: in lanes it took longer)
                        e0, e1, e2 = separation(X, i, j, dim)
                        for a in range(dim):
                            xa = component(a, e0, e1, e2) + d[j, a] - d[i, a]
                            fi = 0.0
                            fj = 0.0
                            for b in range(dim):
                                fi += fs[i, a, b] * component(b, e0, e1, e2)
                                fj += fs[j, a, b] * component(b, e0, e1, e2)
                            h0, h1, h2 = added(a, -(hgc[p] * (youngs[i] * (fi - xa) + youngs[j] * (fj - xa))),
                                               h0, h1, h2)
                        k0 += hgc[p] * (youngs[i] + youngs[j])
                if hourglass == HOURGLASS_PAPER:  # the springs' terms in lanes, then summed
                    spring_lanes(dim, lanes, lanes_used(stop - start), mine, youngs[i], support[i])
                    for lane in range(stop - start):
                        x0, x1, x2 = lanes[SEP, lane], lanes[SEP + 1, lane], lanes[SEP + 2, lane]
                        r2 = lanes[R2, lane]
                        r = lanes[DISTANCE, lane]
                        c = lanes[COEFFICIENT, lane]  # the spring's [G eq. 27, 32], zero where r = 0
                        p = start + lane
                        j = idx[p]
                        yielded = viscous and max(plastic[i, int(vc[4])], plastic[j, int(vc[4])]) > VISCOUS_ONSET
                        h = closing = approach = scale = slope = 0.0
                        if yielded or (viscous and bound and r > 0.0):
                            h = 0.5 * (support[i] + support[j])
                            r0 = 0.0
                            err2 = 0.0
                            for a in range(dim):
                                ea = lanes[REF + a, lane]
                                fi = 0.0
                                for b in range(dim):
                                    fi += 0.5 * (fs[i, a, b] + lanes[GRADIENT + 3 * a + b, lane]) * lanes[REF + b, lane]
                                xa = component(a, x0, x1, x2)
                                gamma = fi - xa
                                err2 += gamma * gamma
                                closing += gamma * xa
                                approach += xa * (v[j, a] - v[i, a])
                                r0 += ea * ea
                            r0 = math.sqrt(r0)
                            e = max(math.sqrt(err2) / r0, 0.05)
                            slope = value_and_slope(kind, r0, h, dim)[1]
                            scale = mass[i] * mass[j] * e * vc[0] * vc[1] / vc[2] * (youngs[i] / vc[3]) * (
                                youngs[j] / vc[3])
                            if bound:  # the damper's coefficient on the pair's closing speed, along x_ij
                                # (a pair not yet yielded too: its damper may switch on within the step)
                                damped = True
                                c0, c1, c2, c3, c4, c5 = spring_terms(
                                    scale * h * abs(slope) / ((r + 0.1 * h) ** 2 * (r + 0.01 * h)), x0, x1, x2,
                                    c0, c1, c2, c3, c4, c5)
                        if yielded:
                            c = 0.0
                            approach = min(max(approach / (r + 0.1 * h), -0.01 * vc[1]), 0.01 * vc[1])
                            if approach * closing < 0.0:
                                mu = h * approach / (r + 0.1 * h)
                                c = -scale * mu * slope / (r + 0.01 * h)
                        elif bound and r > 0.0:
                            k0, k1, k2, k3, k4, k5 = spring_terms(hgc[p] * (youngs[i] + youngs[j]) / r2, x0, x1, x2,
                                                                  k0, k1, k2, k3, k4, k5)
                        h0 += c * x0  # (a pair without a force adds 0.0, which changes no sum)
                        h1 += c * x1
                        h2 += c * x2
                start = stop
            for a in range(dim):
                if force_form == FORCE_RLM:
                    f_int[i, a] = component(a, f0, f1, f2)
                else:
                    f_int[i, a] = measure[i] * component(a, f0, f1, f2) + component(a, t0, t1, t2)
                if hourglass != HOURGLASS_OFF:
                    f_hg[i, a] = component(a, h0, h1, h2)
            if bound and hourglass == HOURGLASS_PAPER:
                tensor[0, 0], tensor[1, 1], tensor[2, 2] = k0, k1, k2
                tensor[0, 1] = tensor[1, 0] = k3
                tensor[1, 2] = tensor[2, 1] = k4
                tensor[0, 2] = tensor[2, 0] = k5
                omega_hg2[i] = 2.0 * symmetric_extremes(tensor, dim)[1] / mass[i]
                if viscous:  # an explicit damper is stable for dt below 2 / (its damping rate)
                    damper_rate2[i] = 0.0
                    if damped:
                        tensor[0, 0], tensor[1, 1], tensor[2, 2] = c0, c1, c2
                        tensor[0, 1] = tensor[1, 0] = c3
                        tensor[1, 2] = tensor[2, 1] = c4
                        tensor[0, 2] = tensor[2, 0] = c5
                        damper_rate2[i] = (2.0 * symmetric_extremes(tensor, dim)[1] / mass[i]) ** 2
            elif bound and hourglass == HOURGLASS_VARIATIONAL:
                omega_hg2[i] = 2.0 * k0 / mass[i]

    return CompiledOnce(forces, f"{COMPILED_SOURCE} {dim} {force_form} {hourglass} {hessian} {viscous}")


@njit(cache=True, inline="always")
def particle_block(dim, i, fs, d, mine):
    """Particle i's fs (row by row) and d into `mine`, the block the lane passes read them from
    (loads the compiler cannot then mistake for per-lane ones)."""
    for a in range(dim):
        for b in range(dim):
            mine[3 * a + b] = fs[i, a, b]
        mine[9 + a] = d[i, a]


@njit(cache=True, inline="always")
def gather_separation(dim, lanes, lane, X, i, j, d, hgc):
    """Pair (i, j)'s X_ij, d_j and coefficient hgc into column `lane` of a stage's block."""
    e0, e1, e2 = separation(X, i, j, dim)
    for a in range(dim):
        lanes[REF + a, lane] = component(a, e0, e1, e2)
        lanes[NEIGHBOUR_D + a, lane] = d[j, a]
    lanes[HGC, lane] = hgc


@njit(cache=True, inline="always")
def gather_pair(dim, lanes, lane, X, i, j, d, fs, youngs, support, hgc):
    """Pair (i, j)'s data for the hourglass force into column `lane` of the force stage's block:
    X_ij, d_j, the coefficient hgc, fs_j, E_j and h_j."""
    gather_separation(dim, lanes, lane, X, i, j, d, hgc)
    for a in range(dim):
        for b in range(dim):
            lanes[GRADIENT + 3 * a + b, lane] = fs[j, a, b]
    lanes[YOUNGS, lane] = youngs[j]
    lanes[SUPPORT, lane] = support[j]


@njit(cache=True, inline="always")
def spring_lanes(dim, lanes, used, mine, youngs_i, support_i):
    """Lane by lane, particle i's pairs' x_ij = X_ij + d_j - d_i, |x_ij|^2, |x_ij| and the
    coefficient c of the paper's hourglass force c x_ij [G eq. 27, 32], the errors projected on
    the current separation, a central force:
    c = -c_ij (E_i delta^i + E_j delta^j) / (|x_ij| (|x_ij| + 0.1 h_ij)),
    delta^i = (fs_i X_ij - x_ij) . x_ij, the regularising length 0.1 h_ij with h_ij the pair's
    mean support (`mine`: fs_i, d_i). Where x_ij = 0 (coinciding particles: a wall's
    projection) c is zero, the force's limit."""
    for lane in range(used):
        r2 = 0.0
        for a in range(dim):
            xa = lanes[REF + a, lane] + lanes[NEIGHBOUR_D + a, lane] - mine[9 + a]
            lanes[SEP + a, lane] = xa
            r2 += xa * xa
        r = math.sqrt(r2)
        di = 0.0
        dj = 0.0
        for a in range(dim):
            fi = 0.0
            fj = 0.0
            for b in range(dim):
                eb = lanes[REF + b, lane]
                fi += mine[3 * a + b] * eb
                fj += lanes[GRADIENT + 3 * a + b, lane] * eb
            xa = lanes[SEP + a, lane]
            di += (fi - xa) * xa
            dj += (fj - xa) * xa
        c = quotient(-lanes[HGC, lane] * (youngs_i * di + lanes[YOUNGS, lane] * dj),
                     r * (r + 0.1 * (0.5 * (support_i + lanes[SUPPORT, lane]))))
        lanes[R2, lane] = r2
        lanes[DISTANCE, lane] = r
        lanes[COEFFICIENT, lane] = c if r > 0.0 else 0.0


@njit(cache=True, inline="always")
def penalty_stress_lanes(dim, lanes, used, mine, youngs_i):
    """Lane by lane, a pair's terms of the variational penalty in stage 1: of the hourglass
    stress A_i = dPhi/dfs_i, k e_ij (x) X_ij (row by row), and of its energy, k |e_ij|^2 / 2,
    with k = c_ij E_i and e_ij = fs_i X_ij - x_ij (`mine`: fs_i, d_i)."""
    for lane in range(used):
        k = lanes[HGC, lane] * youngs_i
        square = 0.0
        for a in range(dim):
            fx = 0.0
            for b in range(dim):
                fx += mine[3 * a + b] * lanes[REF + b, lane]
            error = fx - lanes[REF + a, lane] - lanes[NEIGHBOUR_D + a, lane] + mine[9 + a]
            square += error * error
            for b in range(dim):
                lanes[STRESS_TERMS + 3 * a + b, lane] = k * error * lanes[REF + b, lane]
        lanes[ENERGY_TERM, lane] = 0.5 * k * square


@njit(cache=True, inline="always")
def gradient_row(dim, i, base, ptr, idx, g, d, f):
    """f[i] = I + sum_j (d_j - d_base) (x) g_ij over row i of (ptr, idx, g), the sums
    started from I (row_sums)."""
    s = row_sums(dim, i, base, ptr, idx, g, d, 1.0)
    for a in range(dim):
        for b in range(dim):
            f[i, a, b] = s[3 * a + b]


@njit(cache=True, inline="always")
def corrected_gradient_row(dim, i, ptr, idx, gw, Linv, d, f):
    """f[i] = I + sum_j (d_j - d_i) (x) g_ij = I + (sum_j (d_j - d_i) (x) gw_ij) L_i^-T over
    row i (row_sums)."""
    s = row_sums(dim, i, i, ptr, idx, gw, d, 0.0)
    for a in range(dim):
        for b in range(dim):
            t = 1.0 if a == b else 0.0
            for k in range(dim):
                t += s[3 * a + k] * Linv[i, b, k]
            f[i, a, b] = t


@njit(cache=True, inline="always")
def row_sums(dim, i, base, ptr, idx, g, d, diagonal):
    """The sums s_ab = sum_j (d_j - d_base)_a g_ij,b over row i, started from `diagonal` on
    the diagonal (0 off it), term by term in row order; in one pass, in locals (the nine
    sums' additions overlap), stored by the caller: row by row as nine scalars, those a
    lower dimension lacks zero."""
    s00 = diagonal
    s11 = diagonal if dim > 1 else 0.0
    s22 = diagonal if dim > 2 else 0.0
    s01 = s02 = s10 = s12 = s20 = s21 = 0.0
    b0 = d[base, 0]
    b1 = d[base, 1] if dim > 1 else 0.0
    b2 = d[base, 2] if dim > 2 else 0.0
    for p in range(ptr[i], ptr[i + 1]):
        j = idx[p]
        u0 = d[j, 0] - b0
        s00 += u0 * g[p, 0]
        if dim > 1:
            u1 = d[j, 1] - b1
            s01 += u0 * g[p, 1]
            s10 += u1 * g[p, 0]
            s11 += u1 * g[p, 1]
        if dim > 2:
            u2 = d[j, 2] - b2
            s02 += u0 * g[p, 2]
            s12 += u1 * g[p, 2]
            s20 += u2 * g[p, 0]
            s21 += u2 * g[p, 1]
            s22 += u2 * g[p, 2]
    return s00, s01, s02, s10, s11, s12, s20, s21, s22


@njit(cache=True, inline="always")
def corrected_gradient(dim, Linv, i, gw, p):
    """g_ij = L_i^-1 gw_ij of pair p of row i, as three scalars."""
    g0 = g1 = g2 = 0.0
    for a in range(dim):
        t = 0.0
        for b in range(dim):
            t += Linv[i, a, b] * gw[p, b]
        g0, g1, g2 = replaced(a, t, g0, g1, g2)
    return g0, g1, g2


@njit(cache=True, inline="always")
def corrected_stress(dim, i, VP, B, less_B, Linv, measure, S):
    """S_i = VP_i L_i^-1 / V_i (less_B: (VP_i - B_i) L_i^-1 / V_i), what the force row reads
    (V the reference measure)."""
    scale = 1.0 / measure[i]
    for a in range(dim):
        for b in range(dim):
            s = 0.0
            for k in range(dim):
                s += (VP[i, a, k] - B[i, a, k] if less_B else VP[i, a, k]) * Linv[i, k, b]
            S[i, a, b] = s * scale


@njit(cache=True, _nrt=False)
def corrected_stresses(lo, hi, VP, Linv, measure, S):
    """S_i = VP_i L_i^-1 / V_i for particles lo..hi-1: with an Eulerian kernel, in the reference
    the forces use (formed once it has moved)."""
    for i in range(lo, hi):
        corrected_stress(VP.shape[1], i, VP, VP, False, Linv, measure, S)


@njit(cache=True, inline="always")
def stress_at(dim, law, reference, failure, i, fs, Fr, w, c, state, trial, damaged, damaged_trial, P, work, F,
              VP, J, psi, dt):
    """From the motion fs[i] (F itself in the total-Lagrangian case): F[i] = fs F^r with an
    updated or current reference, the material update (new state in trial[i]), its damage
    (the `failure` model's: materials.damage, johnson_cook_failure), J, psi and VP[i] = w P, or w P F^rT =
    V^r P^r [V eq. 14] (updated), or w P F^T (current: the reference the forces use is
    the configuration F maps to). Returns whether the point is inverted or its stress not finite
    (never for a failed point, which carries no stress)."""
    if reference != REFERENCE_INITIAL:
        for a in range(dim):
            for b in range(dim):
                s = 0.0
                for k in range(dim):
                    s += fs[i, a, k] * Fr[i, k, b]
                F[i, a, b] = s
    e = update.update_failing(law, failure, F[i], dim, c, state, trial, damaged, damaged_trial, i, P, work, dt)
    J[i] = det(F[i], dim)
    psi[i] = e
    for a in range(dim):
        for b in range(dim):
            if reference == REFERENCE_UPDATED:
                s = 0.0
                for k in range(dim):
                    s += P[a, k] * Fr[i, b, k]
                VP[i, a, b] = w * s
            elif reference == REFERENCE_CURRENT:
                s = 0.0
                for k in range(dim):
                    s += P[a, k] * F[i, b, k]
                VP[i, a, b] = w * s
            else:
                VP[i, a, b] = w * P[a, b]
    return not (update.has_failed(failure, damaged, i) or (math.isfinite(e) and J[i] > 0.0))


@njit(cache=True)
def hourglass_coefficients(form, ptr, idx, dx, w, h, volume, measure, alpha, body, b, hgc):
    """Per-pair hourglass coefficients c_ij, written into hgc for the rows of body b (the
    paper form's regularising length 0.1 h_ij is formed by the force stage).

    V_i is the particle's physical volume and V_j W_ij the kernel weight, which uses the
    d-dimensional measure (area in 2D, length in 1D) so that the force is in newtons.
    """
    for i in range(len(ptr) - 1):
        if body[i] != b:
            continue
        for p in range(ptr[i], ptr[i + 1]):
            weight = volume[i] * measure[idx[p]] * w[p]
            dist2 = 0.0
            for a in range(dx.shape[1]):
                dist2 += dx[p, a] * dx[p, a]
            if form == HOURGLASS_PAPER:
                hgc[p] = 0.25 * alpha * weight / (dist2 + 0.01 * h[p] * h[p])
            else:
                hgc[p] = VARIATIONAL_SCALE * 0.5 * alpha * weight / dist2


@functools.lru_cache(maxsize=None)
def hourglass_error(dim: int):
    """The disorder measure per particle for dimension `dim` (compiled for it: the loops over
    components unrolled), a kernel (n, ptr, idx, X, support, kind, u, F, out, G): the part of
    the neighbour separations that F does not explain, relative to the separations
    themselves [G eq. 26],
        eta_i = sqrt( sum_j W_ij |F_i X_ij - x_ij|^2 / sum_j W_ij |X_ij|^2 ),
    W_ij formed from X_ij, the supports and the kernel (kernels.functions: `kind`). Zero for
    any affine motion; grows with hourglass modes and particle disorder."""

    @njit(cache=True, _nrt=False)
    def kernel(n, ptr, idx, X, support, kind, u, F, out, G):  # G: 3x3 scratch for F_i - I
        for i in range(n):
            for a in range(dim):
                for b in range(dim):
                    G[a, b] = F[i, a, b] - (1.0 if a == b else 0.0)
            num = 0.0
            den = 0.0
            for p in range(ptr[i], ptr[i + 1]):
                j = idx[p]
                e0, e1, e2 = separation(X, i, j, dim)
                r2 = 0.0
                for a in range(dim):
                    r2 += component(a, e0, e1, e2) * component(a, e0, e1, e2)
                w = value(kind, math.sqrt(r2), 0.5 * (support[i] + support[j]), dim)
                for a in range(dim):
                    e = u[j, a] - u[i, a]
                    for b in range(dim):
                        e -= G[a, b] * component(b, e0, e1, e2)
                    num += w * e * e
                    den += w * component(a, e0, e1, e2) * component(a, e0, e1, e2)
            out[i] = math.sqrt(num / den) if den > 0 else 0.0

    return kernel


@njit(cache=True, _nrt=False)
def spacing_ratio(n, ptr, idx, x, measure, F, dim, out, C):
    """Particle disorder seen in the current configuration, for any formulation:
        r_i = min_j |x_j - x_i| / (measure_i^(1/d) s_min(F_i)),
    the nearest current neighbour against the spacing the smooth deformation F (total)
    would give. At least about 1 for an affinely deformed lattice; particles that pair up or
    collapse onto each other drive it towards 0. C: 3x3 scratch."""
    for i in range(n):
        nearest = np.inf
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            r2 = 0.0
            for a in range(dim):
                e = x[j, a] - x[i, a]
                r2 += e * e
            nearest = min(nearest, r2)
        s_min = principal_stretches(F[i], dim, C)[0]
        out[i] = math.sqrt(nearest) / (measure[i] ** (1.0 / dim) * s_min) if s_min > 0 else 0.0


@njit(cache=True, _nrt=False)
def principal_stretches(F, dim, C):
    """(smallest, largest) principal stretch of F: square roots of the extreme eigenvalues
    of C = F^T F (C: 3x3 scratch)."""
    if dim == 1:
        s = abs(F[0, 0])
        return s, s
    right_cauchy_green(F, dim, C)
    smallest, largest = symmetric_extremes(C, dim)
    return math.sqrt(max(smallest, 0.0)), math.sqrt(max(largest, 0.0))


@njit(cache=True, inline="always")
def spring_terms(k, x0, x1, x2, t0, t1, t2, t3, t4, t5):
    """(t0..t5) + k x x^T of x = (x0, x1, x2), the symmetric tensor's (xx, yy, zz, xy, yz, xz);
    the components a lower dimension lacks are zero and add zero."""
    return (t0 + k * x0 * x0, t1 + k * x1 * x1, t2 + k * x2 * x2, t3 + k * x0 * x1, t4 + k * x1 * x2,
            t5 + k * x0 * x2)


@njit(cache=True, _nrt=False)
def stable_time_step(lo, hi, fs, F, J, min_spacing, stab, wave_speed, law, c, dim, broken, omega_hg2, hourglass,
                     damper_rate2, omega_c2, step_limit, scale, C):
    """(largest stable step before the CFL factor, largest incremental log strain) of the
    owned particles lo..hi-1:
        dt_i = 2 / sqrt(k^2 (omega_el^2 + omega_hg^2) + r_d^2 + omega_c^2),  omega_el = 2 c_i / (l_i s_min),
    k (`scale`) the body's factor that makes the body's own part match the largest frequency
    of its discrete force operator when measured (parsph.operator_frequency, stability.StableStep.calibrate),
    l_i the nearest reference neighbour distance, s_min the smallest principal stretch of
    the motion from the reference fs (the current spacing shrinks with it), and c_i the
    reference P-wave speed times the square root of the law's stiffening under the total F
    (materials.update.stiffening, from the law's constants c) and times stab_i^(3/4), the
    stiffening by Hessian stabilisation (formulations.reference; the power measured on the
    updated cylinder and punch, where the square root overshot the stable step by up to
    1.35x). omega_hg^2 (with hourglass control) bounds the hourglass springs under the
    current moduli (a yielded particle's is its yield stress, [G §4.5]), written by the
    forces stage: each pair is a spring of stiffness at most k_ij = c_ij (E_i + E_j) along
    the current separation n_ij with the paper's form (the force has |x_ij| / (|x_ij| +
    0.1 h_ij) of it), in every direction with the variational one; as (n.(x_i - x_j))^2 <=
    2 (n.x_i)^2 + 2 (n.x_j)^2, the largest eigenvalue of M^-1 K is at most
    max_i 2 lambda_max(sum_j k_ij n_ij n_ij^T) / m_i, about 1/dim of the scalar sum
    2 sum_j k_ij / m_i on a disordered lattice (the same in 1D). r_d^2 (damper_rate2, empty
    without MACHDYN's viscous hourglass force) bounds its dampers' rate the same way, written
    by the forces stage; k does not scale it (a damper's limit 2 / r_d is not the springs').
    The strain max |ln s| over the principal stretches of fs is the distortion measure of the adaptive reference
    update. omega_c^2 (omega_c2, empty without contact) bounds the contact springs the same
    way (parsph.contact). `step_limit` (empty without artificial viscosity or contact) caps
    a particle's step by its motion: no pair closing in faster than by its separation in a
    step (`artificial_viscosity`, parsph.contact), so that an impact faster than the wave
    speed is seen coming. In the total-Lagrangian formulation fs and F are the same array. Also returns
    the first particle with the smallest step (-1 if there is none); the first flattened or
    inverted particle i gives (0, inf, i). Failed particles (broken) are left out: they
    carry no stress. C: 3x3 scratch."""
    dt = np.inf
    worst = 0.0
    smallest = -1
    for i in range(lo, hi):
        if broken[i]:  # failed (materials.damage): no stiffness
            continue
        s_min, s_max = principal_stretches(F[i], dim, C)
        f_min, f_max = (s_min, s_max) if fs is F else principal_stretches(fs[i], dim, C)
        stiffening = update.stiffening(law, s_max, J[i], c)
        length = min_spacing[i] * min(1.0, f_min)
        if not (length > 0.0 and stiffening < np.inf):
            return 0.0, np.inf, i  # no stable step
        worst = max(worst, math.log(f_max), -math.log(f_min))
        w_el = 2.0 * wave_speed * math.sqrt(stiffening) * stab[i] ** 0.75 / length
        w2 = scale * scale * (w_el * w_el + (omega_hg2[i] if hourglass != HOURGLASS_OFF else 0.0))
        if len(damper_rate2):
            w2 += damper_rate2[i]
        if len(omega_c2):
            w2 += omega_c2[i]
        dt_i = 2.0 / math.sqrt(w2)
        if len(step_limit):
            dt_i = min(dt_i, step_limit[i])
        if dt_i < dt:
            dt, smallest = dt_i, i
    return dt, worst, smallest


@njit(cache=True, _nrt=False)
def artificial_viscosity(lo, hi, ptr, idx, gw, Linv, measure, X, d, v, J, density, gvolume, mass, support, c0, alpha, beta,
                         f_visc, heating, step_limit):
    """Monaghan's artificial viscosity (Monaghan 1992) for particles lo..hi-1: for each pair
    closing in (v_ij . x_ij < 0),
        Pi_ij = (-alpha c0 mu_ij + beta mu_ij^2) / rho_ij,  mu_ij = l v_ij . x_ij / (|x_ij|^2 + 0.01 l^2),
    l the mean smoothing length (half the support radii), rho_ij the mean current density
    rho0 / J, x and v current; the force on i is -sum_j Pi_ij (m_i rho_j g_ij - m_j rho_i g_ji) / 2
    with the pairs' kernel gradients g_ij = L_i^-1 gw_ij, g_ji = -(V^r_i / V^r_j) L_j^-1 gw_ij
    (V^r the reference measures; rho = m / V of `gvolume`, the volumes they were built with): the
    usual -m_i sum_j m_j Pi_ij grad W_ij, antisymmetric in i and j (momentum is conserved).
    The power a pair's forces dissipate, f_ij . (v_j - v_i) >= 0, heats its two particles
    alike (Monaghan 1992's du_i/dt = 1/2 sum_j m_j Pi_ij v_ij . grad W_ij): `heating` [W].
    step_limit: at most r / w over the closing pairs, w = -v_ij . x_ij / r the closing speed
    and r = |x_ij| (the time they take to meet at that speed: `stable_time_step`)."""
    dim = X.shape[1]
    for i in range(lo, hi):
        f0 = f1 = f2 = heat = 0.0  # the row's sums, stored once (as in `forces`)
        limit = step_limit[i]
        for p in range(ptr[i], ptr[i + 1]):
            j = idx[p]
            approach = 0.0
            r2 = 0.0
            e0, e1, e2 = separation(X, i, j, dim)
            for a in range(dim):
                xa = component(a, e0, e1, e2) + d[j, a] - d[i, a]
                approach += xa * (v[j, a] - v[i, a])
                r2 += xa * xa
            if approach >= 0.0:
                continue
            limit = min(limit, -r2 / approach)
            length = 0.25 * (support[i] + support[j])
            mu = length * approach / (r2 + 0.01 * length * length)
            pi = (-alpha * c0 * mu + beta * mu * mu) / (0.5 * density * (1.0 / J[i] + 1.0 / J[j]))
            rho_i, rho_j = mass[i] / gvolume[i], mass[j] / gvolume[j]
            g0, g1, g2 = corrected_gradient(dim, Linv, i, gw, p)
            b0, b1, b2 = corrected_gradient(dim, Linv, j, gw, p)  # g_ji = -(V^r_i / V^r_j) L_j^-1 gw_ij
            ratio = measure[i] / measure[j]
            for a in range(dim):
                f = 0.5 * pi * (mass[i] * rho_j * component(a, g0, g1, g2)
                                + mass[j] * rho_i * ratio * component(a, b0, b1, b2))
                f0, f1, f2 = added(a, -f, f0, f1, f2)
                heat -= 0.5 * f * (v[j, a] - v[i, a])
        for a in range(dim):
            f_visc[i, a] = component(a, f0, f1, f2)
        heating[i] = heat
        step_limit[i] = limit
