"""Optimal control on a loaded route and consist, checked by re-simulation; the seed-000 study.

Layer 5 of the optimal-control stack: it joins the file world (:class:`~locoplan.model.route.Route`,
:class:`~locoplan.model.train.Train`) to the numbers-only problem layer and turns a solution into
the SPEC's JSON object. Library code: it never prints and never exits.

* :func:`train_problem`: a :class:`~locoplan.ocp.problems.MinTimeTrainProblem` from a route and a
  train (constant gradient and limit only; the multi-phase problem of seed 001 is a later issue).
* :func:`solve_ocp` / :func:`run_ocp`: solve, re-simulate, apply the confirmation rule, summarise.
* :func:`exact_minimum` / :func:`exact_minimum_time`: the accelerate / cruise / brake optimum by
  ``scipy.integrate.quad``, independent of the NLP.
* :func:`run_study`: seed 000 Tables 2-3 (CVP 20 / 40, GPM 34 / 48, two-stage 17 / 24 on the level
  and the 30 per-mille routes) with solve-time ratios measured in the same run.

Confirmation rule (issue 4 item 5): a solution is reported as a result only if the re-simulated
train (the method's own control interpolant, clipped to the force bounds as a real drive would be,
integrated by ``solve_ivp``) arrives at the end within ``ARRIVAL_TOL_M`` and stops there, within
``TIME_TOL_S`` of the NLP's objective, and never above the limit by more than ``LIMIT_TOL_KMH``.
Otherwise ``feasible`` is false, ``running_time_s`` / ``traction_energy_kwh`` are null (the NLP's
claim stays in ``objective``, labelled as such by ``reason``) and the CLI exits 1.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.integrate import quad
from scipy.optimize import brentq

from ..errors import InputError, Problem
from ..reporting.files import atomic_write_text
from ..reporting.writers import rows_csv, to_json
from ..physics.gradient import curve_gradient_permille, tunnel_gradient_permille
from ..physics.traction import max_force_kn
from . import nodes as _nodes
from .problems import KMH_PER_MS, MinTimeTrainProblem
from .registry import DEFAULT_OCP_CONSIST, OBJECTIVES, OCP_METHODS, STAGE2_MODES, OcpMethod  # noqa: F401 (re-exported)
from .solve import OcpSolution, Resimulation, resimulate, solve_min_time

__all__ = [
    "ARRIVAL_TOL_M",
    "DEFAULT_OCP_CONSIST",
    "LIMIT_TOL_KMH",
    "OBJECTIVES",
    "OCP_METHODS",
    "OcpMethod",
    "OcpRun",
    "PROFILE_COLUMNS",
    "SEED000_CLAIMS",
    "SEED000_TABLES",
    "STAGE2_MODES",
    "STUDY_RUNS",
    "Study",
    "TIME_TOL_S",
    "ExactMinimum",
    "check_options",
    "check_output_path",
    "exact_minimum",
    "exact_minimum_time",
    "run_ocp",
    "run_study",
    "solve_ocp",
    "STUDY_COLUMNS",
    "study_cells",
    "study_markdown",
    "traction_energy_kwh",
    "train_problem",
    "write_ocp_output",
    "write_study_output",
]

TIME_TOL_S = 0.05
"""Largest accepted |objective - re-simulated running time| [s]."""
LIMIT_TOL_KMH = 0.1
"""Largest accepted overspeed of the re-simulated train [km/h]."""
ARRIVAL_TOL_M = 0.5
"""A re-simulated train that stops within this distance of the end has arrived [m]."""

SOURCE = "ocp"  # the 'file' of a Problem about a command-line option rather than a file





# --------------------------------------------------------------------------------------------------
# route + train -> problem
# --------------------------------------------------------------------------------------------------


def _merged(sections, value: Callable) -> list[tuple[float, float, float]]:
    """``(from_m, to_m, value)`` runs with equal neighbours merged."""
    runs: list[tuple[float, float, float]] = []
    for sec in sections:
        v = float(value(sec))
        if runs and runs[-1][2] == v and abs(runs[-1][1] - sec.from_m) < 1e-9:
            runs[-1] = (runs[-1][0], sec.to_m, v)
        else:
            runs.append((sec.from_m, sec.to_m, v))
    return runs


def _constant_bound_kn(speed_kmh: np.ndarray, force_kn: np.ndarray, limit_kmh: float) -> tuple[float, bool]:
    """Minimum of a piecewise-linear force curve over ``[0, limit_kmh]`` and whether it is constant there."""
    pts = np.concatenate([[0.0, limit_kmh], speed_kmh[(speed_kmh > 0) & (speed_kmh < limit_kmh)]])
    f = max_force_kn(pts, speed_kmh, force_kn)
    return float(np.min(f)), bool(np.ptp(f) <= 1e-9 * max(1.0, float(np.max(np.abs(f)))))


def train_problem(route, train, route_file: str | Path | None = None) -> MinTimeTrainProblem:
    """The minimum-running-time problem of ``train`` over ``route`` from rest to rest.

    Takes ``train.mass_t`` [t], the Davis coefficients ``train.resistance_kn`` (A [kN], B [kN/(km/h)],
    C [kN/(km/h)^2]), the route's length [m], its one gradient [per mille] (plus the 600/R and tunnel
    terms of a curve / tunnel that covers the whole route) and its one speed limit [km/h], capped by
    the train's ``max_speed_kmh``.

    Force bounds: the problem has constant bounds ``-b_max <= F_u <= f_max`` (seed 000 eq. 34 uses
    -461..532 kN). From a consist's speed-dependent curves they are the *minimum* of the traction /
    brake curve over ``[0, limit]``: a conservative constant that the locomotive can always deliver,
    so a plan is drivable, but slower than one using the full curve where it is higher. The seed-000
    consist has flat curves, for which this is exact. (Speed-dependent bounds would be a path
    constraint ``F_u <= F_max(v)`` in the problem layer and a different exact optimum; not built.)

    ``route_file`` names the route in error messages. Raises :class:`InputError` (file and field)
    when the route has more than one gradient or speed-limit section after merging equal neighbours,
    a curve or tunnel covering only part of it, or a neutral section: the single-phase problem needs
    a constant grade and limit (seed 001's multi-phase problem is a later issue).
    """
    name = str(route_file) if route_file is not None else route.name
    why = ("the single-phase minimum-time problem (seed 000) needs one constant gradient and one speed "
           "limit over the whole route; for such a route use seed 001's multi-phase problem (--objective energy)")
    problems: list[Problem] = []
    grades = _merged(route.gradients, lambda s: s.permille)
    limits = _merged(route.speed_limits, lambda s: s.kmh)
    if len(grades) > 1:
        listed = ", ".join(f"{g:g}" for _, _, g in grades[:6]) + (", ..." if len(grades) > 6 else "")
        problems.append(Problem(name, "gradients", f"{len(grades)} sections with different gradients ({listed} per mille): {why}"))
    if len(limits) > 1:
        listed = ", ".join(f"{v:g}" for _, _, v in limits[:6]) + (", ..." if len(limits) > 6 else "")
        problems.append(Problem(name, "speed_limits", f"{len(limits)} sections with different limits ({listed} km/h): {why}"))
    extra = 0.0
    for i, c in enumerate(route.curves):
        if c.from_m > 1e-9 or c.to_m < route.length_m - 1e-9:
            problems.append(Problem(name, f"curves[{i}]", f"a curve over {c.from_m:g}-{c.to_m:g} m makes the "
                                    "equivalent gradient vary along the route (the single-phase problem needs it constant)"))
        else:
            extra += float(curve_gradient_permille(c.radius_m))
    for i, t in enumerate(route.tunnels):
        if t.from_m > 1e-9 or t.to_m < route.length_m - 1e-9:
            problems.append(Problem(name, f"tunnels[{i}]", f"a tunnel over {t.from_m:g}-{t.to_m:g} m makes the "
                                    "equivalent gradient vary along the route (the single-phase problem needs it constant)"))
        else:
            extra += float(tunnel_gradient_permille(t.to_m - t.from_m))
    if route.neutral_sections:
        problems.append(Problem(name, "neutral_sections", "the minimum-time problem has no traction-free "
                                "zones; remove the neutral sections or use the multi-phase problem (--objective energy, seed 001)"))
    if problems:
        raise InputError(problems)
    limit_kmh = min(limits[0][2], float(train.max_speed_kmh))
    f_max, _ = _constant_bound_kn(np.asarray(train.traction_speed_kmh), np.asarray(train.traction_kn), limit_kmh)
    b_max, _ = _constant_bound_kn(np.asarray(train.brake_speed_kmh), np.asarray(train.brake_kn), limit_kmh)
    return MinTimeTrainProblem(
        mass_t=float(train.mass_t),
        resistance_kn=tuple(float(x) for x in train.resistance_kn),
        f_max_kn=f_max,
        b_max_kn=b_max,
        gradient_permille=grades[0][2] + extra,
        speed_limit_kmh=limit_kmh,
        length_m=float(route.length_m),
    )


def _bounds_note(train, limit_kmh: float) -> str | None:
    notes = []
    for what, sp, f in (("traction", train.traction_speed_kmh, train.traction_kn),
                        ("brake", train.brake_speed_kmh, train.brake_kn)):
        lo, flat = _constant_bound_kn(np.asarray(sp), np.asarray(f), limit_kmh)
        if not flat:
            hi = float(np.max(max_force_kn(np.linspace(0.0, limit_kmh, 201), np.asarray(sp), np.asarray(f))))
            notes.append(f"{what} curve varies over 0-{limit_kmh:g} km/h ({lo:g}-{hi:g} kN); its minimum "
                         f"{lo:g} kN is used as the constant bound")
    return "; ".join(notes) or None


# --------------------------------------------------------------------------------------------------
# exact optimum
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ExactMinimum:
    """The bang-cruise-bang minimum-time run: full traction ``f_max_kn`` for ``accelerate_s`` [s] over
    ``accelerate_m`` [m] to ``peak_speed_ms`` [m/s], cruise ``cruise_s`` at that speed with
    ``cruise_force_kn`` (only if the peak is the limit; NaN otherwise), full brake ``b_max_kn`` for
    ``brake_s`` over ``brake_m``; ``time_s`` is the total."""

    time_s: float
    accelerate_s: float
    accelerate_m: float
    cruise_s: float
    cruise_force_kn: float
    brake_s: float
    brake_m: float
    peak_speed_ms: float
    f_max_kn: float
    b_max_kn: float

    def force_at(self, t) -> np.ndarray:
        """The optimal control [kN] at times ``t`` [s]."""
        t = np.asarray(t, dtype=float)
        return np.where(t < self.accelerate_s, self.f_max_kn,
                        np.where(t < self.accelerate_s + self.cruise_s, self.cruise_force_kn, -self.b_max_kn))


def exact_minimum(problem: MinTimeTrainProblem) -> ExactMinimum:
    """Closed-form minimum running time of ``problem`` (independent of any transcription).

    With constant bounds and resistance growing with speed the optimum is: full traction until the
    limit, cruise at the limit, full brake to rest at the end (Pontryagin, state-constrained
    bang-singular-bang). Times and distances of the full-traction / full-brake phases are
    ``int dv / a(v)`` and ``int v dv / a(v)`` by ``scipy.integrate.quad``. If the route is too short to
    reach the limit (or the train's balancing speed lies below it), the peak speed where the traction
    and brake distances add up to the length is found by ``brentq`` and there is no cruise (if that
    peak is within 1e-9 of the balancing speed, the run is taken to hold that speed with full
    traction in between).
    """
    m, vlim, length = problem.mass_t, problem.speed_limit_ms, problem.length_m

    def acc(v):
        return problem.acceleration(v, problem.f_max_kn)

    def dec(v):
        return -problem.acceleration(v, -problem.b_max_kn)

    def phase(f, v):
        t = quad(lambda w: 1.0 / f(w), 0.0, v, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        s = quad(lambda w: w / f(w), 0.0, v, epsabs=1e-13, epsrel=1e-12, limit=200)[0]
        return t, s

    # the balancing speed (acc = 0) bounds what full traction can reach
    v_top = vlim
    if acc(vlim) <= 0.0:
        v_top = brentq(acc, 0.0, vlim, xtol=1e-14)
    reach_limit = acc(vlim) > 0.0
    if reach_limit:
        ta, sa = phase(acc, vlim)
        tb, sb = phase(dec, vlim)
        if sa + sb <= length:
            cruise_force = problem.resistance(vlim) + problem.grade_force_kn
            tc = (length - sa - sb) / vlim
            return ExactMinimum(ta + tc + tb, ta, sa, tc, float(cruise_force), tb, sb, vlim,
                                problem.f_max_kn, problem.b_max_kn)
    hi = v_top * (1.0 - 1e-9) if not reach_limit else vlim

    def gap(v):
        return sum(phase(f, v)[1] for f in (acc, dec)) - length

    if gap(hi) < 0.0:
        # a long route below the balancing speed: the peak is within 1e-9 of it (beyond float
        # resolution of brentq); run there at (almost) constant speed, an error below 1e-9 relative
        ta, sa = phase(acc, hi)
        tb, sb = phase(dec, hi)
        tc = (length - sa - sb) / hi
        return ExactMinimum(ta + tc + tb, ta, sa, tc, float(problem.f_max_kn), tb, sb, hi,
                            problem.f_max_kn, problem.b_max_kn)
    v_peak = brentq(gap, 1e-9, hi, xtol=1e-14)
    ta, sa = phase(acc, v_peak)
    tb, sb = phase(dec, v_peak)
    return ExactMinimum(ta + tb, ta, sa, 0.0, float("nan"), tb, sb, v_peak, problem.f_max_kn, problem.b_max_kn)


def exact_minimum_time(problem: MinTimeTrainProblem) -> float:
    """The exact minimum running time [s] of ``problem`` (see :func:`exact_minimum`)."""
    return exact_minimum(problem).time_s


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
                "v_kmh": round(float(d["v_ms"][k]) * KMH_PER_MS, 4),
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
    return float(np.sum(0.5 * (power_kw[1:] + power_kw[:-1]) * np.diff(t)) / 3600.0)


def check_options(method: str, nodes, state_nodes, stage2: str = "hp", objective: str = "time") -> tuple[int, int | None]:
    """Validate the options of :func:`solve_ocp` before any file is read or NLP built; returns the
    control-node count (the method's seed default if ``None``) and the state-node count (or ``None``).
    Every problem is reported at once as an :class:`InputError` naming the option."""
    problems: list[Problem] = []
    if objective not in OBJECTIVES:
        problems.append(Problem(SOURCE, "--objective", f"unknown objective {objective!r}; choose one of {', '.join(OBJECTIVES)}"))
    elif OBJECTIVES[objective] is None:
        problems.append(Problem(SOURCE, "--objective", f"'{objective}' is not built yet"))
    spec = OCP_METHODS.get(method)
    if spec is None:
        problems.append(Problem(SOURCE, "--method", f"unknown method {method!r}; choose one of {', '.join(OCP_METHODS)}"))
    elif objective in OBJECTIVES and objective not in spec.objectives:
        fit = [k for k, m in OCP_METHODS.items() if objective in m.objectives]
        problems.append(Problem(SOURCE, "--method", f"{method} solves --objective {'/'.join(spec.objectives)}, not "
                                f"{objective}; use {' or '.join(fit)}"))
        spec = None

    def count(flag: str, value, even: bool = False):
        if value is None:
            return None
        try:
            whole = not isinstance(value, bool) and float(value).is_integer()
        except (TypeError, ValueError):
            whole = False
        if not whole:
            problems.append(Problem(SOURCE, flag, f"must be a whole number, got {value!r}"))
            return None
        n = int(value)
        if not 2 <= n <= _nodes.MAX_NODES:
            problems.append(Problem(SOURCE, flag, f"must be between 2 and {_nodes.MAX_NODES}, got {n}"))
            return None
        if even and n % 2:
            problems.append(Problem(SOURCE, flag, f"the two-stage method pairs the control on the LG points "
                                    f"(U_(2l-1) = U_(2l), seed eq. 26-27), so the state nodes must be even, got {n}"))
            return None
        return n

    n = count("--nodes", nodes)
    m = count("--state-nodes", state_nodes, even=method == "two-stage")
    if spec is not None:
        if m is not None and not spec.has_state_nodes:
            problems.append(Problem(SOURCE, "--state-nodes", f"{method} has no state collocation nodes (RK4 states "
                                    "on the control grid); leave --state-nodes out"))
        if method == "gpm" and m is not None and n is not None and m != n:
            problems.append(Problem(SOURCE, "--state-nodes", f"GPM shares its LG points between states and control: "
                                    f"--state-nodes {m} must equal --nodes {n}"))
        if method == "two-stage" and m is not None and n is not None and m != 2 * n:
            problems.append(Problem(SOURCE, "--state-nodes", f"stage 1 pairs the control, so {m} state nodes give "
                                    f"{m // 2} control nodes, not --nodes {n}"))
        if method == "gpm" and m is not None and n is None:
            n = m
        if method == "two-stage" and m is not None and n is None:
            n = m // 2
        if n is None:
            n = spec.seed_nodes[0]
    if stage2 not in STAGE2_MODES:
        problems.append(Problem(SOURCE, "--stage2", f"unknown stage-2 mode {stage2!r}; choose one of {', '.join(STAGE2_MODES)}"))
    if problems:
        raise InputError(problems)
    return n, m


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
                       f"{rs.distance_at_tf_m:.1f} m, running at {rs.final_speed_ms * KMH_PER_MS:.1f} km/h")
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

    ``method`` is a key of :data:`OCP_METHODS`, ``nodes`` its control-node count (default: the seed's
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
        "force_bounds_note": _bounds_note(train, problem.speed_limit_kmh) if train is not None else None,
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


# --------------------------------------------------------------------------------------------------
# outputs
# --------------------------------------------------------------------------------------------------


def check_output_path(path: str | Path | None, flag: str, suffixes: tuple[str, ...]) -> None:
    """Fail early (before solving) on an output file with the wrong suffix or a missing folder."""
    from ..reporting.files import check_output

    check_output(path, flag, suffixes)


def write_ocp_output(path: str | Path, run: OcpRun) -> None:
    """``--out``: ``.csv`` the re-simulated profile (:data:`PROFILE_COLUMNS`), ``.json`` the summary
    plus the profile's columns. Written whole or not at all."""
    check_output_path(path, "--out", (".csv", ".json"))
    rows = run.profile_rows()
    if Path(path).suffix.lower() == ".csv":
        atomic_write_text(path, rows_csv(rows, PROFILE_COLUMNS))
    else:
        data = dict(run.summary)
        data["profile"] = {c: [r[c] for r in rows] for c in PROFILE_COLUMNS}
        atomic_write_text(path, to_json(data) + "\n")


# --------------------------------------------------------------------------------------------------
# seed 000 Tables 2-3
# --------------------------------------------------------------------------------------------------

STUDY_RUNS: tuple[tuple[str, int, str | None], ...] = (
    ("cvp", 20, None), ("cvp", 40, None),
    ("gpm", 34, None), ("gpm", 48, None),
    ("two-stage", 17, "hp"), ("two-stage", 24, "hp"),
    ("two-stage", 17, "global"), ("two-stage", 24, "global"),
)
"""(method, control nodes, stage 2) of every row, per experiment, in the seed's order."""

SEED000_TABLES: dict[int, dict[tuple[str, int], tuple[float, float, tuple[int, int] | None]]] = {
    # table -> (method, nodes) -> (objective [s], solve time [s], stage-2 (control, state) nodes)
    2: {("cvp", 20): (142.25, 50.41, None), ("cvp", 40): (141.81, 210.63, None),
        ("gpm", 34): (141.81, 8.12, None), ("gpm", 48): (141.62, 19.19, None),
        ("two-stage", 17): (141.74, 5.77, (15, 34)), ("two-stage", 24): (141.59, 12.09, (17, 48))},
    3: {("cvp", 20): (142.26, 63.01, None), ("cvp", 40): (141.83, 238.79, None),
        ("gpm", 34): (141.97, 8.10, None), ("gpm", 48): (141.76, 21.47, None),
        ("two-stage", 17): (141.75, 5.66, (15, 34)), ("two-stage", 24): (141.67, 12.60, (15, 48))},
}
"""Seed 000 Tables 2 (level, test 1) and 3 (30 per mille, test 2) as printed."""

SEED000_CLAIMS = {"cvp": 91.93, "gpm": 33.88}
"""The seed's abstract / conclusion: two-stage solve time lower than CVP / GPM by this many per cent."""

STUDY_ROUTES = {2: "routes/seed000-flat.yaml", 3: "routes/seed000-grade30.yaml"}


def _default_path(rel: str) -> Path:
    """A study route: the file in the current folder when there is one, else the package's copy (the
    default works from any directory and from an installed wheel)."""
    from ..io.load import CATALOGUE

    p = Path(rel)
    shipped = Path(str(CATALOGUE / "routes")) / p.name
    return p if p.exists() or not shipped.exists() else shipped


@dataclass(frozen=True)
class Study:
    """Result of :func:`run_study`: ``rows`` (one SPEC object per run, with ``table``, ``test``,
    ``label``, the seed's values and the median ``solve_time_s``), ``ratios`` (solve-time reductions
    of two-stage vs CVP / GPM, measured and as in the seed), ``exact`` (table -> exact minimum [s]),
    ``runs`` ((table, method, nodes, stage2) -> :class:`OcpRun`, for plots), ``repeats``."""

    rows: list[dict]
    ratios: list[dict]
    exact: dict[int, float]
    repeats: int
    runs: dict = field(repr=False, default_factory=dict)

    def to_dict(self) -> dict:
        return {"results": self.rows, "solve_time_ratios": self.ratios,
                "exact_minimum_s": {f"table {k}": round(v, 4) for k, v in self.exact.items()},
                "repeats": self.repeats}


def _label(method: str, stage2: str | None) -> str:
    spec = OCP_METHODS[method]
    return f"{spec.label} {stage2}" if spec.has_stage2 else spec.label


def _reduction(ts: float, other: float) -> float:
    return 100.0 * (1.0 - ts / other)


def run_study(routes: dict[int, str | Path] | None = None, consist: str | Path = DEFAULT_OCP_CONSIST, *,
              runs=STUDY_RUNS, repeats: int = 1, warmup: bool = True,
              progress: Callable[[str], None] | None = None) -> Study:
    """Reproduce seed 000 Tables 2-3 on this machine.

    ``routes``: table number -> route file (default: 2 -> ``routes/seed000-flat.yaml``, 3 ->
    ``routes/seed000-grade30.yaml``); ``consist``: the seed's HXD1 + C64. Each of ``runs``
    ((method, control nodes, stage 2)) is solved ``repeats`` times and its ``solve_time_s`` is the
    median; the objective and re-simulation are those of the first solve (the solves are
    deterministic). ``warmup`` solves once untimed first, so loading IPOPT is not charged to the first
    row. ``progress(text)`` is called before each run (e.g. to drive a progress bar).

    Ratios: for each table and test (CVP 20 / GPM 34 / two-stage 17 is test 1, CVP 40 / GPM 48 /
    two-stage 24 test 2) the reduction ``1 - t_two-stage / t_other`` in per cent, and their mean over
    the four pairs; the same from the seed's printed times, and the seed's claimed 91.93 % / 33.88 %.
    """
    from ..io.load import load_route, load_train

    if not isinstance(repeats, int) or repeats < 1:
        raise InputError(Problem(SOURCE, "--repeats", f"must be a whole number >= 1, got {repeats!r}"))
    routes = {k: _default_path(v) for k, v in (routes or STUDY_ROUTES).items()}
    train = load_train(consist)
    loaded = {k: (load_route(p), p) for k, p in routes.items()}
    problems = {k: train_problem(r, train, p) for k, (r, p) in loaded.items()}
    if warmup:
        solve_min_time(next(iter(problems.values())), "two-stage", 4)
    rows, store, exact = [], {}, {}
    for table, (route, path) in loaded.items():
        problem = problems[table]
        exact[table] = exact_minimum_time(problem)
        seen: dict[tuple, int] = {}
        for method, nodes, stage2 in runs:
            key = (method, stage2)
            seen[key] = seen.get(key, 0) + 1
            test = seen[key]
            if progress:
                progress(f"table {table}: {_label(method, stage2)} {nodes}")
            first = solve_ocp(route, train, method, nodes, stage2=stage2 or "hp", route_file=path, problem=problem)
            times = [first.solution.solve_time_s]
            for _ in range(repeats - 1):  # timing only: the solves are deterministic, re-simulate once
                kwargs = {"stage2": stage2} if stage2 else {}
                times.append(solve_min_time(problem, method, nodes, **kwargs).solve_time_s)
            row = dict(first.summary)
            row.pop("sequence", None)
            seed = SEED000_TABLES.get(table, {}).get((method, nodes))
            row.update({
                "table": table, "test": test, "label": _label(method, stage2),
                "solve_time_s": round(statistics.median(times), 4),
                "solve_times_s": [round(t, 4) for t in times],
                "seed_objective_s": seed[0] if seed else None,
                "seed_solve_time_s": seed[1] if seed else None,
                "seed_stage2_nodes": list(seed[2]) if seed and seed[2] else None,
            })
            rows.append(row)
            store[table, method, nodes, stage2] = first
    return Study(rows, _ratios(rows), exact, repeats, store)


def _ratios(rows: list[dict]) -> list[dict]:
    by = {(r["table"], r["algorithm"], r["control_nodes"], r["stage2"]): r for r in rows}
    out = []
    for stage2 in ("hp", "global"):
        for other, pairs in (("cvp", ((17, 20), (24, 40))), ("gpm", ((17, 34), (24, 48)))):
            per_test = []
            for table in sorted({r["table"] for r in rows}):
                for test, (n_ts, n_other) in enumerate(pairs, start=1):
                    a = by.get((table, "two-stage", n_ts, stage2))
                    b = by.get((table, other, n_other, None))
                    if a is None or b is None:
                        continue
                    seed_t = SEED000_TABLES.get(table, {})
                    seed_pct = None
                    if ("two-stage", n_ts) in seed_t and (other, n_other) in seed_t:
                        seed_pct = round(_reduction(seed_t["two-stage", n_ts][1], seed_t[other, n_other][1]), 2)
                    per_test.append({"table": table, "test": test, "two_stage_nodes": n_ts, "other_nodes": n_other,
                                     "two_stage_s": a["solve_time_s"], "other_s": b["solve_time_s"],
                                     "percent": round(_reduction(a["solve_time_s"], b["solve_time_s"]), 2),
                                     "seed_percent": seed_pct})
            if not per_test:
                continue
            seeds = [p["seed_percent"] for p in per_test if p["seed_percent"] is not None]
            out.append({
                "two_stage": stage2, "versus": other,
                "per_test": per_test,
                "mean_percent": round(statistics.fmean(p["percent"] for p in per_test), 2),
                "seed_tables_mean_percent": round(statistics.fmean(seeds), 2) if seeds else None,
                "seed_claim_percent": SEED000_CLAIMS[other],
            })
    return out


STUDY_COLUMNS = ("table", "method", "test", "u / x nodes", "stage 2 u / x", "objective", "re-simulated",
                 "- exact", "solve time", "confirmed", "seed objective", "seed solve time")
"""Column heads of :func:`study_cells` (times in s)."""


def study_cells(row: dict) -> list[str]:
    """One study row as the strings of :data:`STUDY_COLUMNS` (shared by the CLI table and markdown)."""
    def f(x, nd):
        return "-" if x is None else f"{x:.{nd}f}"

    nodes = f"{row['control_nodes']}" + (f" / {row['state_nodes']}" if row["state_nodes"] else "")
    st2 = "-"
    if row["algorithm"] == "two-stage":
        st2 = f"{row['final_control_nodes']} / {row['final_state_nodes']}, {row['segments']} seg."
    seed_n = row.get("seed_stage2_nodes")
    if seed_n:
        st2 += f" (seed {seed_n[0]} / {seed_n[1]})"
    return [
        str(row["table"]), row["label"], str(row["test"]), nodes, st2,
        f(row["objective"], 3), f(row["resimulated_running_time_s"], 3),
        "-" if row["gap_to_exact_s"] is None else f"{row['gap_to_exact_s']:+.3f}",
        f(row["solve_time_s"], 3),
        "yes" if row["feasible"] else "no",
        f(row.get("seed_objective_s"), 2), f(row.get("seed_solve_time_s"), 2),
    ]


def study_markdown(study: Study) -> str:
    """The study as markdown: the table, the exact minima, the ratios, and why rows are unconfirmed."""
    heads = ["Table", "method", "test", "u / x nodes", "stage-2 u / x nodes", "objective [s]",
             "re-simulated [s]", "objective - exact [s]", "solve time [s]", "confirmed",
             "seed objective [s]", "seed solve time [s]"]
    lines = ["| " + " | ".join(heads) + " |", "|" + "|".join(["---"] * len(heads)) + "|"]
    for row in study.rows:
        lines.append("| " + " | ".join(study_cells(row)) + " |")
    lines.append("")
    lines.append("Exact minimum (accelerate / cruise / brake, `scipy.integrate.quad`): "
                 + ", ".join(f"Table {k}: {v:.4f} s" for k, v in study.exact.items()) + ".")
    lines.append("")
    lines.append("| two-stage | faster than | per pair (Table-test: measured % / seed %) | mean measured | "
                 "mean of the seed's tables | seed's claim |")
    lines.append("|---|---|---|---|---|---|")
    for r in study.ratios:
        pairs = ", ".join(f"{p['table']}-{p['test']}: {p['percent']:.1f} / {p['seed_percent']:.1f}"
                          if p["seed_percent"] is not None else f"{p['table']}-{p['test']}: {p['percent']:.1f}"
                          for p in r["per_test"])
        lines.append(f"| {r['two_stage']} | {r['versus'].upper()} | {pairs} | {r['mean_percent']:.1f} % | "
                     f"{r['seed_tables_mean_percent']:.2f} % | {r['seed_claim_percent']:.2f} % |")
    rejected = [r for r in study.rows if not r["feasible"]]
    if rejected:
        lines.append("")
        lines.append("Unconfirmed rows (re-simulation of the clipped control):")
        lines.append("")
        for r in rejected:
            lines.append(f"- Table {r['table']}, {r['label']} {r['control_nodes']}: {r['reason']}")
    return "\n".join(lines) + "\n"


def write_study_output(path: str | Path, study: Study) -> None:
    """``ocp-study --out``: ``.json`` the whole study, ``.csv`` one line per row, ``.md`` the markdown."""
    check_output_path(path, "--out", (".json", ".csv", ".md"))
    suffix = Path(path).suffix.lower()
    if suffix == ".json":
        atomic_write_text(path, to_json(study.to_dict()) + "\n")
    elif suffix == ".md":
        atomic_write_text(path, study_markdown(study))
    else:
        cols = ["table", "test", "label", "algorithm", "stage2", "control_nodes", "state_nodes",
                "final_control_nodes", "final_state_nodes", "segments", "objective", "resimulated_running_time_s",
                "exact_minimum_s", "gap_to_exact_s", "solve_time_s", "feasible", "max_limit_violation_kmh",
                "seed_objective_s", "seed_solve_time_s", "reason"]
        atomic_write_text(path, rows_csv(study.rows, cols))
