"""Gauss pseudospectral transcription of a generic single-phase optimal control problem.

Layer 2 of the optimal-control stack (nodes -> transcription -> problem -> solve). A problem layer
describes *what* to solve with an :class:`OcpDescription` (dynamics as a callable on CasADi symbols,
bounds, boundary conditions, path constraints, objective); this module decides *how*: it never knows
about trains, and the problem layer never sees a differentiation matrix.

Transcription (seed 000, eq. 15-24; Benson / Huntington's GPM):

* ``t0 = 0`` and the final time ``t_f`` is a decision variable. The horizon is cut into ``K``
  segments (``K = 1`` is the classical global GPM of the seed; ``K > 1`` is an hp mesh). Segment
  ``k`` covers ``[sigma_{k-1} t_f, sigma_k t_f]`` with ``0 = sigma_0 < sigma_1 < ... < sigma_K = 1``
  and is mapped to ``tau in [-1, 1]`` by eq. 15. Interior break points ``sigma_k`` are either fixed
  or decision variables inside given bounds (a "moving" mesh that lets the NLP put a break point on
  a control switch).
* In a segment with ``n`` LG points the state is a degree-``n`` Lagrange polynomial on the support
  points ``(-1, tau_1, ..., tau_n)`` (eq. 17); the dynamics are collocated at the LG points with the
  ``n x (n + 1)`` differentiation matrix (eq. 22): ``D X = (h / 2) f(X, U, t)``.
* The state at ``tau = +1`` is not collocated; it follows from the Gauss quadrature of eq. 24 written
  with the differentiation matrix, ``X(+1) = X(-1) + sum_k w_k sum_i D_{k i} X_i`` (linear in the
  unknowns, and equal to ``X(-1) + (h/2) sum_k w_k f_k`` once the collocation equations hold). It is
  the final state of the last segment and the initial state of the next one otherwise.
* Controls live only at the LG points. The values there are ``U = C P``: ``P`` holds the control
  *parameters* of the segment and ``C`` (``n x m``) is the segment's *control map*. The identity is the
  classical GPM (same nodes for states and controls); a 0/1 grouping matrix ties neighbouring LG
  points to one value (seed eq. 26-27 pairing ``U_{2l-1} = U_{2l}`` and the eq. 31 merging); an
  interpolation matrix puts the control on its own, smaller node set (see
  :func:`lagrange_control_map`). So states and controls may use different node sets.
* The Lagrange term of the objective is Gauss quadrature (eq. 23), path constraints are imposed at
  the LG points, state bounds at every support point and at ``tau = +1``.

The NLP is built with CasADi ``SX`` symbols and solved by ``nlpsol`` with IPOPT (exact Hessian);
decision variables and defects are scaled by the nominal magnitudes of the description.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass
from typing import Callable, Sequence

import casadi as ca
import numpy as np

from ..errors import InputError
from . import nodes as _nodes

__all__ = [
    "Guess",
    "Mesh",
    "NlpSolution",
    "OcpDescription",
    "Segment",
    "SegmentSolution",
    "grouped_control_map",
    "identity_control_map",
    "lagrange_control_map",
    "paired_control_map",
    "CvpSolution",
    "recollocate",
    "recollocated_groups",
    "slope_changes",
    "solve_cvp",
    "solve_gauss",
    "IPOPT_QUIET",
]

#: IPOPT options that silence all solver output.
IPOPT_QUIET = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"}
IPOPT_DEFAULTS = {**IPOPT_QUIET, "ipopt.max_iter": 3000, "ipopt.tol": 1e-10, "ipopt.acceptable_tol": 1e-7}


def _ipopt_solver(name: str, nlp: dict, ipopt_options: dict | None):
    """A silent IPOPT solver with the tight tolerances every transcription here uses."""
    return ca.nlpsol(name, "ipopt", nlp, {**IPOPT_DEFAULTS, **(ipopt_options or {})})


# --------------------------------------------------------------------------------------------------
# Problem description (what the problem layer hands over)
# --------------------------------------------------------------------------------------------------


def _floats(values, n: int, what: str, allow_none: bool = False, allow_inf: bool = True) -> tuple:
    try:
        values = tuple(values)
    except TypeError:
        raise InputError(f"{what}: expected a sequence of {n} numbers, got {values!r}") from None
    if len(values) != n:
        raise InputError(f"{what}: expected {n} values, got {len(values)}")
    out = []
    for v in values:
        if v is None and allow_none:
            out.append(None)
            continue
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise InputError(f"{what}: {v!r} is not a number") from None
        if math.isnan(f) or (not allow_inf and math.isinf(f)):
            raise InputError(f"{what}: {v!r} is not a finite number")
        out.append(f)
    return tuple(out)


@dataclass(frozen=True)
class OcpDescription:
    """A single-phase optimal control problem with ``t0 = 0`` and free final time.

    ``dynamics(x, u, t)`` returns ``dx/dt`` (a list or CasADi vector of length ``n_x``) for CasADi
    column vectors ``x`` (``n_x``) and ``u`` (``n_u``) and scalar ``t``; it must only use operations
    CasADi can differentiate. ``mayer(x0, xf, tf)`` and ``lagrange(x, u, t)`` give the Bolza
    objective of seed eq. 4 (either may be ``None``). ``path(x, u, t)`` returns extra path
    constraints ``path_lower <= path(x, u, t) <= path_upper``. ``initial_state`` / ``final_state``
    fix a component to a number or leave it free with ``None``. The ``*_scale`` numbers are nominal
    magnitudes used to scale the NLP (they do not change the solution).
    """

    state_names: tuple[str, ...]
    control_names: tuple[str, ...]
    dynamics: Callable
    state_lower: tuple[float, ...]
    state_upper: tuple[float, ...]
    control_lower: tuple[float, ...]
    control_upper: tuple[float, ...]
    initial_state: tuple[float | None, ...]
    final_state: tuple[float | None, ...]
    final_time_bounds: tuple[float, float]
    mayer: Callable | None = None
    lagrange: Callable | None = None
    path: Callable | None = None
    path_lower: tuple[float, ...] = ()
    path_upper: tuple[float, ...] = ()
    state_scale: tuple[float, ...] | None = None
    control_scale: tuple[float, ...] | None = None
    time_scale: float = 1.0
    objective_scale: float = 1.0

    def __post_init__(self):
        nx, nu = len(self.state_names), len(self.control_names)
        if nx < 1 or nu < 1:
            raise InputError("optimal control problem: needs at least one state and one control")
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731
        set_("state_lower", _floats(self.state_lower, nx, "state_lower"))
        set_("state_upper", _floats(self.state_upper, nx, "state_upper"))
        set_("control_lower", _floats(self.control_lower, nu, "control_lower"))
        set_("control_upper", _floats(self.control_upper, nu, "control_upper"))
        set_("initial_state", _floats(self.initial_state, nx, "initial_state", allow_none=True, allow_inf=False))
        set_("final_state", _floats(self.final_state, nx, "final_state", allow_none=True, allow_inf=False))
        set_("final_time_bounds", _floats(self.final_time_bounds, 2, "final_time_bounds"))
        set_("state_scale", _floats(self.state_scale or (1.0,) * nx, nx, "state_scale", allow_inf=False))
        set_("control_scale", _floats(self.control_scale or (1.0,) * nu, nu, "control_scale", allow_inf=False))
        npath = len(tuple(self.path_lower))
        set_("path_lower", _floats(self.path_lower, npath, "path_lower"))
        set_("path_upper", _floats(self.path_upper, npath, "path_upper"))
        if npath and self.path is None:
            raise InputError("optimal control problem: path bounds given without a path function")
        for name, lo, hi in zip(self.state_names, self.state_lower, self.state_upper):
            if lo > hi:
                raise InputError(f"state {name}: lower bound {lo} exceeds upper bound {hi}")
        for name, lo, hi in zip(self.control_names, self.control_lower, self.control_upper):
            if lo > hi:
                raise InputError(f"control {name}: lower bound {lo} exceeds upper bound {hi}")
        for which, values in (("initial", self.initial_state), ("final", self.final_state)):
            for name, v, lo, hi in zip(self.state_names, values, self.state_lower, self.state_upper):
                if v is not None and not lo <= v <= hi:
                    raise InputError(f"{which} {name} = {v} lies outside its bounds [{lo}, {hi}]")
        lo, hi = self.final_time_bounds
        if not 0.0 < lo <= hi:
            raise InputError(f"final_time_bounds: need 0 < lower <= upper, got ({lo}, {hi})")
        scales = self.state_scale + self.control_scale + (float(self.time_scale), float(self.objective_scale))
        if any(s <= 0.0 for s in scales):
            raise InputError("optimal control problem: every scale must be positive")
        if self.mayer is None and self.lagrange is None:
            raise InputError("optimal control problem: needs a Mayer or a Lagrange objective term")

    @property
    def n_x(self) -> int:
        return len(self.state_names)

    @property
    def n_u(self) -> int:
        return len(self.control_names)


@dataclass(frozen=True)
class Guess:
    """Initial guess on a normalised time grid ``sigma = t / t_f`` in [0, 1] (linear interpolation).

    ``states`` is ``n_x x m`` and ``controls`` ``n_u x m`` for the ``m`` grid points ``sigma``.
    """

    sigma: np.ndarray
    states: np.ndarray
    controls: np.ndarray
    final_time: float

    def state_at(self, sigma) -> np.ndarray:
        return np.array([np.interp(sigma, self.sigma, row) for row in np.atleast_2d(self.states)])

    def control_at(self, sigma) -> np.ndarray:
        return np.array([np.interp(sigma, self.sigma, row) for row in np.atleast_2d(self.controls)])


# --------------------------------------------------------------------------------------------------
# Mesh and control maps
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
    """Stage-1 map of the two-stage method (seed eq. 26-27): ``U_{2l-1} = U_{2l}``.

    The seed numbers the ``N + 1`` points of a degree-``N`` polynomial and asks for odd ``N``; that is
    an *even* number ``n_lg = N + 1`` of LG points here, giving ``n_lg / 2`` control parameters.
    """
    n_lg = _nodes._check_n(n_lg, "paired control nodes")
    if n_lg % 2:
        raise InputError(
            f"paired control nodes (seed eq. 26, U_(2l-1) = U_(2l)): need an even number of LG points "
            f"(odd polynomial degree N in the seed's notation), got {n_lg} points (N = {n_lg - 1} even)"
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


@dataclass(frozen=True)
class Segment:
    """One mesh segment: ``n_nodes`` LG collocation points and an optional control map."""

    n_nodes: int
    control_map: np.ndarray | None = None

    def __post_init__(self):
        n = _nodes._check_n(self.n_nodes, "mesh segment")
        object.__setattr__(self, "n_nodes", n)
        if self.control_map is None:
            c = identity_control_map(n)
        else:
            c = np.array(self.control_map, dtype=float)
            if c.ndim != 2 or c.shape[0] != n or c.shape[1] < 1:
                raise InputError(f"mesh segment: control map must be {n} x m with m >= 1, got shape {c.shape}")
            if not np.all(np.isfinite(c)):
                raise InputError("mesh segment: control map must be finite")
        c.setflags(write=False)
        object.__setattr__(self, "control_map", c)

    @property
    def n_params(self) -> int:
        return self.control_map.shape[1]

    @property
    def is_convex(self) -> bool:
        """True when every LG value is a convex combination of parameters (0/1 grouping, or linear
        interpolation between two control nodes): bounds on the parameters are then bounds on the
        control at the LG points (and, for those maps, everywhere in the segment)."""
        c = self.control_map
        return bool(np.all(c >= -1e-14) and np.allclose(c.sum(axis=1), 1.0, rtol=0, atol=1e-12))


@dataclass(frozen=True)
class Mesh:
    """Segments plus interior break points (fractions of ``t_f``).

    ``breakpoints`` has ``len(segments) - 1`` increasing values in (0, 1). With ``breakpoint_bounds``
    (one ``(lo, hi)`` per break point) the break points are decision variables in those bounds and
    ``breakpoints`` is only their initial guess; ``min_fraction`` is the smallest segment length.
    """

    segments: tuple[Segment, ...]
    breakpoints: tuple[float, ...] = ()
    breakpoint_bounds: tuple[tuple[float, float], ...] | None = None
    min_fraction: float = 1e-4

    def __post_init__(self):
        segs = tuple(s if isinstance(s, Segment) else Segment(int(s)) for s in self.segments)
        if not segs:
            raise InputError("mesh: needs at least one segment")
        object.__setattr__(self, "segments", segs)
        bp = _floats(self.breakpoints, len(segs) - 1, "mesh breakpoints", allow_inf=False)
        full = (0.0,) + bp + (1.0,)
        if any(b <= a for a, b in zip(full, full[1:])):
            raise InputError(f"mesh breakpoints must increase strictly inside (0, 1), got {bp}")
        object.__setattr__(self, "breakpoints", bp)
        if self.breakpoint_bounds is not None:
            bb = tuple(_floats(b, 2, "mesh breakpoint bounds", allow_inf=False) for b in self.breakpoint_bounds)
            if len(bb) != len(bp):
                raise InputError("mesh: one (lo, hi) bound per break point is needed")
            for (lo, hi), b in zip(bb, bp):
                if not 0.0 < lo <= b <= hi < 1.0:
                    raise InputError(f"mesh: break point {b} must lie in its bounds ({lo}, {hi}) inside (0, 1)")
            object.__setattr__(self, "breakpoint_bounds", bb)

    @classmethod
    def single(cls, n_nodes: int, control_map: np.ndarray | None = None) -> "Mesh":
        """The classical global GPM: one segment."""
        return cls((Segment(n_nodes, control_map),))

    @property
    def n_state_nodes(self) -> int:
        return sum(s.n_nodes for s in self.segments)

    @property
    def n_control_params(self) -> int:
        return sum(s.n_params for s in self.segments)

    @property
    def free_breakpoints(self) -> bool:
        return self.breakpoint_bounds is not None and len(self.breakpoints) > 0


# --------------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SegmentSolution:
    """Solved segment: ``t0, t1`` its time span, ``tau`` the LG points, ``support_states`` the state at
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
        """Degree-``n`` state interpolant on ``(-1, tau_1..tau_n)`` (seed eq. 17), ``n_x x len(t)``."""
        support = _nodes.gauss_support_points(len(self.tau))
        e = _nodes.interpolation_matrix(support, np.atleast_1d(self._tau_of(t)))
        return self.support_states @ e.T


