"""One minimum-time optimal-control run on a loaded route and train, checked by re-simulation.

Joins the file world's objects (:class:`~locoplan.model.route.Route`,
:class:`~locoplan.model.train.Train`) to the problem (:mod:`~locoplan.ocp.min_time`) and the
methods (:mod:`~locoplan.ocp.solve`), and turns a solution into the SPEC's JSON object. Library code:
it never reads or writes a file, never prints and never exits (rendering and writing:
:mod:`locoplan.reporting.ocp_study`).

Confirmation rule: a solution is reported as a result only if the re-simulated train (the method's
own control interpolant, clipped to the force bounds as a real drive would be, integrated by
``solve_ivp``) arrives at the end within ``ARRIVAL_TOL_M`` and stops there, within ``TIME_TOL_S`` of
the NLP's objective, and never above the limit by more than ``LIMIT_TOL_KMH``. Otherwise ``feasible``
is false, ``running_time_s`` / ``traction_energy_kwh`` are null (the NLP's claim stays in
``objective``, labelled as such by ``reason``) and the CLI exits 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..physics.units import kmh, kwh
from .min_time import ExactMinimum, MinTimeTrainProblem, bounds_note, exact_minimum, train_problem
from .registry import OBJECTIVES, OCP_METHODS, SOURCE, STAGE2_MODES, check_options  # noqa: F401  (re-exported)
from .solve import OcpSolution, Resimulation, resimulate, solve_min_time

__all__ = ["ARRIVAL_TOL_M", "LIMIT_TOL_KMH", "OcpRun", "PROFILE_COLUMNS", "TIME_TOL_S", "check_options", "run_ocp",
           "solve_ocp", "traction_energy_kwh"]

TIME_TOL_S = 0.05
"""Largest accepted |objective - re-simulated running time| [s]."""
LIMIT_TOL_KMH = 0.1
"""Largest accepted overspeed of the re-simulated train [km/h]."""
ARRIVAL_TOL_M = 0.5
"""A re-simulated train that stops within this distance of the end has arrived [m]."""


# --------------------------------------------------------------------------------------------------
# one run
# --------------------------------------------------------------------------------------------------

PROFILE_COLUMNS = ("t_s", "s_m", "v_kmh", "limit_kmh", "gradient_permille", "condition", "traction_kn", "brake_kn")
"""Columns of ``--out FILE.csv`` (the re-simulated run, sampled every ``dt_s``)."""


def _condition(force_kn: np.ndarray, f_max: float, b_max: float) -> np.ndarray:
    """T full traction, K partial traction (speed holding), C no force, B brake (any braking force)."""
    tol = 1e-3 * max(f_max, b_max)
    return np.where(force_kn < -tol, "B", np.where(force_kn >= f_max - tol, "T", np.where(force_kn > tol, "K", "C")))


@dataclass(frozen=True)
class OcpRun:
    """One optimal-control run on a loaded route and train: the problem, the NLP's solution, its
    re-simulation, the exact optimum and the SPEC summary (``summary``, the ``--json`` object)."""

    problem: MinTimeTrainProblem
    solution: OcpSolution
    resimulation: Resimulation
    exact: ExactMinimum
    summary: dict
    route_name: str = ""
    train_name: str = ""

    @property
    def feasible(self) -> bool:
        return bool(self.summary["feasible"])

    @property
    def end_time_s(self) -> float:
        """Where the re-simulated run ends [s]: its arrival, else its stop, else ``t_f``."""
        rs = self.resimulation
        for t in (rs.time_to_length_s, rs.stop_time_s):
            if math.isfinite(t):
                return float(t)
        return float(self.solution.objective_s)

    def force_at(self, t) -> np.ndarray:
        """The driven force [kN]: the solved control (clipped to the bounds), held after ``t_f``."""
        t = np.minimum(np.asarray(t, dtype=float), self.solution.objective_s)
        return self.solution.control_at(t, clip=True)

    def sampled(self, dt_s: float = 0.1) -> dict[str, np.ndarray]:
        """The re-simulated run on a uniform time grid ``t_s`` [s] with ``s_m``, ``v_ms``, ``force_kn``."""
        rs = self.resimulation
        t_end = self.end_time_s
        t = np.unique(np.concatenate([np.arange(0.0, t_end, dt_s), [t_end]]))
        keep = np.concatenate([[True], np.diff(rs.time_s) > 0])
        ts, ss, vs = rs.time_s[keep], rs.position_m[keep], rs.speed_ms[keep]
        return {"t_s": t, "s_m": np.interp(t, ts, ss), "v_ms": np.interp(t, ts, vs), "force_kn": self.force_at(t)}

    def profile_rows(self, dt_s: float = 0.1) -> list[dict]:
        """The re-simulated run as rows of :data:`PROFILE_COLUMNS`."""
        p = self.problem
        d = self.sampled(dt_s)
        cond = _condition(d["force_kn"], p.f_max_kn, p.b_max_kn)
        rows = []
        for k in range(d["t_s"].size):
            f = float(d["force_kn"][k])
            rows.append({
                "t_s": round(float(d["t_s"][k]), 4),
                "s_m": round(float(d["s_m"][k]), 3),
                "v_kmh": round(kmh(float(d["v_ms"][k])), 4),
                "limit_kmh": p.speed_limit_kmh,
                "gradient_permille": p.gradient_permille,
                "condition": str(cond[k]),
                "traction_kn": round(max(f, 0.0), 3),
                "brake_kn": round(max(-f, 0.0), 3),
            })
        return rows


def traction_energy_kwh(run: OcpRun, t_end_s: float | None = None, dt_s: float = 1e-3) -> float:
    """``int max(F, 0) v dt`` [kWh] of the re-simulated run up to ``t_end_s`` [s] (default: its arrival).

    Trapezoid rule on a ``dt_s`` grid: the force is the clipped control (held after ``t_f``), the speed
    the re-simulation's dense output, linearly interpolated. SPEC: traction energy is sum F ds at the
    wheel; kN * m = kJ, / 3600 -> kWh.
    """
    t_end = run.end_time_s if t_end_s is None else float(t_end_s)
    rs = run.resimulation
    t = np.unique(np.concatenate([np.arange(0.0, t_end, dt_s), [t_end]]))
    keep = np.concatenate([[True], np.diff(rs.time_s) > 0])
    v = np.interp(t, rs.time_s[keep], rs.speed_ms[keep])
    power_kw = np.maximum(run.force_at(t), 0.0) * v
    return float(kwh(np.sum(0.5 * (power_kw[1:] + power_kw[:-1]) * np.diff(t))))


def _reasons(problem: MinTimeTrainProblem, sol: OcpSolution, rs: Resimulation) -> list[str]:
    """What the re-simulation found wrong with the NLP's claim (empty: confirmed)."""
    out = []
    length = problem.length_m
    if not sol.success:
        out.append(f"IPOPT did not converge ({sol.status})")
    if not math.isfinite(rs.time_to_length_s):
        if math.isfinite(rs.stop_time_s):
            out.append(f"the re-simulated train does not arrive: it stops at {rs.stop_position_m:.1f} m after "
                       f"{rs.stop_time_s:.2f} s, {length - rs.stop_position_m:.1f} m short of the end")
        else:
            out.append(f"the re-simulated train does not arrive: at t_f = {sol.objective_s:.2f} s it is at "
                       f"{rs.distance_at_tf_m:.1f} m, running at {kmh(rs.final_speed_ms):.1f} km/h")
    else:
        if not math.isfinite(rs.stop_position_m):
            out.append("the re-simulated train passes the end and does not stop")
        elif rs.stop_position_m > length + ARRIVAL_TOL_M:
            out.append(f"the re-simulated train overruns the end: it stops at {rs.stop_position_m:.1f} m "
                       f"({rs.stop_position_m - length:.1f} m beyond)")
        gap = rs.time_to_length_s - sol.objective_s
        if abs(gap) > TIME_TOL_S:
            out.append(f"the re-simulated running time {rs.time_to_length_s:.3f} s differs from the objective "
                       f"{sol.objective_s:.3f} s by {gap:+.3f} s (tolerance {TIME_TOL_S:g} s)")
    if rs.max_overspeed_kmh > LIMIT_TOL_KMH:
        out.append(f"the re-simulated train exceeds the {problem.speed_limit_kmh:g} km/h limit by "
                   f"{rs.max_overspeed_kmh:.2f} km/h (tolerance {LIMIT_TOL_KMH:g} km/h)")
    return out


