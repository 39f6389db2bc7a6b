"""Air-brake force of wagons (TB/T 1407, the Chinese train traction calculation regulations).

A block-braked wagon's brake force is B = K_h * phi_h(v) * beta_c [kN]: K_h the converted brake-shoe
force (here braking_ratio * the loaded vehicle's weight), phi_h(v) the converted friction coefficient
of its shoes, beta_c the service braking coefficient of the application (``Consist``).
"""

from __future__ import annotations

import numpy as np

from .units import G_MS2

AIR_BRAKE_SAMPLE_KMH = 2.0
"""Speed spacing [km/h] at which a braking-ratio brake is tabulated into a piecewise-linear curve
(phi_h is smooth: the largest interpolation error is below 0.01 % of the force)."""


def composite_shoe_friction(speed_kmh):
    """Converted friction coefficient phi_h of high-friction composite brake shoes at ``speed_kmh``
    (TB/T 1407: phi_h = 0.322 (v + 150) / (2 v + 150), v in km/h)."""
    v = speed_kmh
    return 0.322 * (v + 150.0) / (2.0 * v + 150.0)


SHOE_FRICTION = {"composite": composite_shoe_friction}


def full_brake_kn(electric_kn, air_kn, catenary):
    """Full braking [kN]: the locomotives' electric brake where the catenary feeds it (``catenary`` 1,
    0 in a neutral section's span, where the main breaker is open) plus the wagons' air brake, which
    works everywhere. Plain arithmetic (numbers, arrays, the compiled kernels)."""
    return electric_kn * catenary + air_kn


def electric_share_kn(brake_kn, electric_max_kn):
    """The electric brake's part of a braking force [kN] (blended braking: the electric brake takes its
    share first, up to what it has at that speed, the air brake the rest)."""
    return np.minimum(brake_kn, electric_max_kn)


def air_brake_curve_kn(braking_ratio: float, shoe: str, loaded_mass_t: float, max_speed_kmh: float):
    """A braking-ratio air brake as a [[speed_kmh, force_kn], ...] table at full cylinder pressure
    (beta_c = 1): B(v) = braking_ratio * loaded_mass_t * g * phi_h(v)."""
    v = np.unique(np.append(np.arange(0.0, max_speed_kmh, AIR_BRAKE_SAMPLE_KMH), max_speed_kmh))
    force = braking_ratio * loaded_mass_t * G_MS2 * SHOE_FRICTION[shoe](v)
    return np.column_stack([v, force])
