"""Seed 001 end to end: the minimum-energy run (MPOC), its drivable plan, and the SPEC summary.

:func:`run_mpoc` builds the multi-phase problem (``train_energy``), solves it with hp refinement
(``energy``), turns the optimum into a condition plan and re-simulates it with the traction
calculator (``drive``). A result counts only when its plan holds every limit, stops at the end and
runs in the asked time; otherwise ``feasible`` is false with the reason (the CLI exits 1).
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numpy as np

from ..model.route import Route
from ..model.train import Train
from ..sim.calculator import ModelOptions, TractionCalculator
from .to_plan import (PlanCheck, check_plan, condition_runs, fit_switches, plan_from_runs, shoot_switches, sequence_runs,
                    tune_coasting_point, tune_last_coast)
from .to_plan import TIME_TOL_S
from .energy import DEFAULT_MAX_DEGREE, DEFAULT_MESH_TOL, EnergySolution, solve_energy
from .train_energy import EnergyOptions, TrainEnergyProblem, build_problem, check_runnable


@dataclass
class MpocRun:
    """One MPOC solve: the problem, the refined NLP solution, its plan's re-simulation and the
    summary (the ``--json`` object)."""

    tep: TrainEnergyProblem
    solution: EnergySolution
    check: PlanCheck
    calc: TractionCalculator
    summary: dict

    @property
    def feasible(self) -> bool:
        return bool(self.summary["feasible"])


def without_neutral(route: Route) -> Route:
    """The route with its neutral sections removed (seed 001's MPOC-N)."""
    return route.model_copy(update={"neutral_sections": []})


def drivable_plan(es: EnergySolution, calc: TractionCalculator) -> tuple[list, PlanCheck, float]:
    """The optimum as a condition plan for ``calc`` (``drive``): runs of the optimum, switches shot and
    fitted to its clock and speed, the last coasting point moved to meet the time, re-simulated.
    Returns the optimum's runs, the plan's check and how far the coasting point moved [m]."""
    tep = es.tep
    runs = condition_runs(es.solution)
    plan = shoot_switches(calc, plan_from_runs(runs), es.solution)
    plan = fit_switches(calc, plan, es.solution)
    plan, shift = tune_last_coast(calc, plan, tep.time_s)
    res = calc.evaluate(plan.conditions, plan.switches_m)
    if not (res.feasible[0] and abs(float(res.running_time_s[0]) - tep.time_s) <= TIME_TOL_S / 2):
        plan, shift = tune_coasting_point(calc, plan, tep.time_s)  # over a whole coasting run, or an earlier one
    return runs, check_plan(calc, plan, tep.time_s, tep.energy.energy, tep.spans_m), shift


def _r(x, nd):
    return None if x is None or not math.isfinite(x) else round(float(x), nd) + 0.0


def run_mpoc(route: Route, train: Train, options: ModelOptions | None = None, time_s: float | None = None, *,
             energy: EnergyOptions | None = None, mesh_tol: float = DEFAULT_MESH_TOL,
             max_degree: int = DEFAULT_MAX_DEGREE, calc: TractionCalculator | None = None,
             warm=None, strategy: str = "mpoc") -> MpocRun:
    """Minimum traction energy of ``train`` over ``route`` in ``time_s`` [s], checked by re-simulation.

    ``energy.ignore_neutral`` solves seed 001's MPOC-N: the route without its neutral sections (its
    plan is checked on that route, since the real one cannot drive it). Raises ``InfeasibleError``
    when the consist cannot run the route, ``time_s`` is below the fastest run or IPOPT finds no
    solution; an unconfirmed plan is *returned* with ``summary["feasible"] = False``."""
    t_wall = _time.perf_counter()
    options = options or ModelOptions()
    energy = energy or EnergyOptions()
    run_route = without_neutral(route) if energy.ignore_neutral else route
    calc = calc or TractionCalculator(run_route, train, options)
    time_s = float(time_s if time_s is not None else route.schedule.run_time_s)
    fastest = check_runnable(calc, time_s)
    tep = build_problem(run_route, train, options, time_s, energy)
    es = solve_energy(tep, calc, mesh_tol=mesh_tol, max_degree=max_degree, warm=warm)
    runs, chk, shift = drivable_plan(es, calc)
    reasons = list(chk.reasons)
    if not es.success:
        reasons.insert(0, f"IPOPT did not converge ({es.solution.status})")
    wall = _time.perf_counter() - t_wall
    objective = es.objective_kwh
    summary = {
        "route": route.name, "consist": train.name, "strategy": strategy, "algorithm": "radau", "seed": None,
        "objective_kind": "energy",
        "feasible": not reasons, "reason": "; ".join(reasons) if reasons else None,
        "running_time_s": _r(chk.running_time_s, 2) if not reasons else None,
        "traction_energy_kwh": _r(chk.energy_kwh, 3) if not reasons else None,
        "planned_time_s": time_s,
        "punctuality_error_s": _r(abs(chk.running_time_s - time_s), 2) if not reasons else None,
        "fitness": None,
        "gap_to_optimum_percent": _r(100 * (chk.energy_kwh - objective) / objective, 3) if not reasons else None,
        "solve_time_s": round(wall, 3),
        "optimal_control_time_s": round(es.wall_time_s, 3),
        "objective": _r(objective, 4),
        "objective_kwh": _r(objective, 4),
        "resimulated_running_time_s": _r(chk.running_time_s, 3),
        "resimulated_energy_kwh": _r(chk.energy_kwh, 3),
        "resimulated_wheel_energy_kwh": _r(chk.wheel_energy_kwh, 3),
        "plan_energy_gap_percent": _r(100 * (chk.energy_kwh - objective) / objective, 3),
        "max_limit_violation_kmh": round(chk.max_overspeed_kmh, 4),
        "fastest_time_s": round(fastest, 2),
        "plan": chk.plan.text(),
        "coast_shift_m": round(shift, 1),
        "switching_points_m": [round(x, 1) for x in chk.plan.starts_m[1:] if not math.isnan(x)],
        "sequence": sequence_runs(chk),
        "optimal_runs": [{"condition": c, "from_m": round(a, 1), "to_m": round(b, 1)} for c, a, b in runs],
        "neutral_margins_s": chk.neutral_margins_s,
        "phases": len(tep.problem.phases),
        "mesh": {"intervals": len(es.solution.mesh.intervals), "points": es.solution.mesh.n_points,
                 "max_error": float(f"{float(np.max(es.errors)):.3g}") if es.errors.size else None,
                 "tolerance": mesh_tol, "max_degree": max_degree, "converged": es.converged,
                 "moving_points": sum(iv.free_start is not None for iv in es.solution.mesh.intervals)},
        "mesh_history": [h.to_dict() for h in es.history],
        "initial_guess": es.guess_plan,
        "energy_model": energy.energy.label(),
        "comfort_ms2": energy.comfort_ms2,
        "neutral_sections": "ignored (MPOC-N)" if energy.ignore_neutral else len(route.neutral_sections),
        "model": {"point_mass": options.point_mass, "air_brake": options.air_brake,
                  "rotating_mass": options.rotating_mass, "step_m": options.step_m},
    }
    if energy.comfort_ms2 is not None:
        summary["plan_note"] = (f"the traction calculator knows no comfort bound: the re-simulated plan accelerates and "
                                f"brakes at full force, not within {energy.comfort_ms2:g} m/s^2, so its time and energy "
                                "are not the comfort-bounded optimum's")
    if not es.converged:
        summary["mesh_note"] = (f"mesh tolerance {mesh_tol:g} not reached in {len(es.history)} refinements "
                                f"(largest error {summary['mesh']['max_error']})")
    return MpocRun(tep, es, chk, calc, summary)
