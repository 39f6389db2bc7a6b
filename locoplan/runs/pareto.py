"""``locoplan pareto ROUTE``: the energy-time front of a route and train.

At each planned time of a grid (factors of the fastest run, or seconds) the ISSA paper's timetabled strategies
(four-stage, proposed) plan, the seeded one over several seeds; its two that ignore the timetable
(time-saving, energy-saving) add the two ends. The lists come from :mod:`locoplan.strategy.registry`. The
result has, per planned time, the best on-time plan found and the optimum's energy E* at that plan's
own running time (:mod:`locoplan.runs.optimum`, the MPOC paper's ``bound``) with the gap to it; and the non-dominated set of every feasible plan found (less time or less energy than any
other). Until E* is known the front is *the best plans found*, an upper bound of the true front, and
the result says so (``front_kind``).

A journey (``RunSpec.journey``) has the same front over its total running time, dwells excluded: every
plan is a journey run (each leg planned at its share of the time) and E* is the journey's, the least-energy
allocation of the plan's total time with each leg's E* (``runs.journey.journey_optimum``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .. import bounds
from ..errors import InfeasibleError, InputError, LocoplanError, Problem
from ..io.load import load_journey, load_route_and_train, load_train
from ..ocp.bound import percent_floor_kwh
from ..sim.calculator import TractionCalculator
from ..strategy import registry
from .many import run_many
from .optimum import optimum_energy_kwh, optimum_providers
from .spec import RunSpec

DEFAULT_FACTORS = tuple(round(1.05 + 0.05 * i, 2) for i in range(12))
"""1.05 .. 1.6 times the fastest run: from a tight timetable to one with a third more time."""
PLANNED = registry.names(source=registry.ISSA_PAPER, timetabled=True)
"""The strategies planned at each time by default: the ISSA paper's timetabled ones (four-stage, proposed)."""
ENDS = registry.names(source=registry.ISSA_PAPER, needs_time=False)
"""The two ends of the front: the ISSA paper's strategies that ignore the timetable (time-saving, energy-saving)."""


def time_grid(fastest_s: float, factors=None, times_s=None) -> list[tuple[float, float]]:
    """(T0 [s], factor) pairs: factors of the fastest run (T0 rounded up to 0.1 s) or times in seconds."""
    if times_s:
        for t in times_s:
            if not math.isfinite(t):
                raise InputError(Problem("", "times_s", f"{t:g} s is not a planned running time"))
            if t < fastest_s:  # a valid request no plan can meet: exit 1, as on every command
                raise InfeasibleError(f"planned running time {t:g} s is below the fastest possible run, {fastest_s:.1f} s")
        return [(float(t), float(t) / fastest_s) for t in times_s]
    factors = factors or DEFAULT_FACTORS
    for f in factors:
        if not (math.isfinite(f) and f >= 1):
            raise InputError(Problem("", "factors", f"a factor of the fastest run must be >= 1 (got {f:g})"))
    return [(math.ceil(f * fastest_s * 10 - 1e-9) / 10, float(f)) for f in factors]


def nondominated(points: list[dict]) -> list[dict]:
    """The points no other point beats in both running time and energy, by increasing time."""
    out: list[dict] = []
    for p in sorted(points, key=lambda p: (p["running_time_s"], p["traction_energy_kwh"])):
        if not out or p["traction_energy_kwh"] < out[-1]["traction_energy_kwh"]:
            out.append(p)
    return out


