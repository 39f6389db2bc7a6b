"""Independent reference values for the tests: seed 000's HXD1-C64 written out by hand (eq. 1-3,
Table 1) and its bang-cruise-bang minimum running time by scipy quad. No locoplan code here."""

from scipy.integrate import quad
from scipy.optimize import brentq

G = 9.81
LIMIT = 11.1  # m/s = 39.96 km/h
MASS_T = 284.0


def seed000_resistance_kn(v):
    """HXD1 200 t + loaded C64 84 t basic resistance [kN] at v [m/s] (Davis terms in km/h)."""
    vk = 3.6 * v
    hxd1 = 200.0 * (2.23 + 0.0053 * vk + 0.000675 * vk * vk)
    c64 = 84.0 * (0.92 + 0.0048 * vk + 0.000125 * vk * vk)
    return (hxd1 + c64) * G / 1000.0


def seed000_exact(grade, length=1500.0):
    """The exact minimum: full traction (532 kN) to the limit, cruise, full braking (461 kN); on a
    route too short to reach the limit, full traction to the peak speed and full braking from it.

    Returns (t_accel, s_accel, t_brake, s_brake, total time [s], cruise force [kN])."""
    grade_kn = MASS_T * G * grade / 1000.0
    acc = lambda v: (532.0 - seed000_resistance_kn(v) - grade_kn) / MASS_T  # noqa: E731
    dec = lambda v: (461.0 + seed000_resistance_kn(v) + grade_kn) / MASS_T  # noqa: E731
    dist = lambda f, v: quad(lambda w: w / f(w), 0.0, v, epsabs=1e-13)[0]  # noqa: E731
    dur = lambda f, v: quad(lambda w: 1.0 / f(w), 0.0, v, epsabs=1e-13)[0]  # noqa: E731
    top = LIMIT
    if dist(acc, LIMIT) + dist(dec, LIMIT) > length:
        top = brentq(lambda v: dist(acc, v) + dist(dec, v) - length, 1e-6, LIMIT, xtol=1e-14)
    ta, sa, tb, sb = dur(acc, top), dist(acc, top), dur(dec, top), dist(dec, top)
    return ta, sa, tb, sb, ta + tb + (length - sa - sb) / top, seed000_resistance_kn(top) + grade_kn
