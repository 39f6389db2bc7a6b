"""The MPOC paper's minimum-energy train problem as a multi-phase optimal control problem (numbers only).

Independent variable: distance ``s`` [m]. States: ``e = v^2 / 2`` [m^2/s^2] and time ``t`` [s];
controls: traction ``F`` and braking ``B`` [kN] (with a regenerative credit and the wagons' air
brake, ``B`` is split into the electric ``B_e`` and the air ``B_a`` part, because only ``B_e``
returns energy). Dynamics, with ``M`` the inertial mass [t] (the calculator's ``m_eff_t``):

    de/ds = (F - B - R(v) - G(s)) / M,     dt/ds = 1 / v,     v = sqrt(2 e)

Why ``e`` and not ``v``: in ``e`` the speed equation has no ``1 / v`` (``dv/ds = a / v`` is singular
at rest, ``de/ds = a`` is not) and the train's work-energy balance is linear in it; only the time
equation keeps ``1 / v``, and at the two rest points the quadratic interval mapping plus the exact
starting rate ``dt / d sqrt(s) = sqrt(2 / a0)`` handle it (``locoplan.ocp.phase``).

Path constraints: ``0 <= F <= Fmax(v)``, ``0 <= B <= Bmax(v)`` with the consist's speed-dependent
curves (``physics.traction.max_force_kn``, a hinge sum on symbols), ``e <= e_limit`` of the phase,
optionally ``|a| <= comfort_ms2``; in a neutral-section phase ``F = 0`` and the electric brake is cut
with it (the main breaker is open), so ``B`` is the wagons' air brake alone, and ``F = B = 0`` without
one (the MPOC paper's eq. 5; the calculator's ``brake_kn_at`` is the same);
rest to rest; ``t_f <= T``. Objective: ``physics.energy.energy_rate_kn`` integrated over ``s``
(the traction work at the wheel by default).

Phases (the MPOC paper's section 2.1): a new phase at every change of speed limit, equivalent gradient and
neutral-section span. In the default train-length-aware model the gradient under the train is
piecewise *linear* between its knots (every gradient / curve / tunnel boundary ``b`` and ``b + L``,
``physics.gradient``), the limit changes where the head reaches a drop and where the tail clears a
rise (``sim.calculator.limit_kmh_at``), and traction is cut over ``sim.calculator.neutral_spans_m``;
with ``point_mass`` the papers' point model (constant gradient per section, head limits, spans
without the train length).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.route import Route
from ..model.train import Train
from ..physics.backend import is_symbolic
from ..physics.energy import WHEEL_WORK, EnergyModel, energy_rate_kn
from ..physics.gradient import equivalent_gradient_permille, point_gradient_knots
from ..physics.resistance import train_resistance_kn
from ..physics.motion import acceleration_ms2
from ..physics.traction import gradient_force_kn, max_force_kn
from ..physics.units import KMH_PER_MS, kinetic_e, ms
from ..sim.calculator import ModelOptions, TractionCalculator, limit_kmh_at, neutral_spans_m
from .phase import MultiPhaseProblem, Phase, PhaseModel

DEFAULT_MESH_TOL = 1e-5
"""hp refinement's tolerance on the relative dynamics error (``energy.solve_energy``)."""
DEFAULT_MAX_DEGREE = 10
"""Highest collocation degree per interval before an interval is split."""
E_FLOOR = 1e-8
"""Added under the square root of ``v = sqrt(2 e + E_FLOOR)``: keeps derivatives finite at the rest
points (a speed error below 1e-4 m/s at rest, below 1e-9 m/s above walking pace)."""
MIN_START_ACCEL_MS2 = 1e-3
"""The train must leave rest with at least this acceleration (the starting rate needs a0 > 0)."""
REST_END = True
PHASE_MERGE_M = 1e-3
"""Breakpoints closer than this are one breakpoint [m]."""


@dataclass(frozen=True)
class EnergyOptions:
    """What the energy problem adds to the train model: the energy counted, the comfort bound and
    whether neutral sections are honoured (``ignore_neutral`` = the MPOC paper's MPOC-N)."""

    energy: EnergyModel = WHEEL_WORK
    comfort_ms2: float | None = None
    ignore_neutral: bool = False


