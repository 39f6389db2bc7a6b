"""An independent fastest run: fine-step RK4 in e = v^2/2, written without locoplan's dynamics.

What the line *is* comes in as plain arrays (cell edges, the gravity force, the speed limit and whether
the catenary is live, per cell), so that the tests can write them out by hand and the benchmark can take
them from any route; what the train *does* is computed here, from the consist's force curves alone:

- the admissible-speed envelope, by the definition of a speed limit: the largest e from which full
  braking keeps every limit ahead and stops at the end, integrated backwards from the stop in steps of at
  most ``ds_m``, kept under each cell's limit (a limit binds wherever it is reached, all along a descent
  that full braking cannot hold too: there the backward run *falls*, the train must enter slower);
- the fastest run: full traction forwards from rest, never above the envelope (there it brakes, as much as
  the envelope takes), time as the sum of 2 ds / (v0 + v1) over the fine steps.

No locoplan function is called: interpolation, resistance and the integrator are written out below.
"""

from __future__ import annotations

import bisect
import math


def _interp(x: float, xs, ys) -> float:
    """Piecewise-linear, flat beyond the ends (what a vehicle file's curve means)."""
    if x <= xs[0]:
        return float(ys[0])
    if x >= xs[-1]:
        return float(ys[-1])
    i = bisect.bisect_right(xs, x) - 1
    w = (x - xs[i]) / (xs[i + 1] - xs[i])
    return float(ys[i] + w * (ys[i + 1] - ys[i]))


class FastestOracle:
    """The fastest run over cells ``edges_m`` (n + 1 rising positions [m]) with per-cell ``gravity_kn``,
    ``limit_kmh`` and ``powered`` (0 = no traction and no electric brake: a neutral section's span).

    ``traction``, ``electric``, ``air``: (speeds [km/h], forces [kN]) curves (``air`` may be None);
    ``davis``: (a [kN], b [kN h/km], c [kN h^2/km^2]) of the whole train, R = a + b v + c v^2;
    ``mass_t``: the inertial mass [t]."""

    def __init__(self, edges_m, gravity_kn, limit_kmh, powered, traction, electric, air, davis, mass_t, ds_m=1.0):
        self.edges = [float(x) for x in edges_m]
        self.grav = [float(x) for x in gravity_kn]
        self.lim_e = [(float(v) / 3.6) ** 2 / 2 for v in limit_kmh]
        self.powered = [float(x) for x in powered]
        self.tr = ([float(x) for x in traction[0]], [float(x) for x in traction[1]])
        self.el = ([float(x) for x in electric[0]], [float(x) for x in electric[1]])
        self.air = None if air is None else ([float(x) for x in air[0]], [float(x) for x in air[1]])
        self.davis = tuple(float(x) for x in davis)
        self.m = float(mass_t)
        # fine steps: each cell cut into equal pieces of at most ds_m
        self.pieces = []  # (cell, length)
        for k, (a, b) in enumerate(zip(self.edges[:-1], self.edges[1:])):
            n = max(1, math.ceil((b - a) / ds_m - 1e-9))
            self.pieces += [(k, (b - a) / n)] * n

    def _resistance(self, v_kmh: float) -> float:
        a, b, c = self.davis
        return a + v_kmh * (b + c * v_kmh)

    def brake_kn(self, v_kmh: float, k: int) -> float:
        air = 0.0 if self.air is None else _interp(v_kmh, *self.air)
        return _interp(v_kmh, *self.el) * self.powered[k] + air

    def _decel(self, e: float, k: int) -> float:
        """-de/ds under full braking [m/s^2]."""
        v = math.sqrt(2.0 * max(e, 0.0)) * 3.6
        return (self.brake_kn(v, k) + self._resistance(v) + self.grav[k]) / self.m

    def _accel(self, e: float, k: int) -> float:
        """de/ds under full traction [m/s^2]."""
        v = math.sqrt(2.0 * max(e, 0.0)) * 3.6
        return (_interp(v, *self.tr) * self.powered[k] - self._resistance(v) - self.grav[k]) / self.m

    @staticmethod
    def _rk4(f, e: float, d: float) -> float:
        k1 = f(e)
        k2 = f(max(e + 0.5 * d * k1, 0.0))
        k3 = f(max(e + 0.5 * d * k2, 0.0))
        k4 = f(max(e + d * k3, 0.0))
        return e + d * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0

    def envelope(self) -> list[float]:
        """e [m^2/s^2] of the envelope at every fine node (len(pieces) + 1 values)."""
        n = len(self.pieces)
        env = [0.0] * (n + 1)
        for j in range(n - 1, -1, -1):
            k, d = self.pieces[j]
            cap = self.lim_e[k]
            e = min(env[j + 1], cap)
            e = min(max(self._rk4(lambda x: self._decel(x, k), e, d), 0.0), cap)
            if j > 0:  # a node between two cells is under both limits
                e = min(e, self.lim_e[self.pieces[j - 1][0]])
            env[j] = e
        return env

    def positions(self) -> list[float]:
        s = [self.edges[0]]
        for _, d in self.pieces:
            s.append(s[-1] + d)
        return s

    def fastest(self) -> tuple[float, list[float]]:
        """(running time [s], speed [km/h] at every fine node); time = nan where the run stalls."""
        env = self.envelope()
        e, v, t = 0.0, 0.0, 0.0
        speeds = [0.0]
        last = len(self.pieces) - 1
        for j, (k, d) in enumerate(self.pieces):
            e1 = min(self._rk4(lambda x: self._accel(x, k), e, d), env[j + 1])
            if e1 <= 0.0 and j < last:
                return float("nan"), speeds
            v1 = math.sqrt(2.0 * max(e1, 0.0))
            t += 2.0 * d / (v + v1)
            e, v = e1, v1
            speeds.append(v1 * 3.6)
        return t, speeds

    def rest_excess(self, from_m: float) -> tuple[float, float]:
        """Full braking forwards from rest at ``from_m``: (the highest speed above the limit [km/h] that it
        reaches before braking holds the train under the limit again, where [m])."""
        s = self.positions()
        j0 = bisect.bisect_left(s, from_m - 1e-9)
        e, best = 0.0, (-math.inf, from_m)
        for j in range(j0, len(self.pieces)):
            k, d = self.pieces[j]
            e = max(self._rk4(lambda x: -self._decel(x, k), e, d), 0.0)
            v = math.sqrt(2 * e) * 3.6
            lim = math.sqrt(2 * self.lim_e[k]) * 3.6
            if v - lim > best[0]:
                best = (v - lim, s[j + 1])
            if best[0] > 0 and v < lim:
                break
        return best
