"""Legendre-Gauss-Radau (LGR) collocation of a multi-phase problem, solved by IPOPT (the MPOC paper's section 3).

Layer 3 of the multi-phase stack. On a :class:`~locoplan.ocp.mesh.Mesh`, every interval with ``n``
LGR points carries the states as a degree-``n`` polynomial through its ``n`` points and its end
(Garg et al.'s Radau pseudospectral method, GPOPS-II): the dynamics are collocated at the LGR points,
``D X = (ds/dtau) f(X, U, s)``, the objective is LGR quadrature of the integrand, path constraints
hold at the LGR points, state bounds at every state point. Controls live at the LGR points only.

The NLP is built from vectorised CasADi ``SX`` expressions over *all* collocation points at once
(one call of the model's functions, a sparse block differentiation matrix), so building it costs
milliseconds, and handed to IPOPT with exact Hessians. Variables and constraints are scaled by the
model's nominal magnitudes.

:func:`interval_errors` is GPOPS-II's error estimate: on ``n + 1`` LGR points per interval, the
states integrated from the interpolated dynamics against the interpolated states, relative to
``1 + max |x|`` on the interval.
"""

from __future__ import annotations

import time as _time
from functools import lru_cache
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from . import nodes as _nodes
from .mesh import Grid, Mesh
from .interrupt import solve_nlp
from .phase import MultiPhaseProblem

IPOPT_OPTIONS = {
    "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
    "ipopt.tol": 1e-6, "ipopt.acceptable_tol": 1e-5, "ipopt.acceptable_iter": 3, "ipopt.constr_viol_tol": 1e-8, "ipopt.max_iter": 500,
    "ipopt.acceptable_obj_change_tol": 1e-7,
    "ipopt.mu_strategy": "adaptive", "ipopt.linear_solver": "mumps", "ipopt.mumps_mem_percent": 100,
}
"""Silent IPOPT with tight tolerances (exact Hessian: CasADi's default). "Acceptable" ends a solve only
once the objective has settled (relative change < 1e-7 per iteration): without that, IPOPT stopped
refinement solves up to 3e-5 short of their optimum, the error estimate took that for discretisation
error and the refinement wandered (12 solves, not converged, instead of 8 on a 50 km line). MUMPS
gets 100 % working-space headroom instead of IPOPT's 1000 %: the same factorisations without zeroing
memory it never uses (-11 % solve time; IPOPT enlarges it if ever short)."""
MAP_THREADS = 1
"""Threads evaluating the model over the collocation points (this machine's two cores)."""
MIN_INTERVAL_M = 1e-3
"""Shortest interval next to a moving mesh point [units of s]."""


_MAP_CODE = {"linear": 0, "start": 1, "end": 2}


@lru_cache(maxsize=None)
def _weights(points: tuple) -> np.ndarray:
    return _nodes.barycentric_weights(np.array(points))


def _eval_model(fn: Callable, x, u, s, p, n_out: int):
    out = fn(x, u, s, p)
    if n_out == 1 and not isinstance(out, (list, tuple)):
        out = [out]
    return list(out)


def _params(problem: MultiPhaseProblem, phase_idx: np.ndarray, s: np.ndarray) -> dict:
    """Each phase's parameters at the positions ``s`` (whose phase is ``phase_idx``), stacked."""
    out: dict = {}
    for k in np.unique(phase_idx):
        sel = np.nonzero(phase_idx == k)[0]
        for name, val in problem.phases[k].params(s[sel]).items():
            arr = out.setdefault(name, np.zeros(s.size))
            arr[sel] = np.broadcast_to(np.asarray(val, dtype=float), sel.shape)
    return out


def _bounds_per_point(problem: MultiPhaseProblem, grid: Grid):
    """State bounds at every state point (a phase boundary point takes the tighter of both phases)
    and control bounds at every collocation point."""
    nx, nu = problem.model.n_x, problem.model.n_u
    xl = np.full((nx, grid.n_col + 1), -np.inf)
    xu = np.full((nx, grid.n_col + 1), np.inf)
    for k, pts in enumerate(grid.phase_points):
        ph = problem.phases[k]
        xl[:, pts] = np.maximum(xl[:, pts], np.asarray(ph.state_lower, float)[:, None])
        xu[:, pts] = np.minimum(xu[:, pts], np.asarray(ph.state_upper, float)[:, None])
    for i, v in enumerate(problem.initial_state):
        if v is not None:
            xl[i, 0] = xu[i, 0] = v
    xl[:, -1] = np.maximum(xl[:, -1], problem.final_lower)
    xu[:, -1] = np.minimum(xu[:, -1], problem.final_upper)
    ul = np.array([problem.phases[k].control_lower for k in grid.phase_col]).T
    uu = np.array([problem.phases[k].control_upper for k in grid.phase_col]).T
    return xl, xu, ul.reshape(nu, -1), uu.reshape(nu, -1)


