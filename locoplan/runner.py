"""Library entry points behind the commands: simulate, optimize, compare, sweep, study.

Each returns typed results and SPEC summary dicts; nothing here prints or exits.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from . import bounds
from .errors import InfeasibleError, InputError, Problem
from .model.plan import Plan, parse_sequence, runs_from_profile
from .model.route import Route
from .io.optimizer_params import read_optimizer_params
from .model.train import Train
from .optimize import registry as optimizer_registry
from .optimize.problem import fitness_eq10
from .physics.units import KMH_PER_MS, S_PER_H
from .sim.calculator import ModelOptions, TractionCalculator
from .settings import RunSettings
from .sim.result import BatchResult
from .strategy import registry
from .strategy.sequence import build_sequence
from .strategy.strategies import evaluate_outcome, StrategyContext, StrategyOutcome

SEARCH_STEP_M = 100.0
"""Grid the optimisers search on [m]: within 0.05 % of the 50 m reporting grid in time and energy on
freight-20km (README), at half the cost. Every reported number is re-simulated on the reporting grid."""


@dataclass(frozen=True)
class RunResult:
    name: str
    outcome: StrategyOutcome
    result: BatchResult  # on the reporting grid, with the profile
    summary: dict


SEARCH_MIN_CELLS = 200
DEFAULT_TOLERANCE_SHARE = 0.01
"""Punctuality window when neither --tolerance nor the route's schedule gives one: +- 1 % of T0."""


def planned_time(route: Route, time_s: float | None) -> float:
    if time_s is not None:
        return bounds.planned_time(time_s, "time_s")
    if route.schedule is None:
        raise InputError(Problem("", "time_s", f"route '{route.name}' has no schedule: give the planned running time as "
                                 f"{bounds.TIME_FORMS}"))
    return float(route.schedule.run_time_s)


def make_context(route: Route, train: Train, settings: RunSettings | None = None, *,
                 callback: Callable[[int, float], None] | None = None,
                 calculators: tuple[TractionCalculator, TractionCalculator] | None = None) -> StrategyContext:
    """Calculators (reporting grid and search grid) and the optimisation settings (:class:`RunSettings`,
    default all defaults).

    The punctuality window is T0 +- ``tolerance_s`` (default: the route's schedule tolerance); with
    ``window=False`` the optimiser ranks by eq. 10 alone, as the ISSA paper's own tables evidently did.
    ``calculators``: (reporting, search) calculators of an earlier context of the same route, train and
    options, to reuse (a batch's runs share them). ``callback(iteration, best)`` follows the search.
    Errors name the setting (``time_s``, ``e_min_kwh``...)."""
    s = settings if settings is not None else RunSettings()
    options, time_s, e_min_kwh, tolerance_s = s.options, s.time_s, s.e_min_kwh, s.tolerance_s
    objective, seed, builder, params = s.objective, s.seed, s.builder, s.params
    bounds.objective(objective, "objective")
    bounds.seed(seed, "seed")
    if e_min_kwh is not None:
        bounds.finite(e_min_kwh, "e_min_kwh", *bounds.LIMITS["e_min_kwh"], "kWh", "the least traction energy whatever the time")
    if tolerance_s is not None:
        bounds.finite(tolerance_s, "tolerance_s", 0.0, bounds.LIMITS["time_s"][1], "s", "the punctuality window +-")
    if calculators is not None:
        calc, search = calculators
    else:
        calc = TractionCalculator(route, train, options)
        # the optimisers search a coarser grid, but not one too coarse for a short line (at least ~200 cells)
        search_step = max(options.step_m, min(SEARCH_STEP_M, route.length_m / SEARCH_MIN_CELLS))
        search = calc if search_step <= options.step_m else TractionCalculator(route, train, replace(options, step_m=search_step))
        if search is not calc and not _drives(search) and _drives(calc):
            # a climb the train barely makes (a few km/h at the top) can stall on the coarser grid alone:
            # then the search grid would refuse every plan the reporting grid accepts, so search on that
            search = calc
    t0 = planned_time(route, time_s) if s.need_time or time_s is not None or route.schedule else float("nan")
    if e_min_kwh is not None and not (math.isfinite(e_min_kwh) and e_min_kwh > 0):
        raise InputError(Problem("", "e_min_kwh", f"must be a finite number > 0 kWh (got {e_min_kwh:g})"))
    if tolerance_s is not None and not (math.isfinite(tolerance_s) and tolerance_s >= 0):
        raise InputError(Problem("", "tolerance_s", f"must be a finite number >= 0 s (got {tolerance_s:g})"))
    tol = None
    if not math.isnan(t0):
        tol = tolerance_s if tolerance_s is not None else (
            route.schedule.tolerance_s if route.schedule else max(1.0, DEFAULT_TOLERANCE_SHARE * t0))
        if tolerance_s is not None and tol >= t0:  # as a route file's schedule.tolerance_s is refused (model/route.py)
            raise InputError(Problem("", "tolerance_s", f"a punctuality window of +-{tol:g} s is not below the planned "
                                     f"running time {t0:g} s: the window would open at or before departure"))
    if builder is None:  # the model (--point-mass) does not choose the method: the ISSA paper's is asked for by name
        builder = "general"
    registry.check_builder(builder)
    builder = registry.builder_name(builder)
    if params is None and s.params_path is not None:
        params = load_optimizer_params(s.algorithm, s.params_path)
    return StrategyContext(calc, search, t0, e_min_kwh, tuple(s.weights), s.algorithm, seed, params, callback,
                           tol, s.window, s.yardstick, builder, objective)



