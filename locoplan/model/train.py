"""A consist resolved against its vehicles: the numbers the physics needs (no physics here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .consist import Consist, Vehicle

G_MS2 = 9.81
"""Gravitational acceleration [m/s^2] (SPEC section 1)."""


@dataclass(frozen=True)
class Train:
    """Whole-train quantities. Force curves are summed over locomotives on the union of their speed points.

    ``resistance_kn`` holds (A, B, C) such that the train's basic resistance is A + B v + C v^2 [kN],
    v in km/h: the mass-weighted sum of each vehicle's w0 [N/kN] times its weight [kN] / 1000.
    """

    name: str
    mass_t: float
    length_m: float
    max_speed_kmh: float
    resistance_kn: tuple[float, float, float]
    traction_speed_kmh: np.ndarray
    traction_kn: np.ndarray
    brake_speed_kmh: np.ndarray
    brake_kn: np.ndarray
    n_vehicles: int

    @classmethod
    def from_consist(cls, consist: Consist, vehicles: dict[str, Vehicle]) -> "Train":
        mass = length = 0.0
        coeffs = np.zeros(3)
        n = 0
        vmax = np.inf
        locos: list[tuple[Vehicle, int]] = []
        for entry in consist.vehicles:
            veh = vehicles[entry.type]
            m = veh.mass_t + entry.load_t
            mass += entry.count * m
            length += entry.count * veh.length_m
            r = veh.resistance_n_per_kn
            coeffs += entry.count * m * G_MS2 / 1000.0 * np.array([r.a, r.b, r.c])
            vmax = min(vmax, veh.max_speed_kmh)
            n += entry.count
            if veh.kind == "locomotive":
                locos.append((veh, entry.count))
        tv, tf = _sum_curves([(v.traction_kn, c) for v, c in locos])
        bv, bf = _sum_curves([(v.brake_kn, c) for v, c in locos])
        return cls(consist.name, mass, length, float(vmax), tuple(float(x) for x in coeffs),
                   tv, tf, bv, bf, n)


def _sum_curves(curves: list[tuple[list, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Sum piecewise-linear force curves [[speed_kmh, force_kn], ...] on the union of their speed points."""
    if not curves:
        return np.array([0.0, 1.0]), np.zeros(2)
    speeds = np.unique(np.concatenate([np.asarray(c, float)[:, 0] for c, _ in curves]))
    total = np.zeros_like(speeds)
    for c, count in curves:
        arr = np.asarray(c, float)
        total += count * np.interp(speeds, arr[:, 0], arr[:, 1])
    for a in (speeds, total):
        a.setflags(write=False)
    return speeds, total