@dataclass
class RadauSolution:
    """The NLP's answer on one mesh: states ``X`` (n_x x N+1 state points), controls ``U`` (n_u x N
    collocation points), the objective, IPOPT's status and timings."""

    problem: MultiPhaseProblem
    grid: Grid
    X: np.ndarray
    U: np.ndarray
    objective: float
    success: bool
    status: str
    iterations: int
    build_time_s: float
    solve_time_s: float
    params: dict = field(repr=False, default_factory=dict)
    lam_x: np.ndarray | None = field(repr=False, default=None)
    lam_g: np.ndarray | None = field(repr=False, default=None)
    n_path: int = 0

    @property
    def mesh(self) -> Mesh:
        return self.grid.mesh

    def _locate(self, s):
        s = np.atleast_1d(np.asarray(s, dtype=float))
        starts = np.array([iv.s_a for iv in self.mesh.intervals])
        return s, np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(starts) - 1)

    def _piecewise(self, s, values: np.ndarray, nodes, width: int):
        """The interval polynomials through ``values`` (one column per point, interval ``i``'s from
        ``offsets[i]``, ``n + width`` of them on ``nodes(n)``) at positions ``s``, and each position's
        interval: the barycentric formula over all positions of intervals of one degree at once."""
        s, idx = self._locate(s)
        ivs = self.mesh.intervals
        sa = np.array([iv.s_a for iv in ivs])[idx]
        d = np.array([iv.length for iv in ivs])[idx]
        kind = np.array([_MAP_CODE[iv.mapping] for iv in ivs])[idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.clip((s - sa) / d, 0.0, 1.0)
        tau = np.where(kind == 1, 2.0 * np.sqrt(rel) - 1.0,
                       np.where(kind == 2, 1.0 - 2.0 * np.sqrt(1.0 - rel), 2.0 * rel - 1.0))
        tau = np.clip(tau, -1.0, 1.0)  # Interval.tau_of, for all positions
        deg = np.array([iv.n for iv in ivs])[idx]
        out = np.empty((values.shape[0], s.size))
        for n in np.unique(deg):
            sel = np.nonzero(deg == n)[0]
            x = nodes(int(n))
            e = _nodes.barycentric_matrix(x, _weights(tuple(x)), tau[sel])  # positions x (n + width)
            cols = self.grid.offsets[idx[sel]][:, None] + np.arange(int(n) + width)[None, :]
            out[:, sel] = np.einsum("vtj,tj->vt", values[:, cols], e)
        return out, idx

    def states_at(self, s) -> np.ndarray:
        """The state polynomials at positions ``s`` (n_x x len(s))."""
        return self._piecewise(s, self.X, _nodes.radau_support_points, 1)[0]

    def controls_at(self, s, lower=None, upper=None) -> np.ndarray:
        """The control polynomials (degree n - 1 through the LGR values) at ``s``, clipped to the
        phases' control bounds."""
        u, idx = self._piecewise(s, self.U, lambda n: _nodes.legendre_gauss_radau(n)[0], 0)
        phase = np.array([iv.phase for iv in self.mesh.intervals])[idx]
        lo = np.array([ph.control_lower for ph in self.problem.phases], dtype=float)[phase].T
        hi = np.array([ph.control_upper for ph in self.problem.phases], dtype=float)[phase].T
        return np.clip(u, lo, hi)


def _sparse(a):
    """A scipy sparse (or numpy) matrix as a CasADi matrix that stores only its nonzeros, built from
    its compressed columns (7x faster than ``casadi.DM(scipy matrix)``: a tenth of a mesh's build)."""
    import casadi as ca

    a = sp.csc_matrix(a)
    a.sort_indices()
    return ca.DM(ca.Sparsity(a.shape[0], a.shape[1], a.indptr.tolist(), a.indices.tolist()), a.data.tolist())


def _affine_params(problem: MultiPhaseProblem, grid: Grid) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Each point's parameters as ``p_ref + slope (s - s_ref)`` around its current position ``s_ref``
    (phase parameters are affine in ``s`` inside a phase, so a moving mesh point keeps them exact)."""
    p0 = _params(problem, grid.phase_col, grid.s_col)
    p1 = _params(problem, grid.phase_col, grid.s_col + 1.0)
    names = sorted(p0)
    ref = np.array([p0[k] for k in names]).reshape(len(names), -1)
    slope = np.array([p1[k] - p0[k] for k in names]).reshape(len(names), -1)
    return names, ref, slope


def _block_diagonal(rows: int, cols: int, count: int):
    """Sparsity of ``count`` dense ``rows x cols`` blocks on the diagonal (nonzeros column by column,
    the layout of a horizontally stacked ``rows x (cols * count)`` matrix)."""
    import casadi as ca

    return ca.diagcat(*[ca.Sparsity.dense(rows, cols)] * count) if count else ca.Sparsity(0, 0)


_POINTS: dict = {}
"""Point functions per model (see :func:`_point_functions`): ``id -> (model, names, SX functions, jit job)``."""


def _point_functions(model, names: tuple[str, ...]):
    """The model at one collocation point as CasADi functions of ``(w, s_ref, p_ref, p_slope, sx)``
    (``w`` = state, control, position, ds/dtau; ``sx`` the state scales): the scaled constraints
    (defects, path), their Jacobian in ``w``, the objective integrand and, with ``mu`` (objective and
    constraint weights), the Lagrangian's Hessian in ``w``. Traced once per model and reused by every
    mesh; compiled versions (``jit.start``) replace the SX ones as soon as they are built."""
    import casadi as ca

    from . import jit

    entry = _POINTS.get(id(model))
    if entry is None or entry[0] is not model or entry[1] != names:
        nx, nu = model.n_x, model.n_u
        npath = model.n_path if model.path is not None else 0
        m, npar = nx + nu + 2, len(names)
        wl = ca.SX.sym("w", m)
        sref, pr, pd, sxs = ca.SX.sym("sref"), ca.SX.sym("pref", npar), ca.SX.sym("pslope", npar), ca.SX.sym("sx", nx)
        xl_ = [wl[i] for i in range(nx)]
        ul_ = [wl[nx + i] for i in range(nu)]
        s_sym, j_sym = wl[nx + nu], wl[nx + nu + 1]
        pdict = {k: pr[i] + pd[i] * (s_sym - sref) for i, k in enumerate(names)}
        f = ca.vertcat(*_eval_model(model.dynamics, xl_, ul_, s_sym, pdict, nx))
        con = -j_sym * f / sxs
        if npath:
            con = ca.vertcat(con, *_eval_model(model.path, xl_, ul_, s_sym, pdict, npath))
        integrand = j_sym * _eval_model(model.integrand, xl_, ul_, s_sym, pdict, 1)[0]
        mu = ca.SX.sym("mu", 1 + nx + npath)
        lag = mu[0] * integrand + ca.dot(mu[1:], con)
        args = [wl, sref, pr, pd, sxs]
        funcs = (ca.Function("lgr_con", args, [con]),
                 ca.Function("lgr_con_jac", args, [ca.densify(ca.jacobian(con, wl))]),
                 ca.Function("lgr_obj", args, [integrand]),
                 ca.Function("lgr_lag_hess", args + [mu], [ca.densify(ca.hessian(lag, wl)[0])]))
        if len(_POINTS) > 16:  # models of finished solves
            _POINTS.clear()
        # compiled: all but the trivial objective; CasADi differentiates the NLP's constraints once
        # (for the multipliers it reports), through the Jacobian compiled beside them
        job = jit.start((funcs[0], funcs[1], funcs[3]), helpers=(funcs[0].jacobian(),))
        entry = _POINTS[id(model)] = (model, names, funcs, job)
    job = entry[3]
    fast = job.ready() if job is not None else None
    return entry[2] if fast is None else (fast[0], fast[1], entry[2][2], fast[2])


def _check_radau(problem: MultiPhaseProblem, mesh: Mesh) -> None:
    """An InputError for a problem or mesh the Radau transcription does not take."""
    if problem.free_end is not None or problem.mayer is not None or problem.model.integrand is None:
        raise InputError("Radau transcription: needs a fixed end and an integrand objective (a free-end "
                         "or Mayer problem goes to the Gauss transcription, locoplan.ocp.gauss)")
    if any(iv.control_map is not None for iv in mesh.intervals):
        raise InputError("Radau transcription: a control map belongs to the Gauss transcription")


@dataclass
class _Layout:
    """What the parts of a Radau NLP read: the model, grid, sizes (``n`` collocation points, ``nc``
    constraints and ``m`` local variables per point, ``n_vars`` NLP variables), scales, the points'
    affine parameters, and (:meth:`RadauTranscription._local_variables`) the NLP's variables ``w``,
    the map ``E``, ``c`` onto the local ones ``wloc`` and the point functions' arguments ``call``."""

    model: object
    grid: Grid
    nx: int
    nu: int
    n: int
    npath: int
    nc: int
    m: int
    sx: np.ndarray
    su: np.ndarray
    names: list
    p_ref: np.ndarray
    p_slope: np.ndarray
    n_vars: int
    objective_scale: float
    E_np: object = None
    c: np.ndarray | None = None
    E: object = None
    w: object = None
    wloc: object = None
    call: tuple = ()


class RadauTranscription:
    """The NLP of ``problem`` on ``mesh``: build once, solve from any initial guess.

    Every collocation point depends on its own local variables ``w_k = (x_k, u_k, s_k, J_k)``
    (state, control, position, ds/dtau), and those are affine in the NLP's variables: a constant
    sparse matrix ``E`` maps one onto the other (positions and ``ds/dtau`` move only with a moving
    mesh point). So the constraints' Jacobian is ``blockdiag(dC_k/dw_k) E`` plus the constant
    differentiation matrix, and the Lagrangian's Hessian ``E' blockdiag(d2L_k/dw_k2) E`` plus the
    few terms of the rest start: the model is traced once on ``SX`` scalars into small point
    functions (value, Jacobian, Hessian), mapped over all points in an ``MX`` graph, and the NLP
    gets these exact derivatives directly. Building costs milliseconds, an IPOPT iteration a few.
    """

    def __init__(self, problem: MultiPhaseProblem, mesh: Mesh, ipopt_options: dict | None = None):
        import casadi as ca

        t0 = _time.perf_counter()
        _check_radau(problem, mesh)
        self.problem, self.mesh = problem, mesh
        L = self._layout(problem, mesh)
        grid, nf, sx, su = L.grid, len(L.grid.free), L.sx, L.su
        # ---- one point: SX functions traced once per model, compiled beside the solve (``jit``)
        f_con, f_jac, f_obj, f_hess = _point_functions(L.model, tuple(L.names))
        self._local_variables(L)
        xl, xu, ul, uu = _bounds_per_point(problem, grid)
        path_lo = np.full((max(L.npath, 1), L.n), -np.inf)
        _fix_arcs(mesh, L.model, grid, ul, uu, path_lo)
        g_parts, j_parts, lbg, ubg, sing_rows = self._constraints(L, f_con, f_jac, path_lo)
        g_all = ca.vertcat(*g_parts)
        jac_g = ca.vertcat(*j_parts)
        obj, lam_f, lam_g, H = self._objective_and_hessian(L, f_obj, f_hess, g_all.size1(), sing_rows)
        p = ca.MX.sym("p", 0, 1)
        w = L.w
        jac_fun = ca.Function("nlp_jac_g", [w, p], [g_all, jac_g], ["x", "p"], ["g", "jac_g_x"])
        hess_fun = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [ca.triu(H)],
                               ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        nlp = {"x": w, "f": obj, "g": g_all}
        opts = {**IPOPT_OPTIONS, **(ipopt_options or {}), "jac_g": jac_fun, "hess_lag": hess_fun}
        self.solver = ca.nlpsol("radau", "ipopt", nlp, opts)
        self.lbg, self.ubg = np.concatenate(lbg), np.concatenate(ubg)
        self.xl, self.xu, self.ul, self.uu = xl, xu, ul, uu
        self.lbx = np.concatenate([(xl / sx[:, None]).ravel(order="F"), (ul / su[:, None]).ravel(order="F"), np.zeros(nf)])
        self.ubx = np.concatenate([(xu / sx[:, None]).ravel(order="F"), (uu / su[:, None]).ravel(order="F"), np.ones(nf)])
        self.n_path = L.npath
        self.n_g = g_all.size1()
        self.build_time_s = _time.perf_counter() - t0

    def _layout(self, problem: MultiPhaseProblem, mesh: Mesh) -> "_Layout":
        """The grid, the sizes, the scales and the points' affine parameters; sets ``grid``, ``sx``, ``su``
        and the state and control variables' counts."""
        model = problem.model
        grid = self.grid = Grid(mesh)
        nx, nu, n = model.n_x, model.n_u, grid.n_col
        npath = model.n_path if model.path is not None else 0
        sx = np.asarray(model.state_scale, dtype=float)
        su = np.asarray(model.control_scale, dtype=float)
        self.sx, self.su = sx, su
        names, p_ref, p_slope = _affine_params(problem, grid)
        n_vars = nx * (n + 1) + nu * n + len(grid.free)
        self.n_x_vars, self.n_u_vars = nx * (n + 1), nu * n
        # nc: constraints per point; m: local variables per point
        return _Layout(model, grid, nx, nu, n, npath, nx + npath, nx + nu + 2, sx, su, names, p_ref, p_slope, n_vars,
                       problem.objective_scale)

    @staticmethod
    def _local_variables(L: "_Layout") -> None:
        """The NLP's variables ``w`` and the points' local ones, ``wloc = E w + c`` (column k*m + j: variable
        j of point k), with the arguments of the mapped point functions."""
        import casadi as ca

        L.E_np, L.c = _local_map(L.grid, L.nx, L.nu, L.sx, L.su, L.n_vars)
        L.E = _sparse(L.E_np)
        L.w = ca.MX.sym("w", L.n_vars)
        L.wloc = ca.reshape(ca.mtimes(L.E, L.w) + ca.DM(L.c), L.m, L.n)
        L.call = (L.wloc, ca.DM(L.grid.s_col).T, ca.DM(L.p_ref), ca.DM(L.p_slope), ca.DM(L.sx))

    def _constraints(self, L: "_Layout", f_con, f_jac, path_lo: np.ndarray) -> tuple:
        """The constraints with their Jacobian and bounds, in blocks: the pointwise ones (defects with the
        linear D X / sx, path), a rest start's start rows, and the lengths next to moving points;
        (expressions, Jacobians, lower, upper bounds, the rest start's (rate, path) or None)."""
        import casadi as ca

        grid, nx, nc, n, m, w, E = L.grid, L.nx, L.nc, L.n, L.m, L.w, L.E
        # ---- linear parts: D X / sx in the defect rows; smoothness; lengths next to moving points
        Dl = sp.kron(grid.D, sp.identity(nx), format="coo")  # rows k*nx + i, cols (state point)*nx + i
        Lin = sp.csc_matrix((Dl.data, ((Dl.row // nx) * nc + Dl.row % nx, Dl.col)), shape=(nc * n, L.n_vars))
        g_parts, j_parts = [], []
        lbg, ubg = [], []
        Lin_dm = _sparse(Lin)
        con_all = ca.vec(f_con.map(n)(*L.call)) + ca.mtimes(Lin_dm, w)
        jac_all = ca.MX(_block_diagonal(nc, m, n), ca.vec(f_jac.map(n)(*L.call)))
        jac_all = ca.mtimes(jac_all, E) + Lin_dm
        lb_pt = np.vstack([np.zeros((nx, n)), path_lo[:L.npath]])
        ub_pt = np.zeros((nc, n))
        small = []  # (expression, lower, upper) of the few constraints that are not pointwise
        sing_rows = None
        if grid.singular.any():
            extra, g_start = self._rest_start(L)
            pad = ca.vertcat(extra, ca.MX.zeros(nc * n - nx, 1))
            con_all = con_all + pad
            jac_all = jac_all + ca.jacobian(pad, w)
            sing_rows = (extra, g_start)
            if L.model.n_start_path:
                k = L.model.n_start_path
                small.append((g_start, np.full(k, -np.inf), np.zeros(k)))
        g_parts.append(con_all)
        j_parts.append(jac_all)
        lbg.append(lb_pt.ravel(order="F"))
        ubg.append(ub_pt.ravel(order="F"))
        for expr, lo_, hi_ in small:
            g_parts.append(expr)
            j_parts.append(ca.jacobian(expr, w))
            lbg.append(lo_)
            ubg.append(hi_)
        if grid.free:  # every interval next to a moving point keeps a positive length
            own = sorted({i for q in grid.free for i in (q - 1, q)})
            rr, dgr = self._length_rows(grid, own, nx + L.nu + 1, m)
            A = sp.csr_matrix(L.E_np[rr, :].multiply(1.0 / dgr[:, None]))
            Ad = _sparse(A)
            g_parts.append(ca.mtimes(Ad, w) + ca.DM(L.c[rr] / dgr))
            j_parts.append(Ad)
            lbg.append(np.full(len(own), MIN_INTERVAL_M))
            ubg.append(np.full(len(own), np.inf))
        return g_parts, j_parts, lbg, ubg, sing_rows

    def _rest_start(self, L: "_Layout") -> tuple:
        """A start from rest (a singular first point): the first point's rate of the states, scaled, and
        the model's start path constraints, as MX expressions of the NLP's variables."""
        import casadi as ca

        nx, nu, npar, model = L.nx, L.nu, len(L.names), L.model
        sref, pr, pd = ca.SX.sym("sref"), ca.SX.sym("pref", npar), ca.SX.sym("pslope", npar)
        xs0, us0 = ca.SX.sym("x0", nx), ca.SX.sym("u0", nu)
        s0, fac = ca.SX.sym("s0"), ca.SX.sym("fac")
        pd0 = {k: pr[i] + pd[i] * (s0 - sref) for i, k in enumerate(L.names)}
        x0l, u0l = [xs0[i] for i in range(nx)], [us0[i] for i in range(nu)]
        rate = ca.vertcat(*_eval_model(model.singular_start, x0l, u0l, s0, pd0, nx))
        start = ca.Function("start", [xs0, us0, s0, fac, sref, pr, pd],
                            [-fac * rate / ca.DM(L.sx),
                             ca.vertcat(*_eval_model(model.start_path, x0l, u0l, s0, pd0, model.n_start_path))])
        w0 = L.wloc[:, 0]
        r0, dg0 = self._length_rows(L.grid, [0], nx + nu + 1, L.m)
        fac_expr = ca.sqrt((ca.mtimes(L.E[int(r0[0]), :], L.w) + float(L.c[r0[0]])) / float(dg0[0])) / 2
        return start(w0[:nx], w0[nx:nx + nu], w0[nx + nu], fac_expr, L.grid.s_col[0], L.p_ref[:, 0], L.p_slope[:, 0])

    @staticmethod
    def _objective_and_hessian(L: "_Layout", f_obj, f_hess, n_g: int, sing_rows) -> tuple:
        """The objective (LGR quadrature of the integrand, scaled) and the Lagrangian's Hessian
        ``E' blockdiag(d2L_k/dw_k2) E`` plus a rest start's terms: (objective, lam_f, lam_g, H)."""
        import casadi as ca

        nx, nc, n, m, w, E = L.nx, L.nc, L.n, L.m, L.w, L.E
        wq = np.concatenate([_nodes.legendre_gauss_radau(iv.n)[1] for iv in L.grid.mesh.intervals])
        obj_scale = L.objective_scale
        obj = ca.mtimes(f_obj.map(n)(*L.call), ca.DM(wq)) / obj_scale
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", n_g)
        lam_pt = ca.reshape(lam_g[: nc * n], nc, n)
        mus = ca.vertcat(lam_f * ca.DM(wq).T / obj_scale, lam_pt)
        hess_blocks = ca.MX(_block_diagonal(m, m, n), ca.vec(f_hess.map(n)(*L.call, mus)))
        H = ca.mtimes(ca.mtimes(_sparse(L.E_np.T), hess_blocks), E)
        if sing_rows is not None:  # the rest start's terms (a few variables)
            extra, g_start = sing_rows
            lag_small = ca.dot(lam_g[:nx], extra)
            if L.model.n_start_path:
                lag_small = lag_small + ca.dot(lam_g[nc * n: nc * n + L.model.n_start_path], g_start)
            H = H + ca.hessian(lag_small, w)[0]
        return obj, lam_f, lam_g, H

    @staticmethod
    def _length_rows(grid: Grid, intervals, j_row: int, m: int) -> tuple[np.ndarray, np.ndarray]:
        """For each interval, the row of ``E`` of ds/dtau at a point where g' > 0, and that g': the
        interval's length is that ds/dtau over g' (affine in the NLP's variables)."""
        pts = np.array([grid.offsets[i] + (1 if grid.dg[grid.offsets[i]] == 0.0 else 0) for i in intervals], dtype=int)
        return pts * m + j_row, grid.dg[pts]

    def solve(self, X0: np.ndarray, U0: np.ndarray, warm: "RadauSolution | None" = None) -> RadauSolution:
        """Solve from states ``X0`` (n_x x N+1) and controls ``U0`` (n_u x N), clipped into bounds;
        moving points start where the mesh has them. With ``warm`` (the solution on a neighbouring
        mesh) its multipliers are carried over (:func:`carry_multipliers`) and IPOPT starts warm."""
        sx, su = self.sx, self.su
        grid = self.grid
        X0 = np.clip(X0, np.where(np.isfinite(self.xl), self.xl, -1e30), np.where(np.isfinite(self.xu), self.xu, 1e30))
        U0 = np.clip(U0, self.ul, self.uu)
        z0 = np.array([self.mesh.intervals[i].s_a for i in grid.free], dtype=float)
        if grid.free:
            lo, hi = grid.free_bounds[:, 0], grid.free_bounds[:, 1]
            z0 = np.clip((z0 - lo) / np.maximum(hi - lo, 1e-300), 0.0, 1.0)
        w0 = np.concatenate([(X0 / sx[:, None]).ravel(order="F"), (U0 / su[:, None]).ravel(order="F"), z0])
        t0 = _time.perf_counter()
        kw = {}
        if warm is not None and warm.lam_g is not None:
            kw["lam_x0"], kw["lam_g0"] = carry_multipliers(warm, self)
        sol = solve_nlp(self.solver, x0=w0, lbx=self.lbx, ubx=self.ubx, lbg=self.lbg, ubg=self.ubg, **kw)
        solve_time = _time.perf_counter() - t0
        stats = self.solver.stats()
        w = np.asarray(sol["x"], dtype=float).ravel()
        nx, nu, n = len(sx), len(su), grid.n_col
        X = w[: self.n_x_vars].reshape(nx, n + 1, order="F") * sx[:, None]
        U = w[self.n_x_vars:self.n_x_vars + self.n_u_vars].reshape(nu, n, order="F") * su[:, None]
        mesh = self.mesh
        if grid.free:  # the moving points where the NLP put them: the solution's own mesh
            lo, hi = grid.free_bounds[:, 0], grid.free_bounds[:, 1]
            z = lo + (hi - lo) * w[self.n_x_vars + self.n_u_vars:]
            ivs = list(mesh.intervals)
            for j, i in enumerate(grid.free):
                ivs[i] = replace(ivs[i], s_a=float(z[j]))
                ivs[i - 1] = replace(ivs[i - 1], s_b=float(z[j]))
            mesh = Mesh(tuple(ivs))
            grid = Grid(mesh)
        return RadauSolution(self.problem, grid, X, U, float(sol["f"]) * self.problem.objective_scale,
                             bool(stats.get("success", False)), str(stats.get("return_status", "unknown")),
                             int(stats.get("iter_count", -1)), self.build_time_s, solve_time,
                             _params(self.problem, grid.phase_col, grid.s_col),
                             np.asarray(sol["lam_x"], dtype=float).ravel(), np.asarray(sol["lam_g"], dtype=float).ravel(),
                             self.n_path)


@lru_cache(maxsize=None)
def _error_matrices(n: int):
    """For an interval of ``n`` LGR points: the ``n + 1`` LGR points ``tau_hat``, the matrices taking
    its state values (``n`` points and the end) and its control values onto the ``n + 1`` points
    (and the end, for the states), and the transposed inverse of the differentiation matrix's
    columns 2.. (integrating the dynamics): the per-degree algebra of :func:`interval_errors`."""
    m = n + 1
    tau_hat, _ = _nodes.legendre_gauss_radau(m)
    support = _nodes.radau_support_points(n)
    to_hat_x = _nodes.barycentric_matrix(support, _weights(tuple(support)), _nodes.radau_support_points(m)).T
    tau_u, _ = _nodes.legendre_gauss_radau(n)
    to_hat_u = _nodes.barycentric_matrix(tau_u, _weights(tuple(tau_u)), tau_hat).T
    d = _nodes.radau_differentiation_matrix(m)
    return tau_hat, to_hat_x, to_hat_u, np.linalg.inv(d[:, 1:]).T


def interval_errors(sol: RadauSolution) -> np.ndarray:
    """GPOPS-II's relative error of each interval (see the module text): on ``M = n + 1`` LGR points,
    ``max |X_integrated - X_interpolated| / (1 + max |X|)`` over the states, with the controls the NLP
    chose, interpolated; and, as large as that, how far the state polynomial passes its upper bound
    between the points (a speed over the limit), relative to the same scale.

    The controls are not cut to their speed-dependent bounds between the points: the force curves are
    piecewise linear, and a control on such a bound across a corner of its curve (the air brake's is
    tabulated every 2 km/h) differs from any polynomial by a share that raising the degree does not
    shrink, so the estimate would never meet the tolerance; the state polynomial follows the collocated
    controls, and its own error is what refinement reduces."""
    problem, grid = sol.problem, sol.grid
    model = problem.model
    errs = np.zeros(len(grid.mesh.intervals))
    for i, iv in enumerate(grid.mesh.intervals):
        m = iv.n + 1
        tau_hat, to_hat_x, to_hat_u, d_inv = _error_matrices(iv.n)
        xs = sol.X[:, grid.points_of(i)]
        x_hat = xs @ to_hat_x  # nx x m+1: the state polynomial on the n + 1 LGR points and the end
        u_hat = sol.U[:, grid.cols_of(i)] @ to_hat_u
        ph = problem.phases[iv.phase]
        u_hat = np.clip(u_hat, np.asarray(ph.control_lower)[:, None], np.asarray(ph.control_upper)[:, None])
        s_hat = iv.s_of(tau_hat)
        p = {k: np.broadcast_to(np.asarray(v, float), s_hat.shape).copy() for k, v in ph.params(s_hat).items()}
        xl = [x_hat[j, :m] for j in range(model.n_x)]
        ul = [u_hat[j] for j in range(model.n_u)]
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.array([np.asarray(v, float) * np.ones(m) for v in _eval_model(model.dynamics, xl, ul, s_hat, p, model.n_x)])
        f = f * iv.ds_dtau(tau_hat)[None, :]
        if iv.mapping == "start" and i == 0 and problem.rest_start:
            p0 = {k: v[:1] for k, v in p.items()}
            rate = _eval_model(model.singular_start, [x[:1] for x in xl], [u[:1] for u in ul], s_hat[:1], p0, model.n_x)
            f[:, 0] = np.array([float(np.asarray(r).ravel()[0]) for r in rate]) * iv.sqrt_factor
        integ = f @ d_inv  # X(tau_2..tau_m, +1) - X(-1)
        x_int = x_hat[:, :1] + integ
        scale = 1.0 + np.max(np.abs(xs), axis=1)
        over = np.maximum(x_hat[:, :m] - np.asarray(ph.state_upper, float)[:, None], 0.0)  # a limit passed between points
        errs[i] = float(max(np.max(np.abs(x_int - x_hat[:, 1:]) / scale[:, None]), np.max(over / scale[:, None])))
    return errs


def control_activity(sol: RadauSolution, tol: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Whether each control sits on its lower bound, and on its upper bound (its speed-dependent path
    bound where the model names one, else its box bound), at each collocation point, within ``tol``
    of its scale."""
    problem, grid = sol.problem, sol.grid
    model = problem.model
    n = grid.n_col
    su = np.asarray(model.control_scale, dtype=float)[:, None]
    ul = np.array([problem.phases[k].control_lower for k in grid.phase_col]).T.reshape(model.n_u, n)
    uu = np.array([problem.phases[k].control_upper for k in grid.phase_col]).T.reshape(model.n_u, n)
    lower = sol.U - ul <= tol * su
    upper = uu - sol.U <= tol * su
    if model.path is not None and model.control_paths:
        x = [sol.X[i, :n] for i in range(model.n_x)]
        u = [sol.U[i] for i in range(model.n_u)]
        with np.errstate(divide="ignore", invalid="ignore"):
            g = [np.asarray(v, float) * np.ones(n) for v in _eval_model(model.path, x, u, grid.s_col, sol.params, model.n_path)]
        for j, row in enumerate(model.control_paths):
            if row is not None:
                upper[j] |= g[row] >= -tol * su[j, 0]
    return lower & ~upper, upper & ~lower


def on_state_bound(sol: RadauSolution, tol: float = 1e-4) -> np.ndarray:
    """Whether a state sits on its upper bound (within ``tol`` of its scale) at each collocation point:
    the train at its speed limit, where the controls hold the state on the bound (a cruise at the limit,
    braking to hold it on a descent) instead of lying on a bound of their own (``mesh.refine`` takes no
    arc from such a point)."""
    problem, grid = sol.problem, sol.grid
    n = grid.n_col
    upper = np.array([problem.phases[k].state_upper for k in grid.phase_col], dtype=float).T
    scale = np.asarray(problem.model.state_scale, dtype=float)[:, None]
    return np.any(upper - sol.X[:, :n] <= tol * scale, axis=0)


def carry_multipliers(old: RadauSolution, new: "RadauTranscription") -> tuple[np.ndarray, np.ndarray]:
    """Multipliers of ``old`` moved onto the mesh of ``new`` (for IPOPT's warm start).

    A defect multiplier is the costate times the point's quadrature weight, a path or bound
    multiplier the multiplier density times weight and ds/dtau; the densities are interpolated
    along ``s`` and multiplied by the new weights (on an unchanged interval this returns the old
    values). The few other constraints start at zero."""
    og, ng = old.grid, new.grid
    nx, nu = old.X.shape[0], old.U.shape[0]
    npath = old.n_path
    nc = nx + npath
    wo = np.concatenate([_nodes.legendre_gauss_radau(iv.n)[1] for iv in og.mesh.intervals])
    wn = np.concatenate([_nodes.legendre_gauss_radau(iv.n)[1] for iv in ng.mesh.intervals])
    jo = np.maximum(og.jacobian, 1e-12)
    jn = np.maximum(ng.jacobian, 1e-12)
    lg = old.lam_g[: nc * og.n_col].reshape(nc, og.n_col, order="F")
    lam_g = np.zeros(new.n_g)
    dens = np.vstack([lg[:nx] / wo, lg[nx:] / (wo * jo)])
    moved = np.array([np.interp(ng.s_col, og.s_col, d) for d in dens])
    moved[:nx] *= wn
    moved[nx:] *= wn * jn
    lam_g[: nc * ng.n_col] = moved.ravel(order="F")
    lam_x = np.zeros(new.n_x_vars + new.n_u_vars + len(ng.free))
    lx = old.lam_x[: nx * (og.n_col + 1)].reshape(nx, og.n_col + 1, order="F")
    lam_x[: nx * (ng.n_col + 1)] = np.array([np.interp(ng.s_points, og.s_points, r) for r in lx]).ravel(order="F")
    lu = old.lam_x[nx * (og.n_col + 1): nx * (og.n_col + 1) + nu * og.n_col].reshape(nu, og.n_col, order="F")
    du = np.array([np.interp(ng.s_col, og.s_col, r / (wo * jo)) for r in lu]) * (wn * jn)
    lam_x[nx * (ng.n_col + 1): nx * (ng.n_col + 1) + nu * ng.n_col] = du.ravel(order="F")
    return lam_x, lam_g


def _local_map(grid: Grid, nx: int, nu: int, sx: np.ndarray, su: np.ndarray, n_vars: int):
    """Each collocation point's local variables (its states, controls, position and the interval's jacobian: m =
    nx + nu + 2 of them) from the NLP's scaled variables: wloc = E w + c, column k * m + j variable j of point k;
    a moving mesh point's position enters through its scaled variable in [0, 1]. Returns (E as scipy CSC, c)."""
    n = grid.n_col
    m = nx + nu + 2
    rows, cols, vals = [], [], []
    c = np.zeros(m * n)
    k_idx = np.arange(n)
    for j in range(nx):
        rows.append(k_idx * m + j)
        cols.append(j + nx * k_idx)
        vals.append(np.full(n, sx[j]))
    for j in range(nu):
        rows.append(k_idx * m + nx + j)
        cols.append(nx * (n + 1) + j + nu * k_idx)
        vals.append(np.full(n, su[j]))
    c[k_idx * m + nx + nu] = grid.s_col
    c[k_idx * m + nx + nu + 1] = grid.jacobian
    if len(grid.free):
        lo, hi = grid.free_bounds[:, 0], grid.free_bounds[:, 1]
        width = hi - lo
        # s = s_a + (s_b - s_a) g, J = (s_b - s_a) g', s_a = a0 + Aa z, s_b = b0 + Ab z, z = lo + width Z
        ds = grid.Aa * (1 - grid.g)[:, None] + grid.Ab * grid.g[:, None]
        dj = (grid.Ab - grid.Aa) * grid.dg[:, None]
        c[k_idx * m + nx + nu] = grid.a0 + (grid.b0 - grid.a0) * grid.g + ds @ lo
        c[k_idx * m + nx + nu + 1] = (grid.b0 - grid.a0) * grid.dg + dj @ lo
        for mat, off in ((ds, nx + nu), (dj, nx + nu + 1)):
            r, q = np.nonzero(mat)
            rows.append(r * m + off)
            cols.append(nx * (n + 1) + nu * n + q)
            vals.append(mat[r, q] * width[q])
    E_np = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m * n, n_vars))
    return E_np, c


def _fix_arcs(mesh: Mesh, model, grid: Grid, ul: np.ndarray, uu: np.ndarray, path_lo: np.ndarray) -> None:
    """In place: on each interval next to a moving point, the arc the refinement fixed (``Interval.regime``): a
    control on its lower bound, or on its upper bound (through its path row where the upper bound is one)."""
    for i, iv in enumerate(mesh.intervals):
        if iv.regime is None:
            continue
        cc = grid.cols_of(i)
        for j, r in enumerate(iv.regime):
            row = model.control_paths[j] if j < len(model.control_paths) else None
            if r == "lower":
                uu[j, cc] = ul[j, cc]
            elif r == "upper" and row is not None:
                path_lo[row, cc] = 0.0
            elif r == "upper":
                ul[j, cc] = uu[j, cc]
