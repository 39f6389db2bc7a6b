"""Closed loop: a run of a train that differs from the model, re-planned as it goes (``locoplan drive``).

The *real* train is the model's with its mass (and the resistance, which grows with the weight) scaled by the
disturbance's ``mass_factor`` and its running resistance by ``resistance_factor``; its line is the route with every
announced restriction in force; it stops at every hold (a signal) for the hold's time. It is run along the
calculator's cells of that line (the calculator's step: forces at the mid-speed, dt = 2 ds / (v0 + v1)), held
under that line's braking envelope (and under the braking curve to a hold until it has stood there), applying the
advice it gets: T full traction, C coast, B full braking, K holding the advised speed (the plan's speed there:
traction up to it, braking down to it); from rest, traction. The driver applies a change of advice
``reaction_s`` late, and holds a condition at least ``min_hold_s`` (a braking curve and a hold override both).

Three runs are compared:
- **open loop**: the departure plan (``Replanner.replan`` from rest at 0) followed by position; where the real train
  has fallen more than ``CATCH_UP_KMH`` under the plan's speed (after a hold), traction until it is back on it;
- **closed loop**: re-planned from the real state every ``every_s`` seconds, at once after a hold and when a
  restriction is announced (the re-planner rebuilt with it); the re-planner keeps the *model* train;
- **hindsight**: E* of the real train on the real line (every restriction from the start), stopping at every hold,
  in the planned running time less the holds: the least traction energy any driving of that run could reach.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.conditions import CODE
from ..model.disturbance import Disturbance
from ..model.route import Route, route_slice, with_restriction
from ..model.train import Train
from ..optimize.dp_kernel import _step
from ..optimize.replan import Replan, Replanner, TrainState
from ..physics.units import KJ_PER_KWH, kinetic_e, kmh_from_e
from ..sim.calculator import ModelOptions, TractionCalculator, limit_kmh_at
from ..sim.kernel import brake_kn, load_kn

CATCH_UP_KMH = 10.0
"""Open loop: more than this under the plan's speed (after a hold, a restriction), the driver takes traction."""
HOLD_BAND_KMH = 0.5
"""K: within this of the advised speed the force holds it; outside, full traction or full braking towards it."""
MAX_STEPS_PER_CELL = 1
T_MAX_FACTOR = 5.0
"""A run longer than this x the planned time has stalled (it is reported as not arriving)."""


def real_train(train: Train, d: Disturbance) -> Train:
    """The model train with the disturbance's mass and resistance: mass (and inertial mass) x ``mass_factor``,
    running resistance x ``mass_factor`` x ``resistance_factor`` (resistance is per unit of weight)."""
    f, r = float(d.mass_factor), float(d.resistance_factor)
    return replace(train, mass_t=train.mass_t * f, inertial_mass_t=train.inertial_mass_t * f,
                   resistance_kn=tuple(float(x) * f * r for x in train.resistance_kn))


def real_route(route: Route, d: Disturbance) -> Route:
    """The line with every restriction of ``d`` in force."""
    for r in d.restrictions:
        route = with_restriction(route, r.from_m, r.to_m, r.kmh)
    return route


def check_disturbance(route: Route, d: Disturbance, source: str) -> None:
    """Every position of ``d`` on ``route``'s line (InputError naming the field)."""
    L = route.length_m
    problems = []
    for i, h in enumerate(d.holds):
        if not 0 < h.at_m < L:
            problems.append(Problem(source, f"holds[{i}].at_m", f"{h.at_m:g} m is not inside the line (0 .. {L:g} m)"))
    for i, r in enumerate(d.restrictions):
        if r.from_m >= L:
            problems.append(Problem(source, f"restrictions[{i}].from_m", f"{r.from_m:g} m is past the line's end ({L:g} m)"))
    if problems:
        raise InputError(problems)