def load_optimizer_params(name: str, path: str | Path | None = None):
    """The parameters of optimiser ``name`` from ``path`` (default: its shipped file), validated with the
    algorithm's ``Params`` model: an unknown algorithm or a bad file raises ``InputError``."""
    return read_optimizer_params(path, name, optimizer_registry.get_algorithm(name).Params)


def _drives(calc: TractionCalculator) -> bool:
    """Whether the fastest run (full traction, held at the limits) reaches the stop on this grid."""
    return bool(calc.evaluate(("T",), np.zeros((1, 0))).feasible[0])


def check_time_possible(ctx: StrategyContext) -> None:
    """A planned time below the fastest run cannot be met by any plan (SPEC: exit 1, say the fastest); nor any
    time where the fastest run itself is refused (the air brake's cycle cannot keep its rules on a descent, say):
    no plan keeps them either, so a time it would scale (``--time 1.1x``) is no time of a drivable run."""
    res = ctx.calc.evaluate(("T",), np.zeros((1, 0)))
    if not res.feasible[0]:
        raise InfeasibleError(f"no run of '{ctx.calc.route.name}' with '{ctx.calc.train.name}' keeps the model's rules: "
                              f"the fastest run {res.reason(0)}")
    fastest = ctx.calc.fastest_time_s
    if not math.isnan(ctx.t0_s) and ctx.t0_s < fastest:
        raise InfeasibleError(f"planned running time {ctx.t0_s:g} s is below the fastest possible run, "
                              f"{fastest:.1f} s{_hours(fastest)} ({ctx.calc.route.name}, {ctx.calc.train.name}): "
                              f"{slowest_limit(ctx.calc)}")


def _hours(seconds: float) -> str:
    return f" = {seconds / S_PER_H:.2f} h" if seconds >= S_PER_H else (f" = {seconds / 60:.1f} min" if seconds >= 120 else "")


def slowest_limit(calc: TractionCalculator) -> str:
    """The speed-limit section that takes longest at its limit (or the train's top speed): a lower bound
    on any run's time that says why the fastest run takes as long as it does."""
    top = calc.train.max_speed_kmh

    def at_limit_s(sec) -> float:
        return (sec.to_m - sec.from_m) / (min(sec.kmh, top) / KMH_PER_MS)

    total = sum(at_limit_s(s) for s in calc.route.speed_limits)
    sec = max(calc.route.speed_limits, key=at_limit_s)
    t = at_limit_s(sec)
    cap = f"the train's top speed {top:g} km/h" if top < sec.kmh else f"the limit of {sec.kmh:g} km/h"
    return (f"at the limit all the way it would take {total:,.1f} s{_hours(total)} (longest part: {cap} over "
            f"{sec.from_m:,.0f} .. {sec.to_m:,.0f} m needs {t:,.1f} s{_hours(t)}); starting, stopping and grades take the rest")


def _evaluate(ctx: StrategyContext, outcome: StrategyOutcome) -> BatchResult:
    return evaluate_outcome(ctx.calc, outcome, profile=True)


def gap_to_optimum(ctx: StrategyContext, res: BatchResult):
    """The plan against E*, the least energy at its own running time (the MPOC paper): ``ocp.bound.Gap`` or None."""
    if not ctx.yardstick or not res.feasible[0]:
        return None
    from .ocp.bound import gap_to_optimum as gap

    if ctx.objective != "traction" and res.recovered_energy_kwh is None:
        return None
    c = ctx.calc
    return gap(c.route, c.train, c.options, float(res.running_time_s[0]), float(res.energy_kwh(ctx.objective)[0]), calc=c,
               objective=ctx.objective)


