"""Tests for parsph.kernels.functions (h = compact support radius)."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from parsph.kernels import functions as kf
from parsph.kernels.functions import KERNELS, evaluate, gradient, hessian

NAMES = ["cubic_spline", "wendland_c2", "spiky"]
DIMS = [1, 2, 3]
HS = [1.0, 0.37]
# interior radii as fractions of h, chosen away from the cubic-spline
# breakpoint h/2 and from inflection points
FRACS = [0.07, 0.21, 0.33, 0.46, 0.58, 0.71, 0.84, 0.93]

CASES = [(n, d) for n in NAMES for d in DIMS]


def test_registry_contents():
    assert set(KERNELS) == set(NAMES)
    assert kf.KERNEL_NAMES == tuple(KERNELS)
    for name, k in KERNELS.items():
        assert isinstance(k, kf.Kernel)
        assert k.name == name
        assert k.w is getattr(kf, f"{name}_w")
        assert k.dw is getattr(kf, f"{name}_dw")
        assert k.d2w is getattr(kf, f"{name}_d2w")
        with pytest.raises(AttributeError):
            k.w = None  # immutable record


@pytest.mark.parametrize("name,dim", CASES)
@pytest.mark.parametrize("h", HS)
def test_unit_integral(name, dim, h):
    w = KERNELS[name].w
    if dim == 1:
        f = lambda r: 2.0 * w(r, h, dim)
    elif dim == 2:
        f = lambda r: 2.0 * math.pi * r * w(r, h, dim)
    else:
        f = lambda r: 4.0 * math.pi * r * r * w(r, h, dim)
    val, err = quad(f, 0.0, h, points=[0.5 * h], epsabs=1e-13, epsrel=1e-13, limit=200)
    assert abs(val - 1.0) < 1e-10, (name, dim, h, val)


EXPECTED_W0 = {
    # W(0) * h^D, from the normalisation constants
    ("cubic_spline", 1): 2.0 / 3.0 * 2.0,
    ("cubic_spline", 2): 10.0 / (7.0 * math.pi) * 4.0,
    ("cubic_spline", 3): 1.0 / math.pi * 8.0,
    ("wendland_c2", 1): 5.0 / 4.0,
    ("wendland_c2", 2): 7.0 / math.pi,
    ("wendland_c2", 3): 21.0 / (2.0 * math.pi),
    ("spiky", 1): 2.0,
    ("spiky", 2): 10.0 / math.pi,
    ("spiky", 3): 15.0 / math.pi,
}


@pytest.mark.parametrize("name,dim", CASES)
def test_central_value_and_scaling(name, dim):
    k = KERNELS[name]
    for h in HS:
        assert k.w(0.0, h, dim) == pytest.approx(EXPECTED_W0[(name, dim)] / h**dim, rel=1e-14)
    # W(r; h) = h^-D W(r/h; 1)
    for f in FRACS:
        h = 0.37
        assert k.w(f * h, h, dim) == pytest.approx(k.w(f, 1.0, dim) / h**dim, rel=1e-12)
        assert k.dw(f * h, h, dim) == pytest.approx(k.dw(f, 1.0, dim) / h ** (dim + 1), rel=1e-12)


@pytest.mark.parametrize("name,dim", CASES)
@pytest.mark.parametrize("h", HS)
def test_derivatives_finite_difference(name, dim, h):
    k = KERNELS[name]
    # scale of the second derivative, for an absolute floor near its zeros
    d2scale = max(abs(k.d2w(f * h, h, dim)) for f in [0.0] + FRACS)
    d1scale = max(abs(k.dw(f * h, h, dim)) for f in FRACS)
    for f in FRACS:
        r = f * h
        e = 1e-5 * h
        fd1 = (k.w(r + e, h, dim) - k.w(r - e, h, dim)) / (2 * e)
        assert abs(fd1 - k.dw(r, h, dim)) <= 1e-6 * max(abs(k.dw(r, h, dim)), 1e-3 * d1scale)
        e2 = 1e-4 * h
        fd2 = (k.w(r + e2, h, dim) - 2 * k.w(r, h, dim) + k.w(r - e2, h, dim)) / e2**2
        assert abs(fd2 - k.d2w(r, h, dim)) <= 1e-6 * max(abs(k.d2w(r, h, dim)), 1e-1 * d2scale)
        # tighter: d2w against central difference of dw
        e3 = 1e-6 * h
        fd2b = (k.dw(r + e3, h, dim) - k.dw(r - e3, h, dim)) / (2 * e3)
        assert abs(fd2b - k.d2w(r, h, dim)) <= 1e-6 * max(abs(k.d2w(r, h, dim)), 1e-3 * d2scale)


@pytest.mark.parametrize("name,dim", CASES)
def test_support_sign_and_origin(name, dim):
    k = KERNELS[name]
    h = 0.8
    for r in [h, h * (1 + 1e-12), 1.5 * h, 10.0 * h]:
        assert k.w(r, h, dim) == 0.0
        assert k.dw(r, h, dim) == 0.0
        assert k.d2w(r, h, dim) == 0.0
    rs = np.linspace(0.0, h, 2001)
    w = np.array([k.w(r, h, dim) for r in rs])
    dw = np.array([k.dw(r, h, dim) for r in rs[1:-1]])
    assert np.all(w >= 0.0)
    assert np.all(w[:-1] > 0.0)
    assert np.all(dw <= 0.0)
    # continuity at the support boundary
    assert k.w(h * (1 - 1e-7), h, dim) < 1e-12 / h**dim
    if name == "spiky":
        assert k.dw(0.0, h, dim) == pytest.approx(-3.0 * EXPECTED_W0[(name, dim)] / h ** (dim + 1))
    else:
        assert k.dw(0.0, h, dim) == 0.0
        # C1 / C2 continuity at the cubic-spline breakpoint h/2
        for fn in (k.w, k.dw, k.d2w):
            a, b = fn(0.5 * h * (1 - 1e-12), h, dim), fn(0.5 * h, h, dim)
            assert a == pytest.approx(b, rel=1e-9, abs=1e-12)


def _wx(k, x, h):
    return k.w(float(np.linalg.norm(x)), h, x.shape[0])


@pytest.mark.parametrize("name,dim", CASES)
def test_gradient_hessian_finite_difference(name, dim):
    k = KERNELS[name]
    rng = np.random.default_rng(1234 + dim)
    h = 0.9
    g = np.empty(dim)
    H = np.empty((dim, dim))
    for _ in range(6):
        n = rng.normal(size=dim)
        n /= np.linalg.norm(n)
        r = rng.uniform(0.1, 0.9) * h
        dx = r * n
        dw, d2w = k.dw(r, h, dim), k.d2w(r, h, dim)
        gradient(dw, dx, r, g)
        hessian(dw, d2w, dx, r, H)
        # gradient vs central differences of W(|x|)
        e = 1e-6 * h
        fdg = np.empty(dim)
        for i in range(dim):
            ei = np.zeros(dim)
            ei[i] = e
            fdg[i] = (_wx(k, dx + ei, h) - _wx(k, dx - ei, h)) / (2 * e)
        gscale = abs(dw)
        np.testing.assert_allclose(g, fdg, rtol=1e-6, atol=1e-6 * gscale)
        np.testing.assert_allclose(np.linalg.norm(g), abs(dw), rtol=1e-12)
        # Hessian vs second-order central differences of W(|x|)
        e = 1e-4 * h
        fdH = np.empty((dim, dim))
        for i in range(dim):
            ei = np.zeros(dim)
            ei[i] = e
            for j in range(dim):
                ej = np.zeros(dim)
                ej[j] = e
                fdH[i, j] = (
                    _wx(k, dx + ei + ej, h)
                    - _wx(k, dx + ei - ej, h)
                    - _wx(k, dx - ei + ej, h)
                    + _wx(k, dx - ei - ej, h)
                ) / (4 * e * e)
        hscale = max(abs(d2w), abs(dw) / r)
        np.testing.assert_allclose(H, fdH, rtol=0, atol=2e-6 * hscale)
        # Hessian vs central differences of the analytic gradient (tighter)
        e = 1e-6 * h
        gp, gm = np.empty(dim), np.empty(dim)
        for j in range(dim):
            ej = np.zeros(dim)
            ej[j] = e
            xp, xm = dx + ej, dx - ej
            rp, rm = np.linalg.norm(xp), np.linalg.norm(xm)
            gradient(k.dw(rp, h, dim), xp, rp, gp)
            gradient(k.dw(rm, h, dim), xm, rm, gm)
            np.testing.assert_allclose(H[:, j], (gp - gm) / (2 * e), rtol=0, atol=1e-6 * hscale)
        # symmetric; trace is the radial Laplacian W'' + (D-1) W'/r
        np.testing.assert_array_equal(H, H.T)
        assert np.trace(H) == pytest.approx(d2w + (dim - 1) * dw / r, rel=1e-12, abs=1e-12 * hscale)


@pytest.mark.parametrize("dim", DIMS)
def test_gradient_hessian_at_origin(dim):
    dx = np.zeros(dim)
    g = np.full(dim, 7.0)
    H = np.full((dim, dim), 7.0)
    k = KERNELS["wendland_c2"]
    gradient(k.dw(0.0, 1.0, dim), dx, 0.0, g)
    hessian(k.dw(0.0, 1.0, dim), k.d2w(0.0, 1.0, dim), dx, 0.0, H)
    np.testing.assert_array_equal(g, 0.0)
    np.testing.assert_array_equal(H, k.d2w(0.0, 1.0, dim) * np.eye(dim))
    # the limit r -> 0 of the Hessian is continuous for the smooth kernels
    for name in ("cubic_spline", "wendland_c2"):
        k = KERNELS[name]
        n = np.ones(dim) / math.sqrt(dim)
        r = 1e-7
        hessian(k.dw(r, 1.0, dim), k.d2w(r, 1.0, dim), r * n, r, H)
        np.testing.assert_allclose(H, k.d2w(0.0, 1.0, dim) * np.eye(dim), rtol=0,
                                   atol=1e-5 * abs(k.d2w(0.0, 1.0, dim)))


@pytest.mark.parametrize("name,dim", CASES)
def test_evaluate_matches_scalar(name, dim):
    k = KERNELS[name]
    rng = np.random.default_rng(7)
    m = 257
    h = rng.uniform(0.5, 2.0, size=m)
    r = rng.uniform(0.0, 1.3, size=m) * h
    r[0] = 0.0
    r[1] = h[1]
    for harg in (h, 1.1):
        w, dw, d2w = evaluate(name, r, harg, dim)
        hh = np.broadcast_to(harg, r.shape)
        assert w.shape == dw.shape == d2w.shape == (m,)
        assert w.dtype == np.float64
        np.testing.assert_array_equal(w, [k.w(a, b, dim) for a, b in zip(r, hh)])
        np.testing.assert_array_equal(dw, [k.dw(a, b, dim) for a, b in zip(r, hh)])
        np.testing.assert_array_equal(d2w, [k.d2w(a, b, dim) for a, b in zip(r, hh)])


def test_evaluate_errors():
    with pytest.raises(ValueError) as exc:
        evaluate("gaussian", np.array([0.1]), 1.0, 2)
    msg = str(exc.value)
    assert "gaussian" in msg
    for n in NAMES:
        assert n in msg
    with pytest.raises(ValueError):
        evaluate("spiky", np.array([0.1]), 1.0, 4)
    with pytest.raises(ValueError):
        kf.get_kernel("nope")
    assert kf.get_kernel("spiky") is KERNELS["spiky"]


@pytest.mark.parametrize("dim, count, r, spread", [(1, 200, 0.03, 1.0), (2, 800, 0.06, 1.0), (3, 1500, 0.15, 1.0),
                                                    (2, 300, 1e-3, 1.0), (3, 200, 0.2, 1e4), (2, 100, 1e-7, 1.0)])
def test_close_pairs_are_every_pair_within_the_radius(dim, count, r, spread):
    """The cell search finds every pair at most r apart, once (i < j), against all pairs by
    brute force; with the cells too many for a table (a sparse cloud), by bisection; with
    too many cells per dimension, by a k-d tree."""
    from parsph.cells import close_pairs

    rng = np.random.default_rng(dim)
    x = rng.random((count, dim)) * spread
    x[:count // 2] = x[:count // 2] / spread  # a dense cluster and, with spread, a far sparse cloud
    i, j = close_pairs(x, r)
    found = set(zip(i.tolist(), j.tolist()))
    d = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=2)
    a, b = np.nonzero(np.triu(d <= r, k=1))
    assert set(zip(a.tolist(), b.tolist())) <= found
    assert len(found) == len(i) and np.all(i < j)
    assert np.all(d[i, j] <= r * (1 + 1e-9))
