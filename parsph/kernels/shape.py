"""Shape-function gradients of the meshfree Galerkin methods at integration points, compiled
(formulations.galerkin gives the formulas and where they come from).

For a relation from integration points q to the particles J whose kernel covers them, with
W_J(X_q) of support h_J and its gradient with respect to X_q:

  kbm  Shepard functions Phi_J = W_J / S, S = sum_J W_J [R eq. 28]; trial gradients
       G_J = A^-T grad Phi_J with A = sum_J (X_J - X_q) (x) grad Phi_J [R eq. 29-32];
       row data (S, grad S)
  mls  linear-basis MLS [R eq. 37-42]: p_J = (1, (X_J - X_q) / l), M = sum_J W_J p_J p_J^T,
       gamma = M^-1 e_0, Phi_J = gamma . p_J W_J and
       d_a Phi_J = (M^-1 p_J)_(1+a) W_J / l - v_a . M^-1 p_J W_J + (gamma . p_J) d_a W_J,
       v_a = (d_a M) gamma; row data (l, M^-1, v)

and the test gradients grad N_I(X_q) of the particles I at the points q (a relation from
particles to points) from the row data of q. A matrix whose condition number
|A|_F |A^-1|_F reaches kernels.correction.MAX_CONDITION counts as singular. The rows of a
point are summed in the order of the relation's columns (global ids).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit

from parsph.kernels.correction import MAX_CONDITION
from parsph.kernels.functions import value_and_slope

FINE, EMPTY, SINGULAR = 0, 1, 2


def row_data_width(shape: str, dim: int) -> int:
    """Columns of a point's row data: (S, grad S) or (l, M^-1, v)."""
    m = dim + 1
    return 1 + dim if shape == "kbm" else 1 + m * m + dim * m


def row_data_sign(shape: str, sign: np.ndarray) -> np.ndarray:
    """The factors (points, row_data_width) that reflect the row data of points whose
    positions reflect by `sign` (points, dim), +1 or -1 per component: kbm (S, grad S) as
    (1, s); mls (l, M^-1, v) with the basis (1, (X_J - X_q) / l), which reflects by
    D = (1, s), as (1, D_a D_b, s_c D_a) (M^-1 -> D M^-1 D, v_c = (d_c M) gamma -> s_c D v_c)."""
    one = np.ones((len(sign), 1))
    if shape == "kbm":
        return np.concatenate([one, sign], axis=1)
    D = np.concatenate([one, sign], axis=1)
    return np.concatenate([one, (D[:, :, None] * D[:, None, :]).reshape(len(sign), -1),
                           (sign[:, :, None] * D[:, None, :]).reshape(len(sign), -1)], axis=1)


@njit(cache=True, inline="always")
def _kernel(kind, xq, xJ, q, J, h, dim, grad):
    """W_J(X_q) with support h, its gradient with respect to X_q into grad."""
    r2 = 0.0
    for a in range(dim):
        e = xq[q, a] - xJ[J, a]
        grad[a] = e
        r2 += e * e
    r = math.sqrt(r2)
    w, dw = value_and_slope(kind, r, h, dim)
    c = dw / r if r > 0.0 else 0.0
    for a in range(dim):
        grad[a] *= c
    return w


@njit(cache=True, inline="always")
def _invert(A, n, out, work):
    """out = A^-1 (n x n) by Gauss-Jordan elimination with partial pivoting; returns the
    condition number |A|_F |A^-1|_F (inf if a pivot vanishes). work: n x 2n scratch."""
    norm = 0.0
    for a in range(n):
        for b in range(n):
            work[a, b] = A[a, b]
            work[a, n + b] = 1.0 if a == b else 0.0
            norm += A[a, b] * A[a, b]
    for c in range(n):
        pivot = c
        for a in range(c + 1, n):
            if abs(work[a, c]) > abs(work[pivot, c]):
                pivot = a
        if not abs(work[pivot, c]) > 0.0:
            return np.inf
        if pivot != c:
            for b in range(2 * n):
                work[c, b], work[pivot, b] = work[pivot, b], work[c, b]
        scale = 1.0 / work[c, c]
        for b in range(2 * n):
            work[c, b] *= scale
        for a in range(n):
            if a != c and work[a, c] != 0.0:
                f = work[a, c]
                for b in range(2 * n):
                    work[a, b] -= f * work[c, b]
    inv_norm = 0.0
    for a in range(n):
        for b in range(n):
            out[a, b] = work[a, n + b]
            inv_norm += out[a, b] * out[a, b]
    return math.sqrt(norm * inv_norm)