def summarize(ctx: StrategyContext, name: str, outcome: StrategyOutcome, res: BatchResult,
              with_fitness: bool = True) -> dict:
    """The SPEC's JSON object for one result."""
    route, train = ctx.calc.route, ctx.calc.train
    t = float(res.running_time_s[0])
    e = float(res.traction_energy_kwh[0])
    # what the objective counts (a measured result without the recovered energy has no net energy)
    e_obj = (e if ctx.objective == "traction" else math.nan if res.recovered_energy_kwh is None
             else float(res.energy_kwh(ctx.objective)[0]))
    t0 = ctx.t0_s
    prof = res.profile
    e_min = next((e for e in (outcome.e_min_kwh, ctx.e_min_known) if e is not None), None)
    fit = None
    if with_fitness and e_min is not None and res.feasible[0] and not math.isnan(t0) and not math.isnan(e_obj):
        fit = round(float(fitness_eq10(t, e_obj, t0, e_min, *ctx.weights)), 5)
    tol = ctx.tolerance_s
    gap = gap_to_optimum(ctx, res)
    return {
        "route": route.name,
        "consist": train.name,
        "strategy": name,
        "algorithm": outcome.algorithm,
        "seed": ctx.seed if outcome.algorithm else None,
        "feasible": bool(res.feasible[0]),
        "reason": res.reason(0),
        "running_time_s": round(t, 2),
        "traction_energy_kwh": round(e, 2),
        **recovered_energy(train, res),
        "objective": ctx.objective,
        "planned_time_s": None if math.isnan(t0) else t0,
        "punctuality_error_s": None if (math.isnan(t0) or math.isnan(t)) else round(abs(t - t0), 2),
        "punctual": None if (math.isnan(t0) or tol is None or math.isnan(t)) else bool(abs(t - t0) <= tol + 1e-9),
        "window_s": None if (math.isnan(t0) or tol is None) else [round(t0 - tol, 2), round(t0 + tol, 2)],
        "fitness": fit,
        "gap_to_optimum_percent": None if gap is None else gap.gap_percent,
        "gap_to_optimum_kwh": None if gap is None else gap.gap_kwh,
        "optimum_kwh": None if gap is None else gap.optimum_kwh,
        "optimum_accuracy_percent": None if gap is None else gap.accuracy_percent,
        **cycle_gap(ctx, res),
        "weights": list(ctx.weights) if fit is not None else None,
        "e_min_kwh": None if e_min is None else round(float(e_min), 2),
        "e_min_source": None if e_min is None else ctx.e_min_source,
        "e_min_time_s": None if e_min is None or ctx.e_min_time_s is None else round(ctx.e_min_time_s, 2),
        "cruise_kmh": outcome.cruise_kmh,
        "solve_time_s": round(outcome.solve_time_s, 3),
        "n_evaluations": outcome.n_evaluations,
        "plan": outcome.plan.text(),
        "switching_points_m": [round(x, 1) for x in outcome.plan.starts_m[1:] if not math.isnan(x)],
        "sequence": runs_from_profile(prof.s_m, prof.condition[0], 1.0, None if prof.event_m is None else prof.event_m[0]),
        **coupler_summary(train, prof),
        **air_brake_summary(res),
        "release_margins": [{"from_m": round(a, 1), "to_m": round(b, 1), "margin": round(m, 3)}
                            for a, b, m in outcome.plan.release_margins] or None,
        **(outcome.extra or {}),
    }