@dataclass
class RunTrace:
    """One run of the real train: arrival [s], traction energy [kWh], its profile, and what happened."""

    name: str
    arrival_s: float
    traction_energy_kwh: float
    arrived: bool
    s_m: np.ndarray = field(repr=False)
    v_kmh: np.ndarray = field(repr=False)
    t_s: np.ndarray = field(repr=False)
    replans: int = 0
    replan_ms: list[float] = field(default_factory=list, repr=False)
    note: str | None = None

    def summary(self, planned_s: float, tolerance_s: float) -> dict:
        late = self.arrival_s - planned_s
        d = {"arrival_s": round(self.arrival_s, 2), "traction_energy_kwh": round(self.traction_energy_kwh, 3),
             "arrived": self.arrived, "late_s": round(max(late, 0.0), 2),
             "inside_window": bool(self.arrived and abs(late) <= tolerance_s + 1e-9)}
        if self.replans:
            ms = np.array(self.replan_ms)
            d.update(replans=self.replans, replan_ms_p50=round(float(np.percentile(ms, 50)), 3),
                     replan_ms_max=round(float(ms.max()), 3))
        if self.note:
            d["note"] = self.note
        return d


class _Advisor(Protocol):
    """What the driver is told at a state: (condition, the advised speed for K [km/h])."""

    def advise(self, s: float, v: float, t: float, applied: str, event: bool) -> tuple[str, float]: ...


def _plan_speed(plan: Replan, s: float) -> float:
    return float(np.interp(s, plan.s_m, plan.v_kmh))


class OpenLoop:
    def __init__(self, plan: Replan):
        self.plan = plan

    def advise(self, s, v, t, applied, event):
        u = self.plan.condition_at(s) or "B"
        target = _plan_speed(self.plan, s)
        if u in ("C", "K") and v < target - CATCH_UP_KMH:
            return "T", target
        return u, target


class ClosedLoop:
    def __init__(self, replanner: Replanner, every_s: float, d: Disturbance, first: Replan):
        self.rp, self.every_s, self.d = replanner, float(every_s), d
        self.plan = first
        self.next_t = float(every_s)
        self.announced = 0
        self.replans = 0
        self.ms: list[float] = []
        self.restrictions = sorted(d.restrictions, key=lambda r: r.announced_at_m)

    def advise(self, s, v, t, applied, event):
        while self.announced < len(self.restrictions) and s >= self.restrictions[self.announced].announced_at_m:
            r = self.restrictions[self.announced]
            self.announced += 1
            route = with_restriction(self.rp.route, r.from_m, r.to_m, r.kmh)
            self.rp = Replanner(route, self.rp.train, self.rp.options, planned_s=self.rp.planned_s,
                                tolerance_s=self.rp.tolerance_s, prices=self.rp.prices, cycle=False)
            event = True
        if event or t >= self.next_t:
            self.next_t = t + self.every_s
            # the model's limits: a real train over them (its braking differs) is planned from the highest it allows
            env = float(np.interp(s, self.rp.calc.s_m, self.rp.calc.e_envelope))
            v_plan = min(v, float(kmh_from_e(max(env, 0.0))))
            lim = float(min(limit_kmh_at(self.rp.route, s, self.rp.train.length_m if self.rp.options.strip else None),
                            self.rp.train.max_speed_kmh))
            v_plan = min(v_plan, lim)
            try:
                self.plan = self.rp.replan(TrainState(s, v_plan, t, applied if applied != "E" else None))
                self.replans += 1
                self.ms.append(self.plan.solve_time_s * 1e3)
            except (InfeasibleError, InputError):
                pass  # (the last plan stays)
        u = self.plan.condition_at(s) or "B"
        return u, _plan_speed(self.plan, s)


def _hold_curves(sim: TractionCalculator, holds) -> list[tuple[int, float, np.ndarray]]:
    """Per hold: its node (the first at or after ``at_m``), its time, and the braking curve (e) to rest there."""
    out = []
    fo = sim.forces
    for hd in holds:
        k = int(np.searchsorted(sim.s_m, hd.at_m - 1e-6))
        k = min(max(k, 1), len(sim.s_m) - 1)
        e = np.full(len(sim.s_m), np.inf)
        e[k] = 0.0
        for i in range(k - 1, -1, -1):
            e1 = e[i + 1]
            e0 = e1
            for _ in range(3):
                vm = float(kmh_from_e(0.5 * (e0 + e1)))
                dec = brake_kn(vm, sim.traction_allowed[i], fo) + load_kn(vm, sim.gravity_kn[i], fo)
                e0 = e1 + sim.h_m[i] / fo.m * max(dec, 1e-6)
            e[i] = e0
            if e0 > sim.e_envelope[i] * 4 + 1e4:
                break
        out.append((k, float(hd.s), e))
    return out


