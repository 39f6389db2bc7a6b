"""A primal-dual interior-point method for cell-structured NLPs, with a banded KKT solve.

The minimum-energy problem on a fine grid of cells (``ocp/cells.py``) has a structure a general NLP
solver does not use: every function belongs to one cell and reads only that cell's few variables (the
speeds at its two nodes and its forces), except a few global ones, the running time (and on a journey
the times at its stations), which sum over many cells. Its KKT matrix, with each cell's equality
multiplier placed beside its variables, is therefore banded (half-bandwidth 4 there) plus a term of low
rank from the global ones. A banded LU solves that in time linear in the number of cells, and the low-rank
term costs one more right-hand side per global inequality (Sherman-Morrison-Woodbury).
Through IPOPT (CasADi, MUMPS) the same Newton steps cost 10-40 us per variable and iteration on this
problem, and IPOPT needed 80-160 iterations from the same start; this solver takes about 0.3 us and 30-60
(its per-iteration vector work compiled, ``ocp/ipm_kernel.py``).

The algorithm is IPOPT's (Waechter and Biegler, Math. Program. 106, 2006) in a compact form: slacks
for the inequalities; the barrier problem solved approximately for a falling barrier parameter
(monotone Fiacco-McCormick rule, mu <- min(0.2 mu, mu^1.5) once the barrier problem's error is below
10 mu); the primal-dual Newton step with the slacks and bound multipliers eliminated; the
fraction-to-the-boundary rule; the filter line search with second-order corrections (an l1 merit
function instead took steps of 1 % for dozens of iterations on long lines); and regularisation of the
Hessian where the step's curvature is not positive (the inertia-free test of Chiang and Zavala, Comput.
Optim. Appl. 64, 2016: a banded LU gives no inertia). There is no feasibility restoration phase: a
trial that no step length makes acceptable takes a short step, and a solve that does not converge says
so (the caller refuses the result).

A problem gives, for its variables ``x`` (scaled to order one):
- ``lb``, ``ub``: bounds (``-inf`` / ``inf`` for none; ``lb == ub`` fixes a variable);
- ``local``: (cells, p) the indices of each cell's variables;
- ``pos_x``, ``pos_y``: the place of every variable and of every cell's equality multiplier in the
  KKT ordering (the problem chooses one that makes the matrix banded);
- ``values(x)``: :class:`CellValues`, the objective, one equality and q inequalities (<= 0) per cell,
  and m global inequalities (<= 0);
- ``derivatives(x)``: :class:`CellDerivatives`, their gradients on each cell's variables (the global
  inequalities' as per-cell parts that add up);
- ``hessian(x, y, z, zc)``: the Lagrangian's Hessian on each cell's variables, (cells, p, p).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..sim.native import kernels
from ..sim.records import IPMLayout, contiguous


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """a . b without BLAS (whose threads cost milliseconds per call on vectors of this size once LAPACK
    or another library has started them, and far more on a busy machine)."""
    return float(np.einsum("i,i->", a, b))


@dataclass
class CellValues:
    """A cell-structured NLP's functions at one point (N cells, q inequalities per cell)."""

    f: float
    e: np.ndarray  # (N,) one equality per cell, = 0
    g: np.ndarray  # (N, q) inequalities, <= 0
    c: np.ndarray  # (m,) the global inequalities, <= 0

    def finite(self) -> bool:
        return bool(np.isfinite(self.f) and np.all(np.isfinite(self.c)) and np.all(np.isfinite(self.e))
                    and np.all(np.isfinite(self.g)))


@dataclass
class CellDerivatives:
    """Their gradients on each cell's p variables."""

    grad_f: np.ndarray  # (N, p)
    grad_e: np.ndarray  # (N, p)
    grad_g: np.ndarray  # (N, q, p)
    grad_c: np.ndarray  # (m, N, p): per-cell parts of each global inequality's gradient


