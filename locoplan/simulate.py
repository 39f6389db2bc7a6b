"""Library entry point behind ``locoplan simulate``: one plan through the traction calculator."""

from __future__ import annotations

import time
from dataclasses import dataclass

from .model.plan import Plan, parse_sequence, runs_from_profile
from .model.route import Route
from .model.train import Train
from .sim.calculator import ModelOptions, TractionCalculator
from .sim.result import BatchResult
from .strategy.strategies import get_strategy


@dataclass(frozen=True)
class SimulationRun:
    route: Route
    train: Train
    label: str
    plan: Plan
    result: BatchResult
    solve_time_s: float

    def summary(self) -> dict:
        """The SPEC's JSON object for one result (keys scripts rely on)."""
        r = self.result
        t = float(r.running_time_s[0])
        schedule = self.route.schedule
        prof = r.profile
        return {
            "route": self.route.name,
            "consist": self.train.name,
            "strategy": self.label,
            "algorithm": None,
            "seed": None,
            "feasible": bool(r.feasible[0]),
            "reason": r.reason(0),
            "running_time_s": round(t, 2),
            "traction_energy_kwh": round(float(r.traction_energy_kwh[0]), 2),
            "planned_time_s": schedule.run_time_s if schedule else None,
            "punctuality_error_s": round(abs(t - schedule.run_time_s), 2) if schedule else None,
            "fitness": None,
            "solve_time_s": round(self.solve_time_s, 4),
            "plan": self.plan.text(),
            "sequence": runs_from_profile(prof.s_m, prof.condition[0], 1.0, prof.event_m[0]) if prof is not None else [],
        }


def simulate(route: Route, train: Train, *, strategy: str | None = None, sequence: str | None = None,
             options: ModelOptions | None = None) -> SimulationRun:
    """Run a built-in strategy or a user's sequence ("T:0,K:2200,C:9000,B") and keep its profile."""
    t0 = time.perf_counter()
    calc = TractionCalculator(route, train, options)
    if sequence is not None:
        plan, label = parse_sequence(sequence, route.length_m), "sequence"
    else:
        name = strategy or "time-saving"
        plan, label = get_strategy(name)(calc), name
    result = calc.evaluate(plan.conditions, plan.switches_m, profile=True)
    return SimulationRun(route, train, label, plan, result, time.perf_counter() - t0)
