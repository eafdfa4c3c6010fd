"""Radial SPH smoothing kernels W(r, h) in dimension D = 1, 2, 3.

Convention
----------
Throughout parsph, ``h`` denotes the **compact support radius** of the
kernel: W(r) = 0 (and dW/dr = 0) for r >= h.  Note that many papers instead
use a "smoothing length" that is a fraction of the support radius; any such
length is converted here so that the support is always exactly ``h``.

Kernels
-------
``cubic_spline``
    The cubic B-spline as written in Rabczuk, Belytschko & Xiao (2004),
    "Stable particle methods based on Lagrangian kernels", CMAME 193,
    eqs. (14)-(15).  With smoothing length s = h/2 and z = r/s::

        W = C/s^D (1 - 1.5 z^2 + 0.75 z^3)   0 <= z < 1
        W = C/(4 s^D) (2 - z)^3              1 <= z < 2
        W = 0                                z >= 2

    with C = 2/3 (1D), 10/(7 pi) (2D), 1/pi (3D) (Monaghan & Lattanzio 1985).

``wendland_c2``
    Wendland's C2 compactly supported function (H. Wendland, "Piecewise
    polynomial, positive definite and compactly supported radial functions of
    minimal degree", Adv. Comput. Math. 4 (1995) 389-396), q = r/h::

        1D:     W = 5/(4 h)          (1-q)^3 (1+3q)
        2D:     W = 7/(pi h^2)       (1-q)^4 (1+4q)
        3D:     W = 21/(2 pi h^3)    (1-q)^4 (1+4q)

    (the 1D function is the C2 Wendland function phi_{1,1}, the 2D/3D function
    is phi_{3,1}; constants make the integral over R^D equal to one, see also
    Dehnen & Aly 2012, MNRAS 425, Table 1).

``spiky``
    Desbrun & Gascuel (1996), "Smoothed particles: a new paradigm for
    animating highly deformable bodies", Eurographics CAS '96, as popularised
    by Mueller, Charypar & Gross (2003, SCA), eq. (21)::

        W = C_D (h - r)^3,   C_1 = 2/h^4,  C_2 = 10/(pi h^5),  C_3 = 15/(pi h^6)

Public API
----------
For each kernel ``<name>`` there are ``numba.njit`` scalar functions
``<name>_w(r, h, dim)``, ``<name>_dw(r, h, dim)`` (dW/dr) and
``<name>_d2w(r, h, dim)`` (d^2W/dr^2).  At r = 0 the one-sided (r -> 0+) values
are returned; dW/dr(0) = 0 for the cubic spline and Wendland kernels, while
the spiky kernel has dW/dr(0) = -3 C h^2 (it is only meant to be used with
r > 0).  ``KERNELS`` maps each name to a :class:`Kernel` record of these
functions; :func:`gradient` and :func:`hessian` turn radial derivatives into
Cartesian ones; :func:`evaluate` is a vectorised Python-level helper.
"""

from collections import namedtuple

import numpy as np
from numba import njit

__all__ = [
    "Kernel",
    "KERNELS",
    "KERNEL_NAMES",
    "get_kernel",
    "cubic_spline_w",
    "cubic_spline_dw",
    "cubic_spline_d2w",
    "wendland_c2_w",
    "wendland_c2_dw",
    "wendland_c2_d2w",
    "spiky_w",
    "spiky_dw",
    "spiky_d2w",
    "gradient",
    "hessian",
    "evaluate",
    "value_and_slope",
    "curvature",
]


# ---------------------------------------------------------------------------
# Cubic B-spline (Rabczuk, Belytschko & Xiao 2004, eqs. 14-15), s = h/2
# ---------------------------------------------------------------------------
@njit(cache=True)
def _cubic_spline_sigma(h, dim):
    """Return C / s^D with s = h/2 (the prefactor of W)."""
    s = 0.5 * h
    if dim == 1:
        return (2.0 / 3.0) / s
    elif dim == 2:
        return (10.0 / (7.0 * np.pi)) / (s * s)
    elif dim == 3:
        return (1.0 / np.pi) / (s * s * s)
    raise ValueError("kernel dimension must be 1, 2 or 3")