def energy_options(efficiency: str | float | None = None, regen: float = 0.0, comfort_ms2: float | None = None,
                   ignore_neutral: bool = False, source: str = "<command line>") -> EnergyOptions:
    """:class:`EnergyOptions` from the command line: ``efficiency`` a number in [0.1, 1] or a curve
    ``"0:0.80,40:0.88,120:0.90"`` (speed_kmh:eta, rising speeds), ``regen`` the credited share of the
    electric brake's work in [0, 1], ``comfort_ms2`` the largest acceleration / deceleration [m/s^2]."""
    problems = []
    eff: float | tuple = 1.0
    if efficiency is not None and str(efficiency).strip():
        from .. import bounds

        try:
            eff = bounds.efficiency(str(efficiency), "--efficiency")
        except InputError as exc:
            problems += [Problem(source, p.field, p.message, p.line) for p in exc.problems]
    if not (math.isfinite(regen) and 0 <= regen <= 1):
        problems.append(Problem(source, "--regen", f"the credited share of the electric brake's work must be in [0, 1] (got {regen:g})"))
    if comfort_ms2 is not None and not (math.isfinite(comfort_ms2) and comfort_ms2 > 0):
        problems.append(Problem(source, "--comfort", f"must be a positive acceleration in m/s^2 (got {comfort_ms2:g})"))
    if problems:
        raise InputError(problems)
    return EnergyOptions(EnergyModel(eff, float(regen)), comfort_ms2, ignore_neutral)


def _speed(e):
    """v [m/s] from e = v^2 / 2 (numbers or symbols)."""
    if is_symbolic(e):
        import casadi as ca

        return ca.sqrt(ca.fmax(2.0 * e, 0.0) + E_FLOOR)  # IPOPT relaxes the bound e >= 0 by a hair
    return np.sqrt(2.0 * np.maximum(np.asarray(e, dtype=float), 0.0) + E_FLOOR)


def _fmax0(a):
    if is_symbolic(a):
        import casadi as ca

        return ca.fmax(a, MIN_START_ACCEL_MS2 * 1e-3)
    return np.maximum(a, MIN_START_ACCEL_MS2 * 1e-3)


@dataclass(frozen=True)
class TrainModel:
    """The consist's numbers the dynamics need (built once per train and model options)."""

    mass_t: float
    inertial_mass_t: float
    resistance_kn: tuple[float, float, float]
    traction_curve: tuple[np.ndarray, np.ndarray]
    brake_curve: tuple[np.ndarray, np.ndarray]
    electric_curve: tuple[np.ndarray, np.ndarray]
    air_curve: tuple[np.ndarray, np.ndarray] | None
    energy: EnergyModel
    comfort_ms2: float | None

    @property
    def split_brake(self) -> bool:
        """Brake as two controls (electric, air): needed when only the electric part earns a credit."""
        return self.energy.regen_credit > 0 and self.air_curve is not None

    @property
    def controls(self) -> tuple[str, ...]:
        return ("F", "B_e", "B_a") if self.split_brake else ("F", "B")

    def brakes(self, u):
        """(total braking, electric braking) [kN] from the control list."""
        if self.split_brake:
            return u[1] + u[2], u[1]
        return u[1], u[1]

    def accel(self, x, u, p, speed_kmh):
        """The equation of motion of ``physics.motion`` (shared with the minimum-time problem)."""
        brake, _ = self.brakes(u)
        load = train_resistance_kn(speed_kmh, self.resistance_kn) + p["gravity_kn"]
        return acceleration_ms2(u[0], self.inertial_mass_t, brake, load)

    def dynamics(self, x, u, s, p):
        v = _speed(x[0])
        a = self.accel(x, u, p, KMH_PER_MS * v)
        return [a, 1.0 / v]

    def integrand(self, x, u, s, p):
        v_kmh = KMH_PER_MS * _speed(x[0])
        _, b_e = self.brakes(u)
        return energy_rate_kn(u[0], b_e, v_kmh, self.energy)

    def path(self, x, u, s, p):
        v_kmh = KMH_PER_MS * _speed(x[0])
        out = [u[0] - max_force_kn(v_kmh, *self.traction_curve)]
        # the electric brake needs the catenary: p["powered"] is 0 in a neutral-section phase
        electric = max_force_kn(v_kmh, *self.electric_curve) * p["powered"]
        if self.split_brake:
            out += [u[1] - electric, u[2] - max_force_kn(v_kmh, *self.air_curve)]
        elif self.air_curve is not None:
            out.append(u[1] - (electric + max_force_kn(v_kmh, *self.air_curve)))
        else:
            out.append(u[1] - electric)
        if self.comfort_ms2 is not None:
            a = self.accel(x, u, p, v_kmh)
            out += [a - self.comfort_ms2, -a - self.comfort_ms2]
        return out

    @property
    def n_path(self) -> int:
        return (3 if self.split_brake else 2) + (2 if self.comfort_ms2 is not None else 0)

    def singular_start(self, x, u, s, p):
        """d(e, t) / d sqrt(s - s0) at rest: e ~ a0 (s - s0) gives 0 and sqrt(2 / a0)."""
        a0 = self.accel(x, u, p, 0.0 * x[0])
        return [0.0 * a0, (2.0 / _fmax0(a0)) ** 0.5]

    def start_path(self, x, u, s, p):
        return [MIN_START_ACCEL_MS2 - self.accel(x, u, p, 0.0 * x[0])]