@dataclass
class IPMResult:
    """The solution (primal ``x``, equality multipliers ``y``, inequality multipliers ``z`` (N, q), the
    global inequalities' multipliers ``zc`` (m,), the bounds' multipliers ``zl``, ``zu``), the objective, whether it converged, the iterations, the
    final optimality error, the status, and per iteration (error, barrier parameter, primal step,
    dual step, regularisation, objective)."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    zc: np.ndarray
    zl: np.ndarray
    zu: np.ndarray
    f: float
    converged: bool
    iterations: int
    error: float
    status: str
    trace: list


@dataclass(frozen=True)
class IPMSettings:
    tol: float = 1e-8
    """Tolerance on the scaled optimality error (dual, primal, complementarity), IPOPT's scaling."""
    acceptable_tol: float = 1e-4
    acceptable_iter: int = 5
    acceptable_obj_change: float = 1e-7
    """Also converged ("acceptable") after ``acceptable_iter`` iterations in a row with the error below
    ``acceptable_tol``, the barrier parameter at its floor and the objective moving by at most this share:
    where Newton's method cannot reach ``tol`` (a force curve's slope changing fast right at the optimum's
    speed) while the optimum itself has settled (IPOPT's acceptable level)."""
    max_iter: int = 300
    mu_strategy: str = "monotone"
    """"monotone" (Fiacco-McCormick, IPOPT's default) or "adaptive": the barrier parameter of each step
    from Mehrotra's probing (the affine-scaling step's complementarity, sigma = (mu_aff / mu)^3, at least
    0.1), falling back to "monotone" when the optimality error stops falling or a step is not accepted
    (IPOPT's mu_strategy adaptive with mu_oracle probing). Adaptive takes 20-35 % fewer iterations from a
    start near the optimum (the finer grid from the coarser), monotone fewer from a cold start, which
    lies far from the central path (there the probing asks for too little centring and the steps
    shrink to a few per cent)."""
    mu_init: float = 1e-1
    kappa_eps: float = 10.0
    kappa_mu: float = 0.2
    theta_mu: float = 1.5
    tau_min: float = 0.99
    bound_push: float = 1e-2
    max_rejected: int = 10
    """A solve whose line search accepts no step this many iterations in a row stops ("stalled"): it then
    creeps at steps of 1e-3 with its error stuck (a warm start on a finer grid did so for 110 iterations
    at an error of 1.3e-4; a cold start then converged in 55)."""
    max_soc: int = 4
    """Second-order corrections tried when a full step is rejected (the Maratos effect: the constraints'
    curvature raises the violation although the step is good)."""
    curvature: float = 1e-8
    """A step is taken when dx' W dx >= curvature * dx'dx, else the Hessian is regularised."""


def _raw(entry):
    """A compiled entry point without its argument checks (``sim.native``), or the function itself."""
    return getattr(entry, "fn", entry)


