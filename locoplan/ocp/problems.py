"""The minimum-running-time train problem of seed 000 (eq. 1-4, 34) as plain numbers.

Layer 3 of the optimal-control stack. :class:`MinTimeTrainProblem` only holds numbers and turns them
into a generic :class:`~locoplan.ocp.transcription.OcpDescription` (dynamics on CasADi symbols,
bounds, boundary conditions, objective ``t_f``); it never sees a node or a differentiation matrix and
imports nothing from the rest of locoplan except the error types and g.

Model (seed eq. 1-3, point mass, ideal tractive effort):

    ds/dt = v,     dv/dt = (F_u - R(v) - G) / M

with ``M`` in t and forces in kN (kN / t = m/s^2), ``R(v) = r0 + r1 V + r2 V^2`` the whole-train
basic resistance in kN with ``V = 3.6 v`` in km/h, and ``G = M g i / 1000`` the grade resistance in
kN for a constant gradient ``i`` in per mille (positive = uphill; the per-mille gradient is the
railway convention N/kN, i.e. ``sin(theta)`` of eq. 1 is taken as ``i / 1000``). ``g = 9.81``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.train import G_MS2  # one g for the whole project (SPEC: 9.81 m/s^2)
from ..physics.resistance import train_resistance_kn
from ..physics.traction import gradient_force_kn
from .transcription import Guess, OcpDescription

__all__ = ["G_MS2", "KMH_PER_MS", "MinTimeTrainProblem", "davis_resistance_kn", "seed000_problem"]

KMH_PER_MS = 3.6


def davis_resistance_kn(vehicles) -> tuple[float, float, float]:
    """Whole-train resistance coefficients ``(r0, r1, r2)`` in kN (``V`` in km/h) from vehicles given
    as ``(mass_t, a, b, c)`` with unit resistance ``w0 = a + b V + c V^2`` in N/kN:
    ``R = sum w0 * mass_t * g / 1000``."""
    r = np.zeros(3)
    for mass_t, a, b, c in vehicles:
        r += np.array([a, b, c], dtype=float) * float(mass_t) * G_MS2 / 1000.0
    return tuple(float(x) for x in r)


@dataclass(frozen=True)
class MinTimeTrainProblem:
    """Minimum running time over ``length_m`` from rest to rest on a constant gradient.

    Numbers only: ``mass_t`` [t], ``resistance_kn = (r0, r1, r2)`` [kN, kN/(km/h), kN/(km/h)^2],
    ``f_max_kn`` / ``b_max_kn`` constant maximum traction / braking force [kN, both >= 0],
    ``gradient_permille`` (uphill positive), ``speed_limit_kmh``, ``length_m``.
    Invalid numbers raise :class:`InputError`; a train that cannot start (traction below resistance
    plus grade at standstill) or cannot stop (brake plus resistance below a downhill grade) raises
    :class:`InfeasibleError`.
    """

    mass_t: float
    resistance_kn: tuple[float, float, float]
    f_max_kn: float
    b_max_kn: float
    gradient_permille: float
    speed_limit_kmh: float
    length_m: float

    def __post_init__(self):
        problems: list[Problem] = []

        def bad(field: str, message: str):
            problems.append(Problem(file="min-time problem", field=field, message=message))

        def number(field: str, value):
            try:
                v = float(value)
            except (TypeError, ValueError):
                bad(field, f"{value!r} is not a number")
                return None
            if not math.isfinite(v):
                bad(field, f"{value!r} is not a finite number")
                return None
            return v

        mass = number("mass_t", self.mass_t)
        try:
            res = tuple(self.resistance_kn)
        except TypeError:
            res = ()
        if len(res) != 3:
            bad("resistance_kn", f"expected (r0, r1, r2), got {self.resistance_kn!r}")
            res = (0.0, 0.0, 0.0)
        res = tuple(number(f"resistance_kn[{i}]", r) for i, r in enumerate(res))
        f_max = number("f_max_kn", self.f_max_kn)
        b_max = number("b_max_kn", self.b_max_kn)
        grad = number("gradient_permille", self.gradient_permille)
        vlim = number("speed_limit_kmh", self.speed_limit_kmh)
        length = number("length_m", self.length_m)
        if mass is not None and mass <= 0:
            bad("mass_t", f"must be positive, got {mass}")
        for i, r in enumerate(res):
            if r is not None and r < 0:
                bad(f"resistance_kn[{i}]", f"must be >= 0, got {r}")
        if f_max is not None and f_max <= 0:
            bad("f_max_kn", f"must be positive, got {f_max}")
        if b_max is not None and b_max <= 0:
            bad("b_max_kn", f"must be positive (a braking force magnitude), got {b_max}")
        if grad is not None and abs(grad) >= 1000:
            bad("gradient_permille", f"must lie in (-1000, 1000), got {grad}")
        if vlim is not None and vlim <= 0:
            bad("speed_limit_kmh", f"must be positive, got {vlim}")
        if length is not None and length <= 0:
            bad("length_m", f"must be positive, got {length}")
        if problems:
            raise InputError(problems)
        for k, v in (("mass_t", mass), ("f_max_kn", f_max), ("b_max_kn", b_max), ("gradient_permille", grad),
                     ("speed_limit_kmh", vlim), ("length_m", length)):
            object.__setattr__(self, k, v)
        object.__setattr__(self, "resistance_kn", res)

        start = self.resistance(0.0) + self.grade_force_kn
        if self.f_max_kn <= start:
            raise InfeasibleError(
                f"the train cannot start: maximum traction {self.f_max_kn:g} kN does not exceed "
                f"resistance + grade at standstill ({self.resistance(0.0):g} + {self.grade_force_kn:g} = {start:g} kN)"
            )
        stop = self.b_max_kn + self.resistance(0.0) + self.grade_force_kn
        if stop <= 0:
            raise InfeasibleError(
                f"the train cannot stop: maximum brake {self.b_max_kn:g} kN plus resistance does not exceed "
                f"the downhill grade force {-self.grade_force_kn:g} kN"
            )

    # ---- physics (works on floats, NumPy arrays and CasADi symbols) ------------------------------

    @property
    def speed_limit_ms(self) -> float:
        return self.speed_limit_kmh / KMH_PER_MS

    @property
    def grade_force_kn(self) -> float:
        """Grade resistance ``M g i / 1000`` [kN] (positive uphill), from ``physics``."""
        return float(gradient_force_kn(self.gradient_permille, self.mass_t))

    def resistance(self, v_ms):
        """Basic resistance of the whole train [kN] at speed ``v_ms`` [m/s], from ``physics`` (floats,
        arrays and CasADi symbols alike)."""
        return train_resistance_kn(KMH_PER_MS * v_ms, tuple(self.resistance_kn))

    def acceleration(self, v_ms, force_kn):
        """``dv/dt`` [m/s^2] for traction (+) / brake (-) force ``force_kn``."""
        return (force_kn - self.resistance(v_ms) - self.grade_force_kn) / self.mass_t

    def rhs(self, t, x, u):
        """``(ds/dt, dv/dt)`` for state ``x = (s, v)`` and control ``u`` [kN] (plain numbers)."""
        return np.array([x[1], self.acceleration(x[1], u)])

    # ---- generic optimal control description -----------------------------------------------------

    @property
    def nominal_time_s(self) -> float:
        return self.length_m / self.speed_limit_ms

    def to_ocp(self) -> OcpDescription:
        """States ``(s [m], v [m/s])``, control ``F_u [kN]``, objective ``t_f`` (seed eq. 34)."""
        vlim = self.speed_limit_ms
        t_lo = self.length_m / vlim  # cannot be faster than running at the limit all the way
        return OcpDescription(
            state_names=("s", "v"),
            control_names=("F_u",),
            dynamics=lambda x, u, t: [x[1], self.acceleration(x[1], u[0])],
            state_lower=(0.0, 0.0),
            state_upper=(self.length_m, vlim),
            control_lower=(-self.b_max_kn,),
            control_upper=(self.f_max_kn,),
            initial_state=(0.0, 0.0),
            final_state=(self.length_m, 0.0),
            final_time_bounds=(t_lo, 1000.0 * t_lo),
            mayer=lambda x0, xf, tf: tf,
            state_scale=(self.length_m, vlim),
            control_scale=(max(self.f_max_kn, self.b_max_kn),),
            time_scale=t_lo,
            objective_scale=t_lo,
        )

    def initial_guess(self, m: int = 41) -> Guess:
        """A trapezoidal speed profile (accelerate / run / brake at the physical rates, cruise at
        the limit or the balancing speed) and zero force, as the seed's "initial control 0"."""
        vlim = self.speed_limit_ms
        a = max(self.acceleration(0.5 * vlim, self.f_max_kn), 1e-3)
        b = max(-self.acceleration(0.5 * vlim, -self.b_max_kn), 1e-3)
        v = vlim
        if v * v / (2 * a) + v * v / (2 * b) > self.length_m:  # too short to reach the limit
            v = math.sqrt(2 * self.length_m / (1 / a + 1 / b))
        ta, tb = v / a, v / b
        tc = (self.length_m - v * v / (2 * a) - v * v / (2 * b)) / v
        tf = ta + tc + tb
        t = np.linspace(0.0, tf, m)
        speed = np.minimum.reduce([np.full_like(t, v), a * t, b * (tf - t)])
        s = np.concatenate(([0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))))
        s *= self.length_m / s[-1]
        return Guess(sigma=t / tf, states=np.vstack([s, speed]), controls=np.zeros((1, m)), final_time=tf)


def seed000_problem(gradient_permille: float = 0.0) -> MinTimeTrainProblem:
    """Seed 000, Table 1: HXD1 (200 t, w0 = 2.23 + 0.0053 V + 0.000675 V^2 N/kN) + C64 (84 t,
    w0 = 0.92 + 0.0048 V + 0.000125 V^2 N/kN), -461 kN <= F_u <= 532 kN, 1500 m, 0 <= v <= 11.1 m/s
    (39.96 km/h). Test 1 is level track, test 2 a 30 per mille grade."""
    return MinTimeTrainProblem(
        mass_t=284.0,
        resistance_kn=davis_resistance_kn([(200.0, 2.23, 0.0053, 0.000675), (84.0, 0.92, 0.0048, 0.000125)]),
        f_max_kn=532.0,
        b_max_kn=461.0,
        gradient_permille=gradient_permille,
        speed_limit_kmh=39.96,
        length_m=1500.0,
    )