def run_train(name: str, sim: TractionCalculator, advisor: _Advisor, d: Disturbance, planned_s: float) -> RunTrace:
    """The real train (``sim``: its calculator on the real line) driven by ``advisor`` (see the module docstring)."""
    fo = sim.forces
    s_nodes, h, grav, allowed, env = sim.s_m, sim.h_m, sim.gravity_kn, sim.traction_allowed, sim.e_envelope
    n = len(h)
    holds = _hold_curves(sim, d.holds)
    hold_i = 0
    e, t, work = 0.0, 0.0, 0.0
    applied, applied_since, target = "T", 0.0, 0.0
    history: list[tuple[float, str, float]] = [(0.0, "T", 0.0)]
    ss, vs, ts = [0.0], [0.0], [0.0]
    event = True
    t_max = T_MAX_FACTOR * planned_s + sum(hd.s for hd in d.holds)
    for i in range(n):
        v = float(kmh_from_e(e))
        u_adv, tgt = advisor.advise(float(s_nodes[i]), v, t, applied, event)
        event = False
        if u_adv != history[-1][1]:
            history.append((t, u_adv, tgt))
        else:
            history[-1] = (history[-1][0], u_adv, tgt)
        # the driver: the advice as it was reaction_s ago, each condition held at least min_hold_s
        seen = history[0]
        for rec in history:
            if rec[0] <= t - d.reaction_s + 1e-9:
                seen = rec
        u, target = seen[1], seen[2]
        if u != applied and t - applied_since < d.min_hold_s - 1e-9:
            u = applied
        if u != applied:
            applied, applied_since = u, t
        if e <= kinetic_e(1.0) and i < n - 1:
            u = "T"  # from rest (or nearly): away
        cap = float(env[i + 1])
        if hold_i < len(holds) and i + 1 <= holds[hold_i][0]:
            cap = min(cap, float(holds[hold_i][2][i + 1]))
        code = CODE[u]
        if u == "K":
            if v < target - HOLD_BAND_KMH:
                code = CODE["T"]
            elif v > target + HOLD_BAND_KMH:
                code = CODE["B"]
        e1, w = _step(e, code, float(h[i]), float(grav[i]), float(allowed[i]), fo)
        if u == "K" and code == CODE["K"] and e1 < 0:  # the force cannot hold: full traction up, full braking down
            load = load_kn(v, float(grav[i]), fo)
            e1, w = _step(e, CODE["T"] if load > 0 else CODE["B"], float(h[i]), float(grav[i]), float(allowed[i]), fo)
        if e1 > cap:
            e_b, _ = _step(e, CODE["B"], float(h[i]), float(grav[i]), float(allowed[i]), fo)
            if e_b <= cap:  # held at the cap: the force that does it (traction only if it takes some)
                vm = float(kmh_from_e(0.5 * (e + cap)))
                need = fo.m * (cap - e) / h[i] + load_kn(vm, float(grav[i]), fo)
                w = max(need, 0.0) * h[i] if code in (CODE["T"], CODE["K"]) else 0.0
                e1 = cap
            else:
                e1, w = e_b, 0.0
        if e1 <= 0.0:
            if i == n - 1 or (hold_i < len(holds) and i + 1 == holds[hold_i][0]):
                e1 = 0.0
            else:
                e1, w = _step(e, CODE["T"], float(h[i]), float(grav[i]), float(allowed[i]), fo)
                if e1 <= 0.0:
                    return RunTrace(name, math.inf, work / KJ_PER_KWH, False, np.array(ss), np.array(vs), np.array(ts),
                                    note=f"stalled at {s_nodes[i]:.0f} m")
        v1 = float(kmh_from_e(e1))
        dv = (v + v1) / 3.6
        t += 2.0 * h[i] / dv if dv > 0 else 0.0
        work += w
        e = e1
        if hold_i < len(holds) and i + 1 == holds[hold_i][0]:
            e = 0.0
            v1 = 0.0
            ss.append(float(s_nodes[i + 1]))
            vs.append(0.0)
            ts.append(t)
            t += holds[hold_i][1]
            hold_i += 1
            event = True
        ss.append(float(s_nodes[i + 1]))
        vs.append(v1)
        ts.append(t)
        if t > t_max:
            return RunTrace(name, math.inf, work / KJ_PER_KWH, False, np.array(ss), np.array(vs), np.array(ts),
                            note=f"still running after {t:.0f} s at {s_nodes[i + 1]:.0f} m")
    return RunTrace(name, t, work / KJ_PER_KWH, True, np.array(ss), np.array(vs), np.array(ts))


