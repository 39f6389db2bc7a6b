"""Adhesion: the force a locomotive's driven wheels can pass to the rail, in traction and in electric braking.

A wheel pulls (or brakes electrically) at most mu(v) x the weight on it; for a locomotive whose axles are all
driven, F <= mu(v) m g. The adhesion coefficient mu falls with speed (e.g. TB/T 1407's mu = 0.24 + 12 / (100 +
8 v) for AC-drive locomotives, Curtius-Kniffler's 0.161 + 7.5 / (v + 44)); a vehicle file gives it as points
``adhesion_mu: [[speed_kmh, mu], ...]``, linear between them and held flat beyond the ends like every curve.

The limit is applied where a locomotive's curves are read (``model.train``), so every method that evaluates the
train's traction or electric brake -- the calculator, the DP, E*'s cells, the optimal-control problems -- sees the
limited curve. The minimum of two piecewise-linear curves is itself piecewise linear, with points at both curves'
speeds and where they cross, so the limited curve is exact, not sampled.
"""

from __future__ import annotations

import numpy as np

from .units import G_MS2


def adhesion_force_kn(speed_kmh, mu_speed_kmh, mu, adhesive_mass_t: float):
    """The most force [kN] the driven wheels pass to the rail at ``speed_kmh``: mu(v) x m g."""
    return np.interp(speed_kmh, mu_speed_kmh, mu) * adhesive_mass_t * G_MS2


def adhesion_limited(curve: np.ndarray, mu_curve: np.ndarray, adhesive_mass_t: float) -> np.ndarray:
    """A force curve ``[[speed_kmh, force_kn], ...]`` capped by adhesion (``mu_curve`` [[speed_kmh, mu], ...] on
    ``adhesive_mass_t`` [t]), exactly: points at both curves' speeds and at every crossing."""
    curve = np.asarray(curve, dtype=float)
    mu_curve = np.asarray(mu_curve, dtype=float)
    v = np.union1d(curve[:, 0], mu_curve[:, 0])
    gap = np.interp(v, curve[:, 0], curve[:, 1]) - adhesion_force_kn(v, mu_curve[:, 0], mu_curve[:, 1], adhesive_mass_t)
    crosses = np.flatnonzero(gap[:-1] * gap[1:] < 0.0)  # a sign change between two points: they cross once there
    at = v[crosses] + (v[crosses + 1] - v[crosses]) * gap[crosses] / (gap[crosses] - gap[crosses + 1])
    v = np.union1d(v, at)
    force = np.minimum(np.interp(v, curve[:, 0], curve[:, 1]),
                       adhesion_force_kn(v, mu_curve[:, 0], mu_curve[:, 1], adhesive_mass_t))
    return np.column_stack([v, force])
