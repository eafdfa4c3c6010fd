"""Vectors of up to three components held in local variables in compiled loops.

A compiled loop that adds into an array element (f[i, a] += ...) stores to memory at each
term, and as the array may overlap its inputs the compiler reloads those too. Summing into
locals and storing once keeps the sums and the row's data in registers: the same additions
in the same order, so the same bits. These helpers address the locals (v0, v1, v2) by a
component index a; in a loop over a literal dimension the choices fold away.
"""

from numba import njit


@njit(cache=True, inline="always")
def component(a, v0, v1, v2):
    """Component a of (v0, v1, v2)."""
    return v0 if a == 0 else (v1 if a == 1 else v2)


@njit(cache=True, inline="always")
def replaced(a, value, v0, v1, v2):
    """(v0, v1, v2) with component a replaced by value."""
    return (value, v1, v2) if a == 0 else ((v0, value, v2) if a == 1 else (v0, v1, value))


@njit(cache=True, inline="always")
def added(a, value, v0, v1, v2):
    """(v0, v1, v2) with value added to component a."""
    return (v0 + value, v1, v2) if a == 0 else ((v0, v1 + value, v2) if a == 1 else (v0, v1, v2 + value))


@njit(cache=True, inline="always")
def separation(X, i, j, dim):
    """X_j - X_i of the rows i, j of positions X (n, dim), the components a lower dimension
    lacks zero: formed where a pair loop needs it rather than stored per pair (the same
    subtraction, so the same bits as a stored X_j - X_i)."""
    x0 = X[j, 0] - X[i, 0]
    x1 = X[j, 1] - X[i, 1] if dim > 1 else 0.0
    x2 = X[j, 2] - X[i, 2] if dim > 2 else 0.0
    return x0, x1, x2
