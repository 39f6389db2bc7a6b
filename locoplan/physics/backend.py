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


def piecewise_linear_slope(x, xs, ys):
    """The slope of :func:`piecewise_linear` at ``x`` (numbers or arrays): the slope of the segment that
    holds ``x`` (the right one at a point), 0 beyond the ends. What a Newton method differentiating the
    curve needs; its second derivative is 0 between points."""
    xs = np.asarray(xs, dtype=float)
    slopes = np.concatenate([[0.0], np.diff(np.asarray(ys, dtype=float)) / np.diff(xs), [0.0]])
    return slopes[np.searchsorted(xs, x, side="right")]


class RoundedCurve:
    """:func:`piecewise_linear` with every corner rounded over ``width`` (in x), for a Newton method: called
    with ``x`` (numbers or arrays) it gives the value, slope and curvature there. At a point ``x_k`` where the
    slope changes by ``d``, the corner ``d * max(t, 0)`` (t = x - x_k) becomes ``d * (t + width/2)^2 /
    (2 width)`` for ``|t| < width/2``: continuous in value and slope, and nowhere further from the curve than
    ``|d| * width / 8``. ``width`` must be below the spacing of the points (then one corner at most is near
    any x). The segments' slopes are worked out once, when the curve is made (a solver evaluates the same
    curve thousands of times)."""

    def __init__(self, xs, ys, width: float):
        self.xs = np.asarray(xs, dtype=float)
        self.ys = np.asarray(ys, dtype=float)
        self.width = float(width)
        self.slopes = np.concatenate([[0.0], np.diff(self.ys) / np.diff(self.xs), [0.0]])
        self.dslope = np.diff(self.slopes)  # at each point

    def __call__(self, x):
        xs, ys, slopes, width = self.xs, self.ys, self.slopes, self.width
        x = np.asarray(x, dtype=float)
        i = np.searchsorted(xs, x, side="right")  # x in [xs[i-1], xs[i]): the segment's slope is slopes[i]
        left = np.maximum(i - 1, 0)
        slope = slopes[i]
        value = np.where(i > 0, ys[left] + slope * (x - xs[left]), ys[0])
        right = np.minimum(i, len(xs) - 1)
        j = np.where((i > 0) & (np.abs(x - xs[left]) <= np.abs(x - xs[right])), left, right)  # the nearest point
        t = x - xs[j]
        half = 0.5 * width
        near = np.abs(t) < half
        d = np.where(near, self.dslope[j], 0.0)
        tn = np.where(near, t, 0.0)
        value = value + d * ((tn + half) ** 2 / (2 * width) - np.maximum(tn, 0.0))
        slope = slope + d * ((tn + half) / width - (tn >= 0))
        curvature = d / width
        return value, slope, curvature


def rounded_curve_at(x, xs, ys, width, lo, hi):
    """:class:`RoundedCurve` of the points ``xs[lo:hi]``, ``ys[lo:hi]`` over ``width`` at one number ``x``:
    (value, slope, curvature). The scalar twin of ``RoundedCurve.__call__``, step for step the same
    arithmetic (each slope and change of slope from the same difference quotients), in plain Python that the
    compiled kernels take (``ocp/cell_kernel.py``, where the curves lie end to end in one array; tests/
    test_estar_cells.py holds the two equal)."""
    a, b = lo, hi  # i = the first point > x (np.searchsorted(xs, x, side="right"), from lo)
    while a < b:
        mid = (a + b) // 2
        if xs[mid] <= x:
            a = mid + 1
        else:
            b = mid
    i = a
    left = max(i - 1, lo)
    # the slope of the segment ending at point i (0 before the first point and beyond the last)
    slope = (ys[i] - ys[i - 1]) / (xs[i] - xs[i - 1]) if lo < i < hi else 0.0
    value = ys[left] + slope * (x - xs[left]) if i > lo else ys[lo]
    right = min(i, hi - 1)
    j = left if i > lo and abs(x - xs[left]) <= abs(x - xs[right]) else right  # the nearest point
    t = x - xs[j]
    half = 0.5 * width
    d = 0.0
    if abs(t) < half:
        after = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j]) if j + 1 < hi else 0.0
        before = (ys[j] - ys[j - 1]) / (xs[j] - xs[j - 1]) if j > lo else 0.0
        d = after - before
        value = value + d * ((t + half) ** 2 / (2 * width) - max(t, 0.0))
        slope = slope + d * ((t + half) / width - (1.0 if t >= 0 else 0.0))
    return value, slope, d / width


def piecewise_linear_rounded(x, xs, ys, width: float):
    """:class:`RoundedCurve` of ``(xs, ys)`` over ``width`` at ``x``: (value, slope, curvature)."""
    return RoundedCurve(xs, ys, width)(x)