@dataclass
class DriveResult:
    planned_s: float
    tolerance_s: float
    open_loop: RunTrace
    closed_loop: RunTrace
    hindsight_kwh: float | None
    hindsight_s: float
    hindsight_accuracy: float | None
    hindsight_note: str | None
    departure: Replan
    setup_s: float
    cycle_relaxed: bool
    hindsight_s_m: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    hindsight_v_kmh: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    def summary(self) -> dict:
        hs = {"arrival_s": round(self.hindsight_s, 2),
              "traction_energy_kwh": None if self.hindsight_kwh is None else round(self.hindsight_kwh, 3)}
        if self.hindsight_accuracy is not None:
            hs["within_percent"] = round(100 * self.hindsight_accuracy, 5)
        if self.hindsight_note:
            hs["note"] = self.hindsight_note
        out = {"planned_arrival_s": self.planned_s, "window_s": [self.planned_s - self.tolerance_s,
                                                                 self.planned_s + self.tolerance_s],
               "open_loop": self.open_loop.summary(self.planned_s, self.tolerance_s),
               "closed_loop": self.closed_loop.summary(self.planned_s, self.tolerance_s),
               "hindsight": hs, "setup_time_s": round(self.setup_s, 3)}
        for key, run in (("open_loop", self.open_loop), ("closed_loop", self.closed_loop)):
            if self.hindsight_kwh and run.arrived:
                out[key]["over_hindsight_percent"] = round(100 * (run.traction_energy_kwh / self.hindsight_kwh - 1), 3)
        if self.cycle_relaxed:
            out["air_brake"] = ("the air brake is a continuous force in the re-plans and the runs (its cycle, which "
                                "binds on this line, is not tracked)")
        return out


def hindsight_estar(route: Route, train: Train, options: ModelOptions, d: Disturbance, planned_s: float,
                    tol: float = 1e-4):
    """E* of the real run (module docstring): (kWh, accuracy) at the planned time less the holds."""
    from ..ocp.journey_energy import journey_estar

    line = real_route(route, d)
    cuts = [0.0] + [h.at_m for h in d.holds] + [line.length_m]
    legs = [route_slice(line, a, b, f"{line.name} ({a:.0f} .. {b:.0f} m)") for a, b in zip(cuts[:-1], cuts[1:])]
    moving = planned_s - sum(h.s for h in d.holds)
    res = journey_estar(legs, cuts[:-1], real_train(train, d), options, moving, [], tol=tol)
    sol = res.finest.solution
    return res.energy_kwh, res.accuracy, np.asarray(res.finest.grid.s_m), np.asarray(sol.v_ms) * 3.6


def drive(route: Route, train: Train, options: ModelOptions, d: Disturbance, *, planned_s: float, tolerance_s: float,
          every_s: float = 30.0, replanner: Replanner | None = None) -> DriveResult:
    """The three runs of the module docstring."""
    rp = replanner or Replanner(route, train, options, planned_s=planned_s, tolerance_s=tolerance_s, cycle=False)
    departure = rp.replan(TrainState(0.0, 0.0, 0.0))
    sim = TractionCalculator(real_route(route, d), real_train(train, d), options)
    open_run = run_train("open loop", sim, OpenLoop(departure), d, planned_s)
    loop = ClosedLoop(rp, every_s, d, departure)
    closed_run = run_train("closed loop", sim, loop, d, planned_s)
    closed_run.replans, closed_run.replan_ms = loop.replans, loop.ms
    note = None
    s_h = v_h = np.zeros(0)
    try:
        e_h, acc, s_h, v_h = hindsight_estar(route, train, options, d, planned_s)
    except InfeasibleError as exc:
        e_h, acc, note = None, None, str(exc)
    return DriveResult(planned_s, tolerance_s, open_run, closed_run, e_h, planned_s, acc, note, departure, rp.setup_s,
                       rp.cycle_relaxed, s_h, v_h)
