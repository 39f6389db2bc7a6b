"""From an optimal control to a plan a driver can follow, checked by the traction calculator.

The optimum's controls are read at its collocation points: full traction (``F`` on its speed-
dependent bound) is T, partial traction or partial braking (holding a speed: at a limit, or a cruise
speed on a grade) is K, no force is C, full braking is B (the MPOC paper's Fig. 7 shows such plans). Runs of
equal conditions become a condition sequence with switching points for the calculator
(``sim.calculator``): its T is full traction held at the limit, its K holds the speed at which it
starts, its braking curves brake for every limit drop and the stop by themselves (so braking runs in
mid-route become coasting into those curves, and the last B is the stop's). The last coasting point
is then moved so that the plan runs in the asked time (the MPOC paper's section 1.2 does the same for its
MPOC-C), and the plan is re-simulated: its time, energy, limits, stop and the neutral sections'
coasting margins are what gets reported, not the NLP's claim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.plan import Plan, runs_from_profile
from ..physics.energy import EnergyModel, profile_energy_kwh
from ..physics.units import kmh
from ..sim.calculator import TractionCalculator
from ..sim.result import BatchResult
from .radau import RadauSolution, control_activity

MIN_RUN_M = 15.0
"""Shorter runs are absorbed by their neighbours (a single collocation point between two arcs)."""
MIN_HOLD_M = 150.0
"""A K run shorter than this next to traction is the optimum passing between arcs, not a held speed."""
HOLD_ACCEL_MS2 = 5e-3
"""Partial force with |dv^2/2 / ds| at most this [m/s^2] holds the speed (K)."""
HOLD_KMH = 0.5
"""Holds either side of a short traction run within this of each other [km/h] are one hold."""
IDLE_SHARE = 0.01
"""A force below this share of its scale is no force (the NLP's round-off on a coasting arc)."""
TIME_TOL_S = 1.0  # [s]
EARLY_SHARE = 1e-3
"""A plan meets the asked time T when it arrives at most TIME_TOL_S late and at most
max(TIME_TOL_S, EARLY_SHARE x T) early (an early plan is on time, just not the least energy)."""
FIT_MOVE_M = 300.0
FIT_SPACING_M = 250.0
FIT_TIME_S = 1.0
FIT_SPEED_KMH = 1.0
FIT_ITERATIONS = 12
"""The fit of the switching points: how far each may move [m], how often the clock [s] and the speed
[km/h] are compared along the route [m] and with what weights, how many steps."""
SHOOT_SPAN_M = 150.0
"""How far a switch may move to reproduce the optimum's speed after it [m]."""
TUNE_SPAN_M = 600.0
"""How far the last coasting point may move to meet the time [m]."""


def condition_runs(sol: RadauSolution) -> list[tuple[str, float, float]]:
    """The optimum's conditions as runs ``(condition, from_m, to_m)`` over the route.

    At each collocation point: traction on its speed-dependent bound is T; partial traction or
    braking that holds the speed (``|dv^2/2 / ds| <= HOLD_ACCEL_MS2``) is K; partial traction that
    changes the speed is T (the shots of :func:`shoot_switches` then give it the optimum's effect);
    full braking is B; a force below ``IDLE_SHARE`` of its scale counts as none (C)."""
    grid = sol.grid
    n = grid.n_col
    model = sol.problem.model
    lower, upper = control_activity(sol)
    su = np.asarray(model.control_scale, dtype=float)
    idle = sol.U <= IDLE_SHARE * su[:, None]
    x = [sol.X[i, :n] for i in range(model.n_x)]
    u = [sol.U[i] for i in range(model.n_u)]
    accel = np.asarray(model.dynamics(x, u, grid.s_col, sol.params)[0], dtype=float) * np.ones(n)
    holding = np.abs(accel) <= HOLD_ACCEL_MS2
    split = model.n_u == 3  # (F, B_e, B_a)
    cond = []
    for k in range(n):
        f_on, f_full = not idle[0, k], upper[0, k]
        b_on = any(not idle[j, k] for j in range(1, model.n_u))
        b_full = all(upper[j, k] for j in range(1, model.n_u)) if split else upper[1, k]
        if f_full:
            c = "T"
        elif f_on:
            c = "K" if holding[k] else "T"
        elif b_full and b_on:
            c = "B"
        elif b_on:
            c = "K" if holding[k] else "C"
        else:
            c = "C"
        cond.append(c)
    # switches sit on interval boundaries where the mesh put a point there, else half-way
    last_of = set(grid.offsets[1:-1] - 1)
    runs: list[list] = [[cond[0], grid.s_points[0], None]]
    for k in range(1, n):
        if cond[k] == runs[-1][0]:
            continue
        at = grid.s_col[k] if (k - 1) in last_of else 0.5 * (grid.s_col[k - 1] + grid.s_col[k])
        runs[-1][2] = at
        runs.append([cond[k], at, None])
    runs[-1][2] = grid.s_points[-1]
    # a short K next to traction is the optimum passing from one arc to the next between two points;
    # a short T between two holds at the same speed is the hold adjusting to a change of gradient
    for i, r in enumerate(runs):
        if r[2] - r[1] >= MIN_HOLD_M or not 0 < i < len(runs) - 1:
            continue
        near = {runs[i - 1][0], runs[i + 1][0]}
        if r[0] == "K" and "T" in near:
            r[0] = "T"
        elif r[0] == "T" and near == {"K"}:
            ss = np.linspace(runs[i - 1][1], runs[i + 1][2], 33)
            v = kmh(np.sqrt(2.0 * np.maximum(sol.states_at(ss)[0], 0.0)))
            if np.ptp(v) <= HOLD_KMH:
                r[0] = "K"
    merged: list[list] = []
    for r in runs:
        if merged and (r[2] - r[1] < MIN_RUN_M or r[0] == merged[-1][0]):
            merged[-1][2] = r[2]
        else:
            merged.append(r)
    return [(c, float(a), float(b)) for c, a, b in merged]


def plan_from_runs(runs: list[tuple[str, float, float]]) -> Plan:
    """The calculator's plan: braking runs inside the route become coasting (the calculator's braking
    curves brake there), the last condition is the stop's bare B."""
    conds, starts = [], []
    for i, (c, a, _) in enumerate(runs):
        c = "C" if c == "B" else c
        if conds and conds[-1] == c:
            continue
        conds.append(c)
        starts.append(0.0 if i == 0 else a)
    conds.append("B")
    starts.append(float("nan"))
    return Plan(tuple(conds), tuple(starts))


def shoot_switches(calc: TractionCalculator, plan: Plan, sol: RadauSolution, span_m: float = SHOOT_SPAN_M,
                   count: int = 41) -> Plan:
    """Place each switch into or out of traction, and into a cruise, so that the calculator's speed in
    the middle of the run that follows equals the optimum's there (one batch of calculator runs per
    switch, in order). The optimum's switches are between collocation points and its force may ramp
    over a few metres; matching the speed that results is what makes the plan run like the optimum
    (the calculator's K holds the speed at which it starts)."""
    starts = list(plan.starts_m)
    conds = plan.conditions
    length = calc.route.length_m
    for j in range(1, len(conds) - 1):
        if not (conds[j - 1] == "T" or conds[j] in ("T", "K")):
            continue
        nxt = starts[j + 1] if j + 1 < len(starts) and not math.isnan(starts[j + 1]) else length
        if j + 1 >= len(conds) - 1:  # the last coasting point is tuned for the running time instead
            continue
        x0, lo = starts[j], starts[j - 1]
        cand = np.linspace(max(lo + 1.0, x0 - span_m), min(nxt - 1.0, x0 + span_m), count)
        if cand[-1] <= cand[0]:
            continue
        q = 0.5 * (x0 + nxt)
        target = float(kmh(np.sqrt(2.0 * max(float(sol.states_at([q])[0, 0]), 0.0))))
        sw = np.repeat(np.array([starts[1:]]), cand.size, axis=0)
        sw[:, j - 1] = cand
        res = calc.evaluate(conds, sw, profile=True, couplers=False)
        v_q = np.array([np.interp(q, res.profile.s_m, res.profile.v_kmh[i]) for i in range(cand.size)])
        ok = res.feasible & np.isfinite(v_q)
        if not ok.any():
            continue
        c, v = cand[ok], v_q[ok]
        best = c[int(np.argmin(np.abs(v - target)))]
        d = v - target
        hit = np.nonzero(d[:-1] * d[1:] <= 0)[0]
        if hit.size:  # interpolate between the candidates that bracket the target, nearest to x0
            a = int(hit[np.argmin(np.abs(c[hit] - x0))])
            if d[a] != d[a + 1]:
                best = c[a] + (c[a + 1] - c[a]) * d[a] / (d[a] - d[a + 1])
        starts[j] = float(best)
    return Plan(conds, tuple(starts))


def tune_last_coast(calc: TractionCalculator, plan: Plan, time_s: float, span_m: float = TUNE_SPAN_M,
                    index: int | None = None) -> tuple[Plan, float]:
    """Move the last coasting point (or the one at ``index``) so that the plan runs in ``time_s`` (one
    batch of calculator runs and an interpolation). Returns the plan and the shift [m] (0 if there is
    nothing to move)."""
    idx = [i for i, c in enumerate(plan.conditions) if c == "C" and i > 0]
    if not idx:
        return plan, 0.0
    j = idx[-1] if index is None else index
    starts = np.array(plan.starts_m, dtype=float)
    lo = starts[j - 1] + 1.0
    hi = calc.route.length_m - 1.0
    if j + 1 < len(starts) and not math.isnan(starts[j + 1]):
        hi = starts[j + 1] - 1.0
    x0 = starts[j]
    cand = np.unique(np.clip(x0 + np.linspace(-span_m, span_m, 121), lo, hi))
    sw = np.repeat(starts[None, 1:], cand.size, axis=0)
    sw[:, j - 1] = cand
    res = calc.evaluate(plan.conditions, sw)
    t = np.where(res.feasible, res.running_time_s, np.nan)
    ok = np.isfinite(t)
    if not ok.any():
        return plan, 0.0
    x_ok, t_ok = cand[ok], t[ok]
    # later coasting runs faster: find where the time crosses the target (else the nearest)
    order = np.argsort(x_ok)
    x_ok, t_ok = x_ok[order], t_ok[order]
    best = x_ok[int(np.argmin(np.abs(t_ok - time_s)))]
    for a in range(len(x_ok) - 1):
        if (t_ok[a] - time_s) * (t_ok[a + 1] - time_s) <= 0 and t_ok[a] != t_ok[a + 1]:
            w = (t_ok[a] - time_s) / (t_ok[a] - t_ok[a + 1])
            best = x_ok[a] + w * (x_ok[a + 1] - x_ok[a])
            if abs(_time_at(calc, plan, j, best) - time_s) > TIME_TOL_S / 2:
                # the time is not linear across the bracket (a braking curve, an air-brake cycle): look inside it
                inner = np.linspace(x_ok[a], x_ok[a + 1], 41)
                sw = np.repeat(starts[None, 1:], inner.size, axis=0)
                sw[:, j - 1] = inner
                r2 = calc.evaluate(plan.conditions, sw)
                t2 = np.where(r2.feasible, r2.running_time_s, np.nan)
                if np.isfinite(t2).any():
                    best = float(inner[int(np.nanargmin(np.abs(t2 - time_s)))])
            break
    new = list(plan.starts_m)
    new[j] = float(best)
    return Plan(plan.conditions, tuple(new)), float(best - x0)


def _time_at(calc: TractionCalculator, plan: Plan, j: int, x: float) -> float:
    """The running time [s] of ``plan`` with its ``j``-th condition starting at ``x`` (inf if it fails)."""
    sw = np.array(plan.starts_m[1:], dtype=float)[None, :]
    sw[0, j - 1] = x
    res = calc.evaluate(plan.conditions, sw)
    return float(res.running_time_s[0]) if res.feasible[0] else math.inf


def fit_switches(calc: TractionCalculator, plan: Plan, sol: RadauSolution, max_move_m: float = FIT_MOVE_M,
                 spacing_m: float = FIT_SPACING_M) -> Plan:
    """Least-squares fit of the plan's switching points to the optimum's clock and speed along the
    route (every ``spacing_m``): the calculator's run should pass each point when and as fast as the
    optimum does. Jacobians by one batch of shifted plans per step (the calculator runs plans in
    batches); each point moves at most ``max_move_m`` and never past its neighbours. The final bare B
    is the stop's braking curve and has no point to fit."""
    from scipy.optimize import least_squares

    starts = np.array(plan.starts_m, dtype=float)
    free = np.nonzero(np.isfinite(starts) & (np.arange(starts.size) > 0))[0]
    if not free.size:
        return plan
    length = calc.route.length_m
    q = np.arange(spacing_m, length - spacing_m / 2, spacing_m)
    xo = sol.states_at(q)
    t_ref = xo[1]
    v_ref = kmh(np.sqrt(2.0 * np.maximum(xo[0], 0.0)))
    x0 = starts[free]
    ext = np.concatenate([[0.0], x0, [length]])
    lo = np.maximum(x0 - max_move_m, 0.5 * (ext[:-2] + ext[1:-1]) + 0.5)
    hi = np.minimum(x0 + max_move_m, 0.5 * (ext[1:-1] + ext[2:]) - 0.5)
    lo, hi = np.minimum(lo, x0 - 1e-3), np.maximum(hi, x0 + 1e-3)

    def run(X):
        sw = np.repeat(starts[None, 1:], X.shape[0], axis=0)
        sw[:, free - 1] = X
        res = calc.evaluate(plan.conditions, sw, profile=True, couplers=False)
        prof = res.profile
        t = np.array([np.interp(q, prof.s_m, prof.t_s[i]) for i in range(X.shape[0])])
        v = np.array([np.interp(q, prof.s_m, prof.v_kmh[i]) for i in range(X.shape[0])])
        bad = ~res.feasible | ~np.isfinite(t).all(axis=1)
        r = np.hstack([(t - t_ref) / FIT_TIME_S, (v - v_ref) / FIT_SPEED_KMH])
        r[bad] = 1e3
        return r

    step = 1.0

    def fun(x):
        return run(x[None, :])[0]

    def jac(x):
        X = np.vstack([x] + [x + step * np.eye(x.size)[i] for i in range(x.size)])
        R = run(X)
        return ((R[1:] - R[0]) / step).T

    try:
        out = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", max_nfev=FIT_ITERATIONS, x_scale=10.0)
    except ValueError:
        return plan
    if not out.cost < 0.5 * float(np.sum(fun(x0) ** 2)):
        return plan
    new = starts.copy()
    new[free] = out.x
    return Plan(plan.conditions, tuple(float(v) for v in new))


def tune_coasting_point(calc: TractionCalculator, plan: Plan, time_s: float, tol_s: float = TIME_TOL_S / 2,
                        least_energy: bool = False) -> tuple[Plan, float]:
    """The MPOC paper's 'move the last coasting point so that T is still met', made sure to work: the last
    coasting point first, over its whole run; if the time cannot be met there, the one before it, and
    so on. With ``least_energy`` every coasting point is tried and, of the plans that meet the time, the
    one of least energy kept (on a descent where the air brake cycles, moving the last coasting point
    changes the cycles more than the time; the time is cheaper bought elsewhere). Returns the plan and
    the shift [m] of the point moved."""
    idx = [i for i, c in enumerate(plan.conditions) if c == "C" and i > 0]
    best = (plan, 0.0)
    on_time: list[tuple[float, Plan, float]] = []
    for j in reversed(idx):
        starts = np.array(plan.starts_m, dtype=float)
        nxt = starts[j + 1] if j + 1 < len(starts) and not math.isnan(starts[j + 1]) else calc.route.length_m
        span = max(nxt - starts[j], starts[j] - starts[j - 1])
        cand, shift = tune_last_coast(calc, plan, time_s, span_m=span, index=j)
        res = calc.evaluate(cand.conditions, cand.switches_m)
        if res.feasible[0] and abs(float(res.running_time_s[0]) - time_s) <= tol_s:
            if not least_energy:
                return cand, shift
            on_time.append((float(res.traction_energy_kwh[0]), cand, shift))
        if j == idx[-1]:
            best = (cand, shift)
    if on_time:
        _, cand, shift = min(on_time, key=lambda c: c[0])
        return cand, shift
    return best


@dataclass(frozen=True)
class PlanCheck:
    """A plan re-simulated by the calculator: its result (with profile), running time [s], energy
    [kWh] (``energy_model`` applied to the profile), how far it is above the limits [km/h], the
    coasting margins around each neutral section [s] and every reason it does not count."""

    plan: Plan
    result: BatchResult
    running_time_s: float
    energy_kwh: float
    wheel_energy_kwh: float
    max_overspeed_kmh: float
    neutral_margins_s: list[list[float]]
    reasons: list[str]

    @property
    def confirmed(self) -> bool:
        return not self.reasons


def neutral_margins_s(calc: TractionCalculator, profile, spans) -> list[list[float]]:
    """For each neutral section: seconds from the traction cut to the head entering, and from the tail
    leaving to traction again, on the re-simulated run (``neutral_spans_m`` turns the margins into
    distances at the line speed; a slower train takes longer, so these are at least the margins)."""
    route = calc.route
    L = calc.train.length_m if calc.options.strip else 0.0
    s, t = profile.s_m, profile.t_s[0]
    out = []
    for ns, (a, b) in zip(route.neutral_sections, spans):
        t_cut, t_in = np.interp([a, ns.from_m], s, t)
        t_out, t_back = np.interp([min(ns.to_m + L, route.length_m), b], s, t)
        out.append([round(float(t_in - t_cut), 2), round(float(t_back - t_out), 2)])
    return out


def check_plan(calc: TractionCalculator, plan: Plan, time_s: float, energy: EnergyModel,
               spans=(), time_tol_s: float = TIME_TOL_S) -> PlanCheck:
    """Re-simulate ``plan`` and judge it: feasible (limits held, stops at the end), within
    ``time_tol_s`` of ``time_s``, coasting margins of the neutral sections kept."""
    res = calc.evaluate(plan.conditions, plan.switches_m, profile=True)
    prof = res.profile
    t = float(res.running_time_s[0])
    wheel = float(res.traction_energy_kwh[0])
    e = wheel if energy.is_wheel_work else profile_energy_kwh(
        prof.s_m, prof.v_kmh[0], prof.traction_kn[0], prof.brake_kn[0],
        (calc.train.electric_brake_speed_kmh, calc.train.electric_brake_kn), energy)
    over = float(np.max(np.maximum(prof.v_kmh[0][:-1] - prof.limit_kmh, prof.v_kmh[0][1:] - prof.limit_kmh)))
    reasons = []
    if not res.feasible[0]:
        reasons.append(f"the plan fails in the traction calculator: {res.reason(0)}")
    elif t > time_s + time_tol_s or t < time_s - max(time_tol_s, EARLY_SHARE * time_s):
        reasons.append(f"the plan runs {t:.1f} s, not the asked {time_s:g} s (tolerance +{time_tol_s:g} / "
                       f"-{max(time_tol_s, EARLY_SHARE * time_s):.1f} s)")
    margins = []
    if spans and res.feasible[0]:
        margins = neutral_margins_s(calc, prof, spans)
        for ns, (before, after) in zip(calc.route.neutral_sections, margins):
            if before < ns.coast_before_s - 1e-6 or after < ns.coast_after_s - 1e-6:
                reasons.append(f"neutral section {ns.from_m:g}-{ns.to_m:g} m: coasting {before:.1f} s before / "
                               f"{after:.1f} s after, less than the {ns.coast_before_s:g} / {ns.coast_after_s:g} s asked")
    return PlanCheck(plan, res, t, e, wheel, max(0.0, over), margins, reasons)


def sequence_runs(check: PlanCheck) -> list[dict]:
    """The re-simulated plan's applied conditions as SPEC ``sequence`` runs."""
    prof = check.result.profile
    return runs_from_profile(prof.s_m, prof.condition[0], 1.0, prof.event_m[0])
