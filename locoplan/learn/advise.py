"""Advice from learned patterns (the pattern-curve patent's claim 1 steps 5-6, claim 2): for a route, a train and a
running time, the time shares (upper layer), the speed curve section by section (lower layer, each
division's exit speed the next one's entry), and the operation sequence that follows that curve,
computed with the physical model and checked by the traction calculator.

From speed curve to operations (claim 2). The advice is a condition sequence the calculator
evaluates (T full traction, K hold the speed at which it starts, C coast, B full braking), built one
division at a time from the speed the train actually has at the division's start, v_a, towards the
pattern's speed at its end, v_b:

- faster (v_b > v_a): coast if coasting alone gets there (a descent), else traction; then K from
  where v_b is reached ("T until v, then K");
- slower: K, then C from the point whose coasting curve ends at v_b (found by integrating coasting
  backward from the division's end);
- slower, where coasting cannot get down to v_b (a descent): C all the way (the train runs above the
  pattern rather than brake away energy bought with traction);
- about the same: C where coasting keeps or gains speed, K where it would lose it.

Braking mid-route is left to the calculator's braking envelope (a lower limit ahead), as in the
ISSA paper's energy-saving sequences: a pattern is never followed by braking. With ``--strict-limits``
(coasting into a limit is infeasible) a coast that would reach a limit becomes K just below it.
- the last division: coast into the final bare B (the stop's braking curve, as everywhere here).

The positions come from integrating the calculator's own forces (``calc.forces_kn``, its cells,
neutral sections and braking envelope) along distance; the calculator then evaluates the sequence.
The pattern's speeds are finally scaled by one factor (a bisection) until the calculator's running
time meets the asked time: the shape is the pattern's, the level is what the timetable demands.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.plan import Plan
from ..model.route import Route
from ..model.train import Train
from ..physics.units import kinetic_e, kmh_from_e, ms_from_e
from ..sim.calculator import ModelOptions, TractionCalculator
from ..sim.result import BatchResult
from .patterns import LineModel, Patterns, line_model

SUBSTEP_M = 25.0
"""Largest integration sub-step of the follower [m] (within the calculator's cells)."""
SAME_KMH = 1.0
"""Speeds closer than this count as the same target [km/h]."""
SCALE_RANGE = (0.5, 1.8)
"""Range of the speed-scale factor searched to meet the running time (scanned in steps of 0.1, then
bisected between the neighbouring feasible scales that bracket the time)."""


# ------------------------------------------------------------------------------------------ follower
class Follower:
    """Distance integration of one condition on the calculator's model, for placing switches.

    ``run(cond, x0, x1, e0)`` returns positions and e = v^2 / 2 along the way (RK2 sub-steps); T is
    capped at the braking envelope (the limit, or a braking curve), as in the calculator;
    ``run_back(cond, x1, x0, e1)`` integrates backward from x1 (the curve that ends at e1)."""

    def __init__(self, calc: TractionCalculator):
        self.calc = calc
        self.m = calc.m_eff_t
        self.s = calc.s_m
        self.last = len(calc.h_m) - 1

    def _slope(self, cond: str, e: float, k: int) -> float:
        f_max, b_max, load = (float(x) for x in self.calc.forces_kn(ms_from_e(np.float64(max(e, 0.0))), k))
        force = {"T": f_max, "C": 0.0, "B": -b_max, "K": min(max(load, -b_max), f_max)}[cond]
        return (force - load) / self.m

    def _grid(self, x0: float, x1: float) -> np.ndarray:
        inner = self.s[(self.s > min(x0, x1) + 1e-6) & (self.s < max(x0, x1) - 1e-6)]
        pts = np.unique(np.concatenate([[x0, x1], inner]))
        out = [pts[0]]
        for b in pts[1:]:
            n = max(1, math.ceil((b - out[-1]) / SUBSTEP_M - 1e-9))
            out += list(np.linspace(out[-1], b, n + 1)[1:])
        return np.array(out)

    def run(self, cond: str, x0: float, x1: float, e0: float) -> tuple[np.ndarray, np.ndarray]:
        x = self._grid(x0, x1)
        e = np.empty(len(x))
        e[0] = e0
        env = np.interp(x, self.s, self.calc.e_envelope)
        for i in range(len(x) - 1):
            d = x[i + 1] - x[i]
            k = min(int(np.searchsorted(self.s, 0.5 * (x[i] + x[i + 1]), side="right")) - 1, self.last)
            if cond == "K" and e[i] > 0:
                e_mid = e[i] + 0.5 * d * self._slope("K", e[i], k)
                nxt = e[i] + d * self._slope("K", e_mid, k)
            else:
                nxt = e[i] + d * self._slope(cond, e[i] + 0.5 * d * self._slope(cond, e[i], k), k)
            e[i + 1] = min(max(nxt, 0.0), env[i + 1])
        return x, e

    def reaches_limit(self, x: np.ndarray, e: np.ndarray, margin_kmh: float = 0.5) -> float | None:
        """First position of a trajectory within ``margin_kmh`` of the static limit (None if never)."""
        cell = np.clip(np.searchsorted(self.s, x, side="right") - 1, 0, self.last)
        e_lim = kinetic_e(np.maximum(self.calc.limit_kmh[cell] - margin_kmh, 0.0))
        hit = np.flatnonzero(e >= e_lim)
        return float(x[hit[0]]) if hit.size else None

    def run_back(self, cond: str, x1: float, x0: float, e1: float) -> tuple[np.ndarray, np.ndarray]:
        """Backward from (x1, e1) to x0: the e(x) from which ``cond`` arrives at e1 at x1 (ascending x)."""
        x = self._grid(x0, x1)[::-1]
        e = np.empty(len(x))
        e[0] = e1
        for i in range(len(x) - 1):
            d = x[i] - x[i + 1]
            k = min(int(np.searchsorted(self.s, 0.5 * (x[i] + x[i + 1]), side="right")) - 1, self.last)
            e_mid = e[i] - 0.5 * d * self._slope(cond, e[i], k)
            e[i + 1] = max(e[i] - d * self._slope(cond, e_mid, k), 0.0)
        return x[::-1], e[::-1]


def _crossing(x: np.ndarray, e: np.ndarray, level: float, rising: bool) -> float | None:
    """First position where e(x) reaches ``level`` (rising or falling through it), interpolated."""
    hit = np.flatnonzero(e >= level) if rising else np.flatnonzero(e <= level)
    if not hit.size:
        return None
    j = int(hit[0])
    if j == 0:
        return float(x[0])
    a, b = e[j - 1], e[j]
    return float(x[j - 1] + (x[j] - x[j - 1]) * ((level - a) / (b - a) if b != a else 1.0))


def operations(calc: TractionCalculator, points_m: np.ndarray, target_kmh: np.ndarray,
               follower: Follower | None = None) -> tuple[list[str], list[float], np.ndarray]:
    """Conditions and their start positions that follow the speed targets ``target_kmh`` at
    ``points_m`` (rising, from 0 m to the route's end), division by division (see the module
    docstring); the final condition is a bare B (NaN start). Also returns the follower's speeds at
    the points [km/h]."""
    fol = follower or Follower(calc)
    same = kinetic_e  # km/h -> e
    conds: list[str] = []
    starts: list[float] = []

    def add(c: str, x: float) -> None:
        if conds and conds[-1] == c:
            return
        if conds and x <= starts[-1] + 1e-6:  # the previous condition never ran: replace it
            conds.pop()
            starts.pop()
            if conds and conds[-1] == c:
                return
        conds.append(c)
        starts.append(float(x))

    e = 0.0
    reached = [0.0]
    n = len(points_m) - 1
    for j in range(n):
        xa, xb = float(points_m[j]), float(points_m[j + 1])
        e_b = same(float(target_kmh[j + 1]))
        tol = max(same(float(target_kmh[j + 1]) + SAME_KMH) - e_b, 1e-3)
        if j == n - 1:  # coast into the stop's braking curve
            add("C" if e > 0 else "T", xa)
            xs, es = fol.run("C" if e > 0 else "T", xa, xb, e)
            e = float(es[-1])
            reached.append(float(kmh_from_e(e)))
            break
        xc, ec = fol.run("C", xa, xb, e)
        if e <= 0.0:  # at rest: the train has to start
            e_b = max(e_b, 2.0 * tol)
        if e_b > e + tol:  # faster
            cond = "C" if ec[-1] >= e_b - tol else "T"
            xs, es = (xc, ec) if cond == "C" else fol.run("T", xa, xb, e)
            hit = _crossing(xs, es, e_b, rising=True)
            add(cond, xa)
            if hit is not None and hit < xb - 1.0:
                add("K", hit)
                xk, ek = fol.run("K", hit, xb, float(np.interp(hit, xs, es)))
                e = float(ek[-1])
            else:
                e = float(es[-1])
        elif e_b < e - tol and ec[-1] <= e_b + tol:  # slower, and coasting gets there
            # hold, then coast from where the coasting curve into v_b begins
            xr, er = fol.run_back("C", xb, xa, e_b)
            xk, ek = fol.run("K", xa, xb, e)
            start = _crossing(xr, er - np.interp(xr, xk, ek), 0.0, rising=False)
            if start is None or start <= xa + 1.0:
                add("C", xa)
                e = float(ec[-1])
            else:
                add("K", xa)
                add("C", start)
                xs, es = fol.run("C", start, xb, float(np.interp(start, xk, ek)))
                e = float(es[-1])
        elif e_b < e - tol or ec[-1] >= e - tol:
            # slower, but coasting alone does not get down to v_b: coasting is still the cheapest way
            # towards it; or about the same speed where coasting keeps or gains it (a descent). Either
            # way coast: a pattern is never followed by braking, nor by traction above it
            add("C", xa)
            e = float(ec[-1])
            hit = fol.reaches_limit(xc, ec) if calc.options.strict_limits else None
            if hit is not None and hit < xb - 1.0:  # --strict-limits: coasting must not run into a limit
                add("K", hit)
                xk, ek = fol.run("K", hit, xb, float(np.interp(hit, xc, ec)))
                e = float(ek[-1])
        else:  # about the same speed on a grade that slows a coasting train: hold it
            add("K", xa)
            xk, ek = fol.run("K", xa, xb, e)
            e = float(ek[-1])
        reached.append(float(kmh_from_e(max(e, 0.0))))
    if conds[-1] == "B":  # a braking run at the end becomes the final bare B
        conds.pop()
        starts.pop()
    conds.append("B")
    starts.append(float("nan"))
    return conds, starts, np.array(reached)


# ------------------------------------------------------------------------------------------ advice
@dataclass(frozen=True)
class Advice:
    line: LineModel
    mass_t: float
    time_s: float
    shares: np.ndarray  # upper layer, per section (sums to 1)
    pattern_kmh: np.ndarray  # lower layer, chained: (n_sections, p + 1)
    scale: float  # the factor on the pattern's speeds that meets the time
    target_kmh: np.ndarray  # the followed targets at the division points (scaled, within the limits)
    plan: Plan
    result: BatchResult  # the calculator's verdict, with the profile
    realised_shares: np.ndarray
    solve_time_s: float

    @property
    def points_m(self) -> np.ndarray:
        return _flat_points(self.line)

    def sections(self) -> list[dict]:
        out = []
        for i, sec in enumerate(self.line.sections):
            out.append({"index": i, "from_m": round(sec.from_m, 1), "to_m": round(sec.to_m, 1), "type": sec.kind,
                        "gradient_permille": round(sec.gradient_permille, 3), "share": round(float(self.shares[i]), 5),
                        "time_s": round(float(self.shares[i] * self.time_s), 1),
                        "realised_share": round(float(self.realised_shares[i]), 5),
                        "pattern_kmh": [round(float(v), 2) for v in self.pattern_kmh[i]]})
        return out


def _flat_points(line: LineModel) -> np.ndarray:
    """Every division point of the line once, rising (sections share their end points)."""
    return np.concatenate([line.points_m[0]] + [line.points_m[i][1:] for i in range(1, len(line.sections))])


def _flat_speeds(line: LineModel, speeds: np.ndarray) -> np.ndarray:
    return np.concatenate([speeds[0]] + [speeds[i][1:] for i in range(1, len(line.sections))])


def advise(patterns: Patterns, route: Route, train: Train, time_s: float, options: ModelOptions,
           calc: TractionCalculator | None = None) -> Advice:
    """Claim 1 steps 5-6 and claim 2 (see the module docstring). Raises ``InfeasibleError`` (exit 1)
    when ``time_s`` is below the fastest run, or when no scale of the pattern meets it."""
    t_start = time.perf_counter()
    line = line_model(route, train, options, patterns.settings)
    if calc is not None:
        line = LineModel(route, train, calc, line.sections, line.divisions, line.points_m, line.division_limit_kmh,
                         line.envelope_kmh)
    calc = line.calc
    if time_s < calc.fastest_time_s:
        raise InfeasibleError(f"planned running time {time_s:g} s is below the fastest possible run, "
                              f"{calc.fastest_time_s:.1f} s ({route.name}, {train.name})")
    shares = patterns.shares(line, train.mass_t, time_s)
    pattern = patterns.speeds(line, train.mass_t, time_s, shares)
    points = _flat_points(line)
    base = _flat_speeds(line, pattern)
    cap = np.concatenate([[0.0]] + [np.minimum(line.division_limit_kmh[i], line.envelope_kmh[i, 1:]) for i in range(len(line.sections))])
    follower = Follower(calc)

    def build(scale: float):
        target = np.minimum(base * scale, cap)
        target[0] = 0.0
        target[-1] = 0.0
        conds, starts, _ = operations(calc, points, target, follower)
        res = calc.evaluate(tuple(conds), np.array([starts[1:]], dtype=float))
        t = float(res.running_time_s[0]) if res.feasible[0] else math.inf
        return t, conds, starts, target

    # a coarse scan of the scale first (a build can be infeasible, e.g. --strict-limits), then
    # bisection between the two neighbouring feasible scales whose times bracket the asked time
    tol = (route.schedule.tolerance_s if route.schedule else 0.01 * time_s) * 0.25
    grid = np.arange(SCALE_RANGE[0], SCALE_RANGE[1] + 1e-9, 0.1)
    builds = [(float(x), *build(float(x))) for x in grid]
    ok = [b for b in builds if math.isfinite(b[1])]
    if not ok:
        raise InfeasibleError(f"advice: no scale of the learned pattern gives a feasible run on '{route.name}' "
                              f"({train.name}); e.g. {calc.evaluate(tuple(builds[0][2]), np.array([builds[0][3][1:]], dtype=float)).reason(0)}")
    best = min(ok, key=lambda b: abs(b[1] - time_s))
    pairs = [(a, b) for a, b in zip(ok, ok[1:]) if (a[1] - time_s) * (b[1] - time_s) <= 0]
    if pairs and abs(best[1] - time_s) > tol:
        (lo, t_lo, *_), (hi, t_hi, *_) = pairs[0]
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            cand = (mid, *build(mid))
            if math.isfinite(cand[1]) and abs(cand[1] - time_s) < abs(best[1] - time_s):
                best = cand
            if abs(best[1] - time_s) <= tol or hi - lo < 1e-4:
                break
            if not math.isfinite(cand[1]) or cand[1] > time_s:
                lo = mid  # too slow (or infeasible, treated as the slow side): faster
            else:
                hi = mid
    best = (best[0], best[2], best[3], best[4])
    scale, conds, starts, target = best
    plan = Plan(tuple(conds), tuple(starts))
    res = calc.evaluate(plan.conditions, plan.switches_m, profile=True)
    prof = res.profile
    t_nodes = prof.t_s[0]
    bounds = np.array([s.from_m for s in line.sections] + [line.sections[-1].to_m])
    t_b = np.interp(bounds, prof.s_m, t_nodes)
    realised = np.diff(t_b) / max(t_b[-1] - t_b[0], 1e-9)
    return Advice(line, train.mass_t, time_s, shares, pattern, scale, target, plan, res, realised,
                  time.perf_counter() - t_start)


def check_model(patterns: Patterns, options: ModelOptions, name: str) -> None:
    """A pattern learned with one train model is applied with the same model (the time reserve and
    the limits it reads depend on it)."""
    learned = patterns.model
    if not learned:
        return
    now = {"point_mass": options.point_mass, "air_brake": options.air_brake}
    diff = [k for k, v in now.items() if learned.get(k) is not None and learned.get(k) != v]
    if diff:
        raise InputError(Problem(name, "model", f"the pattern was learned with {', '.join(f'{k}={learned[k]}' for k in diff)}; "
                                 f"advise with the same train model (now {', '.join(f'{k}={now[k]}' for k in diff)})"))
