"""The MPOC paper's comparisons (its Tables 3-5) as strategies of ``compare``: mpoc, mpoc-n, mpoc-c, sfs
(their entries and traits: ``strategy/registry.py``).

- ``mpoc``: the multi-phase minimum-energy optimum with the neutral sections inside the model
  (``locoplan.ocp.mpoc``), as a drivable plan;
- ``mpoc-n``: the same with the neutral sections ignored: a lower bound the train cannot drive (its
  plan is run on the route without its neutral sections);
- ``mpoc-c``: ``mpoc-n`` made drivable (the MPOC paper's Fig. 2): coast through each neutral section's span,
  re-accelerate after it to the speed the plan held, and move the last coasting point so that the
  planned time is still met;
- ``sfs``: the standard four-stage method with neutral-section coasting (the MPOC paper's section 3): full
  traction to the allowed speed and held there (the calculator's T coasts through every neutral
  span and re-accelerates after it), coast, brake; the coasting point found by brute force at 1 m
  steps, the earliest one that keeps the planned time.

CasADi is imported only when an optimal-control strategy runs.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..errors import InfeasibleError
from ..model.plan import Plan
from ..sim.calculator import TractionCalculator, neutral_spans_m
from .strategies import StrategyContext, StrategyOutcome

SFS_STEP_M = 1.0
"""The MPOC paper's brute-force step for the SFS coasting point [m]."""
SFS_COARSE_M = 100.0


def _mpoc_run(ctx: StrategyContext, ignore_neutral: bool):
    from ..ocp.mpoc import run_mpoc, without_neutral  # CasADi: imported when an optimum is asked for
    from ..ocp.train_energy import EnergyOptions

    calc = ctx.calc
    run_calc = None
    if ignore_neutral:
        run_calc = TractionCalculator(without_neutral(calc.route), calc.train, calc.options)
    return run_mpoc(calc.route, calc.train, calc.options, ctx.t0_s, energy=EnergyOptions(ignore_neutral=ignore_neutral),
                    calc=run_calc or calc, strategy="mpoc-n" if ignore_neutral else "mpoc")


def _outcome(run, t0: float, calc=None) -> StrategyOutcome:
    if not run.feasible:
        raise InfeasibleError(f"{run.summary['strategy']}: the optimum is not confirmed by the traction calculator: "
                              f"{run.summary['reason']}")
    return StrategyOutcome(run.check.plan, algorithm="radau", solve_time_s=time.perf_counter() - t0, calc=calc)


def mpoc(ctx: StrategyContext) -> StrategyOutcome:
    """The MPOC paper's MPOC: the least-energy run with the neutral sections in the model."""
    t0 = time.perf_counter()
    return _outcome(_mpoc_run(ctx, ignore_neutral=False), t0)


def mpoc_n(ctx: StrategyContext) -> StrategyOutcome:
    """The MPOC paper's MPOC-N: neutral sections ignored; run on the route without them (not drivable)."""
    t0 = time.perf_counter()
    run = _mpoc_run(ctx, ignore_neutral=True)
    return _outcome(run, t0, calc=run.calc)


def _condition_at(plan: Plan, x: float) -> int:
    """Index of the condition of ``plan`` running at position ``x`` (a final bare B never runs here)."""
    starts = [v if not math.isnan(v) else math.inf for v in plan.starts_m]
    return int(np.searchsorted(starts, x, side="right") - 1)


