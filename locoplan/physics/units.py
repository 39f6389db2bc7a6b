"""Units and constants, once (SPEC section 1). Plain numbers and scalar functions that numbers, numpy
arrays and (compiled with ``numba.njit``) the kernels all take; all but the two square roots
(``ms_from_e``, ``kmh_from_e``) are plain arithmetic, so CasADi symbols take them too."""

from __future__ import annotations

import numpy as np

G_MS2 = 9.81
"""Gravitational acceleration [m/s^2]."""
KMH_PER_MS = 3.6
"""1 m/s = 3.6 km/h."""
KJ_PER_KWH = 3600.0
"""1 kWh = 3600 kJ (a force in kN over a distance in m is a work in kJ)."""
S_PER_H = 3600.0
"""Seconds in an hour."""
KMH2_PER_E = 2.0 * KMH_PER_MS**2
"""v [km/h] = sqrt(e * KMH2_PER_E) for e = v^2/2 [m^2/s^2] (= 25.92, one multiplication for the
calculator's mid-cell speed)."""


def ms(speed_kmh):
    """Speed [km/h] -> [m/s]."""
    return speed_kmh / KMH_PER_MS


def kmh(speed_ms):
    """Speed [m/s] -> [km/h]."""
    return speed_ms * KMH_PER_MS


def kinetic_e(speed_kmh):
    """e = v^2/2 [m^2/s^2] (kinetic energy per unit mass) of a speed in km/h: the calculator's state."""
    return (speed_kmh / KMH_PER_MS) ** 2 / 2


def e_from_ms(speed_ms):
    """e = v^2/2 [m^2/s^2] of a speed in m/s."""
    return speed_ms * speed_ms / 2.0


def ms_from_e(e):
    """Speed [m/s] of e = v^2/2 [m^2/s^2] (e >= 0)."""
    return np.sqrt(2.0 * e)


def kmh_from_e(e):
    """Speed [km/h] of a kinetic energy per unit mass e = v^2/2 [m^2/s^2] (e >= 0)."""
    return np.sqrt(2.0 * e) * KMH_PER_MS


def kwh(work_kj):
    """Work [kJ] (e.g. kN x m) -> [kWh]."""
    return work_kj / KJ_PER_KWH