@njit(cache=True)
def cubic_spline_w(r, h, dim):
    """Cubic B-spline W(r); support radius h (smoothing length h/2)."""
    sig = _cubic_spline_sigma(h, dim)
    z = 2.0 * r / h
    if z < 1.0:
        return sig * (1.0 - 1.5 * z * z + 0.75 * z * z * z)
    elif z < 2.0:
        t = 2.0 - z
        return sig * 0.25 * t * t * t
    return 0.0


@njit(cache=True)
def cubic_spline_dw(r, h, dim):
    """Cubic B-spline dW/dr; zero at r = 0 and for r >= h."""
    s = 0.5 * h
    sig = _cubic_spline_sigma(h, dim) / s
    z = r / s
    if z < 1.0:
        return sig * (-3.0 * z + 2.25 * z * z)
    elif z < 2.0:
        t = 2.0 - z
        return -0.75 * sig * t * t
    return 0.0


@njit(cache=True)
def cubic_spline_d2w(r, h, dim):
    """Cubic B-spline d^2W/dr^2 (continuous; zero for r >= h)."""
    s = 0.5 * h
    sig = _cubic_spline_sigma(h, dim) / (s * s)
    z = r / s
    if z < 1.0:
        return sig * (-3.0 + 4.5 * z)
    elif z < 2.0:
        return 1.5 * sig * (2.0 - z)
    return 0.0


# ---------------------------------------------------------------------------
# Wendland C2 (Wendland 1995), q = r/h
# ---------------------------------------------------------------------------
@njit(cache=True)
def _wendland_c2_sigma(h, dim):
    """Normalisation C_D / h^D of the Wendland C2 kernel."""
    if dim == 1:
        return 1.25 / h
    elif dim == 2:
        return (7.0 / np.pi) / (h * h)
    elif dim == 3:
        return (21.0 / (2.0 * np.pi)) / (h * h * h)
    raise ValueError("kernel dimension must be 1, 2 or 3")


@njit(cache=True)
def wendland_c2_w(r, h, dim):
    """Wendland C2 W(r): (1-q)^3(1+3q) in 1D, (1-q)^4(1+4q) in 2D/3D."""
    sig = _wendland_c2_sigma(h, dim)
    q = r / h
    if q >= 1.0:
        return 0.0
    t = 1.0 - q
    if dim == 1:
        return sig * t * t * t * (1.0 + 3.0 * q)
    return sig * t * t * t * t * (1.0 + 4.0 * q)


@njit(cache=True)
def wendland_c2_dw(r, h, dim):
    """Wendland C2 dW/dr; zero at r = 0 and for r >= h."""
    sig = _wendland_c2_sigma(h, dim) / h
    q = r / h
    if q >= 1.0:
        return 0.0
    t = 1.0 - q
    if dim == 1:
        return -12.0 * sig * q * t * t
    return -20.0 * sig * q * t * t * t


@njit(cache=True)
def wendland_c2_d2w(r, h, dim):
    """Wendland C2 d^2W/dr^2; zero for r >= h."""
    sig = _wendland_c2_sigma(h, dim) / (h * h)
    q = r / h
    if q >= 1.0:
        return 0.0
    t = 1.0 - q
    if dim == 1:
        return 12.0 * sig * t * (3.0 * q - 1.0)
    return 20.0 * sig * t * t * (4.0 * q - 1.0)


# ---------------------------------------------------------------------------
# Spiky kernel (Desbrun & Gascuel 1996; Mueller et al. 2003 eq. 21)
# ---------------------------------------------------------------------------
@njit(cache=True)
def _spiky_sigma(h, dim):
    """Normalisation C_D of the spiky kernel W = C_D (h - r)^3."""
    if dim == 1:
        h2 = h * h
        return 2.0 / (h2 * h2)
    elif dim == 2:
        h2 = h * h
        return 10.0 / (np.pi * h2 * h2 * h)
    elif dim == 3:
        h3 = h * h * h
        return 15.0 / (np.pi * h3 * h3)
    raise ValueError("kernel dimension must be 1, 2 or 3")


