"""Solve the minimum-time train problem and check the answer by re-simulation.

On the shared machinery (problem: ``phase.MultiPhaseProblem``, mesh: ``mesh.Mesh``, transcriptions:
``gauss``, method ``cvp``); one function per method in :data:`METHOD_SOLVERS`. Methods (the two-stage Gauss paper's
section 5, Tables 2-3):

* ``"gpm"``: the classical Gauss pseudospectral method, one global interval, ``nodes`` LG points for
  both the states and the control.
* ``"two-stage"``: the paper's two-stage adaptive Gauss re-collocation. Stage 1: ``2 * nodes`` LG
  points for the states, the control paired ``U_{2l-1} = U_{2l}`` (``nodes`` control values, eq.
  26-27). Stage 2: slope change ``S`` (eq. 28) with ``eps_U = eps_L = eps`` (0.04), subdivide where
  ``S >= eps_U``, merge where ``S <= eps_L`` (eq. 29-31), then re-solve warm-started from stage 1.
  ``stage2="global"`` keeps the single global interval exactly as in the paper; ``stage2="hp"``
  (default, our extension) also cuts the *state* mesh at the detected jumps into segments whose
  break points are NLP variables (a moving hp mesh, see
  :func:`~locoplan.ocp.recollocation.recollocate`), and merges the control to one value per smooth
  segment (eq. 31). A single global polynomial cannot resolve the bang-bang optimum to 0.02 s; the
  hp mesh puts a break point on each switch and reproduces the exact optimum. If a break point ends
  on its bound, stage 2 is re-solved with the break points free in (0, 1) (Fig. 4's re-selection);
  if stage 2 fails the stage-1 solution is returned with a note in ``status``.
* ``"cvp"``: control vector parameterisation: ``nodes`` control values on a uniform grid, piecewise
  linear, states by fixed-step RK4 inside CasADi (exact derivatives by AD), same IPOPT.

:func:`resimulate` integrates the solved control (the method's own interpolant) with
``scipy.integrate.solve_ivp`` and reports running time, distance, final speed and overspeed.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..errors import InfeasibleError, InputError
from ..physics.units import kmh
from . import nodes as _nodes
from .cvp import solve_cvp
from .gauss import GaussSolution, paired_control_map, single_mesh, solve_gauss
from .mesh import Mesh
from .min_time import MinTimeTrainProblem
from .recollocation import recollocate

__all__ = [
    "METHODS",
    "ControlPiece",
    "OcpSolution",
    "Resimulation",
    "StageReport",
    "resimulate",
    "solve_min_time",
]

DEFAULT_NODES = {"gpm": 34, "two-stage": 17, "cvp": 20}
_INFEASIBLE = {"Infeasible_Problem_Detected", "Restoration_Failed"}


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ControlPiece:
    """The control on ``[t0, t1]``: ``kind="lagrange"`` is the polynomial through ``(times, values)``
    (a GPM segment's LG points), ``kind="linear"`` the piecewise-linear interpolant (CVP grid)."""

    t0: float
    t1: float
    kind: str
    times: np.ndarray
    values: np.ndarray

    @cached_property
    def _barycentric(self) -> tuple[np.ndarray, np.ndarray]:
        """Nodes on [-1, 1] and their barycentric weights, computed once (the re-simulation calls the
        control thousands of times)."""
        tau_nodes = 2.0 * (self.times - self.t0) / (self.t1 - self.t0) - 1.0
        return tau_nodes, _nodes.barycentric_weights(tau_nodes)

    def __call__(self, t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        if self.kind == "linear":
            return np.interp(t, self.times, self.values)
        x, lam = self._barycentric
        tau = 2.0 * (t - self.t0) / (self.t1 - self.t0) - 1.0
        diff = tau[:, None] - x[None, :]
        exact = diff == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            terms = lam[None, :] / diff
            out = (terms @ self.values) / terms.sum(axis=1)  # second barycentric formula
        hit = exact.any(axis=1)
        if hit.any():  # at a node the interpolant is the nodal value
            out[hit] = self.values[exact[hit].argmax(axis=1)]
        return out


@dataclass(frozen=True)
class StageReport:
    """One NLP solve inside a method (two-stage has two)."""

    name: str
    objective_s: float
    control_nodes: int
    state_nodes: int
    segments: int
    iterations: int
    status: str
    solve_time_s: float


@dataclass(frozen=True)
class OcpSolution:
    """Result of :func:`solve_min_time`.

    ``objective_s`` is the NLP's ``t_f``. ``time_s``, ``position_m``, ``speed_ms`` and ``control_kn``
    are the values at the method's nodes (GPM / two-stage: ``t = 0``, the LG points of every segment
    and ``t_f``; CVP: the uniform grid); the control at ``t = 0`` / ``t_f`` / segment ends of a
    pseudospectral method is its interpolant's value there (clipped to the bounds).
    ``control_nodes`` / ``state_nodes`` count the NLP's control parameters / state collocation
    points of the final stage. ``solve_time_s`` is the wall time of the whole call (building and
    solving every stage); ``iterations`` adds up IPOPT iterations over the stages.
    """

    method: str
    objective_s: float
    time_s: np.ndarray
    position_m: np.ndarray
    speed_ms: np.ndarray
    control_kn: np.ndarray
    control_nodes: int
    state_nodes: int
    solve_time_s: float
    iterations: int
    status: str
    success: bool
    control_pieces: tuple[ControlPiece, ...] = field(repr=False)
    control_bounds_kn: tuple[float, float] = (-math.inf, math.inf)
    breakpoints_s: np.ndarray = field(default_factory=lambda: _ro([]))
    stages: tuple[StageReport, ...] = ()

    def control_at(self, t, clip: bool = True) -> np.ndarray:
        """The solved control [kN] at times ``t`` (the method's interpolant, clipped to the bounds)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty_like(t)
        edges = np.array([p.t0 for p in self.control_pieces] + [self.control_pieces[-1].t1])
        idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(self.control_pieces) - 1)
        for k, piece in enumerate(self.control_pieces):
            sel = idx == k
            if np.any(sel):
                out[sel] = piece(t[sel])
        if clip:
            out = np.clip(out, *self.control_bounds_kn)
        return out


# --------------------------------------------------------------------------------------------------
# solve
# --------------------------------------------------------------------------------------------------


def _check_nlp(result, problem: MinTimeTrainProblem, method: str, nodes: int):
    if result.status in _INFEASIBLE:
        raise InfeasibleError(
            f"{method}: IPOPT finds the transcribed minimum-time problem infeasible ({result.status}) for "
            f"{problem.length_m:g} m with traction {problem.f_max_kn:g} kN, brake {problem.b_max_kn:g} kN, "
            f"gradient {problem.gradient_permille:g} per mille, speed limit {problem.speed_limit_kmh:g} km/h. "
            f"The train can start and stop, so the discretisation with {nodes} control nodes is probably too "
            f"coarse: try more nodes"
        )


def _gauss_solution(method, problem, nlp: GaussSolution, stages, wall, status: str | None = None) -> OcpSolution:
    bounds = (-problem.b_max_kn, problem.f_max_kn)
    pieces = tuple(
        ControlPiece(s.t0, s.t1, "lagrange", _ro(s.lg_times), _ro(s.controls[0])) for s in nlp.segments
    )
    t, x, u = [0.0], [nlp.segments[0].support_states[:, 0]], []
    for k, s in enumerate(nlp.segments):
        if k == 0:
            u.append(np.clip(s.control_polynomial([s.t0])[0, 0], *bounds))
        t.extend(s.lg_times)
        x.extend(s.support_states[:, 1:].T)
        u.extend(s.controls[0])  # the NLP's own values at the LG points
        t.append(s.t1)
        x.append(s.end_state)
        u.append(np.clip(s.control_polynomial([s.t1])[0, 0], *bounds))
    x = np.asarray(x).T
    return OcpSolution(
        method=method,
        objective_s=nlp.final_time,
        time_s=_ro(t),
        position_m=_ro(x[0]),
        speed_ms=_ro(x[1]),
        control_kn=_ro(u),
        control_nodes=nlp.mesh.n_control_params,
        state_nodes=nlp.mesh.n_state_nodes,
        solve_time_s=wall,
        iterations=sum(st.iterations for st in stages),
        status=status or nlp.status,
        success=nlp.success,
        control_pieces=pieces,
        control_bounds_kn=bounds,
        breakpoints_s=_ro(nlp.breakpoints),
        stages=tuple(stages),
    )


def _stage(name: str, nlp) -> StageReport:
    if isinstance(nlp, GaussSolution):
        cn, sn, ns = nlp.mesh.n_control_params, nlp.mesh.n_state_nodes, len(nlp.segments)
    else:
        cn, sn, ns = nlp.params.shape[1], 0, 1
    return StageReport(
        name=name,
        objective_s=nlp.final_time,
        control_nodes=cn,
        state_nodes=sn,
        segments=ns,
        iterations=nlp.iterations,
        status=nlp.status,
        solve_time_s=nlp.solve_time_s + nlp.build_time_s,
    )


def solve_min_time(
    problem: MinTimeTrainProblem,
    method: str = "two-stage",
    nodes: int | None = None,
    *,
    state_nodes: int | None = None,
    eps: float = 0.04,
    eps_lower: float | None = None,
    stage2: str = "hp",
    substeps: int = 4,
    ipopt_options: dict | None = None,
) -> OcpSolution:
    """Minimum running time of ``problem`` by ``method`` in ``("gpm", "two-stage", "cvp")``.

    ``nodes`` is the number of control parameters of the (first) NLP, as the "u(t) nodes" column of
    the paper's Tables 2-3: GPM 34 / 48 (= LG points), two-stage 17 / 24 (stage 1; the states then use
    ``2 * nodes`` LG points), CVP 20 / 40. For the two-stage method ``state_nodes`` may be given
    instead; it must be even (odd ``N`` in the paper's eq. 26). ``eps`` / ``eps_lower`` are the
    slope-change thresholds ``eps_U`` / ``eps_L`` (``eps_lower`` defaults to ``eps`` as in the paper);
    ``stage2`` is ``"hp"`` or ``"global"``; ``substeps`` is the number of RK4 steps per CVP grid
    interval; ``ipopt_options`` go to CasADi's ``nlpsol`` (e.g. ``{"ipopt.tol": 1e-8}``). Raises :class:`InputError` for bad arguments and :class:`InfeasibleError` when IPOPT
    finds the problem infeasible; other solver failures are reported in ``status`` / ``success``.
    """
    if not isinstance(problem, MinTimeTrainProblem):
        raise InputError(f"solve_min_time: expected a MinTimeTrainProblem, got {type(problem).__name__}")
    if method not in METHODS:
        raise InputError(f"solve_min_time: method must be one of {', '.join(METHODS)}, got {method!r}")
    if nodes is None and not (method == "two-stage" and state_nodes is not None):
        nodes = DEFAULT_NODES[method]
    if nodes is not None:
        nodes = _nodes._check_n(nodes, f"{method} control nodes")
    t_wall = _time.perf_counter()
    settings = _Settings(state_nodes, eps, eps_lower, stage2, substeps, ipopt_options, t_wall)
    return METHOD_SOLVERS[method](problem, problem.to_ocp(), problem.initial_guess(), nodes, settings)


@dataclass(frozen=True)
class _Settings:
    """The options of :func:`solve_min_time` a method may read, and when its wall time started."""

    state_nodes: int | None
    eps: float
    eps_lower: float | None
    stage2: str
    substeps: int
    ipopt_options: dict | None
    t_wall: float


def _solve_cvp(problem: MinTimeTrainProblem, ocp, guess, nodes: int, st: _Settings) -> OcpSolution:
    """Control vector parameterisation (:mod:`~locoplan.ocp.cvp`)."""
    res = solve_cvp(ocp, nodes, guess, substeps=st.substeps, ipopt_options=st.ipopt_options)
    _check_nlp(res, problem, "cvp", nodes)
    wall = _time.perf_counter() - st.t_wall
    k = res.substeps
    return OcpSolution(
        method="cvp",
        objective_s=res.final_time,
        time_s=_ro(res.grid),
        position_m=_ro(res.step_states[0, ::k]),
        speed_ms=_ro(res.step_states[1, ::k]),
        control_kn=_ro(res.params[0]),
        control_nodes=res.params.shape[1],
        state_nodes=0,
        solve_time_s=wall,
        iterations=res.iterations,
        status=res.status,
        success=res.success,
        control_pieces=(ControlPiece(0.0, res.final_time, "linear", _ro(res.grid), _ro(res.params[0])),),
        control_bounds_kn=(-problem.b_max_kn, problem.f_max_kn),
        stages=(_stage("cvp", res),),
    )


def _solve_gpm(problem: MinTimeTrainProblem, ocp, guess, nodes: int, st: _Settings) -> OcpSolution:
    """The classical GPM: one global Gauss interval, states and control on the same LG points."""
    if st.state_nodes is not None and st.state_nodes != nodes:
        raise InputError(f"gpm: states and control share the LG points; state_nodes {st.state_nodes} != nodes {nodes}")
    res = solve_gauss(ocp, single_mesh(nodes), guess, ipopt_options=st.ipopt_options)
    _check_nlp(res, problem, "gpm", nodes)
    return _gauss_solution("gpm", problem, res, [_stage("gpm", res)], _time.perf_counter() - st.t_wall)


def _solve_two_stage(problem: MinTimeTrainProblem, ocp, guess, nodes: int | None, st: _Settings) -> OcpSolution:
    """The two-stage Gauss paper's two-stage method: paired stage 1, then the re-collocated stage 2
    (:mod:`~locoplan.ocp.recollocation`) warm-started from it."""
    state_nodes, ipopt_options = st.state_nodes, st.ipopt_options
    if state_nodes is None:
        state_nodes = 2 * nodes
    else:
        state_nodes = _nodes._check_n(state_nodes, "two-stage state nodes")
        if nodes is not None and 2 * nodes != state_nodes:
            raise InputError(
                f"two-stage: stage 1 pairs the control (U_(2l-1) = U_(2l)), so {state_nodes} state nodes "
                f"give {state_nodes // 2} control nodes, not {nodes}"
            )
    mesh1 = single_mesh(state_nodes, paired_control_map(state_nodes))  # InputError for odd counts
    res1 = solve_gauss(ocp, mesh1, guess, ipopt_options=ipopt_options)
    _check_nlp(res1, problem, "two-stage (stage 1)", state_nodes // 2)
    stages = [_stage("stage 1", res1)]
    final = res1
    if res1.success:
        u_range = problem.f_max_kn + problem.b_max_kn
        guess2, bps2 = res1.to_guess(), None
        for widen in (1.0, math.inf):  # Fig. 4: re-select if a break point ends on its bound
            mesh2 = recollocate(res1, u_range, eps_upper=st.eps, eps_lower=st.eps_lower, mode=st.stage2, widen=widen)
            if bps2 is not None and len(bps2) == len(mesh2.breakpoints):
                mesh2 = mesh2.with_breakpoints(bps2)  # continue from the last solve
            res2 = solve_gauss(ocp, mesh2, guess2, ipopt_options=ipopt_options)
            stages.append(_stage("stage 2" if widen == 1.0 else "stage 2 (free break points)", res2))
            if res2.success:
                final = res2
                guess2 = res2.to_guess()
                bps2 = tuple(float(b) for b in res2.breakpoints / res2.final_time)
            if not mesh2.free_breakpoints or (res2.success and not _breakpoint_at_bound(res2, mesh2)):
                break
    status = None
    if final is res1 and len(stages) > 1:
        status = f"{res1.status} (stage 2 failed: {stages[-1].status}; stage-1 result)"
    return _gauss_solution("two-stage", problem, final, stages, _time.perf_counter() - st.t_wall, status)


METHOD_SOLVERS = {"gpm": _solve_gpm, "two-stage": _solve_two_stage, "cvp": _solve_cvp}
"""The minimum-time methods by name (the keys of ``registry.OCP_METHODS`` that solve ``time``); a new
method is one function here (or its own module) and one entry."""
METHODS = tuple(METHOD_SOLVERS)


def _breakpoint_at_bound(res: GaussSolution, mesh: Mesh) -> bool:
    sig = res.breakpoints / res.final_time
    for s, (lo, hi) in zip(sig, mesh.breakpoint_bounds):
        if hi - lo > 1e-6 and (s - lo < 1e-6 or hi - s < 1e-6):
            return True
    return False


# --------------------------------------------------------------------------------------------------
# re-simulation
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Resimulation:
    """Result of :func:`resimulate`.

    ``time_to_length_s``: first time the re-simulated train reaches ``length_m``; if it instead comes
    to rest less than ``position_tol_m`` short of it, the time it comes to rest (the stop is then a
    station stop within tolerance); ``inf`` otherwise. Reaching the end exactly at zero speed is
    ill-conditioned (``t_f - t ~ sqrt(2 gap / deceleration)``), hence the tolerance on the stop.
    ``distance_at_tf_m`` / ``final_speed_ms``: position and speed at the NLP's ``t_f``.
    ``stop_time_s`` / ``stop_position_m``: where the train first comes to rest after departing
    (after ``t_f`` the last control value is held; ``inf`` / ``nan`` if it never stops).
    ``max_overspeed_kmh``: the largest ``v - limit`` over ``[0, t_f]`` (0 if never above).
    ``max_control_excess_kn``: how far the *unclipped* control interpolant leaves the traction /
    brake bounds on ``[0, t_f]`` (0 if never; a GPM polynomial through bang-bang values does).
    """

    time_to_length_s: float
    distance_at_tf_m: float
    final_speed_ms: float
    max_overspeed_kmh: float
    max_control_excess_kn: float
    stop_time_s: float
    stop_position_m: float
    time_s: np.ndarray = field(repr=False)
    position_m: np.ndarray = field(repr=False)
    speed_ms: np.ndarray = field(repr=False)


def _control_function(solution: OcpSolution, interpolation: str, clip: bool):
    if interpolation == "method":
        return lambda t: solution.control_at(t, clip=clip)
    if interpolation == "linear":
        # piecewise linear through the NLP's control values (the paper's Fig. 5 plots)
        if solution.method == "cvp":
            tn, un = solution.time_s, solution.control_kn
        else:
            tn = np.concatenate([p.times for p in solution.control_pieces])
            un = np.concatenate([p.values for p in solution.control_pieces])
        lo, hi = solution.control_bounds_kn if clip else (-np.inf, np.inf)
        return lambda t: np.clip(np.interp(np.atleast_1d(t), tn, un), lo, hi)
    raise InputError(f"resimulate: interpolation must be 'method' or 'linear', got {interpolation!r}")


def resimulate(
    problem: MinTimeTrainProblem,
    solution: OcpSolution,
    *,
    rtol: float = 1e-9,
    atol: float = 1e-9,
    clip: bool = True,
    interpolation: str = "method",
    position_tol_m: float = 0.5,
) -> Resimulation:
    """Integrate the solved control with ``scipy.integrate.solve_ivp`` (DOP853, ``rtol`` 1e-9).

    ``interpolation="method"`` uses the method's own control interpolant: the Lagrange polynomial
    through each segment's LG values (GPM / two-stage), piecewise linear on the grid (CVP);
    ``"linear"`` joins the NLP's control values by straight lines for every method. With ``clip`` the
    control is saturated at the traction / brake limits, as a real drive would be. A train at rest
    does not roll back: it stays put while the force cannot overcome resistance plus grade.
    """
    from scipy.integrate import solve_ivp  # ~0.5 s to import: only where a minimum-time run is re-simulated

    tf = float(solution.objective_s)
    length = problem.length_m
    vlim = problem.speed_limit_ms
    ufun = _control_function(solution, interpolation, clip)
    u_last = float(ufun([tf])[0])
    start_force = problem.resistance(0.0) + problem.grade_force_kn

    def reach(t, y):
        return y[0] - length

    reach.terminal = False
    reach.direction = 1

    def stop(t, y):
        return y[1]

    stop.terminal = True
    stop.direction = -1

    edges = sorted({0.0, tf, *[p.t0 for p in solution.control_pieces], *[p.t1 for p in solution.control_pieces]})
    edges = [e for e in edges if 0.0 <= e <= tf]
    spans = [(a, b, False) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    spans.append((tf, tf + 10.0 * length / vlim, True))  # after t_f: hold the last control

    ts, ss, vs = [0.0], [0.0], [0.0]
    y = np.array([0.0, 0.0])
    t = 0.0
    t_reach, t_stop, s_stop = math.inf, math.inf, math.nan
    at_tf = None
    moved = False
    for a, b, hold in spans:
        if hold:
            at_tf = y.copy()
            if not math.isinf(t_stop) or (y[1] <= 0.0 and moved):
                break
        force = (lambda tt: np.full(np.size(tt), u_last)) if hold else ufun

        def rhs(tt, yy, force=force):
            return [yy[1], problem.acceleration(yy[1], float(force([tt])[0]))]

        t = a
        while t < b:
            if y[1] <= 0.0:  # at rest: wait until the force overcomes resistance + grade
                y[1] = 0.0
                if float(force([t])[0]) <= start_force:
                    grid = np.linspace(t, b, max(3, int((b - t) / 0.01) + 1))
                    ok = np.nonzero(force(grid) > start_force)[0]
                    if ok.size == 0:
                        ts.append(b), ss.append(y[0]), vs.append(0.0)
                        t = b
                        break
                    t = float(grid[ok[0]])
                    ts.append(t), ss.append(y[0]), vs.append(0.0)
            sol = solve_ivp(rhs, (t, b), y, method="DOP853", rtol=rtol, atol=atol, events=(reach, stop),
                            dense_output=True)
            moved = True
            dense = np.unique(np.concatenate([sol.t, np.linspace(sol.t[0], sol.t[-1], max(3, int((sol.t[-1] - sol.t[0]) / 0.02)))]))
            yy = sol.sol(dense)
            ts.extend(dense[1:]), ss.extend(yy[0, 1:]), vs.extend(yy[1, 1:])
            if sol.t_events[0].size and math.isinf(t_reach):
                t_reach = float(sol.t_events[0][0])
            t = float(sol.t[-1])
            y = sol.y[:, -1].copy()
            if sol.status == 1 and sol.t_events[1].size:
                y[1] = 0.0
                if math.isinf(t_stop):
                    t_stop, s_stop = t, float(y[0])
                if hold:
                    break
        if hold:
            break
    if at_tf is None:
        at_tf = y.copy()
    ts, ss, vs = np.array(ts), np.array(ss), np.array(vs)
    within = ts <= tf + 1e-9
    over = float(np.max(vs[within]) - vlim)
    t_len = t_reach
    if math.isinf(t_len) and not math.isinf(t_stop) and s_stop >= length - position_tol_m:
        t_len = t_stop
    raw = _control_function(solution, interpolation, clip=False)(np.linspace(0.0, tf, 20001))
    excess = max(0.0, float(np.max(raw)) - problem.f_max_kn, -problem.b_max_kn - float(np.min(raw)))
    return Resimulation(
        time_to_length_s=t_len,
        distance_at_tf_m=float(at_tf[0]),
        final_speed_ms=float(at_tf[1]),
        max_overspeed_kmh=max(0.0, kmh(over)),
        max_control_excess_kn=excess,
        stop_time_s=t_stop,
        stop_position_m=s_stop,
        time_s=_ro(ts),
        position_m=_ro(ss),
        speed_ms=_ro(vs),
    )
