"""Control vector parameterisation (CVP): the baseline of the two-stage Gauss paper (section 5, Tables 2-3).

A method of its own, on the same free-end single-phase problem as the Gauss transcription
(:class:`~locoplan.ocp.phase.MultiPhaseProblem` with ``free_end``): ``M`` control values on a uniform
grid over ``[0, t_f]``, piecewise linear in between, and the states integrated by fixed-step RK4
inside CasADi (single shooting), so IPOPT gets exact derivatives by automatic differentiation.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..errors import InputError
from . import nodes as _nodes
from .interrupt import solve_nlp
from .nlp import Guess, as_column, final_bounds, ipopt_solver, phase_functions
from .phase import MultiPhaseProblem

__all__ = ["CvpSolution", "solve_cvp"]


@dataclass(frozen=True)
class CvpSolution:
    """Raw result of a CVP solve: control values ``params`` (``n_u x M``) on the uniform grid
    ``grid`` (``M`` times, ``0 .. t_f``), piecewise linear in between; ``step_times`` / ``step_states``
    are the fixed-step RK4 points (``n_x x len(step_times)``)."""

    success: bool
    status: str
    iterations: int
    objective: float
    final_time: float
    grid: np.ndarray
    params: np.ndarray
    step_times: np.ndarray
    step_states: np.ndarray
    solve_time_s: float
    build_time_s: float
    substeps: int


def _augmented(dynamics, lagrange, path, n_path: int, nx: int, nu: int):
    """The dynamics with the running cost as one more state (``f(x, u, t)``, nx + 1 rows), and the path constraints
    as a CasADi function (None without)."""
    xs_, us_, t_ = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("t")
    rhs = as_column(dynamics(xs_, us_, t_), nx, "dynamics")
    if lagrange is not None:
        rhs = ca.vertcat(rhs, as_column(lagrange(xs_, us_, t_), 1, "lagrange"))
    else:
        rhs = ca.vertcat(rhs, 0)
    f_aug = ca.Function("f", [xs_, us_, t_], [rhs])
    path_fun = None
    if path is not None:
        path_fun = ca.Function("p", [xs_, us_, t_], [as_column(path(xs_, us_, t_), n_path, "path")])
    return f_aug, path_fun


def _interval(f_aug, nx: int, nu: int, substeps: int):
    """One grid interval: ``substeps`` classical RK4 steps of the augmented system with the control going linearly
    from u0 to u1; the augmented state after every step (nx + 1 x substeps)."""
    xa, ua0, ua1, th, hh = ca.SX.sym("xa", nx + 1), ca.SX.sym("u0", nu), ca.SX.sym("u1", nu), ca.SX.sym("t"), ca.SX.sym("h")
    um = 0.5 * (ua0 + ua1)
    k1 = f_aug(xa[:nx], ua0, th)
    k2 = f_aug(xa[:nx] + 0.5 * hh * k1[:nx], um, th + 0.5 * hh)
    k3 = f_aug(xa[:nx] + 0.5 * hh * k2[:nx], um, th + 0.5 * hh)
    k4 = f_aug(xa[:nx] + hh * k3[:nx], ua1, th + hh)
    rk4 = ca.Function("rk4", [xa, ua0, ua1, th, hh], [xa + hh / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)])
    xi, ui0, ui1, ti, hi = ca.SX.sym("x", nx + 1), ca.SX.sym("u0", nu), ca.SX.sym("u1", nu), ca.SX.sym("t"), ca.SX.sym("h")
    cols, xc = [], xi
    for i in range(substeps):
        a, b = i / substeps, (i + 1) / substeps
        xc = rk4(xc, (1 - a) * ui0 + a * ui1, (1 - b) * ui0 + b * ui1, ti + i * hi, hi)
        cols.append(xc)
    return ca.Function("interval", [xi, ui0, ui1, ti, hi], [ca.horzcat(*cols)])


def _path_rows(path_fun, p_phys, states, h, m: int, substeps: int, n_path: int):
    """The path constraints at every RK4 step's end (the control there interpolated linearly between the grid
    values): (g, lower, upper)."""
    n_steps = (m - 1) * substeps
    step_t = h * ca.DM(np.arange(1, n_steps + 1)).T
    frac = np.arange(1, n_steps + 1) / substeps  # position in grid units
    jj = np.minimum(np.floor(frac - 1e-12).astype(int), m - 2)
    aa = frac - jj
    w_mat = np.zeros((m, n_steps))
    w_mat[jj, np.arange(n_steps)] = 1 - aa
    w_mat[jj + 1, np.arange(n_steps)] = aa
    u_steps = p_phys @ ca.DM(w_mat)
    return (ca.vec(path_fun.map(n_steps)(states, u_steps, step_t)), np.full(n_path * n_steps, -np.inf),
            np.zeros(n_path * n_steps))


def _start(problem: MultiPhaseProblem, phase, guess: Guess, su, ts: float, m: int):
    """The NLP's start and bounds (the final time scaled by ``ts``, the control values by ``su``): (x0, lbx, ubx,
    the grid on [0, 1])."""
    tf_lo, tf_hi = (float(v) for v in problem.free_end)
    tf0 = float(np.clip(guess.final_time, tf_lo, tf_hi))
    grid_sigma = np.linspace(0.0, 1.0, m)
    u_lo = np.array(phase.control_lower, dtype=float) / su
    u_hi = np.array(phase.control_upper, dtype=float) / su
    p0 = np.clip(guess.control_at(grid_sigma) / su[:, None], u_lo[:, None], u_hi[:, None])
    lbx = np.concatenate(([tf_lo / ts], np.repeat(u_lo[:, None], m, 1).ravel(order="F")))
    ubx = np.concatenate(([tf_hi / ts], np.repeat(u_hi[:, None], m, 1).ravel(order="F")))
    x0 = np.concatenate(([tf0 / ts], p0.ravel(order="F")))
    return x0, lbx, ubx, grid_sigma


def solve_cvp(
    problem: MultiPhaseProblem,
    n_params: int,
    guess: Guess,
    *,
    substeps: int = 4,
    ipopt_options: dict | None = None,
) -> CvpSolution:
    """Control vector parameterisation (single shooting): ``n_params`` control values on a uniform
    grid over ``[0, t_f]`` with linear interpolation in between; the states are integrated by a fixed
    classical RK4 scheme (``substeps`` steps per grid interval) inside CasADi, so IPOPT gets exact
    derivatives by automatic differentiation. State bounds and path constraints are imposed at every
    RK4 point, the final-state conditions as equality constraints. Needs a fixed initial state.
    """
    t_build = _time.perf_counter()
    m = _nodes._check_n(n_params, "CVP control grid")
    substeps = int(substeps)
    if substeps < 1:
        raise InputError(f"CVP: substeps must be >= 1, got {substeps}")
    if any(v is None for v in problem.initial_state):
        raise InputError("CVP (single shooting) needs every initial state fixed")
    phase, dynamics, lagrange, path, n_path, nx, nu, sx, su, ts = phase_functions(problem)
    f_aug, path_fun = _augmented(dynamics, lagrange, path, n_path, nx, nu)
    interval = _interval(f_aug, nx, nu, substeps)

    tf_s = ca.MX.sym("tf")
    p_s = ca.MX.sym("P", nu, m)
    tf = tf_s * ts
    p_phys = ca.diag(ca.DM(su)) @ p_s
    dt = tf / (m - 1)
    h = dt / substeps
    x = ca.vertcat(ca.DM([float(v) for v in problem.initial_state]), 0.0)
    traj = [x]
    for j in range(m - 1):
        steps = interval(x, p_phys[:, j], p_phys[:, j + 1], j * dt, h)
        traj.append(steps)
        x = steps[:, -1]
    traj_m = ca.horzcat(*traj)  # nx+1 x (1 + (m-1) substeps)
    states = traj_m[:nx, 1:]
    n_steps = (m - 1) * substeps
    g_parts = [ca.vec(ca.diag(ca.DM(1.0 / sx)) @ states)]
    lo_all = np.repeat((np.array(phase.state_lower, dtype=float) / sx)[:, None], n_steps, 1)
    hi_all = np.repeat((np.array(phase.state_upper, dtype=float) / sx)[:, None], n_steps, 1)
    f_lo, f_hi = final_bounds(problem)  # the final conditions replace the last bound column
    lo_all[:, -1], hi_all[:, -1] = f_lo / sx, f_hi / sx
    lbg, ubg = [lo_all.ravel(order="F")], [hi_all.ravel(order="F")]
    if path_fun is not None:
        g, lo, hi = _path_rows(path_fun, p_phys, states, h, m, substeps, n_path)
        g_parts.append(g)
        lbg.append(lo)
        ubg.append(hi)

    objective = x[nx]
    if problem.mayer is not None:
        x0 = ca.DM([float(v) for v in problem.initial_state])
        objective = objective + as_column(problem.mayer(x0, x[:nx], tf), 1, "mayer")
    w = ca.vertcat(tf_s, ca.vec(p_s))
    nlp = {"x": w, "f": objective / problem.objective_scale, "g": ca.vertcat(*g_parts)}
    solver = ipopt_solver("cvp", nlp, ipopt_options)
    build_time = _time.perf_counter() - t_build

    x0, lbx, ubx, grid_sigma = _start(problem, phase, guess, su, ts, m)
    t_solve = _time.perf_counter()
    sol = solve_nlp(solver, x0=x0, lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    solve_time = _time.perf_counter() - t_solve
    stats = solver.stats()

    out = ca.Function("out", [w], [tf, p_phys, traj_m])
    tf_v, p_v, traj_v = (np.asarray(v, dtype=float) for v in out(sol["x"]))
    tf_v = float(np.ravel(tf_v)[0])
    return CvpSolution(
        success=bool(stats.get("success", False)),
        status=str(stats.get("return_status", "unknown")),
        iterations=int(stats.get("iter_count", -1)),
        objective=float(np.ravel(np.asarray(sol["f"]))[0]) * problem.objective_scale,
        final_time=tf_v,
        grid=grid_sigma * tf_v,
        params=p_v.reshape(nu, m),
        step_times=np.linspace(0.0, tf_v, n_steps + 1),
        step_states=traj_v[:nx, :],
        solve_time_s=solve_time,
        build_time_s=build_time,
        substeps=substeps,
    )