def cycle_gap(ctx: StrategyContext, res: BatchResult) -> dict:
    """The plan against the optimum with the air brake's cycle at its own running time (``strategy.cycle_start``:
    the least traction energy of a drive that keeps the cycle, with its accuracy): ``optimum_with_cycle_kwh``,
    ``optimum_with_cycle_accuracy_percent`` and ``gap_to_cycle_optimum_percent``, all None where the model has no
    cycle, the cycle cannot bind on the line (then it is E* itself), the objective is not the traction energy, or
    there is no such drive at that time. E* <= it: the plan's gap to E* splits into what the cycle costs and what
    a better plan could save."""
    none = {"optimum_with_cycle_kwh": None, "optimum_with_cycle_accuracy_percent": None,
            "gap_to_cycle_optimum_percent": None}
    c = ctx.calc
    if not ctx.yardstick or not res.feasible[0] or ctx.objective != "traction" or c.air_cycle is None:
        return none
    from .errors import LocoplanError
    from .strategy.cycle_start import cycle_optimum

    t, e = float(res.running_time_s[0]), float(res.traction_energy_kwh[0])
    try:
        co = cycle_optimum(c.route, c.train, c.options, t, calc=c)
    except LocoplanError:
        return none
    if not co.cycles or co.energy_kwh is None:
        return none
    from .ocp.bound import percent_floor_kwh

    acc = co.accuracy_percent
    # a percentage only where the optimum is not a few kWh (a line nearly coasted), as for E*'s gap
    pct = (round(100.0 * (e - co.energy_kwh) / co.energy_kwh, 2) if co.energy_kwh >= percent_floor_kwh(c.route, c.train)
           else None)
    return {"optimum_with_cycle_kwh": round(co.energy_kwh, 2),
            "optimum_with_cycle_accuracy_percent": None if acc is None else float(f"{acc:.2g}"),
            "gap_to_cycle_optimum_percent": pct}


def air_brake_summary(res: BatchResult) -> dict:
    """The air brake's cycle in a run: its applications, the shortest recharge margin [s] (time from a release
    to the next application less the recharge time; None when no application follows a release) and the
    recharge time; all None without the cycle (the electric brake alone, the papers' model)."""
    if res.air_applications is None:
        return {"air_applications": None, "min_recharge_margin_s": None, "recharge_s": None}
    margin = float(res.air_margin_s[0])
    return {"air_applications": int(res.air_applications[0]),
            "min_recharge_margin_s": round(margin, 1) + 0.0 if math.isfinite(margin) else None,  # (no -0.0)
            "recharge_s": round(float(res.recharge_s), 1)}


def recovered_energy(train: Train, res: BatchResult) -> dict:
    """``{"recovered_energy_kwh": ..., "net_energy_kwh": ...}``: what the electric brake returned to the line
    (0 for a train whose locomotives give no ``regen_efficiency``) and the traction energy less it, rounded
    as the traction energy is; None where the run has none (it failed before the end)."""
    if res.recovered_energy_kwh is None:
        return {"recovered_energy_kwh": None, "net_energy_kwh": None}
    x = float(res.recovered_energy_kwh[0])
    e = float(res.traction_energy_kwh[0])
    if not (math.isfinite(x) and math.isfinite(e)):
        return {"recovered_energy_kwh": None, "net_energy_kwh": None}
    return {"recovered_energy_kwh": round(x, 2), "net_energy_kwh": round(e - x, 2)}


def coupler_summary(train: Train, prof) -> dict:
    """The largest tensile and compressive coupler force of the run [kN] and where [m] (the head's position,
    the middle of the cell), with the consist's limits (None where it gives none, or for a single vehicle)."""
    out = {"max_coupler_tension_kn": None, "max_coupler_tension_at_m": None,
           "max_coupler_compression_kn": None, "max_coupler_compression_at_m": None,
           "coupler_limit_kn": train.coupler_limit_kn, "force_rate_limit_kn_per_s": train.force_rate_limit_kn_per_s}
    if prof is None or prof.coupler_tension_kn is None:
        return out
    mid = 0.5 * (prof.s_m[1:] + prof.s_m[:-1])
    for side, arr in (("tension", prof.coupler_tension_kn[0]), ("compression", prof.coupler_compression_kn[0])):
        if np.isfinite(arr).any():
            k = int(np.nanargmax(arr))
            out[f"max_coupler_{side}_kn"] = round(float(arr[k]), 1)
            out[f"max_coupler_{side}_at_m"] = round(float(mid[k]), 1)
    return out


def schedule_verdict(ctx: StrategyContext, run: RunResult, strict: bool | None = None) -> str | None:
    """Why a result fails its job, or None: infeasible, or (for a strategy that must keep the timetable,
    or any plan when ``strict``) outside the window T0 +- tolerance, naming what is reachable."""
    s = run.summary
    if not s["feasible"]:
        return f"{s['strategy']}: no feasible plan ({s['reason']})"
    must = (registry.is_timetabled(run.name) and ctx.use_window) if strict is None else strict
    if not must or s["punctual"] is not False:
        return None
    lo, hi = s["window_s"]
    fastest = ctx.calc.fastest_time_s
    span = run.outcome.time_range_s
    reach = f"the fastest possible run is {fastest:,.1f} s"
    if span is not None:
        reach = f"its plans ran {max(span[0], fastest):,.1f} .. {span[1]:,.1f} s here ({reach})"
    return (f"{s['strategy']}: running time {s['running_time_s']:,.1f} s misses the window {lo:,.1f} .. {hi:,.1f} s "
            f"(T0 = {ctx.t0_s:g} s); {reach}")