@dataclass(frozen=True)
class NlpSolution:
    """Raw result of one transcribed NLP."""

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
        """This solution as a :class:`Guess` (states at support points, controls at LG points)."""
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


def _as_column(value, n: int, what: str):
    if isinstance(value, (list, tuple)):
        value = ca.vertcat(*value)
    if not isinstance(value, (ca.SX, ca.MX)):
        value = ca.SX(value)
    if value.shape != (n, 1):
        if value.shape == (1, n):
            value = value.T
        else:
            raise InputError(f"{what} must return {n} values, got shape {value.shape}")
    return value


def solve_gauss(
    ocp: OcpDescription,
    mesh: Mesh,
    guess: Guess,
    *,
    ipopt_options: dict | None = None,
) -> NlpSolution:
    """Transcribe ``ocp`` on ``mesh`` with the Gauss pseudospectral method and solve with IPOPT.

    Never raises for a failed solve: the returned :class:`NlpSolution` carries ``success`` and
    IPOPT's ``status``; the caller decides what to do.
    """
    t_build = _time.perf_counter()
    nx, nu = ocp.n_x, ocp.n_u
    sx = np.asarray(ocp.state_scale)
    su = np.asarray(ocp.control_scale)
    ts = float(ocp.time_scale)

    # symbolic dynamics / objective / path as CasADi functions (problem layer stays casadi-generic)
    xs_, us_, ts_ = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("t")
    f_fun = ca.Function("f", [xs_, us_, ts_], [_as_column(ocp.dynamics(xs_, us_, ts_), nx, "dynamics")])
    l_fun = None
    if ocp.lagrange is not None:
        l_fun = ca.Function("l", [xs_, us_, ts_], [_as_column(ocp.lagrange(xs_, us_, ts_), 1, "lagrange")])
    n_path = len(ocp.path_lower)
    p_fun = None
    if ocp.path is not None:
        p_fun = ca.Function("p", [xs_, us_, ts_], [_as_column(ocp.path(xs_, us_, ts_), n_path, "path")])

    w_parts, lbw, ubw, w0 = [], [], [], []
    g_parts, lbg, ubg = [], [], []

    def add_var(sym, lo, hi, init):
        w_parts.append(ca.vec(sym))
        size = (sym.numel(),)
        lbw.append(np.broadcast_to(np.ravel(lo, order="F"), size))
        ubw.append(np.broadcast_to(np.ravel(hi, order="F"), size))
        w0.append(np.broadcast_to(np.ravel(init, order="F"), size))

    def add_con(expr, lo, hi):
        expr = ca.vec(expr)
        g_parts.append(expr)
        lbg.append(np.broadcast_to(np.ravel(lo, order="F"), (expr.numel(),)))
        ubg.append(np.broadcast_to(np.ravel(hi, order="F"), (expr.numel(),)))

    # final time
    tf_lo, tf_hi = ocp.final_time_bounds
    tf_s = ca.SX.sym("tf")
    tf0 = float(np.clip(guess.final_time, tf_lo, tf_hi))
    add_var(tf_s, tf_lo / ts, tf_hi / ts, tf0 / ts)
    tf = tf_s * ts

    # break points
    k_seg = len(mesh.segments)
    if mesh.free_breakpoints:
        sig_s = ca.SX.sym("sigma", k_seg - 1)
        lo = [b[0] for b in mesh.breakpoint_bounds]
        hi = [b[1] for b in mesh.breakpoint_bounds]
        add_var(sig_s, lo, hi, mesh.breakpoints)
        sig = ca.vertcat(0.0, sig_s, 1.0)
        add_con(sig[1:] - sig[:-1], mesh.min_fraction, np.inf)
    else:
        sig = ca.DM([0.0, *mesh.breakpoints, 1.0])
    sig_guess = np.array([0.0, *mesh.breakpoints, 1.0])

    x_lo = np.array(ocp.state_lower) / sx
    x_hi = np.array(ocp.state_upper) / sx
    u_lo = np.array(ocp.control_lower) / su
    u_hi = np.array(ocp.control_upper) / su

    objective = 0
    seg_syms = []
    x_start = None  # scaled state at the start of the current segment (symbolic)
    for k, seg in enumerate(mesh.segments):
        n = seg.n_nodes
        tau, w = _nodes.legendre_gauss(n)
        d = _nodes.gauss_differentiation_matrix(n)
        support = _nodes.gauss_support_points(n)
        xk = ca.SX.sym(f"X{k}", nx, n + 1)
        pk = ca.SX.sym(f"P{k}", nu, seg.n_params)
        lo_k = np.repeat(x_lo[:, None], n + 1, axis=1)
        hi_k = np.repeat(x_hi[:, None], n + 1, axis=1)
        if k == 0:
            for i, v in enumerate(ocp.initial_state):
                if v is not None:
                    lo_k[i, 0] = hi_k[i, 0] = v / sx[i]
        s_sup = sig_guess[k] + (support + 1.0) * 0.5 * (sig_guess[k + 1] - sig_guess[k])
        add_var(xk, lo_k, hi_k, guess.state_at(s_sup) / sx[:, None])
        s_lg = sig_guess[k] + (tau + 1.0) * 0.5 * (sig_guess[k + 1] - sig_guess[k])
        u_guess = guess.control_at(s_lg) / su[:, None]  # nu x n
        p_guess = np.linalg.lstsq(seg.control_map, u_guess.T, rcond=None)[0].T
        if seg.is_convex:
            add_var(pk, np.repeat(u_lo[:, None], seg.n_params, 1), np.repeat(u_hi[:, None], seg.n_params, 1),
                    np.clip(p_guess, u_lo[:, None], u_hi[:, None]))
        else:
            add_var(pk, -np.inf, np.inf, p_guess)
        c_map = ca.DM(np.asarray(seg.control_map))
        uk = ca.mtimes(pk, c_map.T)  # nu x n, scaled
        if not seg.is_convex:
            add_con(uk, np.repeat(u_lo[:, None], n, 1), np.repeat(u_hi[:, None], n, 1))

        if x_start is not None:
            add_con(xk[:, 0] - x_start, 0.0, 0.0)  # continuity with the previous segment

        h = (sig[k + 1] - sig[k]) * tf
        t_lg = sig[k] * tf + (ca.DM(tau) + 1.0) * 0.5 * h  # n x 1
        x_phys = ca.diag(ca.DM(sx)) @ xk[:, 1:]
        u_phys = ca.diag(ca.DM(su)) @ uk
        f_val = f_fun.map(n)(x_phys, u_phys, t_lg.T)  # nx x n (physical)
        defect = ca.mtimes(xk, ca.DM(d).T) - (h / 2.0) * (ca.diag(ca.DM(1.0 / sx)) @ f_val)
        add_con(defect, 0.0, 0.0)
        if p_fun is not None:
            add_con(p_fun.map(n)(x_phys, u_phys, t_lg.T), np.repeat(np.array(ocp.path_lower)[:, None], n, 1),
                    np.repeat(np.array(ocp.path_upper)[:, None], n, 1))
        if l_fun is not None:
            objective = objective + (h / 2.0) * ca.mtimes(l_fun.map(n)(x_phys, u_phys, t_lg.T), ca.DM(w))
        # eq. 24: X(+1) = X(-1) + sum_k w_k sum_i D_ki X_i  (linear)
        x_start = xk[:, 0] + ca.mtimes(xk, ca.DM(np.asarray(w) @ np.asarray(d)))
        seg_syms.append((xk, pk, uk))

    xf = ca.SX.sym("Xf", nx)
    lo_f, hi_f = x_lo.copy(), x_hi.copy()
    for i, v in enumerate(ocp.final_state):
        if v is not None:
            lo_f[i] = hi_f[i] = v / sx[i]
    add_var(xf, lo_f, hi_f, guess.state_at(1.0).ravel() / sx)
    add_con(xf - x_start, 0.0, 0.0)

    if ocp.mayer is not None:
        x0_phys = ca.diag(ca.DM(sx)) @ seg_syms[0][0][:, 0]
        xf_phys = ca.diag(ca.DM(sx)) @ xf
        objective = objective + _as_column(ocp.mayer(x0_phys, xf_phys, tf), 1, "mayer")

    wv = ca.vertcat(*w_parts)
    gv = ca.vertcat(*g_parts)
    nlp = {"x": wv, "f": objective / ocp.objective_scale, "g": gv}
    solver = _ipopt_solver("gpm", nlp, ipopt_options)
    build_time = _time.perf_counter() - t_build

    lbw_v, ubw_v, w0_v = (np.concatenate(a) for a in (lbw, ubw, w0))
    w0_v = np.clip(w0_v, lbw_v, ubw_v)
    t_solve = _time.perf_counter()
    sol = solver(x0=w0_v, lbx=lbw_v, ubx=ubw_v, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    solve_time = _time.perf_counter() - t_solve
    stats = solver.stats()

    # unpack
    out = ca.Function("out", [wv], [tf, sig] + [a for trip in seg_syms for a in trip] + [xf])
    vals = [np.asarray(v, dtype=float) for v in out(sol["x"])]
    tf_v = float(np.ravel(vals[0])[0])
    sig_v = np.ravel(vals[1])
    segs = []
    for k, seg in enumerate(mesh.segments):
        xk_v, pk_v, uk_v = vals[2 + 3 * k : 5 + 3 * k]
        xk_v = xk_v.reshape(nx, -1) * sx[:, None]
        end = vals[2 + 3 * (k + 1)] if k + 1 < k_seg else vals[-1]
        end = (end.reshape(nx, -1)[:, 0] if k + 1 < k_seg else end.ravel()) * sx
        tau, _ = _nodes.legendre_gauss(seg.n_nodes)
        segs.append(
            SegmentSolution(
                t0=float(sig_v[k] * tf_v),
                t1=float(sig_v[k + 1] * tf_v),
                tau=tau,
                support_states=xk_v,
                end_state=end,
                controls=uk_v.reshape(nu, -1) * su[:, None],
                params=pk_v.reshape(nu, -1) * su[:, None],
                control_map=seg.control_map,
            )
        )
    return NlpSolution(
        success=bool(stats.get("success", False)),
        status=str(stats.get("return_status", "unknown")),
        iterations=int(stats.get("iter_count", -1)),
        objective=float(np.ravel(np.asarray(sol["f"]))[0]) * ocp.objective_scale,
        final_time=tf_v,
        breakpoints=sig_v[1:-1] * tf_v,
        segments=tuple(segs),
        solve_time_s=solve_time,
        build_time_s=build_time,
        mesh=mesh,
    )


# --------------------------------------------------------------------------------------------------
# Control vector parameterisation (seed section 5: the CVP baseline)
# --------------------------------------------------------------------------------------------------


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


def solve_cvp(
    ocp: OcpDescription,
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
    if any(v is None for v in ocp.initial_state):
        raise InputError("CVP (single shooting) needs every initial state fixed")
    nx, nu = ocp.n_x, ocp.n_u
    sx = np.asarray(ocp.state_scale)
    su = np.asarray(ocp.control_scale)
    ts = float(ocp.time_scale)

    xs_, us_, t_ = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("t")
    rhs = _as_column(ocp.dynamics(xs_, us_, t_), nx, "dynamics")
    if ocp.lagrange is not None:
        rhs = ca.vertcat(rhs, _as_column(ocp.lagrange(xs_, us_, t_), 1, "lagrange"))
    else:
        rhs = ca.vertcat(rhs, 0)
    f_aug = ca.Function("f", [xs_, us_, t_], [rhs])
    path_fun = None
    if ocp.path is not None:
        path_fun = ca.Function("p", [xs_, us_, t_], [_as_column(ocp.path(xs_, us_, t_), len(ocp.path_lower), "path")])

    # one RK4 step of the augmented system with a linearly varying control u0 -> u1 over [t, t + h]
    xa, ua0, ua1, th, hh = ca.SX.sym("xa", nx + 1), ca.SX.sym("u0", nu), ca.SX.sym("u1", nu), ca.SX.sym("t"), ca.SX.sym("h")
    um = 0.5 * (ua0 + ua1)
    k1 = f_aug(xa[:nx], ua0, th)
    k2 = f_aug(xa[:nx] + 0.5 * hh * k1[:nx], um, th + 0.5 * hh)
    k3 = f_aug(xa[:nx] + 0.5 * hh * k2[:nx], um, th + 0.5 * hh)
    k4 = f_aug(xa[:nx] + hh * k3[:nx], ua1, th + hh)
    rk4 = ca.Function("rk4", [xa, ua0, ua1, th, hh], [xa + hh / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)])

    # one grid interval: ``substeps`` RK4 steps with u going linearly from u0 to u1; returns the
    # augmented state after every step (nx+1 x substeps)
    xi, ui0, ui1, ti, hi = ca.SX.sym("x", nx + 1), ca.SX.sym("u0", nu), ca.SX.sym("u1", nu), ca.SX.sym("t"), ca.SX.sym("h")
    cols, xc = [], xi
    for i in range(substeps):
        a, b = i / substeps, (i + 1) / substeps
        xc = rk4(xc, (1 - a) * ui0 + a * ui1, (1 - b) * ui0 + b * ui1, ti + i * hi, hi)
        cols.append(xc)
    interval = ca.Function("interval", [xi, ui0, ui1, ti, hi], [ca.horzcat(*cols)])

    tf_s = ca.MX.sym("tf")
    p_s = ca.MX.sym("P", nu, m)
    tf = tf_s * ts
    p_phys = ca.diag(ca.DM(su)) @ p_s
    dt = tf / (m - 1)
    h = dt / substeps
    x = ca.vertcat(ca.DM([float(v) for v in ocp.initial_state]), 0.0)
    x_lo = np.array(ocp.state_lower) / sx
    x_hi = np.array(ocp.state_upper) / sx
    traj = [x]
    for j in range(m - 1):
        steps = interval(x, p_phys[:, j], p_phys[:, j + 1], j * dt, h)
        traj.append(steps)
        x = steps[:, -1]
    traj_m = ca.horzcat(*traj)  # nx+1 x (1 + (m-1) substeps)
    states = traj_m[:nx, 1:]
    n_steps = (m - 1) * substeps
    g_parts = [ca.vec(ca.diag(ca.DM(1.0 / sx)) @ states)]
    lo_all = np.repeat(x_lo[:, None], n_steps, 1)
    hi_all = np.repeat(x_hi[:, None], n_steps, 1)
    for i, v in enumerate(ocp.final_state):  # final conditions replace the last bound column
        if v is not None:
            lo_all[i, -1] = hi_all[i, -1] = v / sx[i]
    lbg, ubg = [lo_all.ravel(order="F")], [hi_all.ravel(order="F")]
    if path_fun is not None:
        step_t = h * ca.DM(np.arange(1, n_steps + 1)).T
        # control at every step end (linear interpolation of the grid values)
        frac = np.arange(1, n_steps + 1) / substeps  # position in grid units
        jj = np.minimum(np.floor(frac - 1e-12).astype(int), m - 2)
        aa = frac - jj
        w_mat = np.zeros((m, n_steps))
        w_mat[jj, np.arange(n_steps)] = 1 - aa
        w_mat[jj + 1, np.arange(n_steps)] = aa
        u_steps = p_phys @ ca.DM(w_mat)
        g_parts.append(ca.vec(path_fun.map(n_steps)(states, u_steps, step_t)))
        lbg.append(np.tile(np.array(ocp.path_lower), n_steps))
        ubg.append(np.tile(np.array(ocp.path_upper), n_steps))

    objective = x[nx]
    if ocp.mayer is not None:
        x0 = ca.DM([float(v) for v in ocp.initial_state])
        objective = objective + _as_column(ocp.mayer(x0, x[:nx], tf), 1, "mayer")
    w = ca.vertcat(tf_s, ca.vec(p_s))
    nlp = {"x": w, "f": objective / ocp.objective_scale, "g": ca.vertcat(*g_parts)}
    solver = _ipopt_solver("cvp", nlp, ipopt_options)
    build_time = _time.perf_counter() - t_build

    tf_lo, tf_hi = ocp.final_time_bounds
    tf0 = float(np.clip(guess.final_time, tf_lo, tf_hi))
    grid_sigma = np.linspace(0.0, 1.0, m)
    u_lo = np.array(ocp.control_lower) / su
    u_hi = np.array(ocp.control_upper) / su
    p0 = np.clip(guess.control_at(grid_sigma) / su[:, None], u_lo[:, None], u_hi[:, None])
    lbx = np.concatenate(([tf_lo / ts], np.repeat(u_lo[:, None], m, 1).ravel(order="F")))
    ubx = np.concatenate(([tf_hi / ts], np.repeat(u_hi[:, None], m, 1).ravel(order="F")))
    x0 = np.concatenate(([tf0 / ts], p0.ravel(order="F")))
    t_solve = _time.perf_counter()
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    solve_time = _time.perf_counter() - t_solve
    stats = solver.stats()

    out = ca.Function("out", [w], [tf, p_phys, traj_m])
    tf_v, p_v, traj_v = (np.asarray(v, dtype=float) for v in out(sol["x"]))
    tf_v = float(np.ravel(tf_v)[0])
    return CvpSolution(
        success=bool(stats.get("success", False)),
        status=str(stats.get("return_status", "unknown")),
        iterations=int(stats.get("iter_count", -1)),
        objective=float(np.ravel(np.asarray(sol["f"]))[0]) * ocp.objective_scale,
        final_time=tf_v,
        grid=grid_sigma * tf_v,
        params=p_v.reshape(nu, m),
        step_times=np.linspace(0.0, tf_v, n_steps + 1),
        step_states=traj_v[:nx, :],
        solve_time_s=solve_time,
        build_time_s=build_time,
        substeps=substeps,
    )


# --------------------------------------------------------------------------------------------------
# Two-stage adaptive Gauss re-collocation of the control (seed section 3, eq. 26-31, Fig. 3-4)
# --------------------------------------------------------------------------------------------------


def slope_changes(params: np.ndarray, tau: np.ndarray, u_range: float) -> np.ndarray:
    """Seed eq. 28 for one control after the paired stage 1:
    ``S_{l+1} = (U_{l+1} - U_l) / (tau_{2l+1} - tau_{2l-1})``, ``l = 1 .. L-1``.

    ``params`` are the ``L`` paired values, ``tau`` the ``2 L`` LG points. The seed's thresholds
    (``eps = 0.04``) only make sense for a dimensionless control, so the values are divided by
    ``u_range`` (the width of the control bounds) and the magnitude ``|S|`` is returned (a drop is as
    much a jump as a rise).
    """
    u = np.asarray(params, dtype=float).reshape(-1) / float(u_range)
    tau = np.asarray(tau, dtype=float).reshape(-1)
    if tau.size != 2 * u.size:
        raise InputError(f"slope change: {u.size} paired values need {2 * u.size} LG points, got {tau.size}")
    first = tau[0::2]  # tau_{2l-1}, l = 1..L
    return np.abs(np.diff(u)) / np.diff(first)


def _groups_from_ties(tied: np.ndarray) -> list[int]:
    """Group sizes from ``tied[i]`` = "LG point i shares the value of point i-1" (tied[0] ignored)."""
    sizes = [1]
    for t in tied[1:]:
        if t:
            sizes[-1] += 1
        else:
            sizes.append(1)
    return sizes


def recollocated_groups(s: np.ndarray, eps_upper: float, eps_lower: float) -> list[int]:
    """Stage-2 control groups on the *same* LG points (the seed's single-interval stage 2).

    Start from the pairs ``U_{2l-1} = U_{2l}``. Where ``S_{l+1} <= eps_L`` (eq. 30) the next pair is
    merged into the current group (``U_{l+1} = U_l``, eq. 31). Where ``S_{l+1} >= eps_U`` (eq. 29) the
    interval ``[tau_{2l-1}, tau_{2l+1}]`` is subdivided: the points of pair ``l`` and of pair ``l + 1``
    get a value each. Subdivision wins over merging. Returns group sizes (they sum to ``2 L``).
    """
    s = np.asarray(s, dtype=float)
    n = 2 * (s.size + 1)
    tied = np.zeros(n, dtype=bool)
    tied[1::2] = True  # pairs (0-based: point 2l+1 tied to 2l)
    for l, sl in enumerate(s):  # boundary between pair l and pair l+1 (0-based)
        if sl <= eps_lower and sl < eps_upper:
            tied[2 * l + 2] = True  # merge pair l+1 into the group of pair l
    for l, sl in enumerate(s):
        if sl >= eps_upper:
            tied[2 * l + 1] = False  # split pair l
            tied[2 * l + 2] = False  # new value at tau_{2l+1}
            tied[2 * l + 3] = False  # split pair l+1
    return _groups_from_ties(tied)


def recollocate(
    stage1: NlpSolution,
    u_range: float,
    *,
    eps_upper: float = 0.04,
    eps_lower: float | None = None,
    mode: str = "hp",
    max_jump_boundaries: int = 3,
    widen: float = 1.0,
) -> Mesh:
    """Stage-2 mesh from a paired stage-1 solution (single segment, paired control map).

    ``mode="global"`` is the seed's stage 2: same LG points, control groups from
    :func:`recollocated_groups`. ``mode="hp"`` (our extension, needed for a bang-bang optimum to be
    resolved to ~0.01 s) uses the same eq. 28-31 classification to cut the *state* mesh as well:

    * every short run (``<= max_jump_boundaries``) of consecutive jump boundaries ``S >= eps_U`` is a
      control switch; it gets a break point, first guessed at the largest jump of the run;
    * a longer run is a steep stretch (or stage-1 noise) and becomes a segment of its own with a
      linear control between its two ends (a break point at each end; two control parameters whose
      bounds keep the whole ramp inside the control bounds);
    * the break points are decision variables ("moving mesh"): each may move half-way towards the
      neighbouring guesses (``widen = 1``) or anywhere in (0, 1) (``widen = inf``), segments being
      kept at least ``1e-4 t_f`` long;
    * between them the control is smooth (``S <= eps_L``): by eq. 31 it is merged to one value;
    * the ``2 L`` state nodes of stage 1 are shared out evenly among the segments (if that leaves
      fewer than 3 per segment, the global mode is used instead).

    Multiple controls: a boundary counts as a jump if any control jumps there.
    """
    if mode not in ("hp", "global"):
        raise InputError(f"two-stage: stage-2 mode must be 'hp' or 'global', got {mode!r}")
    eps_lower = eps_upper if eps_lower is None else float(eps_lower)
    if not (eps_upper > 0 and eps_lower > 0 and eps_lower <= eps_upper):
        raise InputError(f"two-stage: need 0 < eps_L <= eps_U, got eps_U = {eps_upper}, eps_L = {eps_lower}")
    if len(stage1.segments) != 1:
        raise InputError("two-stage: stage 1 must be a single-segment (global) solution")
    seg = stage1.segments[0]
    n = len(seg.tau)
    s = np.max(np.atleast_2d([slope_changes(p, seg.tau, u_range) for p in seg.params]), axis=0)
    if mode == "global":
        return Mesh.single(n, grouped_control_map(recollocated_groups(s, eps_upper, eps_lower)))

    tf = stage1.final_time
    sig_lg = seg.lg_times / tf
    jump = s >= eps_upper
    # runs of consecutive jump boundaries (0-based boundary l sits between pair l and pair l+1)
    runs, l = [], 0
    while l < jump.size:
        if jump[l]:
            start = l
            while l + 1 < jump.size and jump[l + 1]:
                l += 1
            runs.append((start, l))
        l += 1
    # break point guesses: the largest jump of a short run (a control switch); both ends of a long
    # run (a steep stretch, which becomes a segment with a linear control)
    bps, kinds = [], ["flat"]
    for a, b in runs:
        lo_idx, hi_idx = 2 * a, min(2 * b + 2, n - 1)  # tau_{2a-1} .. tau_{2b+1} (0-based)
        if b - a + 1 <= max_jump_boundaries:
            big = a + int(np.argmax(s[a : b + 1]))
            bps.append(0.5 * (sig_lg[2 * big + 1] + sig_lg[min(2 * big + 2, n - 1)]))
            kinds.append("flat")
        else:
            bps.extend([sig_lg[lo_idx], sig_lg[hi_idx]])
            kinds.extend(["ramp", "flat"])
    k = len(kinds)
    sizes = [n // k + (1 if i < n % k else 0) for i in range(k)]
    if min(sizes) < 3:  # too many jumps for the nodes: keep the seed's single interval
        return Mesh.single(n, grouped_control_map(recollocated_groups(s, eps_upper, eps_lower)))
    segments = tuple(
        Segment(m, np.ones((m, 1)) if kind == "flat" else lagrange_control_map(m, (-1.0, 1.0)))
        for m, kind in zip(sizes, kinds)
    )
    if not bps:
        return Mesh(segments)
    # every break point is free: it may move half-way towards its neighbours' guesses (``widen`` =
    # 1), or anywhere between the ends (``widen = inf``; the ordering constraint keeps segments apart)
    margin = 0.5 * min(sig_lg[0], 1.0 - sig_lg[-1])
    ext = [0.0] + bps + [1.0]
    bounds = []
    for i in range(1, len(ext) - 1):
        if math.isinf(widen):
            lo, hi = margin, 1.0 - margin
        else:
            lo = max(margin, ext[i] - 0.5 * widen * (ext[i] - ext[i - 1]))
            hi = min(1.0 - margin, ext[i] + 0.5 * widen * (ext[i + 1] - ext[i]))
        bounds.append((lo, hi))
    bps = [float(np.clip(v, lo, hi)) for v, (lo, hi) in zip(bps, bounds)]
    return Mesh(segments, tuple(bps), tuple(bounds), min_fraction=1e-4)