@njit(cache=True)
def spiky_w(r, h, dim):
    """Spiky W(r) = C_D (h - r)^3 for r < h."""
    if r >= h:
        return 0.0
    t = h - r
    return _spiky_sigma(h, dim) * t * t * t


@njit(cache=True)
def spiky_dw(r, h, dim):
    """Spiky dW/dr = -3 C_D (h - r)^2 for r < h (non-zero at r = 0)."""
    if r >= h:
        return 0.0
    t = h - r
    return -3.0 * _spiky_sigma(h, dim) * t * t


@njit(cache=True)
def spiky_d2w(r, h, dim):
    """Spiky d^2W/dr^2 = 6 C_D (h - r) for r < h."""
    if r >= h:
        return 0.0
    return 6.0 * _spiky_sigma(h, dim) * (h - r)


# ---------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------
Kernel = namedtuple("Kernel", ["name", "w", "dw", "d2w"])
Kernel.__doc__ = """Immutable record of a kernel's njit scalar functions
(name, w(r, h, dim), dw(r, h, dim), d2w(r, h, dim)); h is the support radius."""

KERNELS = {
    "cubic_spline": Kernel("cubic_spline", cubic_spline_w, cubic_spline_dw, cubic_spline_d2w),
    "wendland_c2": Kernel("wendland_c2", wendland_c2_w, wendland_c2_dw, wendland_c2_d2w),
    "spiky": Kernel("spiky", spiky_w, spiky_dw, spiky_d2w),
}

KERNEL_NAMES = tuple(KERNELS)


@njit(cache=True, inline="always")
def curvature(kind, r, h, dim):
    """d^2 W / dr^2 of the kernel KERNEL_NAMES[kind], support radius h."""
    if kind == 0:
        return cubic_spline_d2w(r, h, dim)
    if kind == 1:
        return wendland_c2_d2w(r, h, dim)
    return spiky_d2w(r, h, dim)


@njit(cache=True, inline="always")
def value(kind, r, h, dim):
    """W(r) of the kernel KERNEL_NAMES[kind], support radius h: the value `evaluate` gives."""
    if kind == 0:
        return cubic_spline_w(r, h, dim)
    if kind == 1:
        return wendland_c2_w(r, h, dim)
    return spiky_w(r, h, dim)


@njit(cache=True, inline="always")
def value_and_slope(kind, r, h, dim):
    """(W(r), dW/dr) of the kernel KERNEL_NAMES[kind], support radius h; the cubic spline
    written out with one division (equal to cubic_spline_w, _dw to round-off)."""
    if kind == 0:
        q = 2.0 / h  # 1 / s
        z = r * q
        if dim == 1:
            sig = (2.0 / 3.0) * q
        elif dim == 2:
            sig = (10.0 / (7.0 * np.pi)) * q * q
        else:
            sig = q * q * q / np.pi
        if z < 1.0:
            return sig * (1.0 - 1.5 * z * z + 0.75 * z * z * z), sig * q * (-3.0 * z + 2.25 * z * z)
        if z < 2.0:
            t = 2.0 - z
            return sig * 0.25 * t * t * t, -0.75 * sig * q * t * t
        return 0.0, 0.0
    if kind == 1:
        return wendland_c2_w(r, h, dim), wendland_c2_dw(r, h, dim)
    return spiky_w(r, h, dim), spiky_dw(r, h, dim)


def _unknown(name):
    return ValueError(
        f"unknown kernel {name!r}; valid kernel names are: {', '.join(KERNEL_NAMES)}"
    )


def get_kernel(name):
    """Return the :class:`Kernel` record for ``name`` (ValueError if unknown)."""
    try:
        return KERNELS[name]
    except (KeyError, TypeError):
        raise _unknown(name) from None


