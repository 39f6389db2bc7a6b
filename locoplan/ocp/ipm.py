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
        return _Solve(self, x0, mu_init, warm).run()


class _Solve:
    """One solve of a :class:`CellIPM`: the iterate (``x``, the slacks ``s``, ``sc``, the multipliers ``y``, ``z``,
    ``zc``, ``zl``, ``zu``, the distances to the bounds ``dl``, ``du``), the barrier parameter ``mu``, the filter,
    and the iteration's work arrays. Each step of the method is one method here."""

    def __init__(self, ipm: CellIPM, x0: np.ndarray, mu_init: float | None, warm: "IPMResult | None"):
        self.ipm, self.S, self.p, self.lay = ipm, ipm.set, ipm.p, ipm.layout
        self.N, self.n = ipm.N, ipm.n
        self.x = self._initial_point(x0, warm)
        self.mu = float(mu_init if mu_init is not None else self.S.mu_init)
        self.val = self.p.values(self.x)
        self._initial_slacks_and_multipliers(warm)
        self._bind_kernels()
        self._work_arrays()
        self.filt, self.filter_mu, self.theta_max, self.theta_min = [], None, math.inf, 0.0
        self.delta_w_last, self.needed_last = 0.0, False
        self.status, self.trace, self.it, self.err0 = "max_iter", [], 0, math.inf
        self.rejected = 0
        self.acceptable, self.f_prev = 0, math.inf
        self.adaptive = self.S.mu_strategy == "adaptive"
        self.errs: list[float] = []

    # ------------------------------------------------------------------ the start
    def _initial_point(self, x0: np.ndarray, warm: "IPMResult | None") -> np.ndarray:
        """``x0`` pushed inside its bounds (IPOPT's bound_push; barely for a warm start), fixed variables at
        their value."""
        ipm = self.ipm
        has_l, has_u, lb, ub = ipm.has_l, ipm.has_u, ipm._lb, ipm._ub
        x = np.array(x0, dtype=float)
        push = self.S.bound_push if warm is None else 1e-9
        with np.errstate(invalid="ignore"):
            span = np.where(has_l & has_u, ub - lb, np.inf)
        x = np.where(has_l, np.maximum(x, lb + np.minimum(push * np.maximum(1.0, np.abs(lb)), 0.49 * span)), x)
        x = np.where(has_u, np.minimum(x, ub - np.minimum(push * np.maximum(1.0, np.abs(ub)), 0.49 * span)), x)
        return np.ascontiguousarray(np.where(ipm.fixed, self.p.lb, x))

    def _initial_slacks_and_multipliers(self, warm: "IPMResult | None") -> None:
        """Slacks at least a floor off zero; multipliers on the central path (mu / slack) from a cold start,
        a warm solution's (kept off zero) from a warm one."""
        ipm, mu, val = self.ipm, self.mu, self.val
        has_l, has_u = ipm.has_l, ipm.has_u
        floor = 1e-2 if warm is None else mu
        s = np.maximum(-val.g, floor)
        sc = np.maximum(-val.c, floor)
        dl, du = ipm._dist(self.x)
        if warm is None:
            z, zc, y = mu / s, mu / sc, np.zeros(self.N)
            zl = np.where(has_l, mu / dl, 0.0)
            zu = np.where(has_u, mu / du, 0.0)
        else:
            y = warm.y.copy()
            z = np.maximum(warm.z, mu / s * 1e-2)
            zc = np.maximum(warm.zc, mu / sc * 1e-2)
            zl = np.where(has_l, np.maximum(warm.zl, mu / dl * 1e-2), 0.0)
            zu = np.where(has_u, np.maximum(warm.zu, mu / du * 1e-2), 0.0)
        self.y, self.z, self.zc, self.zl, self.zu = (np.ascontiguousarray(v, dtype=float) for v in (y, z, zc, zl, zu))
        self.s, self.sc, self.dl, self.du = s, sc, dl, du
        self.q, self.m = s.shape[1], sc.shape[0]

    def _bind_kernels(self) -> None:
        """The compiled kernels, without their entry points' argument checks (the arrays are made here)."""
        K = kernels()
        self.factor, self.solve_b, self.assemble = _raw(K.band_factor), _raw(K.band_solve), _raw(K.band_assemble)
        self.errors_k, self.newton_k, self.rhs_k = _raw(K.ipm_errors), _raw(K.ipm_newton), _raw(K.ipm_rhs)
        self.curvature_k, self.steps_k, self.merit_k = _raw(K.ipm_curvature), _raw(K.ipm_steps), _raw(K.ipm_merit)
        self.mean_k, self.update_k = _raw(K.ipm_mean_complementarity), _raw(K.ipm_update)

    def _work_arrays(self) -> None:
        """The iteration's work arrays, made once."""
        n, N, q, m, size = self.n, self.N, self.q, self.m, self.ipm.size
        self.full = np.empty((size, 3 * self.ipm.bw + 1))
        self.piv = np.empty(size, dtype=np.int64)
        self.r_d = np.empty(n)
        self.sig, self.sig_c, self.sig_x = np.empty((N, q)), np.empty(m), np.empty(n)
        self.grad_f, self.base_x, self.bound_x = np.empty(n), np.empty(n), np.empty(n)
        self.grad_c, self.a_mat = np.empty((m, n)), np.empty((size, m))
        self.diag_y = np.empty(N)

    # ------------------------------------------------------------------ the iteration
    def run(self) -> IPMResult:
        """Iterate until converged, stuck, or out of iterations."""
        for it in range(1, self.S.max_iter + 1):
            self.it = it
            status = self._iteration()
            if status is not None:
                self.status = status
                break
        return IPMResult(self.x, self.y, self.z, self.zc, self.zl, self.zu, float(self.val.f),
                         self.status in ("converged", "acceptable"), self.it, float(self.err0), self.status, self.trace)

    def _iteration(self) -> str | None:
        """One Newton step with its line search; the status when the solve stops here."""
        self.der = self.p.derivatives(self.x)
        self._errors()
        status = self._convergence()
        if status is not None:
            return status
        self._update_barrier()
        self._newton_system()
        d = self._regularised_direction()
        if d is None:
            return "singular"
        return self._step(d)

    def _errors(self) -> None:
        """The optimality error's terms (dual, primal, complementarity and its scaling), the mean
        complementarity, and the unscaled error ``err0``."""
        der, val = self.der, self.val
        e_dual, e_prim, p_max, p_min, s_c, self.mean_c = self.errors_k(
            self.lay, der.grad_f, der.grad_e, self.y, der.grad_g, self.z, der.grad_c, self.zc, self.zl, self.zu,
            val.e, val.g, self.s, val.c, self.sc, self.dl, self.du, self.r_d)
        self.terms = (e_dual, e_prim, p_max, p_min, s_c)
        self.err0 = max(e_dual, e_prim, p_max / s_c)

    def _err_at(self, mu_: float) -> float:
        """The barrier problem's optimality error for ``mu_``."""
        e_dual, e_prim, p_max, p_min, s_c = self.terms
        return max(e_dual, e_prim, max(p_max - mu_, mu_ - p_min) / s_c)

    def _convergence(self) -> str | None:
        """The convergence test: "not finite", "converged", "acceptable" (IPOPT's acceptable level held for
        ``acceptable_iter`` iterations with the objective settled), or None to go on."""
        S, err0, f = self.S, self.err0, self.val.f
        if not (np.isfinite(err0) and np.all(np.isfinite(self.x))):  # lost: say so at once
            return "not finite"
        if err0 <= S.tol:
            return "converged"
        settled = abs(f - self.f_prev) <= S.acceptable_obj_change * max(1.0, abs(f))
        self.acceptable = (self.acceptable + 1 if err0 <= S.acceptable_tol and (self.mu <= S.tol or self.adaptive)
                           and settled else 0)
        self.f_prev = f
        if self.acceptable >= S.acceptable_iter:
            return "acceptable"
        return None

    def _update_barrier(self) -> None:
        """The adaptive rule falls back to the monotone one when the error stops falling; the monotone rule
        lowers mu while the barrier problem is solved to kappa_eps mu."""
        S = self.S
        err_mu = self._err_at(self.mu)
        self.errs.append(self.err0)
        if self.adaptive and len(self.errs) > 12 and self.err0 > 0.9999 * self.errs[-5]:  # no progress
            self.adaptive = False
            self.mu = max(S.tol / 10, 0.8 * self.mean_c)
            err_mu = self._err_at(self.mu)
        while not self.adaptive and err_mu <= S.kappa_eps * self.mu and self.mu > S.tol / 10:
            self.mu = max(S.tol / 10, min(S.kappa_mu * self.mu, self.mu ** S.theta_mu))
            err_mu = self._err_at(self.mu)

    def _newton_system(self) -> None:
        """The Newton system's parts: W dx + A' dy = rhs_x, A dx = -e, with the slacks and bound multipliers
        eliminated; the Hessian; the residuals and the first right-hand side."""
        der, val = self.der, self.val
        self.newton_k(self.lay, der.grad_f, der.grad_e, self.y, der.grad_c, self.s, self.z, self.sc, self.zc,
                      self.dl, self.du, self.zl, self.zu, self.sig, self.sig_c, self.sig_x, self.grad_f, self.base_x,
                      self.bound_x, self.grad_c, self.a_mat)
        self.hess = self.p.hessian(self.x, self.y, self.z, self.zc)
        self.r_g0, self.r_c0 = val.g + self.s, val.c + self.sc
        self.first = self._rhs(val.e, self.r_g0, self.r_c0, 0.0 if self.adaptive else self.mu)

    def _rhs(self, r_e, r_g, r_c, mu_: float) -> np.ndarray:
        """The right-hand side for the residuals r_e (equalities), r_g = g + s, r_c = c + sc, and the barrier
        parameter mu_."""
        out = np.empty(self.ipm.size)
        self.rhs_k(self.lay, self.base_x, self.bound_x, self.der.grad_g, self.s, self.sig, r_g, self.grad_c, self.sc,
                   self.sig_c, r_c, r_e, mu_, out)
        return out

    def _regularised_direction(self) -> np.ndarray | None:
        """The Newton step for the first right-hand side, the Hessian regularised (delta_w) until the step's
        curvature is positive and the equality block (delta_c) while a pivot is zero; None after 25 tries.
        Where the last step needed delta_w, start from a third of it (IPOPT tries 0 first: here the reduced
        Hessian stays indefinite for many iterations in a row, and each try costs a factorisation)."""
        S, ipm = self.S, self.ipm
        delta_w, delta_c = (self.delta_w_last / 3 if self.delta_w_last > 0 and self.needed_last else 0.0), 0.0
        for _attempt in range(25):
            sol = self._factor(delta_w, delta_c)
            if sol is not None:
                d = self._direction(self.first, sol)
                if np.all(np.isfinite(d)):
                    dx = d[ipm.pos_x]
                    curv, dxdx = self.curvature_k(self.lay, dx, self.hess, self.der.grad_g, self.sig, self.sig_x,
                                                  delta_w, self.sig_c, self.grad_c)
                    if curv >= S.curvature * dxdx:
                        break
            else:  # a zero pivot: regularise the equality block too, more each time
                delta_c = 10 * delta_c if delta_c > 0 else 1e-8 * self.mu ** 0.25
            delta_w = (max(1e-20, self.delta_w_last / 3) if delta_w == 0 and self.delta_w_last > 0
                       else 1e-4 if delta_w == 0 else 8.0 * delta_w)
        else:
            return None
        self.needed_last = delta_w > 0
        self.delta_w_last = delta_w if delta_w > 0 else self.delta_w_last
        self.delta_w = delta_w
        return d

    def _factor(self, delta_w: float, delta_c: float) -> np.ndarray | None:
        """Assemble and factor the banded KKT matrix with the regularisations; solve it for the first
        right-hand side and the global inequalities' columns A (kept with the Woodbury matrix); None at a
        zero pivot."""
        ipm, m = self.ipm, self.m
        self.diag_y.fill(-delta_c)
        self.assemble(self.full, ipm.bw, ipm.pos, self.hess, self.der.grad_g, self.sig, self.der.grad_e, ipm.pos_x,
                      self.sig_x + delta_w, ipm.pos_y, self.diag_y, ipm.fixed_pos)
        if self.factor(self.full, ipm.bw, ipm.bw, self.piv) != 0:
            return None
        sol = np.empty((ipm.size, 1 + m))
        sol[:, 0] = self.first
        sol[:, 1:] = self.a_mat
        self.solve_b(self.full, ipm.bw, ipm.bw, self.piv, sol)
        self.qm = sol[:, 1:].copy()  # K_b^-1 A
        self.small = np.diag(1.0 / self.sig_c) + np.einsum("nj,nk->jk", self.a_mat, self.qm)
        return sol

    def _direction(self, rv: np.ndarray, sol: np.ndarray | None = None) -> np.ndarray:
        """The Newton step for a right-hand side (the global inequalities' low-rank term by
        Sherman-Morrison-Woodbury on the factored banded part); ``sol``: the banded solve, when done."""
        bw, a_mat, qm, small = self.ipm.bw, self.a_mat, self.qm, self.small
        if sol is None:
            sol = rv.reshape(-1, 1).copy()
            self.solve_b(self.full, bw, bw, self.piv, sol)
        pv = sol[:, 0]
        if self.m == 1:  # the running time alone: a division (what LAPACK does for 1 x 1)
            return pv - qm[:, 0] * (_dot(a_mat[:, 0], pv) / small[0, 0])
        return pv - np.einsum("nj,j->n", qm, np.linalg.solve(small, np.einsum("nj,n->j", a_mat, pv)))

    def _steps(self, d, r_g, r_c, mu_: float, tau_: float, dual: bool = True):
        """(dx, dy, ds, dsc, dz, dzc, dzl, dzu, primal step, dual step, the barrier function's slope): the
        step's parts and its lengths by the fraction to the boundary ``tau_``."""
        n, N, q, m = self.n, self.N, self.q, self.m
        out = (np.empty(n), np.empty(N), np.empty((N, q)), np.empty(m), np.empty((N, q)), np.empty(m),
               np.empty(n), np.empty(n))
        a_p_, a_d_, dphi_ = self.steps_k(self.lay, d, self.der.grad_g, r_g, r_c, self.grad_c, self.s, self.sc,
                                         self.z, self.zc, self.zl, self.zu, self.dl, self.du, self.sig, self.sig_c,
                                         self.grad_f, mu_, tau_, dual, *out)
        return (*out, a_p_, a_d_, dphi_)

    def _probe_mu(self, d: np.ndarray) -> np.ndarray:
        """Mehrotra's probing: mu from how far the affine-scaling step (mu = 0) gets; the step for it."""
        S, val = self.S, self.val
        dx_a, _, ds_a, dsc_a, dz_a, dzc_a, dzl_a, dzu_a, ap, ad, _ = self._steps(d, self.r_g0, self.r_c0, 0.0, 1.0)
        mu_aff = self.mean_k(self.lay, ap, ad, self.x, dx_a, self.s, ds_a, self.sc, dsc_a, self.z, dz_a, self.zc,
                             dzc_a, self.zl, dzl_a, self.zu, dzu_a)
        self.mu = max(S.tol / 10, min(max((mu_aff / self.mean_c) ** 3, 0.1), 1.0) * self.mean_c)
        return self._direction(self._rhs(val.e, self.r_g0, self.r_c0, self.mu))

    def _step(self, d: np.ndarray) -> str | None:
        """The step along ``d``: its lengths, the filter line search, and the update of the iterate; "stalled"
        when no step has been accepted for too long."""
        S, n = self.S, self.n
        if self.adaptive:
            d = self._probe_mu(d)
        tau = max(S.tau_min, 1.0 - self.mu)
        dx, dy, ds, dsc, dz, dzc, dzl, dzu, a_p, a_d, self.dphi = self._steps(d, self.r_g0, self.r_c0, self.mu, tau)
        self._merit_and_filter()
        accepted, f_type, alpha, trial, dy_soc = self._line_search(dx, ds, dsc, a_p, tau)
        if dy_soc is not None:
            dy = dy_soc
        if not accepted and self.adaptive:  # the adaptive rule lost its way: the monotone one from here
            self.adaptive = False
            self.mu = max(S.tol / 10, 0.8 * self.mean_c)
        self.rejected = 0 if accepted else self.rejected + 1
        if self.rejected > S.max_rejected:  # the line search has found nothing for a while: give up
            return "stalled"
        if not accepted:  # a short step anyway (IPOPT would restore feasibility here)
            alpha = min(a_p, 1e-3)
            trial = self._trial(alpha, dx, ds, dsc)
        if not f_type:  # the filter keeps this point's margin
            self.filt.append(((1 - 1e-5) * self.theta0, self.phi0 - 1e-8 * self.theta0))
        self.trace.append((self.err0, self.mu, alpha, a_d, self.delta_w, self.val.f))
        self.x, self.s, self.sc, self.val = trial
        self.dl, self.du = np.empty(n), np.empty(n)
        self.update_k(self.lay, self.x, self.s, self.sc, alpha, dy, a_d, dz, dzc, dzl, dzu, self.mu, self.y, self.z,
                      self.zc, self.zl, self.zu, self.dl, self.du)
        return None

    # ------------------------------------------------------------------ the filter line search
    def _merit_and_filter(self) -> None:
        """The current point's constraint violation theta0 and barrier function phi0; a new filter for a new
        barrier problem."""
        logs0, self.theta0 = self.merit_k(self.lay, self.x, self.s, self.sc, self.val.e, self.val.g, self.val.c)
        self.phi0 = self.val.f - self.mu * logs0
        if self.mu != self.filter_mu:  # a new barrier problem: a new filter
            self.filt, self.filter_mu = [], self.mu
            self.theta_max, self.theta_min = 1e4 * max(1.0, self.theta0), 1e-4 * max(1.0, self.theta0)

    def _trial(self, alpha: float, dx, ds, dsc) -> tuple:
        """The trial point (x, s, sc, its values) a step ``alpha`` along (dx, ds, dsc)."""
        xn, sn, scn = self.x + alpha * dx, self.s + alpha * ds, self.sc + alpha * dsc
        return xn, sn, scn, self.p.values(xn)

    def _judge(self, v_t: CellValues, x_t, s_t, sc_t, alpha: float) -> tuple[bool, bool, float]:
        """(accepted, f-type, the violation): acceptable to the filter, and either an Armijo decrease of the
        barrier function (when the step is mostly an objective step) or a sufficient decrease of the
        violation or of the barrier function."""
        theta0, phi0, dphi = self.theta0, self.phi0, self.dphi
        if not v_t.finite():
            return False, False, math.inf
        logs_t, theta_t = self.merit_k(self.lay, x_t, s_t, sc_t, v_t.e, v_t.g, v_t.c)
        phi_t = v_t.f - self.mu * logs_t
        if not np.isfinite(phi_t) or theta_t > self.theta_max:
            return False, False, theta_t
        if any(theta_t >= th and phi_t >= ph for th, ph in self.filt):
            return False, False, theta_t
        if dphi < 0 and alpha * (-dphi) ** 2.3 > theta0 ** 1.1 and theta0 <= self.theta_min:
            return bool(phi_t <= phi0 + 1e-8 * alpha * dphi + 1e-14 * abs(phi0)), True, theta_t
        return bool(theta_t <= (1 - 1e-5) * theta0 or phi_t <= phi0 - 1e-8 * theta0), False, theta_t

    def _line_search(self, dx, ds, dsc, a_p: float, tau: float) -> tuple:
        """Backtracking from the step to the boundary ``a_p``, halving up to 40 times, with second-order
        corrections of a rejected full step: (accepted, f-type, alpha, the trial point, the corrected dy
        or None)."""
        S = self.S
        alpha, accepted, f_type = a_p, False, False
        for k in range(40):
            trial = self._trial(alpha, dx, ds, dsc)
            vn = trial[3]
            accepted, f_type, theta_n = self._judge(vn, *trial[:3], alpha)
            if accepted:
                break
            if k == 0 and S.max_soc > 0 and theta_n >= self.theta0 and vn.finite():
                corrected = self._second_order_corrections(alpha, trial, tau)
                if corrected is not None:
                    trial, dy_soc, f_type = corrected
                    return True, f_type, alpha, trial, dy_soc
            alpha *= 0.5
        return accepted, f_type, alpha, trial, None

    def _second_order_corrections(self, alpha: float, trial: tuple, tau: float) -> tuple | None:
        """Up to ``max_soc`` corrections of the full step for the constraints' curvature (the Maratos effect),
        while the violation falls: (the accepted point, its dy, f-type), or None."""
        val, mu = self.val, self.mu
        _, sn, scn, vn = trial
        c_e, c_g, c_c = alpha * val.e + vn.e, alpha * self.r_g0 + (vn.g + sn), alpha * self.r_c0 + (vn.c + scn)
        theta_soc = self.theta0
        for _ in range(self.S.max_soc):
            d_soc = self._direction(self._rhs(c_e, c_g, c_c, mu))
            dx_s, dy_s, ds_s, dsc_s, *_, a_s, _, _ = self._steps(d_soc, c_g, c_c, mu, tau, False)
            xs_, ss_, scs_ = self.x + a_s * dx_s, self.s + a_s * ds_s, self.sc + a_s * dsc_s
            vs = self.p.values(xs_)
            accepted, f_type, theta_new = self._judge(vs, xs_, ss_, scs_, alpha)
            if accepted:
                return (xs_, ss_, scs_, vs), dy_s, f_type
            if theta_new > 0.99 * theta_soc:
                return None
            theta_soc = theta_new
            c_e, c_g, c_c = a_s * c_e + vs.e, a_s * c_g + (vs.g + ss_), a_s * c_c + (vs.c + scs_)
        return None
