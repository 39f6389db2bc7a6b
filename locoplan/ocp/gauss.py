"""Gauss pseudospectral (LG) transcription of a free-end single-phase problem (the two-stage Gauss paper, eq. 15-24).

The second transcription beside :mod:`~locoplan.ocp.radau`: it takes the same problem notion
(:class:`~locoplan.ocp.phase.MultiPhaseProblem` with one phase and ``free_end``, the model's
callables on CasADi symbols) and the same :class:`~locoplan.ocp.mesh.Mesh`, laid over the fraction
``sigma = t / t_f`` of the free end; the problem never sees a differentiation matrix.

Transcription (Benson / Huntington's GPM):

* ``t0 = 0`` and the final time ``t_f`` is a decision variable. The mesh cuts ``[0, 1]`` into ``K``
  intervals (``K = 1`` is the classical global GPM of the paper; ``K > 1`` an hp mesh). Interval
  ``k`` covers ``[sigma_{k-1} t_f, sigma_k t_f]`` and is mapped to ``tau in [-1, 1]`` by eq. 15. Its
  start is fixed or, with ``free_start``, a decision variable in those bounds (a moving mesh that
  lets the NLP put a break point on a control switch).
* In an interval with ``n`` LG points the state is a degree-``n`` Lagrange polynomial on the support
  points ``(-1, tau_1, ..., tau_n)`` (eq. 17); the dynamics are collocated at the LG points with the
  ``n x (n + 1)`` differentiation matrix (eq. 22): ``D X = (h / 2) f(X, U, t)``.
* The state at ``tau = +1`` is not collocated; it follows from the Gauss quadrature of eq. 24 written
  with the differentiation matrix, ``X(+1) = X(-1) + sum_k w_k sum_i D_{k i} X_i`` (linear in the
  unknowns). It is the final state of the last interval and the initial state of the next otherwise.
* Controls live only at the LG points: ``U = C P`` with ``P`` the interval's control *parameters* and
  ``C`` its ``control_map`` (``n x m``). The identity is the classical GPM; a 0/1 grouping matrix ties
  neighbouring LG points to one value (the paper's eq. 26-27 pairing and the eq. 31 merging); an
  interpolation matrix puts the control on its own, smaller node set (:func:`lagrange_control_map`).
* The Lagrange term of the objective is Gauss quadrature (eq. 23), path constraints ``g <= 0`` are
  imposed at the LG points, state bounds at every support point and at ``tau = +1``.

The NLP is built with CasADi ``SX`` symbols and solved by IPOPT (exact Hessian); decision variables
and defects are scaled by the model's nominal magnitudes.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from ..errors import InputError
from . import nodes as _nodes
from .mesh import Interval, Mesh
from .interrupt import solve_nlp
from .nlp import Guess, as_column, final_bounds, ipopt_solver, phase_functions
from .phase import MultiPhaseProblem

__all__ = [
    "GaussSolution",
    "SegmentSolution",
    "gauss_interval",
    "gauss_mesh",
    "grouped_control_map",
    "identity_control_map",
    "is_convex",
    "lagrange_control_map",
    "n_params",
    "paired_control_map",
    "single_mesh",
    "solve_gauss",
]


# --------------------------------------------------------------------------------------------------
# Control maps and Gauss meshes
# --------------------------------------------------------------------------------------------------


def identity_control_map(n: int) -> np.ndarray:
    """Classical GPM: one control parameter per LG point."""
    n = _nodes._check_n(n, "control map", minimum=1)
    return np.eye(n)


def grouped_control_map(group_sizes: Sequence[int]) -> np.ndarray:
    """0/1 map tying consecutive LG points together: group ``l`` of size ``g_l`` shares one value.

    ``grouped_control_map([2, 2, 1])`` is the map of 5 LG points onto 3 control parameters.
    """
    sizes = [int(g) for g in group_sizes]
    if not sizes or any(g < 1 for g in sizes):
        raise InputError(f"control groups: every group needs at least one LG point, got {list(group_sizes)}")
    n = sum(sizes)
    c = np.zeros((n, len(sizes)))
    row = 0
    for col, g in enumerate(sizes):
        c[row : row + g, col] = 1.0
        row += g
    return c


def paired_control_map(n_lg: int) -> np.ndarray:
    """Stage-1 map of the two-stage method (the paper's eq. 26-27): ``U_{2l-1} = U_{2l}``.

    The paper numbers the ``N + 1`` points of a degree-``N`` polynomial and asks for odd ``N``; that is
    an *even* number ``n_lg = N + 1`` of LG points here, giving ``n_lg / 2`` control parameters.
    """
    n_lg = _nodes._check_n(n_lg, "paired control nodes")
    if n_lg % 2:
        raise InputError(
            f"paired control nodes (U_(2l-1) = U_(2l)): need an even number of LG points "
            f"(an odd polynomial degree N in the paper's notation), got {n_lg} points (N = {n_lg - 1} even)"
        )
    return grouped_control_map([2] * (n_lg // 2))


def lagrange_control_map(n_lg: int, control_tau: Sequence[float]) -> np.ndarray:
    """Map for a control on its own node set ``control_tau`` (in [-1, 1], at least one node): the
    values at the ``n_lg`` LG points are the Lagrange interpolant of the control nodes (degree
    ``len(control_tau) - 1``)."""
    x, _ = _nodes.legendre_gauss(n_lg)
    tau = np.asarray(control_tau, dtype=float).reshape(-1)
    if tau.size < 1 or np.any(np.abs(tau) > 1.0):
        raise InputError("control nodes: need at least one node, all inside [-1, 1]")
    if tau.size == 1:
        return np.ones((n_lg, 1))
    return _nodes.interpolation_matrix(tau, x)


def gauss_interval(n_nodes: int, control_map: np.ndarray | None = None, s_a: float = 0.0, s_b: float = 1.0,
                   free_start: tuple[float, float] | None = None) -> Interval:
    """One Gauss interval: ``n_nodes`` LG points and a validated, read-only control map (identity by
    default)."""
    n = _nodes._check_n(n_nodes, "mesh segment")
    if control_map is None:
        c = identity_control_map(n)
    else:
        c = np.array(control_map, dtype=float)
        if c.ndim != 2 or c.shape[0] != n or c.shape[1] < 1:
            raise InputError(f"mesh segment: control map must be {n} x m with m >= 1, got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise InputError("mesh segment: control map must be finite")
    c.setflags(write=False)
    return Interval(0, float(s_a), float(s_b), n, free_start=free_start, control_map=c)


def control_matrix(iv: Interval) -> np.ndarray:
    """The interval's control map (the identity when it has none)."""
    return identity_control_map(iv.n) if iv.control_map is None else iv.control_map


def n_params(iv: Interval) -> int:
    """Control parameters of a Gauss interval (per control)."""
    return control_matrix(iv).shape[1]


def is_convex(iv: Interval) -> bool:
    """True when every LG value is a convex combination of parameters (0/1 grouping, or linear
    interpolation between two control nodes): bounds on the parameters are then bounds on the
    control at the LG points (and, for those maps, everywhere in the interval)."""
    c = control_matrix(iv)
    return bool(np.all(c >= -1e-14) and np.allclose(c.sum(axis=1), 1.0, rtol=0, atol=1e-12))


def _fractions(values, n: int, what: str) -> tuple[float, ...]:
    try:
        out = tuple(float(v) for v in values)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected {n} numbers, got {values!r}") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise InputError(f"{what}: expected {n} finite values, got {values!r}")
    return out


def gauss_mesh(segments, breakpoints=(), breakpoint_bounds=None, min_fraction: float = 1e-4) -> Mesh:
    """A mesh of ``[0, 1]`` for :func:`solve_gauss`: ``segments`` are Gauss intervals (or LG point
    counts), ``breakpoints`` their ``len(segments) - 1`` interior boundaries, increasing in (0, 1).
    With ``breakpoint_bounds`` (one ``(lo, hi)`` per break point) every break point is a decision
    variable in its bounds and ``breakpoints`` is only its initial guess; ``min_fraction`` is the
    smallest interval length."""
    segs = [s if isinstance(s, Interval) else gauss_interval(int(s)) for s in segments]
    if not segs:
        raise InputError("mesh: needs at least one segment")
    bp = _fractions(breakpoints, len(segs) - 1, "mesh breakpoints")
    full = (0.0,) + bp + (1.0,)
    if any(b <= a for a, b in zip(full, full[1:])):
        raise InputError(f"mesh breakpoints must increase strictly inside (0, 1), got {bp}")
    bounds: list = [None] * len(segs)
    if breakpoint_bounds is not None:
        bb = tuple(_fractions(b, 2, "mesh breakpoint bounds") for b in breakpoint_bounds)
        if len(bb) != len(bp):
            raise InputError("mesh: one (lo, hi) bound per break point is needed")
        for (lo, hi), b in zip(bb, bp):
            if not 0.0 < lo <= b <= hi < 1.0:
                raise InputError(f"mesh: break point {b} must lie in its bounds ({lo}, {hi}) inside (0, 1)")
        bounds = [None, *bb]
    ivs = tuple(gauss_interval(s.n, s.control_map, a, b, free) for s, a, b, free in zip(segs, full[:-1], full[1:], bounds))
    return Mesh(ivs, min_fraction=float(min_fraction))


def single_mesh(n_nodes: int, control_map: np.ndarray | None = None) -> Mesh:
    """The classical global GPM: one interval over ``[0, 1]``."""
    return Mesh((gauss_interval(n_nodes, control_map),))


# --------------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SegmentSolution:
    """Solved interval: ``t0, t1`` its time span, ``tau`` the LG points, ``support_states`` the state at
    ``(-1, tau_1..tau_n)`` (``n_x x (n + 1)``), ``end_state`` at ``+1``, ``controls`` at the LG points
    (``n_u x n``) and ``params`` the control parameters (``n_u x m``)."""

    t0: float
    t1: float
    tau: np.ndarray
    support_states: np.ndarray
    end_state: np.ndarray
    controls: np.ndarray
    params: np.ndarray
    control_map: np.ndarray

    @property
    def lg_times(self) -> np.ndarray:
        return self.t0 + (self.tau + 1.0) * 0.5 * (self.t1 - self.t0)

    def _tau_of(self, t) -> np.ndarray:
        h = self.t1 - self.t0
        return 2.0 * (np.asarray(t, dtype=float) - self.t0) / h - 1.0

    def control_polynomial(self, t) -> np.ndarray:
        """Lagrange interpolant through the ``n`` LG control values (degree ``n - 1``), ``n_u x len(t)``."""
        e = _nodes.interpolation_matrix(self.tau, np.atleast_1d(self._tau_of(t)))
        return self.controls @ e.T

    def state_polynomial(self, t) -> np.ndarray:
        """Degree-``n`` state interpolant on ``(-1, tau_1..tau_n)`` (the paper's eq. 17), ``n_x x len(t)``."""
        support = _nodes.gauss_support_points(len(self.tau))
        e = _nodes.interpolation_matrix(support, np.atleast_1d(self._tau_of(t)))
        return self.support_states @ e.T


@dataclass(frozen=True)
class GaussSolution:
    """Raw result of one Gauss-transcribed NLP."""

    success: bool
    status: str
    iterations: int
    objective: float
    final_time: float
    breakpoints: np.ndarray
    segments: tuple[SegmentSolution, ...]
    solve_time_s: float
    build_time_s: float
    mesh: Mesh

    def nodes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Concatenated (time, states ``n_x x M``, controls ``n_u x M``) at all LG points."""
        t = np.concatenate([s.lg_times for s in self.segments])
        x = np.concatenate([s.support_states[:, 1:] for s in self.segments], axis=1)
        u = np.concatenate([s.controls for s in self.segments], axis=1)
        return t, x, u

    def to_guess(self) -> Guess:
        """This solution as a :class:`~locoplan.ocp.nlp.Guess` (states at support points, controls at
        LG points)."""
        tf = self.final_time
        sig, xs, us = [0.0], [self.segments[0].support_states[:, 0]], [self.segments[0].controls[:, 0]]
        for s in self.segments:
            for t, x, u in zip(s.lg_times, s.support_states[:, 1:].T, s.controls.T):
                sig.append(t / tf)
                xs.append(x)
                us.append(u)
            sig.append(s.t1 / tf)
            xs.append(s.end_state)
            us.append(s.controls[:, -1])
        sig = np.asarray(sig)
        keep = np.concatenate(([True], np.diff(sig) > 1e-12))
        return Guess(sig[keep], np.array(xs).T[:, keep], np.array(us).T[:, keep], tf)


# --------------------------------------------------------------------------------------------------
# Build and solve
# --------------------------------------------------------------------------------------------------


class _NLPParts:
    """An NLP's decision variables (symbols, bounds, start) and constraints (expressions, bounds) in the
    order they are added."""

    def __init__(self):
        self.w_parts, self.lbw, self.ubw, self.w0 = [], [], [], []
        self.g_parts, self.lbg, self.ubg = [], [], []

    def add_var(self, sym, lo, hi, init) -> None:
        self.w_parts.append(ca.vec(sym))
        size = (sym.numel(),)
        self.lbw.append(np.broadcast_to(np.ravel(lo, order="F"), size))
        self.ubw.append(np.broadcast_to(np.ravel(hi, order="F"), size))
        self.w0.append(np.broadcast_to(np.ravel(init, order="F"), size))

    def add_con(self, expr, lo, hi) -> None:
        expr = ca.vec(expr)
        self.g_parts.append(expr)
        self.lbg.append(np.broadcast_to(np.ravel(lo, order="F"), (expr.numel(),)))
        self.ubg.append(np.broadcast_to(np.ravel(hi, order="F"), (expr.numel(),)))


@dataclass(frozen=True)
class _GaussPhase:
    """What every interval of the transcription reads: the problem and its guess, the sizes and scales,
    the scaled state and control bounds, the model as CasADi functions (``l_fun``, ``p_fun`` None when
    absent), the final time ``tf`` and the break points ``sig`` (symbolic where they move), ``sig_guess``."""

    problem: MultiPhaseProblem
    guess: Guess
    nx: int
    nu: int
    sx: np.ndarray
    su: np.ndarray
    x_lo: np.ndarray
    x_hi: np.ndarray
    u_lo: np.ndarray
    u_hi: np.ndarray
    f_fun: ca.Function
    l_fun: ca.Function | None
    p_fun: ca.Function | None
    tf: ca.SX
    sig: ca.SX | ca.DM
    sig_guess: np.ndarray


def _model_functions(sp) -> tuple:
    """The dynamics, Lagrange integrand and path constraints of a single phase ``sp`` as CasADi functions
    of (x, u, t) (None where the model has none)."""
    nx, nu = sp.nx, sp.nu
    xs_, us_, ts_ = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("t")
    f_fun = ca.Function("f", [xs_, us_, ts_], [as_column(sp.dynamics(xs_, us_, ts_), nx, "dynamics")])
    l_fun = None
    if sp.lagrange is not None:
        l_fun = ca.Function("l", [xs_, us_, ts_], [as_column(sp.lagrange(xs_, us_, ts_), 1, "lagrange")])
    p_fun = None
    if sp.path is not None:
        p_fun = ca.Function("p", [xs_, us_, ts_], [as_column(sp.path(xs_, us_, ts_), sp.n_path, "path")])
    return f_fun, l_fun, p_fun


def _add_final_time(nlp: _NLPParts, problem: MultiPhaseProblem, guess: Guess, ts: float):
    """The final time's variable (scaled by ``ts``); the physical final time."""
    tf_lo, tf_hi = (float(v) for v in problem.free_end)
    tf_s = ca.SX.sym("tf")
    tf0 = float(np.clip(guess.final_time, tf_lo, tf_hi))
    nlp.add_var(tf_s, tf_lo / ts, tf_hi / ts, tf0 / ts)
    return tf_s * ts


def _add_breakpoints(nlp: _NLPParts, mesh: Mesh):
    """The break points ``(0, sigma_1 .. sigma_{K-1}, 1)``: variables kept ``min_fraction`` apart where
    they move, numbers otherwise."""
    breakpoints = mesh.breakpoints
    if mesh.free_breakpoints:
        sig_s = ca.SX.sym("sigma", len(mesh.intervals) - 1)
        lo = [b[0] for b in mesh.breakpoint_bounds]
        hi = [b[1] for b in mesh.breakpoint_bounds]
        nlp.add_var(sig_s, lo, hi, breakpoints)
        sig = ca.vertcat(0.0, sig_s, 1.0)
        nlp.add_con(sig[1:] - sig[:-1], mesh.min_fraction, np.inf)
        return sig
    return ca.DM([0.0, *breakpoints, 1.0])


def _add_interval_variables(nlp: _NLPParts, ph: _GaussPhase, k: int, iv: Interval):
    """Interval ``k``'s states at its support points and its control parameters, started from the guess
    (the initial state fixed in the first); its controls ``U = P C'`` (scaled), bounded through the
    parameters where the map is convex, by constraints otherwise."""
    n, nx, nu, sig_guess = iv.n, ph.nx, ph.nu, ph.sig_guess
    c_np = control_matrix(iv)
    m_k = c_np.shape[1]
    tau, _ = _nodes.legendre_gauss(n)
    support = _nodes.gauss_support_points(n)
    xk = ca.SX.sym(f"X{k}", nx, n + 1)
    pk = ca.SX.sym(f"P{k}", nu, m_k)
    lo_k = np.repeat(ph.x_lo[:, None], n + 1, axis=1)
    hi_k = np.repeat(ph.x_hi[:, None], n + 1, axis=1)
    if k == 0:
        for i, v in enumerate(ph.problem.initial_state):
            if v is not None:
                lo_k[i, 0] = hi_k[i, 0] = v / ph.sx[i]
    s_sup = sig_guess[k] + (support + 1.0) * 0.5 * (sig_guess[k + 1] - sig_guess[k])
    nlp.add_var(xk, lo_k, hi_k, ph.guess.state_at(s_sup) / ph.sx[:, None])
    s_lg = sig_guess[k] + (tau + 1.0) * 0.5 * (sig_guess[k + 1] - sig_guess[k])
    u_guess = ph.guess.control_at(s_lg) / ph.su[:, None]  # nu x n
    p_guess = np.linalg.lstsq(c_np, u_guess.T, rcond=None)[0].T
    convex = is_convex(iv)
    u_lo, u_hi = ph.u_lo[:, None], ph.u_hi[:, None]
    if convex:
        nlp.add_var(pk, np.repeat(u_lo, m_k, 1), np.repeat(u_hi, m_k, 1), np.clip(p_guess, u_lo, u_hi))
    else:
        nlp.add_var(pk, -np.inf, np.inf, p_guess)
    uk = ca.mtimes(pk, ca.DM(np.asarray(c_np)).T)  # nu x n, scaled
    if not convex:
        nlp.add_con(uk, np.repeat(u_lo, n, 1), np.repeat(u_hi, n, 1))
    return xk, pk, uk


def _add_interval_constraints(nlp: _NLPParts, ph: _GaussPhase, k: int, iv: Interval, xk, uk, x_start):
    """Interval ``k``'s continuity with the one before (``x_start`` its end, None for the first), the
    collocated dynamics (eq. 22) and the path constraints at the LG points: (its Gauss quadrature of the
    Lagrange term, eq. 23, or None; its state at ``tau = +1``, eq. 24)."""
    n, sx, sig, tf = iv.n, ph.sx, ph.sig, ph.tf
    tau, w = _nodes.legendre_gauss(n)
    d = _nodes.gauss_differentiation_matrix(n)
    if x_start is not None:
        nlp.add_con(xk[:, 0] - x_start, 0.0, 0.0)  # continuity with the previous interval
    h = (sig[k + 1] - sig[k]) * tf
    t_lg = sig[k] * tf + (ca.DM(tau) + 1.0) * 0.5 * h  # n x 1
    x_phys = ca.diag(ca.DM(sx)) @ xk[:, 1:]
    u_phys = ca.diag(ca.DM(ph.su)) @ uk
    f_val = ph.f_fun.map(n)(x_phys, u_phys, t_lg.T)  # nx x n (physical)
    defect = ca.mtimes(xk, ca.DM(d).T) - (h / 2.0) * (ca.diag(ca.DM(1.0 / sx)) @ f_val)
    nlp.add_con(defect, 0.0, 0.0)
    if ph.p_fun is not None:
        nlp.add_con(ph.p_fun.map(n)(x_phys, u_phys, t_lg.T), -np.inf, 0.0)
    term = None
    if ph.l_fun is not None:
        term = (h / 2.0) * ca.mtimes(ph.l_fun.map(n)(x_phys, u_phys, t_lg.T), ca.DM(w))
    # eq. 24: X(+1) = X(-1) + sum_k w_k sum_i D_ki X_i  (linear)
    return term, xk[:, 0] + ca.mtimes(xk, ca.DM(np.asarray(w) @ np.asarray(d)))


def _unpack_segments(ph: _GaussPhase, mesh: Mesh, vals: list) -> tuple[float, np.ndarray, list]:
    """The final time, the break points (as fractions) and each interval's :class:`SegmentSolution` from
    the solution's values of (tf, sig, each interval's X, P, U, the final state)."""
    nx, nu, sx, su = ph.nx, ph.nu, ph.sx, ph.su
    ivs, k_seg = mesh.intervals, len(mesh.intervals)
    tf_v = float(np.ravel(vals[0])[0])
    sig_v = np.ravel(vals[1])
    segs = []
    for k, iv in enumerate(ivs):
        xk_v, pk_v, uk_v = vals[2 + 3 * k : 5 + 3 * k]
        xk_v = xk_v.reshape(nx, -1) * sx[:, None]
        end = vals[2 + 3 * (k + 1)] if k + 1 < k_seg else vals[-1]
        end = (end.reshape(nx, -1)[:, 0] if k + 1 < k_seg else end.ravel()) * sx
        tau, _ = _nodes.legendre_gauss(iv.n)
        segs.append(
            SegmentSolution(
                t0=float(sig_v[k] * tf_v),
                t1=float(sig_v[k + 1] * tf_v),
                tau=tau,
                support_states=xk_v,
                end_state=end,
                controls=uk_v.reshape(nu, -1) * su[:, None],
                params=pk_v.reshape(nu, -1) * su[:, None],
                control_map=control_matrix(iv),
            )
        )
    return tf_v, sig_v, segs


def solve_gauss(problem: MultiPhaseProblem, mesh: Mesh, guess: Guess, *, ipopt_options: dict | None = None) -> GaussSolution:
    """Transcribe the free-end single-phase ``problem`` on ``mesh`` (over ``sigma = t / t_f``) with the
    Gauss pseudospectral method and solve with IPOPT.

    Never raises for a failed solve: the returned :class:`GaussSolution` carries ``success`` and
    IPOPT's ``status``; the caller decides what to do.
    """
    t_build = _time.perf_counter()
    sp = phase_functions(problem)
    phase, nx, nu, sx, su = sp.phase, sp.nx, sp.nu, sp.state_scale, sp.control_scale
    ivs = mesh.intervals
    if any(iv.free_start is not None for iv in ivs[1:]) and not mesh.free_breakpoints:
        raise InputError("Gauss transcription: either every break point moves or none does")
    # symbolic dynamics / objective / path as CasADi functions (problem layer stays casadi-generic)
    f_fun, l_fun, p_fun = _model_functions(sp)
    nlp = _NLPParts()
    tf = _add_final_time(nlp, problem, guess, sp.length)
    sig = _add_breakpoints(nlp, mesh)
    ph = _GaussPhase(problem, guess, nx, nu, sx, su, np.array(phase.state_lower, dtype=float) / sx,
                     np.array(phase.state_upper, dtype=float) / sx, np.array(phase.control_lower, dtype=float) / su,
                     np.array(phase.control_upper, dtype=float) / su, f_fun, l_fun, p_fun, tf, sig,
                     np.array([0.0, *mesh.breakpoints, 1.0]))

    objective = 0
    seg_syms = []
    x_start = None  # scaled state at the start of the current interval (symbolic)
    for k, iv in enumerate(ivs):
        xk, pk, uk = _add_interval_variables(nlp, ph, k, iv)
        term, x_start = _add_interval_constraints(nlp, ph, k, iv, xk, uk, x_start)
        if term is not None:
            objective = objective + term
        seg_syms.append((xk, pk, uk))

    xf = ca.SX.sym("Xf", nx)
    f_lo, f_hi = final_bounds(problem)
    nlp.add_var(xf, f_lo / sx, f_hi / sx, guess.state_at(1.0).ravel() / sx)
    nlp.add_con(xf - x_start, 0.0, 0.0)

    if problem.mayer is not None:
        x0_phys = ca.diag(ca.DM(sx)) @ seg_syms[0][0][:, 0]
        xf_phys = ca.diag(ca.DM(sx)) @ xf
        objective = objective + as_column(problem.mayer(x0_phys, xf_phys, tf), 1, "mayer")

    wv = ca.vertcat(*nlp.w_parts)
    gv = ca.vertcat(*nlp.g_parts)
    solver = ipopt_solver("gpm", {"x": wv, "f": objective / problem.objective_scale, "g": gv}, ipopt_options)
    build_time = _time.perf_counter() - t_build

    lbw_v, ubw_v, w0_v = (np.concatenate(a) for a in (nlp.lbw, nlp.ubw, nlp.w0))
    w0_v = np.clip(w0_v, lbw_v, ubw_v)
    t_solve = _time.perf_counter()
    sol = solve_nlp(solver, x0=w0_v, lbx=lbw_v, ubx=ubw_v, lbg=np.concatenate(nlp.lbg), ubg=np.concatenate(nlp.ubg))
    solve_time = _time.perf_counter() - t_solve
    stats = solver.stats()

    out = ca.Function("out", [wv], [tf, sig] + [a for trip in seg_syms for a in trip] + [xf])
    tf_v, sig_v, segs = _unpack_segments(ph, mesh, [np.asarray(v, dtype=float) for v in out(sol["x"])])
    return GaussSolution(
        success=bool(stats.get("success", False)),
        status=str(stats.get("return_status", "unknown")),
        iterations=int(stats.get("iter_count", -1)),
        objective=float(np.ravel(np.asarray(sol["f"]))[0]) * problem.objective_scale,
        final_time=tf_v,
        breakpoints=sig_v[1:-1] * tf_v,
        segments=tuple(segs),
        solve_time_s=solve_time,
        build_time_s=build_time,
        mesh=mesh,
    )