def _r(x, nd: int):
    return None if x is None or not math.isfinite(x) else round(float(x), nd) + 0.0  # no -0.0


def solve_ocp(route, train, method: str = "two-stage", nodes: int | None = None, *, state_nodes: int | None = None,
              stage2: str = "hp", objective: str = "time", route_file: str | Path | None = None,
              consist_name: str | None = None, problem: MinTimeTrainProblem | None = None) -> OcpRun:
    """Solve the optimal control problem of ``train`` on ``route`` and check it by re-simulation.

    ``method`` is a key of :data:`OCP_METHODS`, ``nodes`` its control-node count (default: the paper's
    first count, 17 / 34 / 20), ``state_nodes`` the LG points of the states (two-stage: ``2 * nodes``,
    must be even; GPM: ``nodes``), ``stage2`` a key of :data:`STAGE2_MODES`, ``objective`` a key of
    :data:`OBJECTIVES` (only ``"time"`` is built). ``problem`` overrides :func:`train_problem`.
    Raises :class:`InputError` for bad options or routes, :class:`InfeasibleError` when the train
    cannot start or stop or IPOPT finds the transcription infeasible. An unconfirmed solution is
    *returned* with ``summary["feasible"] = False`` and a ``reason`` (the CLI exits 1).
    """
    n, m = check_options(method, nodes, state_nodes, stage2, objective)
    if problem is None:
        problem = train_problem(route, train, route_file)
    kwargs = {"stage2": stage2} if OCP_METHODS[method].has_stage2 else {}
    sol = solve_min_time(problem, method, n, state_nodes=m if method == "two-stage" else None, **kwargs)
    rs = resimulate(problem, sol, position_tol_m=ARRIVAL_TOL_M)
    exact = exact_minimum(problem)
    reasons = _reasons(problem, sol, rs)
    feasible = not reasons
    stage1 = sol.stages[0]
    summary = {
        "route": route.name if route is not None else "",
        "consist": consist_name or (train.name if train is not None else ""),
        "strategy": "ocp",
        "algorithm": method,
        "seed": None,
        "objective_kind": objective,
        "stage2": stage2 if kwargs else None,
        "feasible": feasible,
        "reason": "; ".join(reasons) if reasons else None,
        "running_time_s": _r(rs.time_to_length_s, 4) if feasible else None,  # an unconfirmed objective is no result
        "traction_energy_kwh": None,
        "punctuality_error_s": None,
        "fitness": None,
        "solve_time_s": round(sol.solve_time_s, 4),
        "objective": _r(sol.objective_s, 4),
        "resimulated_running_time_s": _r(rs.time_to_length_s, 4),
        "max_limit_violation_kmh": round(float(rs.max_overspeed_kmh), 4),
        "max_force_excess_kn": round(float(rs.max_control_excess_kn), 3),
        "control_nodes": int(stage1.control_nodes),
        "state_nodes": int(stage1.state_nodes) or None,
        "final_control_nodes": int(sol.control_nodes),
        "final_state_nodes": int(sol.state_nodes) or None,
        "segments": len(sol.control_pieces),  # of the final NLP (stage 1 if stage 2 failed)
        "status": sol.status,
        "iterations": int(sol.iterations),
        "exact_minimum_s": _r(exact.time_s, 4),
        "gap_to_exact_s": _r(sol.objective_s - exact.time_s, 4),
        "breakpoints_s": [round(float(b), 4) for b in sol.breakpoints_s],
        "stages": [{"name": s.name, "objective_s": _r(s.objective_s, 4), "control_nodes": s.control_nodes,
                    "state_nodes": s.state_nodes or None, "segments": s.segments, "iterations": s.iterations,
                    "status": s.status, "solve_time_s": round(s.solve_time_s, 4)} for s in sol.stages],
        "length_m": problem.length_m,
        "gradient_permille": problem.gradient_permille,
        "speed_limit_kmh": problem.speed_limit_kmh,
        "force_bounds_kn": [-problem.b_max_kn, problem.f_max_kn],
        "force_bounds_note": bounds_note(train, problem.speed_limit_kmh) if train is not None else None,
        "sequence": [],
    }
    run = OcpRun(problem, sol, rs, exact, summary, summary["route"], summary["consist"])
    if feasible:
        summary["traction_energy_kwh"] = round(traction_energy_kwh(run), 3)
    d = run.sampled(dt_s=0.01)
    cond = _condition(d["force_kn"], problem.f_max_kn, problem.b_max_kn)[:-1]  # per interval
    starts = np.concatenate([[0], np.nonzero(cond[1:] != cond[:-1])[0] + 1])
    ends = np.concatenate([starts[1:], [cond.size]])
    seq = [{"condition": str(cond[a]), "from_m": round(float(d["s_m"][a]), 2), "to_m": round(float(d["s_m"][b]), 2),
            "from_s": round(float(d["t_s"][a]), 2)} for a, b in zip(starts, ends)]
    summary["sequence"] = seq
    return run


def run_ocp(route, train, method: str = "two-stage", nodes: int | None = None, **kwargs) -> dict:
    """The SPEC's JSON object of :func:`solve_ocp` (same arguments)."""
    return solve_ocp(route, train, method, nodes, **kwargs).summary