class CellIPM:
    """The interior-point solver for one problem layout (its band structure is computed once)."""

    def __init__(self, problem, settings: IPMSettings | None = None):
        self.p = problem
        self.set = settings or IPMSettings()
        loc = problem.local
        self.N, self.np_ = loc.shape
        self.n = len(problem.lb)
        self.fixed = problem.lb == problem.ub
        self.has_l = np.isfinite(problem.lb) & ~self.fixed
        self.has_u = np.isfinite(problem.ub) & ~self.fixed
        self.size = self.n + self.N
        pos = np.empty((self.N, self.np_ + 1), dtype=np.int64)
        pos[:, :-1] = problem.pos_x[loc]
        pos[:, -1] = problem.pos_y
        self.pos = pos
        self.bw = int(np.max(pos.max(axis=1) - pos.min(axis=1)))
        self.pos_x = np.ascontiguousarray(problem.pos_x, dtype=np.int64)
        self.pos_y = np.ascontiguousarray(problem.pos_y, dtype=np.int64)
        self.fixed_pos = np.ascontiguousarray(self.pos_x[self.fixed])
        self._lb = np.where(self.has_l, problem.lb, 0.0)
        self._ub = np.where(self.has_u, problem.ub, 0.0)
        self.layout = contiguous(IPMLayout(np.asarray(loc, dtype=np.int64), self.fixed, np.flatnonzero(self.has_l),
                                           np.flatnonzero(self.has_u), self._lb, self._ub, self.pos_x, self.pos_y))

    # ------------------------------------------------------------------ helpers
    def _dist(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances to the lower and upper bounds (1 where there is none)."""
        return np.where(self.has_l, x - self._lb, 1.0), np.where(self.has_u, self._ub - x, 1.0)

    # ------------------------------------------------------------------ the method
    def solve(self, x0: np.ndarray, mu_init: float | None = None, warm: "IPMResult | None" = None) -> IPMResult:
        """Minimise from ``x0`` (pushed inside its bounds); ``mu_init``: the barrier parameter to start at;
        ``warm``: a solution of a neighbouring problem of the same layout whose multipliers to start from
        (its primal point should then be ``x0``), with the start pushed only slightly off the bounds.
        A trial point off the domain (a speed at zero, an infinite barrier) is rejected by the line search,
        and a solve that goes astray says so in its status: numpy's warnings about them are not shown."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            return self._solve(x0, mu_init, warm)

    def _solve(self, x0: np.ndarray, mu_init: float | None, warm: "IPMResult | None") -> IPMResult:
        S, p, N, n = self.set, self.p, self.N, self.n
        has_l, has_u, fixed = self.has_l, self.has_u, self.fixed
        lb, ub = self._lb, self._ub
        x = np.array(x0, dtype=float)
        push = S.bound_push if warm is None else 1e-9
        with np.errstate(invalid="ignore"):  # push the start inside the bounds (IPOPT's bound_push)
            span = np.where(has_l & has_u, ub - lb, np.inf)
        x = np.where(has_l, np.maximum(x, lb + np.minimum(push * np.maximum(1.0, np.abs(lb)), 0.49 * span)), x)
        x = np.where(has_u, np.minimum(x, ub - np.minimum(push * np.maximum(1.0, np.abs(ub)), 0.49 * span)), x)
        x = np.ascontiguousarray(np.where(fixed, p.lb, x))
        mu = float(mu_init if mu_init is not None else S.mu_init)
        val = p.values(x)
        floor = 1e-2 if warm is None else mu
        s = np.maximum(-val.g, floor)
        sc = np.maximum(-val.c, floor)
        dl, du = self._dist(x)
        if warm is None:
            z, zc, y = mu / s, mu / sc, np.zeros(N)
            zl = np.where(has_l, mu / dl, 0.0)
            zu = np.where(has_u, mu / du, 0.0)
        else:
            y = warm.y.copy()
            z = np.maximum(warm.z, mu / s * 1e-2)
            zc = np.maximum(warm.zc, mu / sc * 1e-2)
            zl = np.where(has_l, np.maximum(warm.zl, mu / dl * 1e-2), 0.0)
            zu = np.where(has_u, np.maximum(warm.zu, mu / du * 1e-2), 0.0)
        y, z, zc, zl, zu = (np.ascontiguousarray(v, dtype=float) for v in (y, z, zc, zl, zu))
        q, m = s.shape[1], sc.shape[0]
        filt, filter_mu, theta_max, theta_min = [], None, math.inf, 0.0
        delta_w_last, needed_last = 0.0, False
        full = np.empty((self.size, 3 * self.bw + 1))
        piv = np.empty(self.size, dtype=np.int64)
        K = kernels()
        # the solver's own calls skip the entry points' argument checks (its arrays are made right here)
        factor, solve_b, assemble = _raw(K.band_factor), _raw(K.band_solve), _raw(K.band_assemble)
        errors_k, newton_k, rhs_k = _raw(K.ipm_errors), _raw(K.ipm_newton), _raw(K.ipm_rhs)
        curvature_k, steps_k, merit_k = _raw(K.ipm_curvature), _raw(K.ipm_steps), _raw(K.ipm_merit)
        mean_k, update_k = _raw(K.ipm_mean_complementarity), _raw(K.ipm_update)
        lay = self.layout
        # the iteration's work arrays, made once
        r_d = np.empty(n)
        sig, sig_c, sig_x = np.empty((N, q)), np.empty(m), np.empty(n)
        grad_f, base_x, bound_x = np.empty(n), np.empty(n), np.empty(n)
        grad_c, a_mat = np.empty((m, n)), np.empty((self.size, m))
        diag_y = np.empty(N)
        status, trace, it, err0 = "max_iter", [], 0, math.inf
        rejected = 0
        acceptable, f_prev = 0, math.inf
        adaptive = S.mu_strategy == "adaptive"
        errs: list[float] = []

        def steps(d, r_g, r_c, mu_, tau_, dual=True):
            """(dx, dy, ds, dsc, dz, dzc, dzl, dzu, primal step, dual step, the barrier function's slope)."""
            out = (np.empty(n), np.empty(N), np.empty((N, q)), np.empty(m), np.empty((N, q)), np.empty(m),
                   np.empty(n), np.empty(n))
            a_p_, a_d_, dphi_ = steps_k(lay, d, der.grad_g, r_g, r_c, grad_c, s, sc, z, zc, zl, zu, dl, du, sig, sig_c,
                                        grad_f, mu_, tau_, dual, *out)
            return (*out, a_p_, a_d_, dphi_)

        for it in range(1, S.max_iter + 1):  # noqa: B007 (the count is returned after the loop)
            der = p.derivatives(x)
            e_dual, e_prim, p_max, p_min, s_c, mean_c = errors_k(
                lay, der.grad_f, der.grad_e, y, der.grad_g, z, der.grad_c, zc, zl, zu, val.e, val.g, s, val.c, sc,
                dl, du, r_d)

            def err_at(mu_):
                """The barrier problem's optimality error for ``mu_``."""
                return max(e_dual, e_prim, max(p_max - mu_, mu_ - p_min) / s_c)

            err0, err_mu = max(e_dual, e_prim, p_max / s_c), err_at(mu)
            if not (np.isfinite(err0) and np.all(np.isfinite(x))):  # lost: say so at once
                status = "not finite"
                break
            if err0 <= S.tol:
                status = "converged"
                break
            settled = abs(val.f - f_prev) <= S.acceptable_obj_change * max(1.0, abs(val.f))
            acceptable = acceptable + 1 if err0 <= S.acceptable_tol and (mu <= S.tol or adaptive) and settled else 0
            f_prev = val.f
            if acceptable >= S.acceptable_iter:
                status = "acceptable"
                break
            errs.append(err0)
            if adaptive and len(errs) > 12 and err0 > 0.9999 * errs[-5]:  # no progress: the monotone rule
                adaptive = False
                mu = max(S.tol / 10, 0.8 * mean_c)
                err_mu = err_at(mu)
            while not adaptive and err_mu <= S.kappa_eps * mu and mu > S.tol / 10:
                mu = max(S.tol / 10, min(S.kappa_mu * mu, mu ** S.theta_mu))
                err_mu = err_at(mu)
            # ---- the Newton system: W dx + A' dy = rhs_x, A dx = -e (slacks and bound multipliers eliminated)
            newton_k(lay, der.grad_f, der.grad_e, y, der.grad_c, s, z, sc, zc, dl, du, zl, zu, sig, sig_c, sig_x,
                     grad_f, base_x, bound_x, grad_c, a_mat)
            hess = p.hessian(x, y, z, zc)

            def rhs(r_e, r_g, r_c, mu_):
                """The right-hand side for the residuals r_e (equalities), r_g = g + s, r_c = c + sc, and the
                barrier parameter mu_."""
                out = np.empty(self.size)
                rhs_k(lay, base_x, bound_x, der.grad_g, s, sig, r_g, grad_c, sc, sig_c, r_c, r_e, mu_, out)
                return out

            r_g0, r_c0 = val.g + s, val.c + sc
            first = rhs(val.e, r_g0, r_c0, 0.0 if adaptive else mu)
            # where the last step needed a regularisation, start from a third of it (IPOPT tries 0 first:
            # here the reduced Hessian stays indefinite for many iterations in a row, and each try costs a
            # factorisation)
            delta_w, delta_c = (delta_w_last / 3 if delta_w_last > 0 and needed_last else 0.0), 0.0
            for _attempt in range(25):
                diag_y.fill(-delta_c)
                assemble(full, self.bw, self.pos, hess, der.grad_g, sig, der.grad_e, self.pos_x, sig_x + delta_w,
                         self.pos_y, diag_y, self.fixed_pos)
                if factor(full, self.bw, self.bw, piv) == 0:
                    sol = np.empty((self.size, 1 + m))
                    sol[:, 0] = first
                    sol[:, 1:] = a_mat
                    solve_b(full, self.bw, self.bw, piv, sol)
                    qm = sol[:, 1:].copy()  # K_b^-1 A
                    small = np.diag(1.0 / sig_c) + np.einsum("nj,nk->jk", a_mat, qm)

                    def direction(rv, sol=None):
                        """The Newton step for a right-hand side (the global inequalities' low-rank term
                        by Sherman-Morrison-Woodbury on the factored banded part)."""
                        if sol is None:
                            sol = rv.reshape(-1, 1).copy()
                            solve_b(full, self.bw, self.bw, piv, sol)
                        pv = sol[:, 0]
                        if m == 1:  # the running time alone: a division (what LAPACK does for 1 x 1)
                            return pv - qm[:, 0] * (_dot(a_mat[:, 0], pv) / small[0, 0])
                        return pv - np.einsum("nj,j->n", qm, np.linalg.solve(small, np.einsum("nj,n->j", a_mat, pv)))

                    d = direction(first, sol)
                    if np.all(np.isfinite(d)):
                        dx = d[self.pos_x]
                        curv, dxdx = curvature_k(lay, dx, hess, der.grad_g, sig, sig_x, delta_w, sig_c, grad_c)
                        if curv >= S.curvature * dxdx:
                            break
                else:  # a zero pivot: regularise the equality block too, more each time
                    delta_c = 10 * delta_c if delta_c > 0 else 1e-8 * mu ** 0.25
                delta_w = (max(1e-20, delta_w_last / 3) if delta_w == 0 and delta_w_last > 0
                           else 1e-4 if delta_w == 0 else 8.0 * delta_w)
            else:
                status = "singular"
                break
            needed_last = delta_w > 0
            delta_w_last = delta_w if delta_w > 0 else delta_w_last

            if adaptive:  # Mehrotra's probing: how far the affine-scaling step (mu = 0) gets
                dx_a, _, ds_a, dsc_a, dz_a, dzc_a, dzl_a, dzu_a, ap, ad, _ = steps(d, r_g0, r_c0, 0.0, 1.0)
                mu_aff = mean_k(lay, ap, ad, x, dx_a, s, ds_a, sc, dsc_a, z, dz_a, zc, dzc_a, zl, dzl_a, zu, dzu_a)
                mu = max(S.tol / 10, min(max((mu_aff / mean_c) ** 3, 0.1), 1.0) * mean_c)
                d = direction(rhs(val.e, r_g0, r_c0, mu))
            tau = max(S.tau_min, 1.0 - mu)
            dx, dy, ds, dsc, dz, dzc, dzl, dzu, a_p, a_d, dphi = steps(d, r_g0, r_c0, mu, tau)
            # ---- filter line search with second-order corrections
            logs0, theta0 = merit_k(lay, x, s, sc, val.e, val.g, val.c)
            phi0 = val.f - mu * logs0
            if mu != filter_mu:  # a new barrier problem: a new filter
                filt, filter_mu = [], mu
                theta_max, theta_min = 1e4 * max(1.0, theta0), 1e-4 * max(1.0, theta0)

            def judge(v_t: CellValues, x_t, s_t, sc_t, alpha) -> tuple[bool, bool, float]:
                """(accepted, f-type, the violation): acceptable to the filter, and either an Armijo decrease
                of the barrier function (when the step is mostly an objective step) or a sufficient decrease
                of the violation or of the barrier function."""
                if not v_t.finite():
                    return False, False, math.inf
                logs_t, theta_t = merit_k(lay, x_t, s_t, sc_t, v_t.e, v_t.g, v_t.c)
                phi_t = v_t.f - mu * logs_t
                if not np.isfinite(phi_t) or theta_t > theta_max:
                    return False, False, theta_t
                if any(theta_t >= th and phi_t >= ph for th, ph in filt):
                    return False, False, theta_t
                if dphi < 0 and alpha * (-dphi) ** 2.3 > theta0 ** 1.1 and theta0 <= theta_min:
                    return bool(phi_t <= phi0 + 1e-8 * alpha * dphi + 1e-14 * abs(phi0)), True, theta_t
                return bool(theta_t <= (1 - 1e-5) * theta0 or phi_t <= phi0 - 1e-8 * theta0), False, theta_t

            alpha, accepted, f_type = a_p, False, False
            for trial in range(40):
                xn, sn, scn = x + alpha * dx, s + alpha * ds, sc + alpha * dsc
                vn = p.values(xn)
                accepted, f_type, theta_n = judge(vn, xn, sn, scn, alpha)
                if accepted:
                    break
                if trial == 0 and S.max_soc > 0 and theta_n >= theta0 and vn.finite():
                    c_e, c_g, c_c = alpha * val.e + vn.e, alpha * r_g0 + (vn.g + sn), alpha * r_c0 + (vn.c + scn)
                    theta_soc = theta0
                    for _ in range(S.max_soc):  # second-order corrections of the full step
                        d_soc = direction(rhs(c_e, c_g, c_c, mu))
                        dx_s, dy_s, ds_s, dsc_s, *_, a_s, _, _ = steps(d_soc, c_g, c_c, mu, tau, False)
                        xs_, ss_, scs_ = x + a_s * dx_s, s + a_s * ds_s, sc + a_s * dsc_s
                        vs = p.values(xs_)
                        accepted, f_type, theta_new = judge(vs, xs_, ss_, scs_, alpha)
                        if accepted:
                            xn, sn, scn, vn = xs_, ss_, scs_, vs
                            dy = dy_s
                            break
                        if theta_new > 0.99 * theta_soc:
                            break
                        theta_soc = theta_new
                        c_e, c_g, c_c = a_s * c_e + vs.e, a_s * c_g + (vs.g + ss_), a_s * c_c + (vs.c + scs_)
                    if accepted:
                        break
                alpha *= 0.5
            if not accepted and adaptive:  # the adaptive rule lost its way: the monotone one from here
                adaptive = False
                mu = max(S.tol / 10, 0.8 * mean_c)
            rejected = 0 if accepted else rejected + 1
            if rejected > S.max_rejected:  # the line search has found nothing for a while: give up
                status = "stalled"
                break
            if not accepted:  # a short step anyway (IPOPT would restore feasibility here)
                alpha = min(a_p, 1e-3)
                xn, sn, scn = x + alpha * dx, s + alpha * ds, sc + alpha * dsc
                vn = p.values(xn)
            if not f_type:  # the filter keeps this point's margin
                filt.append(((1 - 1e-5) * theta0, phi0 - 1e-8 * theta0))
            trace.append((err0, mu, alpha, a_d, delta_w, val.f))
            x, s, sc, val = xn, sn, scn, vn
            dl, du = np.empty(n), np.empty(n)
            update_k(lay, x, s, sc, alpha, dy, a_d, dz, dzc, dzl, dzu, mu, y, z, zc, zl, zu, dl, du)
        return IPMResult(x, y, z, zc, zl, zu, float(val.f), status in ("converged", "acceptable"), it, float(err0),
                         status, trace)
