"""The train's equation of motion along the track, once for every optimal-control problem.

M a = F - (R(v) + G): ``F`` the net force of the controls (traction minus braking) [kN], ``R`` the
basic running resistance and ``G`` the gravity component on the (equivalent) gradient [kN], ``M``
the (inertial) mass [t]; kN / t = m/s^2. Numbers, numpy arrays and CasADi symbols alike (arithmetic
only), as :mod:`locoplan.physics.backend` asks of every formula here.
"""

from __future__ import annotations

from .resistance import train_resistance_kn


def running_load_kn(speed_kmh, resistance_kn: tuple[float, float, float], gravity_kn):
    """What the train runs against [kN]: basic resistance ``A + B v + C v^2`` at ``speed_kmh`` plus the
    gravity force ``gravity_kn`` (positive up-grade)."""
    return train_resistance_kn(speed_kmh, resistance_kn) + gravity_kn


def acceleration_ms2(force_kn, speed_kmh, resistance_kn: tuple[float, float, float], gravity_kn, mass_t):
    """``(F - (R(v) + G)) / M`` [m/s^2] for the net control force ``force_kn`` [kN] at ``speed_kmh``."""
    return (force_kn - running_load_kn(speed_kmh, resistance_kn, gravity_kn)) / mass_t
