"""Solve the MPOC paper's minimum-energy problem with hp mesh refinement (the MPOC solver).

Layer 4 of the multi-phase stack. :func:`solve_energy` takes a
:class:`~locoplan.ocp.train_energy.TrainEnergyProblem`, starts from a plan the traction calculator
already has (the least-energy traction / cruise / coast / brake plan near the asked time, a batch of
a few hundred plans evaluated at once), and alternates LGR solves and mesh refinement
(``mesh.refine``) until every interval's relative error is below the tolerance, each solve warm-
started from the previous solution. The history of meshes is kept for the report.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InfeasibleError
from ..physics.units import KJ_PER_KWH, kinetic_e
from ..sim.calculator import TractionCalculator
from .mesh import Mesh, RefineSettings, initial_mesh, refine
from .radau import RadauSolution, RadauTranscription, control_activity, interval_errors, on_state_bound
from .train_energy import DEFAULT_MAX_DEGREE, DEFAULT_MESH_TOL, TrainEnergyProblem

INITIAL_DEGREE = 5
INITIAL_MAX_INTERVAL_M = 500.0
END_INTERVAL_M = 200.0
MAX_MESH_ITERATIONS = 12
WARM_IPOPT = {"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6, "ipopt.warm_start_bound_push": 1e-8,
              "ipopt.warm_start_mult_bound_push": 1e-8, "ipopt.warm_start_slack_bound_push": 1e-8}
"""IPOPT starting from a solution on a neighbouring mesh (primal values and multipliers)."""
WARM_MAX_ITER = 150
"""Iterations allowed to a solve started from the previous mesh's solution, and to its plain restart
on the same mesh: the ones that converge take 5-80; one that has not by 150 has gone astray (on
CH_Fribourg_Bern, 5200 t, two such solves ran to IPOPT's 500 twice each: 30 of 37 s) and the
fallback below (the same intervals with nothing held or moving) is tried sooner."""
ARC_SHARE = 1e-2
"""For the refinement, a control within this share of its scale of a bound is on it (switches and held
arcs): the interior-point solve leaves a bound whose multiplier is small (a full-braking arc whose exact
force barely changes the energy) a few tenths of a per cent off it, and such an arc unrecognised leaves its
switch free to spread over the points around it; the plan's reading takes the same share for no force
(``to_plan.IDLE_SHARE``)."""
ENERGY_STOP_MAX_ERROR = 3e-3
"""With ``energy_tol``: the largest relative dynamics error at which a settled objective ends refinement."""
_GOOD = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
_FAILED = {"Infeasible_Problem_Detected", "Restoration_Failed", "Error_In_Step_Computation",
           "Maximum_Iterations_Exceeded", "Invalid_Number_Detected"}


@dataclass(frozen=True)
class MeshStep:
    """One NLP solve of the refinement: its mesh, the largest relative error found on it, the
    objective [kWh], IPOPT's iterations and status, build and solve time [s], what refinement did."""

    iteration: int
    intervals: int
    points: int
    max_error: float
    objective_kwh: float
    ipopt_iterations: int
    status: str
    build_time_s: float
    solve_time_s: float
    split: int = 0
    raised: int = 0

    def to_dict(self) -> dict:
        return {"iteration": self.iteration, "intervals": self.intervals, "points": self.points,
                "max_error": float(f"{self.max_error:.3g}"), "objective_kwh": round(self.objective_kwh, 4),
                "ipopt_iterations": self.ipopt_iterations, "status": self.status,
                "build_time_s": round(self.build_time_s, 4), "solve_time_s": round(self.solve_time_s, 4),
                "split": self.split, "raised": self.raised}


@dataclass
class EnergySolution:
    """The refined NLP solution: ``solution`` on the final mesh, ``history`` of every mesh, whether the
    tolerance was reached, the objective [kWh] and the total wall time [s] (building included)."""

    tep: TrainEnergyProblem
    solution: RadauSolution
    history: list[MeshStep]
    converged: bool
    wall_time_s: float
    guess_plan: str = ""
    errors: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def objective_kwh(self) -> float:
        return self.solution.objective / KJ_PER_KWH

    @property
    def slope_kwh_per_s(self) -> float | None:
        """dE*/dT [kWh/s] (negative: a second more saves energy): minus the multiplier of the running
        time's bound ``t_f <= T``, in physical units (IPOPT's ``lam_x`` of the final time, unscaled);
        None when the bound is not active or there are no multipliers."""
        sol = self.solution
        if sol is None or sol.lam_x is None or sol.lam_x.size == 0:
            return None
        nx, npts = sol.X.shape
        lam = float(sol.lam_x[nx * (npts - 1) + 1])
        model = self.tep.problem.model
        return -lam * float(self.tep.problem.objective_scale) / float(model.state_scale[1]) / KJ_PER_KWH

    @property
    def accuracy(self) -> float | None:
        """The objective's estimated relative accuracy: how much it moved over the last refinement
        (``|E_k - E_k-1| / E_k`` of the last two solved meshes); after a single solve that met the
        tolerance, that mesh's error estimate; None when neither is known."""
        good = [h for h in self.history if h.status in _GOOD]
        if len(good) < 2:
            return float(good[-1].max_error) if good and self.converged else None
        e1, e0 = good[-1].objective_kwh, good[-2].objective_kwh
        return float(abs(e1 - e0) / max(abs(e1), 1e-9))

    @property
    def success(self) -> bool:
        return self.solution.success


# --------------------------------------------------------------------------------------------------
# initial guess from the calculator
# --------------------------------------------------------------------------------------------------


def calculator_guess(calc: TractionCalculator, time_s: float):
    """The least-energy plan among traction / cruise (at a grid of speeds) / coast / brake plans that
    runs within 1 % of ``time_s`` (else the one closest in time), as a guess ``s -> (X, U)`` and its
    plan text. One batch of calculator runs."""
    L = calc.route.length_m
    v_top = float(np.max(calc.limit_kmh))
    speeds = np.linspace(0.35, 1.0, 14) * v_top
    coast = np.linspace(0.2, 0.98, 14) * L
    V, X = (a.ravel() for a in np.meshgrid(speeds, coast))
    res = calc.evaluate(("T", "C", "B"), np.column_stack([X, np.full_like(X, np.nan)]), cruise_kmh=V)
    ok = res.feasible & np.isfinite(res.running_time_s)
    if not ok.any():
        res = calc.evaluate(("T",), np.zeros((1, 0)))
        V, X, ok = np.array([np.nan]), np.array([np.nan]), np.array([bool(res.feasible[0])])
        sw, conds, cruise = np.zeros((1, 0)), ("T",), None
    else:
        sw, conds = None, ("T", "C", "B")
    t = np.where(ok, res.running_time_s, np.inf)
    near = ok & (np.abs(t - time_s) <= 0.01 * time_s)
    i = int(np.argmin(np.where(near, res.traction_energy_kwh, np.inf))) if near.any() else int(np.argmin(np.abs(t - time_s)))
    if sw is None:
        sw = np.array([[X[i], np.nan]])
        cruise = [V[i]]
    prof = calc.evaluate(conds, sw, profile=True, cruise_kmh=cruise).profile
    s_nodes = prof.s_m
    e_nodes = kinetic_e(prof.v_kmh[0])
    t_nodes = prof.t_s[0]
    # a slower guess than asked: stretch its clock so that it arrives on time
    if np.isfinite(t_nodes[-1]) and t_nodes[-1] > time_s:
        t_nodes = t_nodes * (time_s / t_nodes[-1])
    mid = 0.5 * (s_nodes[1:] + s_nodes[:-1])
    f_cell, b_cell = prof.traction_kn[0], prof.brake_kn[0]
    text = "T,C,B" if conds == ("T", "C", "B") else "T"
    if cruise is not None:
        text = f"T (cruise {cruise[0]:.1f} km/h), C:{sw[0, 0]:.0f}, B"

    def guess(s, n_controls: int):
        s = np.asarray(s, dtype=float)
        xg = np.vstack([np.interp(s, s_nodes, e_nodes), np.interp(s, s_nodes, t_nodes)])
        f = np.interp(s, mid, f_cell)
        b = np.interp(s, mid, b_cell)
        ug = [f, b] + ([np.zeros_like(s)] if n_controls == 3 else [])
        return xg, np.vstack(ug)

    return guess, text


# --------------------------------------------------------------------------------------------------
# solve with refinement
# --------------------------------------------------------------------------------------------------


def solve_energy(tep: TrainEnergyProblem, calc: TractionCalculator, *, mesh_tol: float = DEFAULT_MESH_TOL,
                 max_degree: int = DEFAULT_MAX_DEGREE, max_iterations: int = MAX_MESH_ITERATIONS,
                 warm: RadauSolution | None = None, mesh: Mesh | None = None,
                 ipopt_options: dict | None = None, energy_tol: float | None = None,
                 end_interval_m: float = END_INTERVAL_M, interval_m: float = INITIAL_MAX_INTERVAL_M,
                 degree: int = INITIAL_DEGREE) -> EnergySolution:
    """Minimum energy of ``tep`` by LGR collocation and hp refinement to ``mesh_tol``.

    ``interval_m``, ``degree``, ``end_interval_m``: a cold start's mesh: intervals at most ``interval_m``
    long with ``degree`` LGR points, the first and last (the departure from rest and the stop) at most
    ``end_interval_m``. ``energy_tol``: also stop once the objective moved by at most this share over a
    refinement while no interval's error exceeds ``ENERGY_STOP_MAX_ERROR`` (E* is wanted to a relative
    accuracy, and the last intervals the dynamics tolerance would split barely move it).

    ``warm``: a solution of a neighbouring problem (another running time, the same route) to start
    from, with its final ``mesh``; otherwise the calculator's best simple plan near the asked time.
    Raises :class:`InfeasibleError` when IPOPT finds no solution on the first mesh.
    """
    t_wall = _time.perf_counter()
    problem = tep.problem
    settings = RefineSettings(tol=mesh_tol, max_degree=max_degree)
    nu = problem.model.n_u
    if warm is not None:
        guess_text = "a neighbouring solution"
        stretch = tep.time_s / float(warm.X[1, -1]) if warm.X[1, -1] > 0 else 1.0

        def guess(s, n_controls):  # another running time: its clock stretched to this one
            x = warm.states_at(s)
            x[0] /= stretch ** 2
            x[1] *= stretch
            return x, warm.controls_at(s)
        mesh = mesh or warm.mesh.plain()
    else:
        g, guess_text = calculator_guess(calc, tep.time_s)

        def guess(s, n_controls):
            return g(s, n_controls)
        mesh = mesh or initial_mesh(problem.phases, degree, interval_m, problem.rest_start, problem.rest_end,
                                    end_interval_m)
    history: list[MeshStep] = []
    best: RadauSolution | None = None
    errors = np.zeros(0)
    converged = False
    last = None
    su = np.asarray(problem.model.control_scale, dtype=float)[:, None]
    for it in range(1, max_iterations + 1):
        opts = dict(ipopt_options or {})
        if last is not None:
            opts = {**WARM_IPOPT, "ipopt.max_iter": WARM_MAX_ITER, **opts}
        nlp = RadauTranscription(problem, mesh, opts)
        X0 = guess(nlp.grid.s_points, nu)[0]
        U0 = guess(nlp.grid.s_col, nu)[1]
        sol = nlp.solve(X0, U0, warm=last)
        for fallback in (mesh, mesh.plain()):
            if sol.success or last is None:
                break
            # a warm start gone astray, or arcs held wrongly: the same mesh started plainly, then the
            # same intervals with nothing held or moving
            capped = {"ipopt.max_iter": WARM_MAX_ITER} if fallback is mesh else {}
            mesh = fallback
            nlp = RadauTranscription(problem, mesh, {**capped, **(ipopt_options or {})})
            retry = nlp.solve(X0, U0)
            sol = replace(retry, build_time_s=sol.build_time_s + retry.build_time_s,
                          solve_time_s=sol.solve_time_s + retry.solve_time_s, iterations=sol.iterations + retry.iterations)
        if not sol.success and best is None:
            comfort = (f" within the comfort bound of {tep.energy.comfort_ms2:g} m/s^2 (the fastest run does not keep it)"
                       if tep.energy.comfort_ms2 is not None else "")
            raise InfeasibleError(f"IPOPT found no minimum-energy run in {tep.time_s:g} s on {tep.route.name}{comfort} "
                                  f"({sol.status}); the fastest run takes {calc.fastest_time_s:.1f} s")
        if not sol.success:  # keep the last good mesh's solution
            history.append(MeshStep(it, len(mesh.intervals), mesh.n_points, float("nan"), sol.objective / KJ_PER_KWH,
                                    sol.iterations, sol.status, sol.build_time_s, sol.solve_time_s))
            break
        best = sol
        errors = interval_errors(sol)
        emax = float(np.max(errors))
        step = MeshStep(it, len(mesh.intervals), mesh.n_points, emax, sol.objective / KJ_PER_KWH, sol.iterations,
                        sol.status, sol.build_time_s, sol.solve_time_s)
        prev = next((h.objective_kwh for h in reversed(history) if h.status in _GOOD), None)
        settled = (energy_tol is not None and prev is not None and emax <= ENERGY_STOP_MAX_ERROR
                   and abs(step.objective_kwh - prev) <= energy_tol * max(abs(step.objective_kwh), 1e-9))
        if emax <= mesh_tol or settled:
            history.append(step)
            converged = True
            break
        lower, upper = control_activity(sol, ARC_SHARE)
        mesh, done = refine(sol.mesh, errors, sol.grid.s_col, sol.U / su, sol.grid.offsets, settings, lower, upper,
                            on_state_bound(sol))
        history.append(MeshStep(**{**step.__dict__, "split": done["split"], "raised": done["raised"]}))
        last = sol

        def guess(s, n_controls, last=last):
            return last.states_at(s), last.controls_at(s)
    return EnergySolution(tep, best, history, converged, _time.perf_counter() - t_wall, guess_text, errors)
