"""Max traction and braking effort from a consist's piecewise-linear curves, and gravity force."""

from __future__ import annotations

import numpy as np

from .backend import RoundedCurve, as_operand, piecewise_linear, piecewise_linear_slope
from .units import G_MS2


def max_force_kn(speed_kmh, curve_speed_kmh: np.ndarray, curve_force_kn: np.ndarray):
    """Max effort [kN] at ``speed_kmh``, linear between curve points, held flat beyond the ends
    (``np.interp`` on numbers and arrays, a hinge sum on CasADi symbols: see ``backend``)."""
    return piecewise_linear(speed_kmh, curve_speed_kmh, curve_force_kn)


def max_force_slope_kn_per_kmh(speed_kmh, curve_speed_kmh: np.ndarray, curve_force_kn: np.ndarray):
    """d(max effort)/dv [kN per km/h] of :func:`max_force_kn` at ``speed_kmh`` (numbers or arrays)."""
    return piecewise_linear_slope(speed_kmh, curve_speed_kmh, curve_force_kn)


def rounded_force_curve(curve_speed_kmh: np.ndarray, curve_force_kn: np.ndarray, width_kmh: float) -> RoundedCurve:
    """:func:`max_force_kn` with its corners rounded over ``width_kmh``, for a Newton method, made once for a
    curve and evaluated many times: ``curve(speed_kmh)`` gives (force [kN], slope [kN per km/h], curvature
    [kN per (km/h)^2]) (``backend.RoundedCurve``)."""
    return RoundedCurve(curve_speed_kmh, curve_force_kn, width_kmh)


def gradient_force_kn(gradient_permille, mass_t: float):
    """Gravity component along the track [kN] on an (equivalent) gradient in per mille (+ = up-grade).

    1 per mille of gradient costs 1 N per kN of weight: F = i * mass_t * g / 1000 [kN].
    """
    return as_operand(gradient_permille) * mass_t * G_MS2 / 1000.0