def coast_through_neutral(calc, plan: Plan, spans, route_calc=None) -> Plan:
    """``plan`` with every neutral span coasted and, after it, the plan's own condition again; where
    that is a cruise (K holds the speed at which it starts), traction first until the speed the plan
    held there, then the cruise (the MPOC paper's Fig. 2). ``route_calc`` ran ``plan`` (the route without its
    neutral sections) and gives the speeds to get back to."""
    ref = (route_calc or calc).evaluate(plan.conditions, plan.switches_m, profile=True).profile
    entries = list(zip(plan.conditions, plan.starts_m))
    for a, b in spans:
        cur = Plan(tuple(c for c, _ in entries), tuple(x for _, x in entries))
        after = cur.conditions[_condition_at(cur, b)]
        before = [(c, x) for c, x in entries if not math.isnan(x) and x < a]
        later = [(c, x) for c, x in entries if math.isnan(x) or x > b]
        new = before + [("C", a)]
        if after == "K":
            hold = float(np.interp(b, ref.s_m, ref.v_kmh[0]))
            trial = new + [("T", b)] + later
            tp = Plan(tuple(c for c, _ in trial), tuple(x for _, x in trial))
            prof = calc.evaluate(tp.conditions, tp.switches_m, profile=True).profile
            nxt = next((x for _, x in later if not math.isnan(x)), calc.route.length_m)
            sel = (prof.s_m > b) & (prof.s_m < nxt)
            reach = np.nonzero(prof.v_kmh[0][sel] >= hold)[0]
            new += [("T", b)] + ([("K", float(prof.s_m[sel][reach[0]]))] if reach.size else [])
        elif after != "C":
            new.append((after, b))
        entries = new + later
    out: list[tuple[str, float]] = []
    for c, x in entries:  # merge repeats; the first condition starts at 0
        if out and c == out[-1][0]:
            continue
        out.append((c, x))
    out[0] = (out[0][0], 0.0)
    return Plan(tuple(c for c, _ in out), tuple(x for _, x in out))


def mpoc_c(ctx: StrategyContext) -> StrategyOutcome:
    """The MPOC paper's MPOC-C: the MPOC-N plan with coasting through every neutral span, re-acceleration
    after it, and the last coasting point moved so that the planned time is met."""
    from ..ocp.to_plan import tune_coasting_point

    t0 = time.perf_counter()
    calc = ctx.calc
    run = _mpoc_run(ctx, ignore_neutral=True)
    if not run.feasible:
        raise InfeasibleError(f"mpoc-c: the MPOC-N optimum it starts from is not confirmed: {run.summary['reason']}")
    spans = neutral_spans_m(calc.route, calc.train.length_m if calc.options.strip else 0.0)
    plan = coast_through_neutral(calc, run.check.plan, spans, route_calc=run.calc)
    plan, _ = tune_coasting_point(calc, plan, ctx.t0_s)
    return StrategyOutcome(plan, algorithm="radau", solve_time_s=time.perf_counter() - t0)


def sfs(ctx: StrategyContext) -> StrategyOutcome:
    """Standard four-stage with neutral-section coasting: T (held at the allowed speed, coasting through
    the neutral spans), C from the coasting point, B; the coasting point by brute force at 1 m."""
    t0 = time.perf_counter()
    calc = ctx.calc
    L = calc.route.length_m
    conds = ("T", "C", "B")

    def times(xs):
        res = calc.evaluate(conds, np.column_stack([xs, np.full_like(xs, np.nan)]))
        return np.where(res.feasible, res.running_time_s, np.nan), res

    coarse = np.arange(SFS_COARSE_M, L, SFS_COARSE_M)
    t_c, _ = times(coarse)
    ok = np.isfinite(t_c) & (t_c <= ctx.t0_s)
    if not ok.any():
        raise InfeasibleError(f"sfs: no coasting point keeps the planned {ctx.t0_s:g} s "
                              f"(fastest with coasting at {coarse[-1]:.0f} m: {np.nanmin(t_c):.1f} s)")
    first = int(np.argmax(ok))  # the earliest coasting point on time (coasting later only runs faster)
    lo = coarse[first - 1] if first > 0 else 0.0
    fine = np.arange(lo + SFS_STEP_M, coarse[first] + SFS_STEP_M / 2, SFS_STEP_M)
    t_f, _ = times(fine)
    on_time = np.isfinite(t_f) & (t_f <= ctx.t0_s)
    x = float(fine[int(np.argmax(on_time))]) if on_time.any() else float(coarse[first])
    return StrategyOutcome(Plan(conds, (0.0, x, float("nan"))), algorithm="brute force (1 m)",
                           n_evaluations=coarse.size + fine.size, solve_time_s=time.perf_counter() - t0,
                           time_range_s=(float(np.nanmin(t_c)), float(np.nanmax(t_c))))
