"""The MPOC paper end to end: the minimum-energy run (MPOC), its drivable plan, and the SPEC summary.

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

from ..errors import InfeasibleError
from ..model.route import Route
from ..model.train import Train
from ..sim.calculator import ModelOptions, TractionCalculator
from .to_plan import (PlanCheck, check_plan, condition_runs, fit_switches, plan_from_runs, shoot_switches, sequence_runs,
                    tune_coasting_point, tune_last_coast)
from .to_plan import TIME_TOL_S
from .energy import DEFAULT_MAX_DEGREE, DEFAULT_MESH_TOL, EnergySolution, solve_energy
from .bound import relaxed
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
    """The route with its neutral sections removed (the MPOC paper's MPOC-N)."""
    return route.model_copy(update={"neutral_sections": []})


CYCLE_RESOLVES = 4
"""At most this many solves of the optimum for another running time when the air brake's cycle makes its
plan miss the asked time (see :func:`run_mpoc`)."""
FASTEST_MARGIN = 1e-3
"""The shortest time the optimum is solved for, above the relaxed problem's fastest run (share of it): at
the fastest run itself the problem has no interior left."""


def drivable_plan(es: EnergySolution, calc: TractionCalculator, time_s: float | None = None,
                  least_energy: bool = False) -> tuple[list, PlanCheck, float]:
    """The optimum as a condition plan for ``calc`` (``drive``): runs of the optimum, switches shot and
    fitted to its clock and speed, the last coasting point moved to meet ``time_s`` (default: the time the
    optimum was solved for; if the last cannot, an earlier one over its whole run, or with ``least_energy``
    whichever meets it at the least energy), re-simulated. Returns the optimum's runs, the plan's check and
    how far the coasting point moved [m]."""
    runs, chk, shift, _ = _drivable(es, calc, time_s, least_energy)
    return runs, chk, shift


def _drivable(es: EnergySolution, calc: TractionCalculator, time_s: float | None, least_energy: bool):
    """:func:`drivable_plan`, and how late [s] the plan ran with only its last coasting point moved (None if
    it failed): the time the optimum's plan loses to what the calculator does and the optimum does not."""
    tep = es.tep
    time_s = tep.time_s if time_s is None else float(time_s)
    runs = condition_runs(es.solution)
    plan = shoot_switches(calc, plan_from_runs(runs), es.solution)
    plan = fit_switches(calc, plan, es.solution)
    plan, shift = tune_last_coast(calc, plan, time_s)
    res = calc.evaluate(plan.conditions, plan.switches_m)
    late = float(res.running_time_s[0]) - time_s if res.feasible[0] else None
    if not (res.feasible[0] and abs(float(res.running_time_s[0]) - time_s) <= TIME_TOL_S / 2):
        plan, shift = tune_coasting_point(calc, plan, time_s, least_energy=least_energy)  # a whole coasting run
    return runs, check_plan(calc, plan, time_s, tep.energy.energy, tep.spans_m), shift, late


def _cycled(calc: TractionCalculator, chk: PlanCheck) -> bool:
    """The plan applied the air brake in cycles the optimum does not have: the calculator runs the cycle
    and the plan's run applied the air brake on a descent the electric brake cannot hold."""
    apps = chk.result.air_applications
    return (calc.air_cycle is not None and len(calc.cycle_regions_m) > 0 and apps is not None
            and chk.result.feasible[0] and int(apps[0]) > 0)


def _late_by(chk: PlanCheck, time_s: float) -> float | None:
    """How much later than ``time_s`` the checked plan runs [s] (negative: earlier), None if it fails."""
    return float(chk.running_time_s) - time_s if chk.result.feasible[0] and math.isfinite(chk.running_time_s) else None


def _cycle_text(calc: TractionCalculator) -> str:
    spans = ", ".join(f"{a / 1000:.1f}-{b / 1000:.1f} km" for a, b in calc.cycle_regions_m)
    return (f"the air brake cycles (released in full, {calc.air_cycle.recharge_s:g} s to recharge) on the descents the "
            f"electric brake cannot hold ({spans}), where the optimum's continuous air brake holds the limit")


def _retime_for_cycle(tep: TrainEnergyProblem, es: EnergySolution, calc: TractionCalculator, late0: float,
                      mesh_tol: float, max_degree: int):
    """The optimum solved again for the running time the air brake's cycle leaves. Its plan cycles on the
    descents the optimum holds at the limit with a continuous air brake, and so runs ``d`` seconds late (or
    early); the optimum for ``T - d`` gives that time back where the relaxed problem finds it cheapest, and
    its plan is timed to ``T``. The time solved for is then corrected by the secant rule on the plan's
    lateness (regula falsi once a late and an early plan bracket it), never below the relaxed problem's
    fastest run. Returns (solution, runs, check, shift, time solved for) of the first plan confirmed, else
    what the last one tried did not keep (a text)."""
    T = tep.time_s
    floor = TractionCalculator(tep.route, tep.train, relaxed(tep.options)).fastest_time_s * (1.0 + FASTEST_MARGIN)
    pts = [(T, late0)]
    t_try = max(T - late0, floor)
    warm = es
    why = ""
    for _ in range(CYCLE_RESOLVES):
        tep2 = build_problem(tep.route, tep.train, tep.options, t_try, tep.energy)
        try:
            es2 = solve_energy(tep2, calc, mesh_tol=mesh_tol, max_degree=max_degree, warm=warm.solution,
                               mesh=warm.solution.mesh.plain())
        except InfeasibleError as exc:
            return f"the optimum for {t_try:.1f} s: {exc}"
        runs2, chk2, shift2, late = _drivable(es2, calc, T, least_energy=True)
        if chk2.confirmed:
            return es2, runs2, chk2, shift2, t_try
        why = f"the plan of the optimum for {t_try:.1f} s: {'; '.join(chk2.reasons)}"
        if late is None or (late > 0 and t_try <= floor):
            return why  # the plan fails (a cycle's rule it cannot keep), or is late even from the fastest optimum
        pts.append((t_try, late))
        warm = es2
        early = [p for p in pts if p[1] < 0]
        behind = [p for p in pts if p[1] > 0]
        if early and behind:  # bracketed: the nearest on either side
            (t0, d0), (t1, d1) = max(early, key=lambda p: p[1]), min(behind, key=lambda p: p[1])
        else:
            (t0, d0), (t1, d1) = pts[-2], pts[-1]
        t_next = t1 - d1 * (t1 - t0) / (d1 - d0) if d1 != d0 else t1 - d1
        t_try = max(t_next, floor)
        if abs(t_try - t1) < 1e-3:
            return why
    return why


def _r(x, nd):
    return None if x is None or not math.isfinite(x) else round(float(x), nd) + 0.0


def run_mpoc(route: Route, train: Train, options: ModelOptions | None = None, time_s: float | None = None, *,
             energy: EnergyOptions | None = None, mesh_tol: float = DEFAULT_MESH_TOL,
             max_degree: int = DEFAULT_MAX_DEGREE, calc: TractionCalculator | None = None,
             warm=None, strategy: str = "mpoc") -> MpocRun:
    """Minimum traction energy of ``train`` over ``route`` in ``time_s`` [s], checked by re-simulation.

    ``energy.ignore_neutral`` solves the MPOC paper's MPOC-N: the route without its neutral sections (its
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
    runs, chk, shift, late0 = _drivable(es, calc, time_s, least_energy=False)
    solved_for = time_s
    cycle_note = None
    if _cycled(calc, chk) and late0 is not None and abs(late0) > TIME_TOL_S / 2:
        # the plan cycles on a descent the optimum holds at the limit with a continuous air brake, and its last
        # coasting point cannot give back the time the cycle costs: the optimum for the time the cycle leaves
        retimed = _retime_for_cycle(tep, es, calc, late0, mesh_tol, max_degree)
        if not isinstance(retimed, str) and (not chk.confirmed or retimed[2].energy_kwh < chk.energy_kwh):
            es, runs, chk, shift, solved_for = retimed
            cycle_note = (f"{_cycle_text(calc)}: its plan with the cycle ran {late0:+.1f} s from the asked time, so the "
                          f"optimum was solved for {solved_for:.1f} s and its plan timed to {time_s:g} s")
        elif isinstance(retimed, str) and not chk.confirmed:
            cycle_note = f"{_cycle_text(calc)}: no optimum's plan with the cycle runs in {time_s:g} s ({retimed})"
    reasons = list(chk.reasons)
    if cycle_note and not chk.confirmed:
        reasons.append(cycle_note)
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
        "optimum_time_s": round(solved_for, 2),
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
    if cycle_note and chk.confirmed:
        summary["cycle_note"] = cycle_note
    if not es.converged:
        summary["mesh_note"] = (f"mesh tolerance {mesh_tol:g} not reached in {len(es.history)} refinements "
                                f"(largest error {summary['mesh']['max_error']})")
    return MpocRun(tep, es, chk, calc, summary)