@njit(cache=True, inline="always")
def _mls_gradient(w, grad, pv, data, q, dim, Mp, out, k):
    """d Phi per pair (the module's formula) into out[k] from p (pv), W, grad W and the row
    data of q; Mp: m scratch."""
    m = dim + 1
    scale = 1.0 / data[q, 0]
    gp = 0.0
    for a in range(m):
        s = 0.0
        for b in range(m):
            s += data[q, 1 + a * m + b] * pv[b]
        Mp[a] = s
        gp += data[q, 1 + a * m] * pv[a]  # gamma = M^-1 e_0, the first column (M^-1 is symmetric)
    base = 1 + m * m
    for a in range(dim):
        second = 0.0
        for b in range(m):
            second += data[q, base + a * m + b] * Mp[b]
        out[k, a] = Mp[1 + a] * w * scale - second * w + gp * grad[a]


@functools.lru_cache(maxsize=None)
def compile_shape(dim: int) -> tuple:
    """(kbm_trial, mls_trial, test_gradients) compiled for dimension `dim` (a constant of
    the machine code: its loops are unrolled)."""
    @njit(cache=True, _nrt=False)
    def kbm_trial(ptr, idx, x_rows, x_cols, support, kind, active, G, data, phi, A, Ainv, work, grad, report):
        """Shepard trial gradients G and values phi per pair, row data (S, grad S) per row;
        rows not `active` get S = 1, grad S = 0. Returns FINE, or EMPTY / SINGULAR with the row
        (and the condition number) in report."""
        for q in range(len(ptr) - 1):
            if not active[q]:
                data[q, 0] = 1.0
                for a in range(dim):
                    data[q, 1 + a] = 0.0
                continue
            if ptr[q + 1] == ptr[q]:
                report[0] = q
                return EMPTY
            S = 0.0
            for a in range(dim):
                data[q, 1 + a] = 0.0
            for p in range(ptr[q], ptr[q + 1]):
                w = _kernel(kind, x_rows, x_cols, q, idx[p], support[idx[p]], dim, grad)
                phi[p] = w
                S += w
                for a in range(dim):
                    G[p, a] = grad[a]
                    data[q, 1 + a] += grad[a]
            data[q, 0] = S
            for a in range(dim):
                for b in range(dim):
                    A[a, b] = 0.0
            for p in range(ptr[q], ptr[q + 1]):
                J = idx[p]
                phi[p] /= S
                for b in range(dim):  # grad Phi_J = (grad W_J - Phi_J grad S) / S
                    G[p, b] = (G[p, b] - phi[p] * data[q, 1 + b]) / S
                for a in range(dim):
                    e = x_cols[J, a] - x_rows[q, a]
                    for b in range(dim):
                        A[a, b] += e * G[p, b]
            condition = _invert(A, dim, Ainv, work)
            if not condition < MAX_CONDITION:
                report[0], report[1] = q, condition
                return SINGULAR
            for p in range(ptr[q], ptr[q + 1]):
                for a in range(dim):
                    grad[a] = G[p, a]
                for a in range(dim):
                    s = 0.0
                    for b in range(dim):
                        s += Ainv[b, a] * grad[b]
                    G[p, a] = s
        return FINE


    @njit(cache=True, _nrt=False)
    def mls_trial(ptr, idx, x_rows, x_cols, support, kind, active, G, data, phi, M, Minv, work, grad, pv, dM, Mp,
                  report):
        """MLS trial gradients G and values phi per pair, row data (l, M^-1, v) per row, l the
        support of the row's first particle (it keeps M well conditioned at any size; the
        shape functions do not depend on it); rows not `active` get l = 1, M^-1 = I, v = 0.
        Returns as kbm_trial. dM: dim x m x m scratch."""
        m = dim + 1
        base = 1 + m * m
        for q in range(len(ptr) - 1):
            if not active[q]:
                data[q, 0] = 1.0
                for a in range(m):
                    for b in range(m):
                        data[q, 1 + a * m + b] = 1.0 if a == b else 0.0
                for a in range(dim * m):
                    data[q, base + a] = 0.0
                continue
            if ptr[q + 1] == ptr[q]:
                report[0] = q
                return EMPTY
            length = support[idx[ptr[q]]]
            scale = 1.0 / length
            for a in range(m):
                for b in range(a, m):
                    M[a, b] = 0.0
                    for c in range(dim):
                        dM[c, a, b] = 0.0
            for p in range(ptr[q], ptr[q + 1]):  # W and grad W kept in phi and G for the second pass
                J = idx[p]
                w = _kernel(kind, x_rows, x_cols, q, J, support[J], dim, grad)
                phi[p] = w
                pv[0] = 1.0
                for a in range(dim):
                    G[p, a] = grad[a]
                    pv[1 + a] = (x_cols[J, a] - x_rows[q, a]) * scale
                for a in range(m):  # the upper triangles: M and d_c M are symmetric
                    for b in range(a, m):
                        pp = pv[a] * pv[b]
                        M[a, b] += w * pp
                        for c in range(dim):
                            dM[c, a, b] += grad[c] * pp
            for a in range(m):
                for b in range(a):
                    M[a, b] = M[b, a]
                    for c in range(dim):
                        dM[c, a, b] = dM[c, b, a]
            condition = _invert(M, m, Minv, work)
            if not condition < MAX_CONDITION:
                report[0], report[1] = q, condition
                return SINGULAR
            data[q, 0] = length
            for a in range(m):
                for b in range(m):
                    data[q, 1 + a * m + b] = Minv[a, b]
            for c in range(dim):  # v_c = (d_c M) gamma
                for a in range(m):
                    s = 0.0
                    for b in range(m):
                        s += dM[c, a, b] * Minv[b, 0]
                    data[q, base + c * m + a] = s
            for p in range(ptr[q], ptr[q + 1]):
                J = idx[p]
                w = phi[p]
                pv[0] = 1.0
                for a in range(dim):
                    grad[a] = G[p, a]
                    pv[1 + a] = (x_cols[J, a] - x_rows[q, a]) * scale
                s = 0.0
                for a in range(m):
                    s += Minv[0, a] * pv[a]
                phi[p] = s * w
                _mls_gradient(w, grad, pv, data, q, dim, Mp, G, p)
        return FINE


    @njit(cache=True, _nrt=False)
    def test_gradients(mls, ptr, idx, x_rows, x_cols, support, kind, data, out, grad, pv, Mp):
        """grad N_I(X_q) per pair of a relation from particles I (rows at x_rows) to points q
        (columns at x_cols), from the row data of q: Shepard (mls False) or MLS."""
        for i in range(len(ptr) - 1):
            for p in range(ptr[i], ptr[i + 1]):
                q = idx[p]
                w = _kernel(kind, x_cols, x_rows, q, i, support[i], dim, grad)
                if mls:
                    pv[0] = 1.0
                    scale = 1.0 / data[q, 0]
                    for a in range(dim):
                        pv[1 + a] = (x_rows[i, a] - x_cols[q, a]) * scale
                    _mls_gradient(w, grad, pv, data, q, dim, Mp, out, p)
                else:
                    S = data[q, 0]
                    for a in range(dim):
                        out[p, a] = (grad[a] - w / S * data[q, 1 + a]) / S

    return kbm_trial, mls_trial, test_gradients