# ---------------------------------------------------------------------------
# Cartesian derivatives of a radial function W(|x|)
# ---------------------------------------------------------------------------
@njit(cache=True)
def gradient(dwdr, dx, r, out):
    """Write grad_x W(|x|) at x = dx, i.e. dW/dr * dx / r, into ``out``.

    ``dx`` and ``out`` have length dim, ``r = |dx|``.  Zero if r == 0.
    """
    n = dx.shape[0]
    if r == 0.0:
        for i in range(n):
            out[i] = 0.0
        return
    f = dwdr / r
    for i in range(n):
        out[i] = f * dx[i]


@njit(cache=True)
def hessian(dwdr, d2wdr2, dx, r, out):
    """Write the Hessian d^2 W(|x|) / dx dx at x = dx into ``out`` (dim, dim).

    H = W'' n n^T + (W'/r)(I - n n^T) with n = dx / r; for r == 0 the limit
    W''(0) I is used.
    """
    n = dx.shape[0]
    if r == 0.0:
        for i in range(n):
            for j in range(n):
                out[i, j] = 0.0
            out[i, i] = d2wdr2
        return
    a = dwdr / r
    b = (d2wdr2 - a) / (r * r)
    for i in range(n):
        out[i, i] = b * (dx[i] * dx[i]) + a
        for j in range(i + 1, n):
            v = b * (dx[i] * dx[j])
            out[i, j] = v
            out[j, i] = v


# ---------------------------------------------------------------------------
# Vectorised evaluation (one njit loop per kernel)
# ---------------------------------------------------------------------------
@njit(cache=True)
def _evaluate_cubic_spline(r, h, dim, w, dw, d2w):
    for k in range(r.shape[0]):
        w[k] = cubic_spline_w(r[k], h[k], dim)
        dw[k] = cubic_spline_dw(r[k], h[k], dim)
        d2w[k] = cubic_spline_d2w(r[k], h[k], dim)


@njit(cache=True)
def _evaluate_wendland_c2(r, h, dim, w, dw, d2w):
    for k in range(r.shape[0]):
        w[k] = wendland_c2_w(r[k], h[k], dim)
        dw[k] = wendland_c2_dw(r[k], h[k], dim)
        d2w[k] = wendland_c2_d2w(r[k], h[k], dim)


@njit(cache=True)
def _evaluate_spiky(r, h, dim, w, dw, d2w):
    for k in range(r.shape[0]):
        w[k] = spiky_w(r[k], h[k], dim)
        dw[k] = spiky_dw(r[k], h[k], dim)
        d2w[k] = spiky_d2w(r[k], h[k], dim)


_EVALUATORS = {
    "cubic_spline": _evaluate_cubic_spline,
    "wendland_c2": _evaluate_wendland_c2,
    "spiky": _evaluate_spiky,
}


def evaluate(name, r, h, dim):
    """Evaluate kernel ``name`` on arrays.

    Parameters
    ----------
    name : str
        One of :data:`KERNEL_NAMES`.
    r : array_like, shape (m,)
        Distances (>= 0).
    h : float or array_like, shape (m,)
        Support radius (per pair, or a single scalar).
    dim : int
        Spatial dimension 1, 2 or 3.

    Returns
    -------
    (w, dw, d2w) : three float64 arrays of shape (m,)
    """
    try:
        fn = _EVALUATORS[name]
    except (KeyError, TypeError):
        raise _unknown(name) from None
    dim = int(dim)
    if dim not in (1, 2, 3):
        raise ValueError(f"dim must be 1, 2 or 3, got {dim}")
    r = np.ascontiguousarray(r, dtype=np.float64)
    if r.ndim != 1:
        raise ValueError(f"r must be a 1-d array, got shape {r.shape}")
    h = np.ascontiguousarray(np.broadcast_to(np.asarray(h, dtype=np.float64), r.shape))
    m = r.shape[0]
    w = np.empty(m)
    dw = np.empty(m)
    d2w = np.empty(m)
    fn(r, h, dim, w, dw, d2w)
    return w, dw, d2w