def train_model(train: Train, options: ModelOptions, energy: EnergyOptions) -> TrainModel:
    m_eff = train.inertial_mass_t if options.rotating_mass is None else train.mass_t * (1.0 + options.rotating_mass)
    brake = train.brake_curve(options.air_brake)
    air = (np.asarray(train.air_brake_speed_kmh), np.asarray(train.air_brake_kn)) if options.air_brake else None
    if air is not None and not np.any(air[1] > 0):
        air = None
    return TrainModel(float(train.mass_t), float(m_eff), tuple(float(c) for c in train.resistance_kn),
                      (np.asarray(train.traction_speed_kmh), np.asarray(train.traction_kn)),
                      (np.asarray(brake[0]), np.asarray(brake[1])),
                      (np.asarray(train.electric_brake_speed_kmh), np.asarray(train.electric_brake_kn)),
                      air, energy.energy, energy.comfort_ms2)


# --------------------------------------------------------------------------------------------------
# phases from the route
# --------------------------------------------------------------------------------------------------


def breakpoints_m(route: Route, train: Train, options: ModelOptions, energy: EnergyOptions) -> np.ndarray:
    """Every position where the limit, the equivalent gradient (or its slope) or the neutral status
    changes, with 0 and the route's length."""
    length = float(route.length_m)
    strip = options.strip
    L = float(train.length_m)
    x, _ = point_gradient_knots(route)
    pts = [0.0, length, *x]
    lim = [b for sec in route.speed_limits for b in (sec.from_m, sec.to_m)]
    pts += lim
    if strip:
        pts += [b + L for b in x] + [b + L for b in lim]
    else:
        pts += [c.from_m + L for c in route.curves]  # the pattern-curve patent's claim 6: a short curve over one train length
    if not energy.ignore_neutral:
        for a, b in neutral_spans_m(route, L if strip else 0.0):
            pts += [a, b]
    p = np.unique(np.clip(np.asarray(pts, dtype=float), 0.0, length))
    keep = np.concatenate([[True], np.diff(p) > PHASE_MERGE_M])
    p = p[keep]
    p[-1] = length
    return p


def _gravity_params(route: Route, train: Train, options: ModelOptions, a: float, b: float):
    """``params(s)`` of a phase: the gravity force on the equivalent gradient [kN], linear over the
    phase in the strip model (exactly: the strip gradient is linear between its knots), constant in
    the point model."""
    mass, L = float(train.mass_t), float(train.length_m)
    if options.strip:
        ga, gb = equivalent_gradient_permille(route, np.array([a, b]), L, strip=True)
        fa, fb = float(gradient_force_kn(ga, mass)), float(gradient_force_kn(gb, mass))

        def params(s):
            w = (np.asarray(s, dtype=float) - a) / (b - a)
            return {"gravity_kn": fa + (fb - fa) * w}

        return params, (float(ga), float(gb))
    g = float(equivalent_gradient_permille(route, np.array([0.5 * (a + b)]), L, strip=False)[0])
    f = float(gradient_force_kn(g, mass))
    return (lambda s: {"gravity_kn": np.full(np.shape(s), f)}), (g, g)


@dataclass(frozen=True)
class TrainEnergyProblem:
    """The multi-phase problem with what made it: route, train, options, the model, the phases'
    limits / gradients / neutral flags, the time asked for."""

    route: Route
    train: Train
    options: ModelOptions
    energy: EnergyOptions
    time_s: float
    model: TrainModel
    problem: MultiPhaseProblem
    spans_m: tuple[tuple[float, float], ...]


