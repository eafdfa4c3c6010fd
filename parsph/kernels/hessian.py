"""Linearly corrected kernel Hessians in a reference configuration [V §3.4, eq. 18-20].

For row i and neighbours k with r_k = x_k - x_i, the kernel Hessian
H_k = grad grad phi(x_i - x_k) (kernels.functions.hessian) and the kernel value W_k:

    C_i = sum_k V_k H_k (x) r_k             (third order: [a, b, c] = H_ab r_c)
    D_i = sum_k V_k w_k r_k (x) r_k
    A_i = C_i . D_i^-1                       [V eq. 19]
    Hc_ik = V_k (H_k - w_k A_i . r_k)        (the corrected Hessian times the volume)

with w_k = 1 as printed in [V eq. 19] ("paper"), or w_k = W_k ("weighted", the default).
The printed A term gives every neighbour the same weight whatever its distance, so the
corrected Hessian jumps when a neighbour enters or leaves the support: harmless in a total-
Lagrangian run, whose neighbours never change, but at every reference update of the
updated formulation it kicks the particles (on the punch, an update one step after the
last changes the acceleration of a particle whose neighbour set changed by 3.7e4 m/s^2;
weighted, no particle's by more than 580 m/s^2). H_k and W_k vanish at the support's
edge, so the weighted form is continuous.

The self coefficient is -sum_k Hc_ik (it carries the B term of [V eq. 20]), so the Hessian
of a field psi at x_i is  sum_k (psi_k - psi_i) Hc_ik,  which is exactly zero for constant
and linear fields (sum_k Hc_ik (x) r_k = C_i - A_i . D_i = 0, either weight) and
approaches the true Hessian of smooth fields.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from parsph.errors import InputError
from parsph.kernels.functions import evaluate, hessian


@njit(cache=True)
def _corrected(ptr, dx, wt, dwdr, d2w, dist, vol_k, dim, Hc, bad):
    H = np.empty((dim, dim))
    C = np.empty((dim, dim, dim))
    D = np.empty((dim, dim))
    A = np.empty((dim, dim, dim))
    for i in range(len(ptr) - 1):
        C[:] = 0.0
        D[:] = 0.0
        for p in range(ptr[i], ptr[i + 1]):
            hessian(dwdr[p], d2w[p], dx[p], dist[p], H)
            for a in range(dim):
                for b in range(dim):
                    Hc[p, a, b] = vol_k[p] * H[a, b]
                    D[a, b] += vol_k[p] * wt[p] * dx[p, a] * dx[p, b]
                    for c in range(dim):
                        C[a, b, c] += vol_k[p] * H[a, b] * dx[p, c]
        if ptr[i + 1] == ptr[i]:
            continue
        if abs(np.linalg.det(D)) <= 1e-300:
            bad[i] = True
            continue
        Dinv = np.linalg.inv(D)
        for a in range(dim):
            for b in range(dim):
                for c in range(dim):
                    s = 0.0
                    for e in range(dim):
                        s += C[a, b, e] * Dinv[e, c]
                    A[a, b, c] = s
        for p in range(ptr[i], ptr[i + 1]):
            for a in range(dim):
                for b in range(dim):
                    s = 0.0
                    for c in range(dim):
                        s += A[a, b, c] * dx[p, c]
                    Hc[p, a, b] -= vol_k[p] * wt[p] * s


def corrected_hessians(pairs, dx, h_pair, measure, gid, kernel: str, weighted: bool) -> np.ndarray:
    """(npairs, d, d): V_k times the linearly corrected kernel Hessian for every pair of
    `pairs` (dx = x_k - x_i, pair supports h_pair, d-dimensional volumes `measure`), the A
    term weighted by the kernel or not (`weighted`)."""
    dim = dx.shape[1]
    dist = np.sqrt(np.einsum("pa,pa->p", dx, dx))
    w, dwdr, d2w = evaluate(kernel, dist, h_pair, dim)
    wt = w if weighted else np.ones_like(w)
    Hc = np.empty((len(dx), dim, dim))
    bad = np.zeros(pairs.n_rows, bool)
    _corrected(pairs.ptr, dx, wt, dwdr, d2w, dist, np.ascontiguousarray(measure[pairs.idx]), dim, Hc, bad)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise InputError(f"the Hessian correction of particle {int(gid[first])} is singular (its "
                         "neighbours are collinear); increase kernel.support")
    return Hc
