"""The specs of the multi-run commands, from one base spec: compare, the two sweeps, the study.

Each function returns the list of :class:`RunSpec` that :func:`locoplan.runs.run_many` runs, so a
Python user does what a command does in two lines::

    base = RunSpec("routes/freight-20km.yaml", settings=RunSettings(time_s=1500))
    batch = run_many(study_specs(base, ["issa", "ssa", "pso"], runs=10))

Errors name the argument (``strategies``, ``weights``, ``times_s``, ``runs``), never a command's flag.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from .. import bounds
from ..errors import InputError, LocoplanError, Problem
from ..io.load import load_route_and_train
from ..runner import check_time_possible as check, make_context, planned_time
from ..settings import RunSettings
from ..strategy import registry
from .spec import RunSpec


def compare_specs(base: RunSpec, strategies: list[str]) -> list[RunSpec]:
    """The ISSA paper's Tables 8-9: one run per strategy, all with the same E_min (run_many computes it once)."""
    if not strategies:
        raise InputError(Problem("", "strategies", "name at least one strategy"))
    for n in strategies:
        registry.get(n, field="strategies")
    return [base.replace(strategy=n) for n in strategies]


def weight_specs(base: RunSpec, w_time: list[float]) -> list[RunSpec]:
    """The ISSA paper's Table 6: the proposed strategy for each time weight (energy weight = 1 - time weight)."""
    for w in w_time:  # every value checked before the first run
        bounds.finite(w, "weights", 0.0, 1.0, why="a time weight")
    bounds.runs(len(w_time), "weights", "time weights")
    return [base.replace(strategy="proposed", weights=(float(w), 1.0 - float(w))) for w in w_time]


def time_specs(base: RunSpec, times_s: list[float]) -> list[RunSpec]:
    """The ISSA paper's Table 7: the proposed strategy for each planned running time (E_min is the same for all)."""
    for t in times_s:  # every value checked before the first run
        bounds.planned_time(t, "times_s")
    bounds.runs(len(times_s), "times_s", "running times")
    return [base.replace(strategy="proposed", time_s=float(t)) for t in times_s]


def study_specs(base: RunSpec, algorithms: list[str], runs: int, params_dir: str | Path | None = None) -> list[RunSpec]:
    """The ISSA paper's Tables 10-12: each algorithm ``runs`` times on the proposed strategy, seeds
    base.seed .. base.seed + runs - 1, parameters from ``params_dir/<algorithm>.yaml`` if given."""
    if not algorithms:
        raise InputError(Problem("", "algorithms", "name at least one optimiser"))
    bounds.count(runs, "runs", 1, bounds.LIMITS["runs"], "independent runs per optimiser")
    bounds.runs(runs * len(algorithms), "runs")
    last = base.seed + runs - 1
    if last > bounds.LIMITS["seed"][1]:
        raise InputError(Problem("", "seed", f"{runs} runs take the seeds {base.seed} .. {last}, past the largest seed "
                                 f"2**63 - 1: give a --seed at most {bounds.LIMITS['seed'][1] - runs + 1}"))
    return [base.replace(strategy="proposed", algorithm=a, seed=base.seed + i,
                         params=str(Path(params_dir) / f"{a}.yaml") if params_dir else base.params)
            for a in algorithms for i in range(runs)]


def check_time_possible(specs: list[RunSpec]) -> None:
    """Before a study or sweep: a planned time below the fastest run cannot be met by any plan, whatever
    the seed (InfeasibleError naming the fastest run), so none of the runs is started; only for the
    strategies that refuse such a time (``StrategyEntry.refuses_impossible_time``)."""
    contexts: dict = {}
    for s in specs:
        entry = registry.lookup(s.strategy)
        if entry is None or not entry.refuses_impossible_time:
            continue
        k = (s.route, s.consist, s.stock_dir, s.options, s.resolved_builder)
        if k not in contexts:
            route, train = load_route_and_train(s.route, s.consist, s.stock_dir)
            contexts[k] = make_context(route, train, RunSettings(s.options, need_time=False,
                                                                 builder=s.resolved_builder))
        ctx = contexts[k]
        check(replace(ctx, t0_s=planned_time(ctx.calc.route, s.time_s)))


def plan_counts(plan: str | None) -> tuple[int | None, int | None]:
    """(switches, coasts) of a plan string ``T:0,K:930,C:3256.2,B``: its condition changes and its C phases."""
    if not plan:
        return None, None
    conds = [c.split(":")[0] for c in plan.split(",")]
    return len(conds) - 1, conds.count("C")


def compare_fields(rows: list[dict]) -> list[dict]:
    """compare's derived fields, the same in its table, --json and --out: ``switches`` and ``coasts`` of
    each plan, and ``energy_reduction_percent``, the energy saved against the time-saving run (the
    fastest), in per cent (None without a feasible time-saving run among the rows)."""
    base = next((r["traction_energy_kwh"] for r in rows if r["strategy"] == "time-saving" and r["feasible"]), None)
    for x in rows:
        x["switches"], x["coasts"] = plan_counts(x.get("plan"))
        e = x["traction_energy_kwh"]
        x["energy_reduction_percent"] = (None if not base or e is None or not x["feasible"]
                                         else round(100 * (1 - e / base), 2))
    return rows


def energies_at_planned_time(rows: list[dict], route, train, options, objective: str = "traction") -> float | None:
    """Every plan's energy also at the planned time T0, so that plans that arrive at different times
    (an optimiser spends its window: 917.9 s against four-stage's 901.0 s for T0 = 900 s) compare at one
    running time: ``energy_at_t0_kwh = E*(T0) + (E - E*(T))``, the plan's gap over the least energy at its
    own time T (the MPOC paper's optimum, ``ocp.bound``) carried to T0, for the plans inside the punctuality
    window (None for the others: time-saving's gap at 1227 s says nothing about 1500 s). Needs each row's gap (--gap); returns
    E*(T0) [kWh], or None when there is none (no T0, no gaps, or no optimum at T0)."""
    from ..ocp.bound import energy_bound  # CasADi: imported when an optimum is asked for

    t0 = next((r.get("planned_time_s") for r in rows if r.get("planned_time_s") is not None), None)
    if t0 is None or not any(r.get("gap_to_optimum_kwh") is not None for r in rows):
        return None
    try:
        e0 = energy_bound(route, train, options, t0, objective=objective).energy_kwh
        e0 = e0 if objective == "net" else max(e0, 0.0)
    except LocoplanError:
        return None
    for r in rows:
        g = r.get("gap_to_optimum_kwh")
        # only a plan inside the punctuality window: carried farther, the gap would not be the plan's at T0
        r["energy_at_t0_kwh"] = None if g is None or not r["feasible"] or not r.get("punctual") else round(e0 + g, 2)
    return round(e0, 2)


def energy_reduction(rows: list[dict]) -> list[dict]:
    """The ISSA paper's Table 7's derived column: each row's energy saved against the first row's, in per cent."""
    base = rows[0]["traction_energy_kwh"] if rows else None
    for x in rows:
        e = x["traction_energy_kwh"]
        x["energy_reduction_percent"] = None if not base or e is None else round(100 * (1 - e / base), 2)
    return rows
