"""One formula for numpy arrays and CasADi symbols alike.

The optimal-control transcriptions evaluate the same physics functions as the traction calculator,
but on CasADi ``SX``/``MX`` symbols. Helpers here let a physics function take either: numbers and
arrays go through numpy (fast, as the calculator needs), symbols through CasADi, which is imported
only when a symbol actually arrives (plain commands never load it).
"""

from __future__ import annotations

import numpy as np


def is_symbolic(x) -> bool:
    """True for a CasADi symbol or expression (``SX``, ``MX``, ``DM``)."""
    return type(x).__module__.startswith("casadi")


def as_operand(x):
    """``x`` unchanged if symbolic, else as a float numpy array (scalars stay 0-d)."""
    return x if is_symbolic(x) else np.asarray(x, dtype=float)


def hinge_coefficients(xs, ys) -> tuple[float, np.ndarray, np.ndarray]:
    """A piecewise-linear curve through ``(xs, ys)`` (``xs`` rising), held flat beyond both ends, as a
    hinge sum ``y0 + sum_k dslope_k * max(x - x_k, 0)``: returns ``(y0, x_k, dslope_k)``, the change of
    slope at every point (the flat ends make the first change the first slope and the last one its
    negative, so the sum is flat beyond the last point as ``np.interp`` is)."""
    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    slopes = np.diff(y) / np.diff(x)
    dslope = np.diff(np.concatenate([[0.0], slopes, [0.0]]))
    return float(y[0]), x, dslope


def piecewise_linear(x, xs, ys):
    """The curve through ``(xs, ys)`` at ``x``, linear between points and flat beyond the ends.

    Arrays: ``np.interp``. Symbols: the hinge sum of :func:`hinge_coefficients` with ``casadi.fmax``,
    equal to ``np.interp`` wherever both are evaluated (tests/test_physics_symbolic.py).
    """
    if not is_symbolic(x):
        return np.interp(x, xs, ys)
    import casadi as ca

    y0, knots, dslope = hinge_coefficients(xs, ys)
    out = y0 + 0 * x  # keep the symbol's shape
    for xk, dk in zip(knots, dslope):
        if dk != 0.0:
            out = out + float(dk) * ca.fmax(x - float(xk), 0.0)
    return out
