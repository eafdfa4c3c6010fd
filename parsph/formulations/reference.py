"""The per-pair data of a reference configuration that the compiled stages read.

Built once in the total-Lagrangian formulation and again at every update of the reference
in the updated one [V §3.1]: neighbours (neighbors.find_pairs), the corrected gradients
g_ij = V_j L_i^-1 grad W [V eq. 13] as the weighted kernel gradients gw_ij = V_j grad W with
their row sums and L_i^-1 of each row (kernels.correction), hourglass coefficients
[G eq. 31], and for Hessian's-difference stabilisation [V eq. 17, 21]

    q_ij  = eta Hc_ij h_i        (corrected kernel Hessian times the vector h, kernels.hessian,
                                  its A term weighted by the kernel unless `weighted_hessian` is off)
    gh_ij = eta g_ij . h_i

with h_i = (l_i, ..., l_i) and l_i = support_i / 2, the smoothing length (Remark 2: equal
components along the Cartesian axes, constant in time). Taking l_i = support_i, the paper's
dilation parameter rho, doubles the stabilisation and was measured further from
total-Lagrangian on the bar and the cylinder (README, Known gaps).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from parsph.errors import ParsphError
from parsph.formulations import tlsph
from parsph.kernels.correction import KeptPairs, reference_pairs, reverse_index, reverse_values
from parsph.kernels.hessian import corrected_hessians
from parsph.neighbors import find_pairs, within_bodies, without
from parsph.relations import Relation


@dataclass
class ReferenceData:
    """CSR rows of the owned particles (indices into the rank's local arrays). The pair loops
    form X_j - X_i from the reference positions (state.RankState.reference_positions), and
    from it the kernel values and regularising lengths: they are not stored. Nor are the
    corrected gradients: g_ij = L_i^-1 gw_ij, and the reverse g_ji = -(V_i / V_j) L_j^-1 gw_ij
    (V the reference measures, state.RankState.reference_measure)."""

    ptr: np.ndarray
    idx: np.ndarray  # 32-bit neighbour rows
    gw: np.ndarray  # V_j w_ij per pair
    gw_sum: np.ndarray  # its row sums
    Linv: np.ndarray  # L_i^-1 of the owned and ghost rows
    hgc: np.ndarray  # hourglass coefficients c_ij (empty without hourglass control)
    q: np.ndarray  # Hessian stabilisation (empty when eta = 0)
    q_rev: np.ndarray
    q_sum: np.ndarray
    gh: np.ndarray
    gh_rev: np.ndarray
    min_spacing: np.ndarray  # nearest reference neighbour distance of each owned particle
    stiffening: np.ndarray  # how much the stabilisation stiffens each owned particle (>= 1)
    kept: KeptPairs | None  # an Eulerian kernel's lists with a skin, kept between searches
    bad: np.ndarray  # owned rows whose correction matrix is singular (with `tolerant`)


@dataclass(frozen=True)
class PairOptions:
    """What one body's reference data needs: corrected gradients (False: plain SPH), the
    hourglass form (tlsph.HOURGLASS_*) and coefficient alpha, Hessian stabilisation."""

    corrected: bool
    hourglass_form: int
    alpha: float
    stabilised: bool = False


NO_PAIRS = PairOptions(corrected=False, hourglass_form=0, alpha=0.0)  # a body another relation holds


def build(X, measure, volume, support, gid, n_owned: int, n_rows: int, kernel: str, body: np.ndarray,
          options: list, eta: float, weighted_hessian: bool, skin: float | None = None,
          kept: KeptPairs | None = None,
          detached: np.ndarray | None = None, cut: np.ndarray | None = None,
          tolerant: bool = False) -> ReferenceData:
    """Reference data for rows 0..n_owned-1 of the local particles; rows up to n_rows (owned
    and layer-1 ghosts) are built to provide the ghosts' L_j^-1 and the stabilisation's
    reverse coefficients. `body` is each
    local particle's body index and options[b] its body's PairOptions, or None for a body
    whose rows are left empty (another kernel relation holds them); particles of
    different bodies are not neighbours, nor are `detached` ones (a bool per local particle:
    failed particles whose pairs are broken, materials.damage) of any, nor the pairs `cut`
    (neighbors.crossing: across a crack). The neighbours are
    searched for, or, given a `skin` (an updated reference), built by KeptPairs on lists
    that much wider, which are kept (`kept`) until a particle has moved half the skin: the
    same pairs in the same order. The kept lists are filtered as the search is (KeptPairs
    keeps its `detached` rows; given `detached`, `kept` is filtered again). `tolerant`:
    owned rows left with a singular correction matrix are listed in `bad` rather than raised."""
    members = np.array([o is not None for o in options])
    options = [o or NO_PAIRS for o in options]
    corrected = np.array([o.corrected for o in options])
    breaks = detached is not None and detached.any()
    cut = np.zeros(0, np.int64) if cut is None else cut
    if skin is not None or kept is not None:
        if kept is None:
            candidates = find_pairs(X, support, gid, n_rows, skin)
            if len(options) > 1:
                candidates = within_bodies(candidates, body)
            if not members.all():
                candidates = _rows_of(candidates, members[body[:n_rows]])
            kept = KeptPairs(candidates, X.shape[1], kernel, (eta, weighted_hessian) if eta > 0 else None)
        if breaks:
            kept = kept.without(detached, gid, cut)
        return _rebuilt(kept, X, measure, volume, support, gid, n_owned, body, options, tolerant)
    pairs = find_pairs(X, support, gid, n_rows)
    if len(options) > 1:
        pairs = within_bodies(pairs, body)
    if not members.all():
        pairs = _rows_of(pairs, members[body[:n_rows]])
    if breaks:
        pairs = without(pairs, detached, gid, cut)
    n = n_owned
    end = int(pairs.ptr[n])
    ptr = pairs.ptr[: n + 1].copy()
    idx = np.ascontiguousarray(pairs.idx[:end], dtype=np.int32)
    hourglass = [(b, o) for b, o in enumerate(options) if o.hourglass_form]
    hgc = np.zeros(end if hourglass else 0)

    def coefficients(r0, r1, p0, p1, dx, w, h):
        """The hourglass coefficients of the owned rows among rows r0..r1-1 (pairs p0..p1-1)."""
        r1 = min(r1, n)
        if r1 > r0:
            q1 = int(ptr[r1])
            for b, o in hourglass:
                tlsph.hourglass_coefficients(o.hourglass_form, ptr[r0:r1 + 1] - p0, idx[p0:q1], dx, w, h,
                                             volume[r0:r1], measure, float(o.alpha), body[r0:r1], b, hgc[p0:q1])

    # the stabilisation needs every pair's separation and support; else they are made and
    # used a block of rows at a time (reference_pairs)
    ref = reference_pairs(X, measure, support, gid, pairs, kernel,
                          None if corrected.all() else corrected[body[:n_rows]],
                          None if detached is None else detached[:n_rows], tolerant,
                          each_block=None if eta > 0 else coefficients)
    if eta > 0:
        coefficients(0, n_rows, 0, len(pairs.idx), ref.dx, ref.w, ref.h)
    dim = X.shape[1]
    q = q_rev = np.zeros((0, dim))
    gh = gh_rev = np.zeros(0)
    q_sum = np.zeros((0, dim))
    rows = pairs.row_of_pair()[:end] if eta > 0 else None
    if eta > 0:
        hvec = 0.5 * support[: n_rows]
        row_all = pairs.row_of_pair()
        Hc = corrected_hessians(pairs, ref.dx, ref.h, measure, gid, kernel, weighted_hessian)
        q_all = eta * hvec[row_all, None] * np.einsum("pab->pa", Hc)
        g = np.einsum("pab,pb->pa", ref.Linv[row_all], ref.gw)
        gh_all = eta * hvec[row_all] * np.einsum("pa->p", g)
        rev = reverse_index(pairs)[:end]
        q, gh = np.ascontiguousarray(q_all[:end]), np.ascontiguousarray(gh_all[:end])
        q_rev, gh_rev = reverse_values(q_all, rev), reverse_values(gh_all, rev)
        q_sum = np.stack([np.bincount(rows, q[:, a], n) for a in range(dim)], axis=1)
    min_spacing = ref.nearest[:n].copy()
    stiffening = np.ones(n)
    if eta > 0 and end:
        # the stabilised gradient g + q - gh (sum g) against g, row by row: the fastest mode's
        # frequency grows with up to its 3/4 power (measured: bar, cylinder, punch, rings)
        size_g = np.bincount(rows, np.sqrt(np.einsum("pa,pa->p", g[:end], g[:end])), n)
        size_q = np.bincount(rows, np.sqrt(np.einsum("pa,pa->p", q, q)), n)
        size_gh = np.bincount(rows, np.abs(gh), n)
        has_g = size_g > 0
        stiffening[has_g] = 1.0 + (size_q[has_g] + size_gh[has_g] * size_g[has_g]) / size_g[has_g]
        stiffening[~np.array([o.stabilised for o in options])[body[:n]]] = 1.0  # the bodies without it
    if (idx >= n_rows).any():
        raise ParsphError("internal: a neighbour of an owned particle has no reference row")
    return ReferenceData(
        ptr=ptr, idx=idx, gw=np.ascontiguousarray(ref.gw[:end]), gw_sum=np.ascontiguousarray(ref.gw_sum[:n]),
        Linv=ref.Linv, hgc=hgc, q=q, q_rev=q_rev, q_sum=q_sum, gh=gh, gh_rev=gh_rev, min_spacing=min_spacing, stiffening=stiffening,
        kept=None, bad=ref.bad[ref.bad < n])


def _rebuilt(kept: KeptPairs, X, measure, volume, support, gid, n: int, body: np.ndarray,
             options: list, tolerant: bool) -> ReferenceData:
    """The reference data of an updated reference from its KeptPairs (views of their arrays,
    rebuilt in place at the next update)."""
    rows = kept.candidates.n_rows
    plain = ~np.array([o.corrected for o in options])[body[:rows]]
    min_spacing, stiffening = np.empty(n), np.ones(n)
    end, bad = kept.rebuild(X, measure, support, gid, plain, n, min_spacing, stiffening, tolerant)
    dim = X.shape[1]
    ptr, idx, dx, w = kept.ptr[: n + 1], kept.idx[:end], kept.dx[:end], kept.w[:end]
    hgc = np.zeros(0)
    if any(o.hourglass_form for o in options):
        hgc = np.zeros(end)
        for b, o in enumerate(options):
            if o.hourglass_form:
                tlsph.hourglass_coefficients(o.hourglass_form, ptr, idx, dx, w, kept.h[:end], volume, measure,
                                             float(o.alpha), body[:n], b, hgc)
    stabilised = kept.eta > 0
    if stabilised:
        stiffening[~np.array([o.stabilised for o in options])[body[:n]]] = 1.0  # the bodies without it
    return ReferenceData(
        ptr=ptr, idx=idx, gw=kept.gw[:end], gw_sum=kept.gw_sum[:n], Linv=kept.Linv, hgc=hgc,
        q=kept.q[:end] if stabilised else np.zeros((0, dim)),
        q_rev=kept.q_rev[:end] if stabilised else np.zeros((0, dim)),
        q_sum=kept.q_sum[:n] if stabilised else np.zeros((0, dim)), gh=kept.gh[:end] if stabilised else np.zeros(0),
        gh_rev=kept.gh_rev[:end] if stabilised else np.zeros(0), min_spacing=min_spacing, stiffening=stiffening,
        kept=kept, bad=bad)


def _rows_of(pairs: Relation, rows: np.ndarray) -> Relation:
    """`pairs` with only the `rows` (a bool per row) keeping theirs: pairs join particles of
    one body, so the other rows are simply left empty."""
    counts = np.where(rows, pairs.counts(), 0)
    ptr = np.zeros(pairs.n_rows + 1, np.int64)
    np.cumsum(counts, out=ptr[1:])
    return Relation(ptr, pairs.idx[np.repeat(rows, pairs.counts())])
