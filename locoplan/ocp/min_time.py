"""The minimum-running-time train problem of the two-stage Gauss paper (eq. 1-4, 34), its exact optimum, and the
problem of a loaded route and train.

:class:`MinTimeTrainProblem` holds numbers only and turns them into a single-phase free-end
:class:`~locoplan.ocp.phase.MultiPhaseProblem` (the problem notion every transcription here takes);
it never sees a node or a differentiation matrix. Its physics are ``physics``' functions (resistance,
gradient force, the equation of motion of ``physics.motion``, units), shared with the energy problem.

Model (the paper's eq. 1-3, point mass, ideal tractive effort):

    ds/dt = v,     dv/dt = (F_u - R(v) - G) / M

with ``M`` in t and forces in kN (kN / t = m/s^2), ``R(v) = r0 + r1 V + r2 V^2`` the whole-train
basic resistance in kN with ``V`` the speed in km/h, and ``G = M g i / 1000`` the grade resistance in
kN for a constant gradient ``i`` in per mille (positive = uphill; the per-mille gradient is the
railway convention N/kN, i.e. ``sin(theta)`` of eq. 1 is taken as ``i / 1000``).

* :func:`train_problem`: the problem of a :class:`~locoplan.model.route.Route` and a
  :class:`~locoplan.model.train.Train` (constant gradient and limit only);
* :func:`exact_minimum`: the accelerate / cruise / brake optimum by ``scipy.integrate.quad``,
  independent of any transcription.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..physics.gradient import curve_gradient_permille, tunnel_gradient_permille
from ..physics.motion import acceleration_ms2
from ..physics.resistance import basic_resistance_kn, train_resistance_kn
from ..physics.traction import gradient_force_kn, max_force_kn
from ..physics.units import kmh, ms
from .nlp import Guess
from .phase import MultiPhaseProblem, Phase, PhaseModel

__all__ = ["ExactMinimum", "MinTimeTrainProblem", "bounds_note", "davis_resistance_kn", "exact_minimum",
           "exact_minimum_time", "gauss_paper_problem", "train_problem"]


def davis_resistance_kn(vehicles) -> tuple[float, float, float]:
    """Whole-train resistance coefficients ``(r0, r1, r2)`` in kN (``V`` in km/h) from vehicles given
    as ``(mass_t, a, b, c)`` with unit resistance ``w0 = a + b V + c V^2`` in N/kN:
    ``R = sum w0 * mass_t * g / 1000``."""
    r = np.zeros(3)
    for mass_t, a, b, c in vehicles:  # each coefficient is the resistance of one unit of V^k
        r += np.array([basic_resistance_kn(0.0, a, 0.0, 0.0, float(mass_t)),
                       basic_resistance_kn(1.0, 0.0, b, 0.0, float(mass_t)),
                       basic_resistance_kn(1.0, 0.0, 0.0, c, float(mass_t))])
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
        return ms(self.speed_limit_kmh)

    @property
    def grade_force_kn(self) -> float:
        """Grade resistance ``M g i / 1000`` [kN] (positive uphill), from ``physics``."""
        return float(gradient_force_kn(self.gradient_permille, self.mass_t))

    def resistance(self, v_ms):
        """Basic resistance of the whole train [kN] at speed ``v_ms`` [m/s], from ``physics`` (floats,
        arrays and CasADi symbols alike)."""
        return train_resistance_kn(kmh(v_ms), tuple(self.resistance_kn))

    def acceleration(self, v_ms, force_kn):
        """``dv/dt`` [m/s^2] for traction (+) / brake (-) force ``force_kn``: the equation of motion
        of ``physics.motion``, as in the energy problem."""
        return acceleration_ms2(force_kn, self.mass_t, self.resistance(v_ms), self.grade_force_kn)

    def rhs(self, t, x, u):
        """``(ds/dt, dv/dt)`` for state ``x = (s, v)`` and control ``u`` [kN] (plain numbers)."""
        return np.array([x[1], self.acceleration(x[1], u)])

    # ---- generic optimal control description -----------------------------------------------------

    @property
    def nominal_time_s(self) -> float:
        return self.length_m / self.speed_limit_ms

    def to_ocp(self) -> MultiPhaseProblem:
        """One phase in time with a free end ``t_f``: states ``(s [m], v [m/s])``, control ``F_u [kN]``,
        objective ``t_f`` (the paper's eq. 34). The phase's nominal end (the time scale of the NLP) is the
        lower bound of ``t_f``: running at the limit all the way."""
        vlim = self.speed_limit_ms
        t_lo = self.length_m / vlim  # cannot be faster than running at the limit all the way
        model = PhaseModel(
            states=("s", "v"),
            controls=("F_u",),
            dynamics=lambda x, u, t, p: [x[1], self.acceleration(x[1], u[0])],
            integrand=None,
            state_scale=(self.length_m, vlim),
            control_scale=(max(self.f_max_kn, self.b_max_kn),),
        )
        phase = Phase("run", 0.0, t_lo, model, lambda t: {}, state_lower=(0.0, 0.0), state_upper=(self.length_m, vlim),
                      control_lower=(-self.b_max_kn,), control_upper=(self.f_max_kn,),
                      info={"limit_kmh": self.speed_limit_kmh, "gradient_permille": self.gradient_permille})
        return MultiPhaseProblem((phase,), initial_state=(0.0, 0.0), final_lower=(self.length_m, 0.0),
                                 final_upper=(self.length_m, 0.0), objective_scale=t_lo,
                                 free_end=(t_lo, 1000.0 * t_lo), mayer=lambda x0, xf, tf: tf)

    def initial_guess(self, m: int = 41) -> Guess:
        """A trapezoidal speed profile (accelerate / run / brake at the physical rates, cruise at
        the limit or the balancing speed) and zero force, as the paper's "initial control 0"."""
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


def gauss_paper_problem(gradient_permille: float = 0.0) -> MinTimeTrainProblem:
    """The two-stage Gauss paper, Table 1: HXD1 (200 t, w0 = 2.23 + 0.0053 V + 0.000675 V^2 N/kN) + C64 (84 t,
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


# --------------------------------------------------------------------------------------------------
# route + train -> problem
# --------------------------------------------------------------------------------------------------


def _merged(sections, value: Callable) -> list[tuple[float, float, float]]:
    """``(from_m, to_m, value)`` runs with equal neighbours merged."""
    runs: list[tuple[float, float, float]] = []
    for sec in sections:
        v = float(value(sec))
        if runs and runs[-1][2] == v and abs(runs[-1][1] - sec.from_m) < 1e-9:
            runs[-1] = (runs[-1][0], sec.to_m, v)
        else:
            runs.append((sec.from_m, sec.to_m, v))
    return runs


def _constant_bound_kn(speed_kmh: np.ndarray, force_kn: np.ndarray, limit_kmh: float) -> tuple[float, bool]:
    """Minimum of a piecewise-linear force curve over ``[0, limit_kmh]`` and whether it is constant there."""
    pts = np.concatenate([[0.0, limit_kmh], speed_kmh[(speed_kmh > 0) & (speed_kmh < limit_kmh)]])
    f = max_force_kn(pts, speed_kmh, force_kn)
    return float(np.min(f)), bool(np.ptp(f) <= 1e-9 * max(1.0, float(np.max(np.abs(f)))))


def train_problem(route, train, route_file: str | Path | None = None) -> MinTimeTrainProblem:
    """The minimum-running-time problem of ``train`` over ``route`` from rest to rest.

    Takes ``train.mass_t`` [t], the Davis coefficients ``train.resistance_kn`` (A [kN], B [kN/(km/h)],
    C [kN/(km/h)^2]), the route's length [m], its one gradient [per mille] (plus the 600/R and tunnel
    terms of a curve / tunnel that covers the whole route) and its one speed limit [km/h], capped by
    the train's ``max_speed_kmh``.

    Force bounds: the problem has constant bounds ``-b_max <= F_u <= f_max`` (the two-stage Gauss paper's eq. 34 uses
    -461..532 kN). From a consist's speed-dependent curves they are the *minimum* of the traction /
    brake curve over ``[0, limit]``: a conservative constant that the locomotive can always deliver,
    so a plan is drivable, but slower than one using the full curve where it is higher. The two-stage Gauss paper's
    consist has flat curves, for which this is exact. (Speed-dependent bounds would be a path
    constraint ``F_u <= F_max(v)`` in the problem layer and a different exact optimum; not built.)

    ``route_file`` names the route in error messages. Raises :class:`InputError` (file and field)
    when the route has more than one gradient or speed-limit section after merging equal neighbours,
    a curve or tunnel covering only part of it, or a neutral section: the single-phase problem needs
    a constant grade and limit (the MPOC paper's multi-phase problem is a later issue).
    """
    name = str(route_file) if route_file is not None else route.name
    why = ("the single-phase minimum-time problem needs one constant gradient and one speed "
           "limit over the whole route; for such a route use the multi-phase problem (--objective energy)")
    problems: list[Problem] = []
    grades = _merged(route.gradients, lambda s: s.permille)
    limits = _merged(route.speed_limits, lambda s: s.kmh)
    if len(grades) > 1:
        listed = ", ".join(f"{g:g}" for _, _, g in grades[:6]) + (", ..." if len(grades) > 6 else "")
        problems.append(Problem(name, "gradients", f"{len(grades)} sections with different gradients ({listed} per mille): {why}"))
    if len(limits) > 1:
        listed = ", ".join(f"{v:g}" for _, _, v in limits[:6]) + (", ..." if len(limits) > 6 else "")
        problems.append(Problem(name, "speed_limits", f"{len(limits)} sections with different limits ({listed} km/h): {why}"))
    extra = 0.0
    for i, c in enumerate(route.curves):
        if c.from_m > 1e-9 or c.to_m < route.length_m - 1e-9:
            problems.append(Problem(name, f"curves[{i}]", f"a curve over {c.from_m:g}-{c.to_m:g} m makes the "
                                    "equivalent gradient vary along the route (the single-phase problem needs it constant)"))
        else:
            extra += float(curve_gradient_permille(c.radius_m))
    for i, t in enumerate(route.tunnels):
        if t.from_m > 1e-9 or t.to_m < route.length_m - 1e-9:
            problems.append(Problem(name, f"tunnels[{i}]", f"a tunnel over {t.from_m:g}-{t.to_m:g} m makes the "
                                    "equivalent gradient vary along the route (the single-phase problem needs it constant)"))
        else:
            extra += float(tunnel_gradient_permille(t.to_m - t.from_m))
    if route.neutral_sections:
        problems.append(Problem(name, "neutral_sections", "the minimum-time problem has no traction-free "
                                "zones; remove the neutral sections or use the multi-phase problem (--objective energy)"))
    if problems:
        raise InputError(problems)
    limit_kmh = min(limits[0][2], float(train.max_speed_kmh))
    f_max, _ = _constant_bound_kn(np.asarray(train.traction_speed_kmh), np.asarray(train.traction_kn), limit_kmh)
    b_max, _ = _constant_bound_kn(np.asarray(train.brake_speed_kmh), np.asarray(train.brake_kn), limit_kmh)
    return MinTimeTrainProblem(
        mass_t=float(train.mass_t),
        resistance_kn=tuple(float(x) for x in train.resistance_kn),
        f_max_kn=f_max,
        b_max_kn=b_max,
        gradient_permille=grades[0][2] + extra,
        speed_limit_kmh=limit_kmh,
        length_m=float(route.length_m),
    )


def bounds_note(train, limit_kmh: float) -> str | None:
    notes = []
    for what, sp, f in (("traction", train.traction_speed_kmh, train.traction_kn),
                        ("brake", train.brake_speed_kmh, train.brake_kn)):
        lo, flat = _constant_bound_kn(np.asarray(sp), np.asarray(f), limit_kmh)
        if not flat:
            hi = float(np.max(max_force_kn(np.linspace(0.0, limit_kmh, 201), np.asarray(sp), np.asarray(f))))
            notes.append(f"{what} curve varies over 0-{limit_kmh:g} km/h ({lo:g}-{hi:g} kN); its minimum "
                         f"{lo:g} kN is used as the constant bound")
    return "; ".join(notes) or None


# --------------------------------------------------------------------------------------------------
# exact optimum
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ExactMinimum:
    """The bang-cruise-bang minimum-time run: full traction ``f_max_kn`` for ``accelerate_s`` [s] over
    ``accelerate_m`` [m] to ``peak_speed_ms`` [m/s], cruise ``cruise_s`` at that speed with
    ``cruise_force_kn`` (only if the peak is the limit; NaN otherwise), full brake ``b_max_kn`` for
    ``brake_s`` over ``brake_m``; ``time_s`` is the total."""

    time_s: float
    accelerate_s: float
    accelerate_m: float
    cruise_s: float
    cruise_force_kn: float
    brake_s: float
    brake_m: float
    peak_speed_ms: float
    f_max_kn: float
    b_max_kn: float

    def force_at(self, t) -> np.ndarray:
        """The optimal control [kN] at times ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        return np.where(t < self.accelerate_s, self.f_max_kn,
                        np.where(t < self.accelerate_s + self.cruise_s, self.cruise_force_kn, -self.b_max_kn))


def exact_minimum(problem: MinTimeTrainProblem) -> ExactMinimum:
    """Closed-form minimum running time of ``problem`` (independent of any transcription).

    With constant bounds and resistance growing with speed the optimum is: full traction until the
    limit, cruise at the limit, full brake to rest at the end (Pontryagin, state-constrained
    bang-singular-bang). Times and distances of the full-traction / full-brake phases are
    ``int dv / a(v)`` and ``int v dv / a(v)`` by ``scipy.integrate.quad``. If the route is too short to
    reach the limit (or the train's balancing speed lies below it), the peak speed where the traction
    and brake distances add up to the length is found by ``brentq`` and there is no cruise (if that
    peak is within 1e-9 of the balancing speed, the run is taken to hold that speed with full
    traction in between).
    """
    from scipy.integrate import quad  # scipy.integrate: ~1 s to import, only for this closed form
    from scipy.optimize import brentq

    vlim, length = problem.speed_limit_ms, problem.length_m

    def acc(v):
        return problem.acceleration(v, problem.f_max_kn)

    def dec(v):
        return -problem.acceleration(v, -problem.b_max_kn)

    def phase(f, v):
        t = quad(lambda w: 1.0 / f(w), 0.0, v, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        s = quad(lambda w: w / f(w), 0.0, v, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        return t, s

    # the balancing speed (acc = 0) bounds what full traction can reach
    v_top = vlim
    if acc(vlim) <= 0.0:
        v_top = brentq(acc, 0.0, vlim, xtol=1e-14)
    reach_limit = acc(vlim) > 0.0
    if reach_limit:
        ta, sa = phase(acc, vlim)
        tb, sb = phase(dec, vlim)
        if sa + sb <= length:
            cruise_force = problem.resistance(vlim) + problem.grade_force_kn
            tc = (length - sa - sb) / vlim
            return ExactMinimum(ta + tc + tb, ta, sa, tc, float(cruise_force), tb, sb, vlim,
                                problem.f_max_kn, problem.b_max_kn)
    hi = v_top * (1.0 - 1e-9) if not reach_limit else vlim

    def gap(v):
        return sum(phase(f, v)[1] for f in (acc, dec)) - length

    if gap(hi) < 0.0:
        # a long route below the balancing speed: the peak is within 1e-9 of it (beyond float
        # resolution of brentq); run there at (almost) constant speed, an error below 1e-9 relative
        ta, sa = phase(acc, hi)
        tb, sb = phase(dec, hi)
        tc = (length - sa - sb) / hi
        return ExactMinimum(ta + tc + tb, ta, sa, tc, float(problem.f_max_kn), tb, sb, hi,
                            problem.f_max_kn, problem.b_max_kn)
    v_peak = brentq(gap, 1e-9, hi, xtol=1e-14)
    ta, sa = phase(acc, v_peak)
    tb, sb = phase(dec, v_peak)
    return ExactMinimum(ta + tb, ta, sa, 0.0, float("nan"), tb, sb, v_peak, problem.f_max_kn, problem.b_max_kn)


def exact_minimum_time(problem: MinTimeTrainProblem) -> float:
    """The exact minimum running time [s] of ``problem`` (see :func:`exact_minimum`)."""
    return exact_minimum(problem).time_s
