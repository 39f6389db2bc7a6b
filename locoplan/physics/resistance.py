"""Basic running resistance (Davis form, TB/T 1407; the ISSA paper's Tables 2-3, the two-stage Gauss paper's eq. 2-3).

Plain arithmetic: numbers, numpy arrays, CasADi symbols and (through ``numba.njit``) the compiled
kernels all take these functions, so the traction calculator, its kernel, the DP and the optimal
control evaluate one formula.
"""

from __future__ import annotations

from .backend import as_operand
from .units import G_MS2


def davis_kn(speed_kmh, a, b, c):
    """A + B v + C v^2 [kN] (or [N/kN] for unit coefficients) at ``speed_kmh`` [km/h]; plain arithmetic."""
    return speed_kmh * (b + c * speed_kmh) + a


def davis_slope_kn_per_kmh(speed_kmh, b, c):
    """d(A + B v + C v^2)/dv = B + 2 C v [kN per km/h] at ``speed_kmh``; plain arithmetic."""
    return b + 2.0 * c * speed_kmh


def running_load_kn(speed_kmh, a, b, c, gravity_kn):
    """What the train must overcome to keep its speed [kN]: basic resistance A + B v + C v^2 plus the
    gravity component ``gravity_kn`` of its (equivalent) gradient (+ = up-grade)."""
    return speed_kmh * (b + c * speed_kmh) + (a + gravity_kn)


def basic_resistance_n_per_kn(speed_kmh, a: float, b: float, c: float):
    """Unit basic resistance w0 = a + b v + c v^2 [N/kN] at ``speed_kmh`` [km/h]; scalars, arrays or
    CasADi symbols."""
    return davis_kn(as_operand(speed_kmh), a, b, c)


def unit_to_train_coefficients_kn(a: float, b: float, c: float, mass_t: float) -> tuple[float, float, float]:
    """A vehicle's unit resistance coefficients w0 = a + b v + c v^2 [N/kN] as its own (A, B, C) [kN]:
    times its weight mass_t * g [kN], divided by 1000."""
    w = mass_t * G_MS2 / 1000.0
    return a * w, b * w, c * w


def train_coefficients_kn(vehicles) -> tuple[float, float, float]:
    """Whole-train Davis coefficients (A, B, C) [kN, kN/(km/h), kN/(km/h)^2]: the sum over ``vehicles``,
    an iterable of ``(mass_t, a, b, c)`` (unit coefficients [N/kN], one entry per vehicle, or
    ``(count * mass_t, ...)`` for a group of equal ones)."""
    total = [0.0, 0.0, 0.0]
    for mass_t, a, b, c in vehicles:
        for i, x in enumerate(unit_to_train_coefficients_kn(a, b, c, mass_t)):
            total[i] += x
    return total[0], total[1], total[2]


def basic_resistance_kn(speed_kmh, a: float, b: float, c: float, mass_t: float):
    """Basic resistance of one vehicle [kN]: w0 [N/kN] times its weight mass_t * g [kN], divided by 1000."""
    return basic_resistance_n_per_kn(speed_kmh, a, b, c) * mass_t * G_MS2 / 1000.0


def train_resistance_kn(speed_kmh, resistance_kn: tuple[float, float, float]):
    """Whole-train basic resistance A + B v + C v^2 [kN], v in km/h (coefficients from ``Train``);
    scalars, arrays or CasADi symbols."""
    a, b, c = resistance_kn
    return davis_kn(as_operand(speed_kmh), a, b, c)