def run_strategy(ctx: StrategyContext, name: str, with_fitness: bool = True) -> RunResult:
    entry = registry.get(name)
    fn = entry.function()
    if entry.refuses_impossible_time:
        check_time_possible(ctx)
    ctx.loaded.update(entry.read_inputs(ctx.inputs, ctx.loaded))
    t = time.perf_counter()
    outcome = fn(ctx)
    if not outcome.solve_time_s:
        outcome = replace(outcome, solve_time_s=time.perf_counter() - t)
    res = outcome.result if outcome.result is not None else _evaluate(ctx, outcome)
    return RunResult(name, outcome, res, summarize(ctx, name, outcome, res, with_fitness))


def run_sequence(ctx: StrategyContext, text: str) -> RunResult:
    t = time.perf_counter()
    plan: Plan = parse_sequence(text, ctx.calc.route.length_m)
    outcome = StrategyOutcome(plan)
    res = _evaluate(ctx, outcome)
    outcome = replace(outcome, solve_time_s=time.perf_counter() - t)
    return RunResult("sequence", outcome, res, summarize(ctx, "sequence", outcome, res))


def proposed_sequence(route: Route, train: Train, options: ModelOptions | None = None, builder: str | None = None):
    """The limit and grade classification behind the ISSA paper's proposed sequence, with its nominal switching
    points (``compare --explain``), on the optimisers' search grid."""
    return build_sequence(make_context(route, train, RunSettings(options, need_time=False, builder=builder)).search)


def study_table(results: dict[str, list[RunResult]], tolerance_s: float | None) -> list[dict]:
    """Per algorithm: best, worst and mean (by fitness), mean fitness, and the best punctual run."""
    rows = []
    for alg, runs in results.items():
        s = [r.summary for r in runs if r.summary["fitness"] is not None]
        if not s:
            rows.append({"algorithm": alg, "runs": len(runs), "feasible_runs": 0})
            continue
        f = np.array([x["fitness"] for x in s])
        best, worst = s[int(np.argmin(f))], s[int(np.argmax(f))]
        punctual = [x for x in s if tolerance_s is None or x["punctuality_error_s"] <= tolerance_s]
        pb = min(punctual, key=lambda x: x["fitness"]) if punctual else None
        rows.append({
            "algorithm": alg, "runs": len(runs), "feasible_runs": len(s),
            "best": {k: best[k] for k in ("seed", "running_time_s", "traction_energy_kwh", "fitness")},
            "worst": {k: worst[k] for k in ("seed", "running_time_s", "traction_energy_kwh", "fitness")},
            "mean_running_time_s": round(float(np.mean([x["running_time_s"] for x in s])), 2),
            "mean_traction_energy_kwh": round(float(np.mean([x["traction_energy_kwh"] for x in s])), 2),
            "mean_fitness": round(float(f.mean()), 5),
            "std_fitness": round(float(f.std(ddof=1)), 5) if len(f) > 1 else 0.0,
            "punctual_runs": len(punctual),
            "punctual_best": None if pb is None else {k: pb[k] for k in ("seed", "running_time_s", "traction_energy_kwh", "fitness")},
            "mean_solve_time_s": round(float(np.mean([x["solve_time_s"] for x in s])), 2),
            "mean_gap_to_optimum_percent": (None if any(x.get("gap_to_optimum_percent") is None for x in s)
                                            else round(float(np.mean([x["gap_to_optimum_percent"] for x in s])), 2)),
        })
    return rows


def punctuality_tolerance(route, t0_s: float, tolerance_s: float | None) -> float:
    """The window's half width [s]: as given, else the route's schedule tolerance, else 1 % of T0 (as ``optimize``)."""
    if tolerance_s is not None:
        if tolerance_s >= t0_s:
            raise InputError(Problem(bounds.CMDLINE, "--tolerance", f"{tolerance_s:g} s is not below the planned time {t0_s:g} s"))
        return float(tolerance_s)
    if route.schedule is not None and route.schedule.tolerance_s is not None:
        return float(route.schedule.tolerance_s)
    return max(1.0, DEFAULT_TOLERANCE_SHARE * t0_s)
