"""An independent fastest run and plan run: fine-step RK4 in e = v^2/2, written without locoplan's dynamics.

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

    @classmethod
    def of(cls, calc, ds_m: float = 1.0) -> "FastestOracle":
        """Over a traction calculator's line tables (its cells, gravity, limits and catenary) and its train's force
        curves, read as plain arrays: what the line and the train are, not how locoplan integrates them."""
        tr = calc.train
        return cls(calc.s_m, calc.gravity_kn, calc.limit_kmh, calc.traction_allowed,
                   (tr.traction_speed_kmh, tr.traction_kn), (calc.electric_brake_speed_kmh, calc.electric_brake_kn),
                   (calc.air_brake_speed_kmh, calc.air_brake_kn), tr.resistance_kn, calc.m_eff_t, ds_m)

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

    def _electric_decel(self, e: float, k: int) -> float:
        """-de/ds under the electric brake alone [m/s^2]."""
        v = math.sqrt(2.0 * max(e, 0.0)) * 3.6
        return (_interp(v, *self.el) * self.powered[k] + self._resistance(v) + self.grav[k]) / self.m

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

    def _hold_accel(self, e: float, k: int, traction: bool = True) -> float:
        """de/ds holding the speed (cruise): the force that cancels resistance and gravity, within what
        traction gives (none with ``traction`` False) and full braking takes; 0 where that suffices."""
        v = math.sqrt(2.0 * max(e, 0.0)) * 3.6
        load = self._resistance(v) + self.grav[k]
        force = min(max(load, -self.brake_kn(v, k)), _interp(v, *self.tr) * self.powered[k] if traction else 0.0)
        return (force - load) / self.m

    def _traction_kn(self, e: float, k: int) -> float:
        return _interp(math.sqrt(2.0 * max(e, 0.0)) * 3.6, *self.tr) * self.powered[k]

    def drive(self, conditions, switches_m, cruise_kmh: float | None = None, trace: list | None = None) -> tuple[float, float]:
        """A driving plan: (running time [s], traction work [kWh]); time nan where it comes to rest before the
        end. ``conditions`` T (full traction), K (hold the speed), C (coast), B (full braking), E (the electric
        brake alone), each from the
        previous switch (the first from 0 m) to the next (nan: never; the previous condition runs on).

        What the plan may not do it is kept from by the envelope (a limit reached is held, a braking curve
        is followed by braking, as speed supervision would); ``cruise_kmh`` caps T and K at that speed (held
        there; above it, braked to it by full braking, as far as that can). Per fine step: RK4 in e, the traction work of T at the step's mean of the RK4 stages' force
        (Simpson's rule over the step), of K the holding force where it is traction."""
        if not hasattr(self, "_env"):  # the line's, the same for every plan
            self._env, self._s = self.envelope(), self.positions()
        env, s = self._env, self._s
        starts = [0.0] + [math.inf if x != x else float(x) for x in switches_m]
        e_cruise = math.inf if cruise_kmh is None else (cruise_kmh / 3.6) ** 2 / 2
        e, v, t, work = 0.0, 0.0, 0.0, 0.0
        last = len(self.pieces) - 1
        for j, (k, d) in enumerate(self.pieces):
            mid = s[j] + 0.5 * d
            c = conditions[max(i for i, a in enumerate(starts) if a <= mid)]
            cap = env[j + 1]
            if c == "T":
                e1 = self._rk4(lambda x: self._accel(x, k), e, d)
                e_half = max(e + 0.5 * d * self._accel(e, k), 0.0)
                f = (self._traction_kn(e, k) + 4 * self._traction_kn(e_half, k) + self._traction_kn(max(e1, 0.0), k)) / 6
            elif c == "K":
                e1 = self._rk4(lambda x: self._hold_accel(x, k), e, d)
                vk = math.sqrt(2.0 * max(e, 0.0)) * 3.6
                f = max(min(self._resistance(vk) + self.grav[k], _interp(vk, *self.tr) * self.powered[k]), 0.0)
            elif c == "C":
                e1 = self._rk4(lambda x: (-self._resistance(math.sqrt(2 * max(x, 0)) * 3.6) - self.grav[k]) / self.m, e, d)
                f = 0.0
            elif c == "E":
                e1 = self._rk4(lambda x: -self._electric_decel(x, k), e, d)
                f = 0.0
            else:
                e1 = self._rk4(lambda x: -self._decel(x, k), e, d)
                f = 0.0
            if c in "TK" and e > e_cruise:  # above the cruise speed: braked to it, as to a limit (full braking,
                e1, f = max(self._rk4(lambda x: -self._decel(x, k), e, d), e_cruise), 0.0  # as far as it can)
            elif c in "TK" and e1 > e_cruise:  # reaching the cruise speed: held there, as far as full braking can
                cap = min(cap, max(e_cruise, self._rk4(lambda x: -self._decel(x, k), e, d)))
            if e1 > cap:  # held at the cap: the traction the step to it takes, if any (braking does the rest)
                if f > 0.0:
                    vm = math.sqrt(e + cap) * 3.6  # sqrt(2 (e + cap) / 2): the step's mean e
                    f = min(max(self.m * (cap - e) / d + self._resistance(vm) + self.grav[k], 0.0), f)
                e1 = cap
            work += f * d
            if trace is not None:  # (position [m], speed [km/h], traction work so far [kWh]) after each step
                trace.append((s[j + 1], math.sqrt(2.0 * max(e1, 0.0)) * 3.6, work / 3600.0))
            if e1 <= 0.0 and j < last:
                return float("nan"), work / 3600.0
            v1 = math.sqrt(2.0 * max(e1, 0.0))
            t += 2.0 * d / (v + v1)
            e, v = e1, v1
        return t, work / 3600.0