def pareto(base: RunSpec, *, factors=None, times_s=None, strategies=PLANNED, seeds=(1,), executor=None,
           progress=None, optimum: bool = True) -> dict:
    """The front of ``base.route`` with ``base.consist`` under ``base.options`` (see the module doc).

    ``strategies``: the strategies planned at each time (a seeded one, ``StrategyEntry.seeded``, once per seed).
    ``optimum``: ask the registered providers for E* at each planned time (the MPOC paper's bound: seconds
    per time, solved in this process, each warm-started from the previous one).
    Returns a JSON-ready dict: route, consist, fastest_time_s, front_kind, grid (per planned time: the
    best on-time plan, E*, gap), points (every plan), front (the non-dominated plans)."""
    seeded = {s: registry.get(s, field="strategies").seeded for s in strategies}
    for seed in seeds:
        bounds.seed(seed, "seeds")
    n_times = len(times_s) if times_s else len(factors or DEFAULT_FACTORS)
    per_time = sum(len(seeds) if seeded[s] else 1 for s in strategies)
    bounds.runs(len(ENDS) + n_times * per_time, "seeds" if len(seeds) > 1 else "strategies",
                f"runs ({n_times} planned times x {per_time} plans each)")
    line = _Line.of(base)
    route, train = line.route, line.train
    fastest = line.fastest_s
    grid = time_grid(fastest, factors, times_s)
    specs = [_with(base, strategy=s, time_s=grid[0][0]) for s in ENDS]
    for t0, _ in grid:
        for s in strategies:
            for seed in (seeds if seeded[s] else seeds[:1]):
                specs.append(_with(base, strategy=s, time_s=t0, seed=seed))
    batch = run_many(specs, executor, progress=progress)
    points = [{"strategy": r.summary["strategy"] + (f" ({r.summary['algorithm']})" if r.summary.get("algorithm") else ""),
               "planned_time_s": r.summary["planned_time_s"] if r.spec["strategy"] not in ENDS else None,
               "seed": r.summary.get("seed"), "running_time_s": r.summary["running_time_s"],
               "traction_energy_kwh": r.summary["traction_energy_kwh"], "punctual": r.summary.get("punctual")}
              for r in batch.records if r.summary.get("feasible")]
    front = nondominated(points)
    on_front = {(p["strategy"], p["running_time_s"], p["traction_energy_kwh"]) for p in front}
    rows = []
    for t0, f in grid:
        ok = [p for p in points if p["planned_time_s"] == t0 and p["punctual"]]
        best = min(ok, key=lambda p: p["traction_energy_kwh"]) if ok else None
        # E* at the best plan's own running time (a plan may run up to its window later than T0, and
        # E* falls with time): the gap compares like with like, as runner.summarize's does
        t_star = t0 if best is None else best["running_time_s"]
        e_star, floor = line.optimum(t_star) if optimum and line.providers else (None, 0.0)
        if e_star is not None:
            e_star = max(e_star, 0.0)  # traction work is never negative: below 0 is the solver's tolerance
        # (E* too small for a percentage of it to mean anything: no per cent, as runner.summarize)
        gap = (None if best is None or e_star is None or e_star < floor
               else round(100 * (best["traction_energy_kwh"] / e_star - 1), 3))
        rows.append({"planned_time_s": t0, "factor": round(f, 4),
                     "best_energy_kwh": None if best is None else best["traction_energy_kwh"],
                     "best_strategy": None if best is None else best["strategy"],
                     "best_running_time_s": None if best is None else best["running_time_s"],
                     "optimum_time_s": t_star, "optimum_kwh": None if e_star is None else round(e_star, 2),
                     "gap_to_optimum_percent": gap,
                     "on_front": best is not None and (best["strategy"], best["running_time_s"], best["traction_energy_kwh"]) in on_front})
    known = any(r["optimum_kwh"] is not None for r in rows)
    return {"route": route.name, **({"journey": line.journey.name} if line.journey else {}), "consist": train.name,
            "fastest_time_s": round(fastest, 2),
            "front_kind": "optimum E*(T) from " + ", ".join(line.providers) if known else
            "best on-time plans found by the strategies (no optimum E* asked for or known: an upper bound of the true front)",
            "strategies": list(strategies), "seeds": list(seeds), "grid": rows, "points": points, "front": front}


@dataclass(frozen=True)
class _Line:
    """What a front is drawn for: a route, or a journey (its whole line, its fastest total running time and
    its own E*)."""

    route: Any
    train: Any
    options: Any
    fastest_s: float
    journey: Any = None

    @classmethod
    def of(cls, base: RunSpec) -> "_Line":
        if base.journey is None:
            route, train = load_route_and_train(base.route, base.consist, base.stock_dir)
            calc = TractionCalculator(route, train, base.options)
            return cls(route, train, base.options, calc.fastest_time_for_factor_s("the front's planned times"))
        from .journey import journey_fastest_s

        journey, route = load_journey(base.journey)
        train = load_train(base.consist, base.stock_dir)
        return cls(route, train, base.options, journey_fastest_s(journey, route, train, base.options), journey)

    @property
    def providers(self) -> list[str]:
        return [JOURNEY_OPTIMUM] if self.journey is not None else optimum_providers()

    def optimum(self, time_s: float) -> tuple[float | None, float]:
        """(E* [kWh] or None where it is not known, the energy below which a percentage of it means nothing)."""
        if self.journey is None:
            return optimum_energy_kwh(self.route, self.train, self.options, time_s), percent_floor_kwh(self.route, self.train)
        from .journey import journey_optimum

        try:
            return journey_optimum(self.journey, self.route, self.train, self.options, time_s)
        except LocoplanError:  # a time the windows or the solver refuse: no E* here
            return None, 0.0


JOURNEY_OPTIMUM = "the journey's least-energy allocation of the time, each leg's E* (the journey command)"


def _with(base: RunSpec, **changes) -> RunSpec:
    return base.replace(**changes)