def build_problem(route: Route, train: Train, options: ModelOptions, time_s: float,
                  energy: EnergyOptions | None = None) -> TrainEnergyProblem:
    """The minimum-energy problem of ``train`` over ``route`` in at most ``time_s`` seconds."""
    energy = energy or EnergyOptions()
    if not (math.isfinite(time_s) and time_s > 0):
        raise InputError(Problem("<command line>", "--time", f"must be a finite number of seconds > 0 (got {time_s:g})"))
    tm = train_model(train, options, energy)
    pts = breakpoints_m(route, train, options, energy)
    strip = options.strip
    L = float(train.length_m)
    spans = () if energy.ignore_neutral else tuple(neutral_spans_m(route, L if strip else 0.0))
    mid = 0.5 * (pts[1:] + pts[:-1])
    limits = np.minimum(limit_kmh_at(route, mid, L if strip else None), float(train.max_speed_kmh))
    f_top = float(np.max(tm.traction_curve[1]))
    brake_tops = ([float(np.max(tm.electric_curve[1])), float(np.max(tm.air_curve[1]))] if tm.split_brake
                  else [float(np.max(tm.brake_curve[1]))])
    e_top = float(kinetic_e(np.max(limits)))
    model = PhaseModel(
        states=("e", "t"), controls=tm.controls, dynamics=tm.dynamics, integrand=tm.integrand,
        state_scale=(e_top, float(time_s)), control_scale=(f_top, *brake_tops),
        path=tm.path, n_path=tm.n_path, singular_start=tm.singular_start, start_path=tm.start_path, n_start_path=1,
        control_paths=tuple(range(len(tm.controls))))
    phases = []
    for k, (a, b) in enumerate(zip(pts[:-1], pts[1:])):
        params, grads = _gravity_params(route, train, options, float(a), float(b))
        neutral = any(lo < mid[k] < hi for lo, hi in spans)
        e_lim = float(kinetic_e(limits[k]))
        if not neutral:
            upper_u = (f_top, *brake_tops)
        elif tm.air_curve is None:  # coasting: no traction, no brake at all
            upper_u = (0.0,) * len(tm.controls)
        else:  # no traction, the air brake alone (the path constraint bounds B by its curve)
            upper_u = (0.0, 0.0, brake_tops[1]) if tm.split_brake else (0.0, brake_tops[0])
        params = _with_power(params, 0.0 if neutral else 1.0)
        phases.append(Phase(f"phase {k + 1}", float(a), float(b), model, params,
                            state_lower=(0.0, 0.0), state_upper=(e_lim, float(time_s)),
                            control_lower=(0.0,) * len(tm.controls), control_upper=upper_u,
                            info={"limit_kmh": float(limits[k]), "gradient_permille": grads, "neutral": neutral}))
    problem = MultiPhaseProblem(tuple(phases), initial_state=(0.0, 0.0), final_lower=(0.0, 0.0),
                                final_upper=(0.0, float(time_s)), objective_scale=_energy_scale_kj(tm, route),
                                rest_start=True, rest_end=REST_END)
    return TrainEnergyProblem(route, train, options, energy, float(time_s), tm, problem, spans)


def _with_power(params, powered: float):
    """A phase's parameters plus ``powered`` (1, or 0 in a neutral-section span: no electric brake)."""
    def with_power(s):
        out = dict(params(s))
        out["powered"] = np.full(np.shape(s), powered)
        return out

    return with_power


def _energy_scale_kj(tm: TrainModel, route: Route) -> float:
    """A nominal traction energy [kJ] for scaling the NLP's objective to about 1: the work of the
    starting resistance over the route plus accelerating to the highest limit."""
    v_top = ms(max(x.kmh for x in route.speed_limits))
    return float(tm.resistance_kn[0] * route.length_m + 0.5 * tm.inertial_mass_t * v_top ** 2)


def check_runnable(calc: TractionCalculator, time_s: float, what: str = "") -> float:
    """The fastest run's time [s]; ``InfeasibleError`` (exit 1) with the reason when the consist cannot
    run the route at all (a grade it cannot climb, traction cut at the start) or when ``time_s`` is
    below the fastest run."""
    res = calc.evaluate(("T",), np.zeros((1, 0)))
    route, train = calc.route, calc.train
    if not res.feasible[0]:
        raise InfeasibleError(f"{what}{train.name} cannot run {route.name} even at full traction: {res.reason(0)}"
                              + _why_stalled(calc, res))
    fastest = float(res.running_time_s[0])
    if time_s < fastest:
        raise InfeasibleError(f"{what}planned running time {time_s:g} s is below the fastest possible run, "
                              f"{fastest:.{1 if fastest - time_s >= 0.05 else 4}f} s ({route.name}, {train.name})")
    return fastest


def _why_stalled(calc: TractionCalculator, res) -> str:
    """The physics of a failed fastest run: the grade where it stalled against the traction at low
    speed, or traction cut there by a neutral section's span."""
    at = float(res.failure_m[0])
    k = int(np.clip(np.searchsorted(calc.s_m, at) - 1, 0, len(calc.h_m) - 1))
    grade = float(np.max(calc.gradient_permille[max(0, k - 2):k + 3]))
    need = float(gradient_force_kn(grade, calc.train.mass_t) + train_resistance_kn(0.0, calc.train.resistance_kn))
    have = float(np.max(calc.train.traction_kn))
    if need > have:
        return (f" (the steepest equivalent grade there, {grade:+.1f} per mille, takes {need:,.0f} kN to climb from rest; "
                f"the consist's traction curve gives at most {have:,.0f} kN)")
    if calc.traction_allowed[k] == 0.0:
        return " (traction is cut there by a neutral section's span)"
    return ""
