"""The pattern-curve patent in ``locoplan compare``: the strategies ``drivers`` (what the drivers' logs say for the
same route, mass and planned time) and ``advice`` (the learned patterns' operation sequence); their
entries and traits are in ``strategy/registry.py``, which imports this module when one of them runs.

Both take their inputs read: ``ctx.loaded["logs"]`` (the logged runs) and ``ctx.loaded["patterns"]``;
``runner.run_strategy`` reads them from ``ctx.inputs`` (log folders or manifests, a patterns.json, set by
``compare --logs / --patterns``) with the readers the registry names.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ..errors import InputError, Problem
from ..model.plan import Plan, runs_from_profile
from ..sim.result import CODE, OK, BatchResult, Profile
from ..sim.calculator import TractionCalculator
from ..strategy.strategies import StrategyContext, StrategyOutcome
from .advise import advise as advise_run
from .advise import check_model
from .patterns import Patterns, good_drivers, tolerance_s

MASS_SHARE = 0.01
"""A log counts for the compared train when its mass is within this share of the train's."""


def matching_runs(runs: list, calc: TractionCalculator, t0_s: float) -> list:
    """The logged runs of the same job: same route (file contents), train mass within 1 %, planned
    time within 1 s."""
    mass = calc.train.mass_t
    return [r for r in runs if r.route == calc.route and abs(r.mass_t - mass) <= MASS_SHARE * mass
            and abs(r.scheduled_time_s - t0_s) <= 1.0]


def log_profile(run, calc: TractionCalculator) -> Profile:
    """A logged run on the calculator's grid (one row): time and speed at the nodes, and per cell the
    driver's action and mean traction / braking force, so that it plots and tabulates like a plan."""
    d = run.data
    pos, first = np.unique(d.position_m, return_index=True)
    s = calc.s_m
    t = np.interp(s, pos, d.time_s[first]) - d.time_s[0]
    v = np.interp(s, pos, d.speed_kmh[first])
    mid = 0.5 * (s[1:] + s[:-1])
    row = np.clip(np.searchsorted(d.position_m, mid, side="right") - 1, 0, len(d.position_m) - 1)
    force = d.force_kn[row]
    if d.action is not None:
        cond = np.array([CODE[a] for a in d.action[row]], dtype=np.int8)
    else:  # no action column: judge by the force (holding cannot be told from a log of forces)
        cond = np.where(force > 0, CODE["T"], np.where(force < 0, CODE["B"], CODE["C"])).astype(np.int8)
    return Profile(s, t[None, :], v[None, :], cond[None, :], np.maximum(force, 0.0)[None, :],
                   np.maximum(-force, 0.0)[None, :], calc.limit_kmh, calc.gradient_permille)


def drivers(ctx: StrategyContext) -> StrategyOutcome:
    """The drivers' logs for this route, train and planned time: time and energy are the drivers'
    means; the sequence and profile are the best driver's run (the punctual run with the least energy)."""
    t_start = time.perf_counter()
    logs, runs = ctx.inputs.get("logs"), ctx.loaded.get("logs")
    if not logs or runs is None:
        raise InputError(Problem("<command line>", "--logs", "the 'drivers' strategy needs the drivers' logs: --logs DIR"))
    calc = ctx.calc
    same = matching_runs(runs, calc, ctx.t0_s)
    if not same:
        have = sorted({(r.route.name, r.mass_t, r.scheduled_time_s) for r in runs})
        listed = "; ".join(f"{n}, {m:g} t, {t:g} s" for n, m, t in have[:8]) + (" ..." if len(have) > 8 else "")
        raise InputError(Problem(", ".join(str(x) for x in logs), "--logs", f"no logged run of '{calc.route.name}' with "
                                 f"{calc.train.mass_t:g} t (+-1 %) planned at {ctx.t0_s:g} s; the logs hold: {listed}"))
    good, _ = good_drivers(same, load_class_t=max(r.mass_t for r in same))  # one job: one group
    energy = np.array([r.traction_energy_kwh for r in same])
    times = np.array([r.running_time_s for r in same])
    punctual = np.array([abs(r.running_time_s - r.scheduled_time_s) <= tolerance_s(r.route, r.scheduled_time_s) for r in same])
    pool = np.flatnonzero(punctual) if punctual.any() else np.arange(len(same))
    best = int(pool[np.argmin(energy[pool])])
    prof = log_profile(same[best], calc)
    runs_ = runs_from_profile(prof.s_m, prof.condition[0], calc.train.length_m / 2)
    plan = Plan(tuple(r["condition"] for r in runs_), tuple(float(r["from_m"]) for r in runs_))
    result = BatchResult(np.array([times.mean()]), np.array([energy.mean()]), np.array([True]), np.array([OK], dtype=np.int8),
                         np.array([math.nan]), prof)
    extra = {"drivers_mean_kwh": round(float(energy.mean()), 2),
             "good_drivers_mean_kwh": round(float(energy[good].mean()), 2) if good.any() else None,
             "best_driver_kwh": round(float(energy[best]), 2), "best_driver_id": same[best].driver_id,
             "best_driver_time_s": round(float(times[best]), 1), "drivers_runs": len(same),
             "good_drivers_runs": int(good.sum()), "drivers_punctual_runs": int(punctual.sum()),
             "synthetic": all(r.synthetic for r in same)}
    return StrategyOutcome(plan, solve_time_s=time.perf_counter() - t_start, result=result, extra=extra)


def advice(ctx: StrategyContext) -> StrategyOutcome:
    """The pattern-curve patent's advice from the learned patterns (``--patterns``), checked by the calculator."""
    path, data = ctx.inputs.get("patterns"), ctx.loaded.get("patterns")
    if not path or data is None:
        raise InputError(Problem("<command line>", "--patterns", "the 'advice' strategy needs learned patterns: --patterns FILE"))
    pat = Patterns.from_dict(data, str(Path(path)))  # the file's format was checked by its reader
    check_model(pat, ctx.calc.options, str(path))
    a = advise_run(pat, ctx.calc.route, ctx.calc.train, ctx.t0_s, ctx.calc.options, calc=ctx.calc)
    return StrategyOutcome(a.plan, solve_time_s=a.solve_time_s, extra={"speed_scale": round(a.scale, 4)})
