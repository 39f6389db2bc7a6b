"""A primal-dual interior-point method for cell-structured NLPs, with a banded KKT solve.

The minimum-energy problem on a fine grid of cells (``ocp/cells.py``) has a structure a general NLP
solver does not use: every function belongs to one cell and reads only that cell's few variables (the
speeds at its two nodes and its forces), except a few global ones, the running time (and on a journey
the times at its stations), which sum over many cells. Its KKT matrix, with each cell's equality
multiplier placed beside its variables, is therefore banded (half-bandwidth 4 there) plus a term of low
rank from the global ones. A banded LU solves that in time linear in the number of cells, and the low-rank
term costs one more right-hand side per global inequality (Sherman-Morrison-Woodbury).
Through IPOPT (CasADi, MUMPS) the same Newton steps cost 10-40 us per variable and iteration on this
problem, and IPOPT needed 80-160 iterations from the same start; this solver takes about 1 us and 30-60.

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
        self._flat = np.ascontiguousarray(loc.ravel())
        self._il, self._iu = np.flatnonzero(self.has_l), np.flatnonzero(self.has_u)  # index arrays: faster than masks
        self._dist_last = None
        self._lb = np.where(self.has_l, problem.lb, 0.0)
        self._ub = np.where(self.has_u, problem.ub, 0.0)

    # ------------------------------------------------------------------ helpers
    def _scatter(self, local_vals: np.ndarray) -> np.ndarray:
        """Per-cell parts (N, p) summed into a vector over the variables."""
        return np.bincount(self._flat, weights=local_vals.ravel(), minlength=self.n)

    def _to_kkt(self, vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
        out = np.zeros(self.size)
        out[self.pos_x] = vx
        out[self.pos_y] = vy
        return out

    def _dist(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distances to the lower and upper bounds (1 where there is none), kept for the last point asked."""
        last = self._dist_last
        if last is not None and last[0] is x:
            return last[1]
        out = np.where(self.has_l, x - self._lb, 1.0), np.where(self.has_u, self._ub - x, 1.0)
        self._dist_last = (x, out)
        return out

    def _barrier(self, v: CellValues, x, s, sc, mu) -> float:
        dl, du = self._dist(x)
        with np.errstate(invalid="ignore", divide="ignore"):
            bar = (np.log(s).sum() + np.log(sc).sum() + np.log(dl[self._il]).sum() + np.log(du[self._iu]).sum())
        return v.f - mu * bar

    @staticmethod
    def _violation(v: CellValues, s, sc) -> float:
        return float(np.abs(v.e).sum() + np.abs(v.g + s).sum() + np.abs(v.c + sc).sum())

    def _errors(self, v: CellValues, d: CellDerivatives, x, s, sc, y, z, zc, zl, zu, mu) -> tuple[float, float]:
        """IPOPT's scaled optimality error of the NLP and of the barrier problem for ``mu``."""
        r_d = self._scatter(d.grad_f + d.grad_e * y[:, None] + np.einsum("kqp,kq->kp", d.grad_g, z)
                            + np.einsum("jkp,j->kp", d.grad_c, zc))
        r_d = r_d - zl + zu
        r_d[self.fixed] = 0.0
        prim = max(np.max(np.abs(v.e), initial=0.0), np.max(np.abs(v.g + s), initial=0.0), np.max(np.abs(v.c + sc)))
        dl, du = self._dist(x)
        prods = np.concatenate([(s * z).ravel(), sc * zc, (dl * zl)[self._il], (du * zu)[self._iu]])
        n_dual = y.size + prods.size
        duals = z.sum() + zc.sum() + zl.sum() + zu.sum()
        s_d = max(100.0, (np.abs(y).sum() + duals) / n_dual) / 100.0
        s_c = max(100.0, duals / max(prods.size, 1)) / 100.0
        dual = np.max(np.abs(r_d)) / s_d
        return (max(dual, prim, np.max(prods) / s_c),
                max(dual, prim, max(np.max(prods) - mu, mu - np.min(prods)) / s_c))

    def _mean_complementarity(self, x, s, sc, z, zc, zl, zu) -> float:
        dl, du = self._dist(x)
        prods = np.concatenate([(s * z).ravel(), sc * zc, (dl * zl)[self._il], (du * zu)[self._iu]])
        return float(prods.mean())

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
        S, p, N = self.set, self.p, self.N
        has_l, has_u, fixed = self.has_l, self.has_u, self.fixed
        il, iu = self._il, self._iu
        loc = p.local
        lb, ub = self._lb, self._ub
        x = np.array(x0, dtype=float)
        push = S.bound_push if warm is None else 1e-9
        with np.errstate(invalid="ignore"):  # push the start inside the bounds (IPOPT's bound_push)
            span = np.where(has_l & has_u, ub - lb, np.inf)
        x = np.where(has_l, np.maximum(x, lb + np.minimum(push * np.maximum(1.0, np.abs(lb)), 0.49 * span)), x)
        x = np.where(has_u, np.minimum(x, ub - np.minimum(push * np.maximum(1.0, np.abs(ub)), 0.49 * span)), x)
        x = np.where(fixed, p.lb, x)
        mu = float(mu_init if mu_init is not None else S.mu_init)
        val = p.values(x)
        floor = 1e-2 if warm is None else mu
        s = np.maximum(-val.g, floor)
        sc = np.maximum(-val.c, floor)
        all_s, all_c = np.arange(s.size, dtype=np.int64), np.arange(sc.size, dtype=np.int64)
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
        filt, filter_mu, theta_max, theta_min = [], None, math.inf, 0.0
        delta_w_last, needed_last = 0.0, False
        full = np.empty((self.size, 3 * self.bw + 1))
        piv = np.empty(self.size, dtype=np.int64)
        K = kernels()
        # the solver's own calls skip the entry points' argument checks (its arrays are made right here)
        factor, solve_b, assemble = _raw(K.band_factor), _raw(K.band_solve), _raw(K.band_assemble)
        ftb = _raw(K.fraction_to_boundary)
        status, trace, it, err0 = "max_iter", [], 0, math.inf
        rejected = 0
        acceptable, f_prev = 0, math.inf
        adaptive = S.mu_strategy == "adaptive"
        errs: list[float] = []
        for it in range(1, S.max_iter + 1):
            der = p.derivatives(x)
            err0, err_mu = self._errors(val, der, x, s, sc, y, z, zc, zl, zu, mu)
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
                mu = max(S.tol / 10, 0.8 * self._mean_complementarity(x, s, sc, z, zc, zl, zu))
                err_mu = self._errors(val, der, x, s, sc, y, z, zc, zl, zu, mu)[1]
            while not adaptive and err_mu <= S.kappa_eps * mu and mu > S.tol / 10:
                mu = max(S.tol / 10, min(S.kappa_mu * mu, mu ** S.theta_mu))
                err_mu = self._errors(val, der, x, s, sc, y, z, zc, zl, zu, mu)[1]
            # ---- the Newton system: W dx + A' dy = rhs_x, A dx = -e (slacks and bound multipliers eliminated)
            sig, sig_c = z / s, zc / sc
            dl, du = self._dist(x)
            sig_x = np.where(has_l, zl / dl, 0.0) + np.where(has_u, zu / du, 0.0)
            hess = p.hessian(x, y, z, zc)
            grad_c = np.stack([self._scatter(gj) for gj in der.grad_c])  # (m, n)
            grad_f = self._scatter(der.grad_f)
            base_x = grad_f + self._scatter(der.grad_e * y[:, None])
            bound_x = np.where(has_u, 1 / du, 0.0) - np.where(has_l, 1 / dl, 0.0)
            a_mat = np.stack([self._to_kkt(np.where(fixed, 0.0, gj), np.zeros(N)) for gj in grad_c], axis=1)  # (size, m)

            def rhs(r_e, r_g, r_c, mu_):
                """The right-hand side for the residuals r_e (equalities), r_g = g + s, r_c = c + sc, and the
                barrier parameter mu_."""
                rx = -(base_x + mu_ * bound_x + self._scatter(np.einsum("kqp,kq->kp", der.grad_g, mu_ / s + sig * r_g))
                       + np.einsum("jn,j->n", grad_c, mu_ / sc + sig_c * r_c))
                rx[fixed] = 0.0
                return self._to_kkt(rx, -r_e)

            r_g0, r_c0 = val.g + s, val.c + sc
            first = rhs(val.e, r_g0, r_c0, 0.0 if adaptive else mu)
            # where the last step needed a regularisation, start from a third of it (IPOPT tries 0 first:
            # here the reduced Hessian stays indefinite for many iterations in a row, and each try costs a
            # factorisation)
            delta_w, delta_c = (delta_w_last / 3 if delta_w_last > 0 and needed_last else 0.0), 0.0
            for _attempt in range(25):
                assemble(full, self.bw, self.pos, hess, der.grad_g, sig, der.grad_e, self.pos_x, sig_x + delta_w,
                                self.pos_y, np.full(N, -delta_c), self.fixed_pos)
                if factor(full, self.bw, self.bw, piv) == 0:
                    sol = np.column_stack([first, a_mat])
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
                        return pv - np.einsum("nj,j->n", qm, np.linalg.solve(small, np.einsum("nj,n->j", a_mat, pv)))

                    d = direction(first, sol)
                    dx = d[self.pos_x]
                    if np.all(np.isfinite(d)):
                        dloc = dx[loc]
                        jd = np.einsum("kqp,kp->kq", der.grad_g, dloc)
                        curv = (np.einsum("ka,kab,kb->", dloc, hess, dloc) + np.einsum("kq,kq->", sig, jd * jd)
                                + _dot(sig_x + delta_w, dx * dx) + _dot(sig_c, np.einsum("jn,n->j", grad_c, dx) ** 2))
                        if curv >= S.curvature * _dot(dx, dx):
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

            def slack_steps(dx, r_g, r_c):
                return -r_g - np.einsum("kqp,kp->kq", der.grad_g, dx[loc]), -r_c - np.einsum("jn,n->j", grad_c, dx)

            def primal_step(dx, ds, dsc, tau):
                return min(ftb(s.ravel(), ds.ravel(), all_s, 1.0, tau), ftb(sc, dsc, all_c, 1.0, tau),
                           ftb(dl, dx, il, 1.0, tau), ftb(du, dx, iu, -1.0, tau))

            def dual_steps(dx, ds, dsc, mu_):
                return (mu_ / s - z - sig * ds, mu_ / sc - zc - sig_c * dsc,
                        np.where(has_l, mu_ / dl - zl - (zl / dl) * dx, 0.0),
                        np.where(has_u, mu_ / du - zu + (zu / du) * dx, 0.0))

            def dual_step(dz, dzc, dzl, dzu, tau):
                return min(ftb(z.ravel(), dz.ravel(), all_s, 1.0, tau), ftb(zc, dzc, all_c, 1.0, tau),
                           ftb(zl, dzl, il, 1.0, tau), ftb(zu, dzu, iu, 1.0, tau))

            if adaptive:  # Mehrotra's probing: how far the affine-scaling step (mu = 0) gets
                ds_a, dsc_a = slack_steps(dx, r_g0, r_c0)
                dz_a, dzc_a, dzl_a, dzu_a = dual_steps(dx, ds_a, dsc_a, 0.0)
                ap, ad = primal_step(dx, ds_a, dsc_a, 1.0), dual_step(dz_a, dzc_a, dzl_a, dzu_a, 1.0)
                mu_avg = self._mean_complementarity(x, s, sc, z, zc, zl, zu)
                mu_aff = self._mean_complementarity(x + ap * dx, s + ap * ds_a, sc + ap * dsc_a, z + ad * dz_a,
                                                    zc + ad * dzc_a, zl + ad * dzl_a, zu + ad * dzu_a)
                mu = max(S.tol / 10, min(max((mu_aff / mu_avg) ** 3, 0.1), 1.0) * mu_avg)
                d = direction(rhs(val.e, r_g0, r_c0, mu))
                dx = d[self.pos_x]
            tau = max(S.tau_min, 1.0 - mu)
            dy = d[self.pos_y]
            ds, dsc = slack_steps(dx, r_g0, r_c0)
            dz, dzc, dzl, dzu = dual_steps(dx, ds, dsc, mu)
            a_p = primal_step(dx, ds, dsc, tau)
            a_d = dual_step(dz, dzc, dzl, dzu, tau)
            # ---- filter line search with second-order corrections
            phi0, theta0 = self._barrier(val, x, s, sc, mu), self._violation(val, s, sc)
            if mu != filter_mu:  # a new barrier problem: a new filter
                filt, filter_mu = [], mu
                theta_max, theta_min = 1e4 * max(1.0, theta0), 1e-4 * max(1.0, theta0)
            dphi = (_dot(grad_f, dx) - mu * (ds / s).sum() - mu * (dsc / sc).sum()
                    - mu * np.sum(dx[il] / dl[il]) + mu * np.sum(dx[iu] / du[iu]))

            def judge(v_t: CellValues, x_t, s_t, sc_t, alpha) -> tuple[bool, bool]:
                """(accepted, f-type): acceptable to the filter, and either an Armijo decrease of the
                barrier function (when the step is mostly an objective step) or a sufficient decrease
                of the violation or of the barrier function."""
                if not v_t.finite():
                    return False, False
                phi_t, theta_t = self._barrier(v_t, x_t, s_t, sc_t, mu), self._violation(v_t, s_t, sc_t)
                if not np.isfinite(phi_t) or theta_t > theta_max:
                    return False, False
                if any(theta_t >= th and phi_t >= ph for th, ph in filt):
                    return False, False
                if dphi < 0 and alpha * (-dphi) ** 2.3 > theta0 ** 1.1 and theta0 <= theta_min:
                    return bool(phi_t <= phi0 + 1e-8 * alpha * dphi + 1e-14 * abs(phi0)), True
                return bool(theta_t <= (1 - 1e-5) * theta0 or phi_t <= phi0 - 1e-8 * theta0), False

            alpha, accepted, f_type = a_p, False, False
            for trial in range(40):
                xn, sn, scn = x + alpha * dx, s + alpha * ds, sc + alpha * dsc
                vn = p.values(xn)
                accepted, f_type = judge(vn, xn, sn, scn, alpha)
                if accepted:
                    break
                if trial == 0 and S.max_soc > 0 and vn.finite() and self._violation(vn, sn, scn) >= theta0:
                    c_e, c_g, c_c = alpha * val.e + vn.e, alpha * r_g0 + (vn.g + sn), alpha * r_c0 + (vn.c + scn)
                    theta_soc = theta0
                    for _ in range(S.max_soc):  # second-order corrections of the full step
                        d_soc = direction(rhs(c_e, c_g, c_c, mu))
                        dx_s = d_soc[self.pos_x]
                        ds_s, dsc_s = slack_steps(dx_s, c_g, c_c)
                        a_s = primal_step(dx_s, ds_s, dsc_s, tau)
                        xs_, ss_, scs_ = x + a_s * dx_s, s + a_s * ds_s, sc + a_s * dsc_s
                        vs = p.values(xs_)
                        accepted, f_type = judge(vs, xs_, ss_, scs_, alpha)
                        if accepted:
                            xn, sn, scn, vn = xs_, ss_, scs_, vs
                            dy = d_soc[self.pos_y]
                            break
                        theta_new = self._violation(vs, ss_, scs_) if vs.finite() else math.inf
                        if theta_new > 0.99 * theta_soc:
                            break
                        theta_soc = theta_new
                        c_e, c_g, c_c = a_s * c_e + vs.e, a_s * c_g + (vs.g + ss_), a_s * c_c + (vs.c + scs_)
                    if accepted:
                        break
                alpha *= 0.5
            if not accepted and adaptive:  # the adaptive rule lost its way: the monotone one from here
                adaptive = False
                mu = max(S.tol / 10, 0.8 * self._mean_complementarity(x, s, sc, z, zc, zl, zu))
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
            y = y + alpha * dy
            z, zc = z + a_d * dz, zc + a_d * dzc
            zl, zu = zl + a_d * dzl, zu + a_d * dzu
            # keep the multipliers near the central path (IPOPT's kappa_sigma safeguard)
            ks = 1e10
            z = np.clip(z, mu / (ks * s), ks * mu / s)
            zc = np.clip(zc, mu / (ks * sc), ks * mu / sc)
            dl, du = self._dist(x)
            zl = np.where(has_l, np.clip(zl, mu / (ks * dl), ks * mu / dl), 0.0)
            zu = np.where(has_u, np.clip(zu, mu / (ks * du), ks * mu / du), 0.0)
        return IPMResult(x, y, z, zc, zl, zu, float(val.f), status in ("converged", "acceptable"), it, float(err0),
                         status, trace)
