"""A primal-dual interior-point method for cell-structured NLPs, with a banded KKT solve.

The minimum-energy problem on a fine grid of cells (``ocp/cells.py``) has a structure a general NLP
solver does not use: every function belongs to one cell and reads only that cell's few variables (the
speeds at its two nodes and its forces), except one, the running time, which sums over all cells. Its
KKT matrix, with each cell's equality multiplier placed beside its variables, is therefore banded
(half-bandwidth 4 there) plus a rank-one term from the running time. LAPACK's banded LU solves that in
time linear in the number of cells, and the rank-one term costs a second right-hand side
(Sherman-Morrison). The same Newton steps through IPOPT (CasADi, MUMPS) cost 10-40 us per variable and
iteration here; this solver about 1 us.

The algorithm is IPOPT's (Waechter and Biegler, Math. Program. 106, 2006) in its simplest robust
form: slacks for the inequalities, the barrier problem solved approximately for a falling barrier
parameter (monotone Fiacco-McCormick rule, mu <- min(0.2 mu, mu^1.5) once the barrier problem's error
is below 10 mu), the primal-dual Newton step with the slacks and bound multipliers eliminated, the
fraction-to-the-boundary rule, the filter line search with second-order corrections (an l1 merit
function instead took steps of 1 % for dozens of iterations on long lines), and regularisation of
the Hessian where the step's curvature is not positive (the inertia-free test of Chiang and Zavala,
Comput. Optim. Appl. 64, 2016: a banded LU gives no inertia).

A problem gives, for its variables ``x`` (already scaled to order one):
- ``lb``, ``ub``: bounds (``-inf`` / ``inf`` for none; ``lb == ub`` fixes a variable);
- ``local``: (cells, p) the indices of each cell's variables;
- ``pos_x``, ``pos_y``: the place of every variable and of every cell's equality multiplier in the
  KKT ordering (the problem chooses one that makes the matrix banded);
- ``evaluate(x)``: a :class:`CellEval` with the objective, one equality and q inequalities (<= 0) per
  cell and the one global inequality (<= 0), each with its gradient and Hessian on the cell's
  variables (the global one as per-cell parts that add up).
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
class CellEval:
    """Values and derivatives of a cell-structured NLP at one point (N cells, p local variables, q
    inequalities per cell)."""

    f: float
    grad_f: np.ndarray  # (N, p)
    hess_f: np.ndarray | None  # (N, p, p) or None (linear objective)
    e: np.ndarray  # (N,) equality per cell, = 0
    grad_e: np.ndarray  # (N, p)
    hess_e: np.ndarray  # (N, p, p)
    g: np.ndarray  # (N, q) inequalities, <= 0
    grad_g: np.ndarray  # (N, q, p)
    hess_g: np.ndarray  # (N, q, p, p)
    c: float  # global inequality, <= 0
    grad_c: np.ndarray  # (N, p): per-cell parts of its gradient
    hess_c: np.ndarray  # (N, p, p)


@dataclass
class IPMResult:
    """The solution (primal ``x``, equality multipliers ``y``, inequality multipliers ``z`` (N, q), the
    global inequality's multiplier ``zc``), the objective, whether it converged, iterations, and the
    final optimality error."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    zc: float
    f: float
    converged: bool
    iterations: int
    error: float
    status: str
    trace: list | None = None
    """Per iteration: (error, mu, primal step, dual step, regularisation, objective)."""


@dataclass(frozen=True)
class IPMSettings:
    tol: float = 1e-8
    """Overall tolerance on the scaled optimality error (dual, primal, complementarity)."""
    acceptable_tol: float = 1e-4
    acceptable_iter: int = 5
    acceptable_obj_change: float = 1e-10
    """Also converged ("acceptable") after ``acceptable_iter`` iterations in a row with the error below
    ``acceptable_tol``, the barrier parameter at its floor and the objective moving by at most this share:
    where the force curves have a kink at the optimum's speed, Newton's method cannot reach ``tol`` (the
    derivative jumps between iterations) while the optimum itself has settled (IPOPT's acceptable level)."""
    max_iter: int = 300
    mu_init: float = 1e-1
    kappa_eps: float = 10.0
    kappa_mu: float = 0.2
    theta_mu: float = 1.5
    tau_min: float = 0.99
    bound_push: float = 1e-2
    armijo: float = 1e-4
    max_soc: int = 4
    """Second-order corrections tried when a full step is rejected (the Maratos effect: the step's
    constraint curvature raises the merit function although the step is good)."""
    curvature: float = 1e-8
    """A step is accepted when dx' W dx >= curvature * dx'dx, else the Hessian is regularised."""


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
        self.pos_x = problem.pos_x
        self.pos_y = problem.pos_y

    # ------------------------------------------------------------------ linear algebra
    def _kkt(self, blocks: np.ndarray, diag_x: np.ndarray, diag_y: np.ndarray) -> np.ndarray:
        """The banded KKT matrix in the storage of ``ocp.band_kernel`` (kl = ku = bw: entry (i, j) at
        ``[j, 2 bw + i - j]``, the first bw entries of each row room for the fill-in) from the cells'
        (p+1) x (p+1) blocks (variables, then the equality multiplier) and the diagonals."""
        bw = self.bw
        full = np.zeros((self.size, 3 * bw + 1))
        ab = full[:, bw:].T  # ab[bw + i - j, j] = a(i, j), a view
        m = self.np_ + 1
        for a in range(m):  # within one (a, b) pair every cell writes a different entry
            ra = self.pos[:, a]
            for b in range(m):
                cb = self.pos[:, b]
                ab[bw + ra - cb, cb] += blocks[:, a, b]
        ab[bw, self.pos_x] += diag_x
        ab[bw, self.pos_y] += diag_y
        # fixed variables: an identity row and column (their step is 0)
        fx = self.pos_x[self.fixed]
        for d in range(-bw, bw + 1):
            cols = fx - d
            ok = (cols >= 0) & (cols < self.size)
            ab[bw + d, cols[ok]] = 0.0  # row fx, column fx - d
            cols = fx + d
            ok = (cols >= 0) & (cols < self.size)
            ab[bw - d, cols[ok]] = 0.0  # column fx, row fx + d
        ab[bw, fx] = 1.0
        return full

    def _to_kkt(self, vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
        out = np.zeros(self.size)
        out[self.pos_x] = vx
        out[self.pos_y] = vy
        return out

    # ------------------------------------------------------------------ the method
    def solve(self, x0: np.ndarray, mu_init: float | None = None) -> IPMResult:
        """Minimise from ``x0`` (pushed inside its bounds); ``mu_init``: the barrier parameter to start at."""
        S = self.set
        p, lb, ub, loc, N = self.p, self.p.lb, self.p.ub, self.p.local, self.N
        has_l, has_u, fixed = self.has_l, self.has_u, self.fixed
        x = np.array(x0, dtype=float)
        # push the start inside the bounds (IPOPT's bound_push)
        with np.errstate(invalid="ignore"):
            span = np.where(has_l & has_u, ub - lb, np.inf)
        push_l = np.minimum(S.bound_push * np.maximum(1.0, np.abs(np.where(has_l, lb, 0.0))), 0.49 * span)
        push_u = np.minimum(S.bound_push * np.maximum(1.0, np.abs(np.where(has_u, ub, 0.0))), 0.49 * span)
        x = np.where(has_l, np.maximum(x, np.where(has_l, lb, 0.0) + push_l), x)
        x = np.where(has_u, np.minimum(x, np.where(has_u, ub, 0.0) - push_u), x)
        x = np.where(fixed, lb, x)
        mu = float(mu_init if mu_init is not None else S.mu_init)
        ev = p.evaluate(x)
        s = np.maximum(-ev.g, 1e-2)
        sc = max(-ev.c, 1e-2)
        z = mu / s
        zc = mu / sc
        y = np.zeros(N)
        dist_l = lambda x: np.where(has_l, x - np.where(has_l, lb, 0.0), 1.0)  # noqa: E731
        dist_u = lambda x: np.where(has_u, np.where(has_u, ub, 0.0) - x, 1.0)  # noqa: E731
        zl = np.where(has_l, mu / dist_l(x), 0.0)
        zu = np.where(has_u, mu / dist_u(x), 0.0)
        filt, filter_mu, theta_max, theta_min = [], None, math.inf, 0.0
        delta_w_last = 0.0
        flat = loc.ravel()

        def scatter(local_vals: np.ndarray) -> np.ndarray:
            return np.bincount(flat, weights=local_vals.ravel(), minlength=self.n)

        def error(ev, x, s, sc, y, z, zc, zl, zu, mu, detail=False) -> float:
            r_d = (scatter(ev.grad_f + ev.grad_e * y[:, None] + np.einsum("kqp,kq->kp", ev.grad_g, z) + zc * ev.grad_c)
                   - zl + zu)
            r_d[fixed] = 0.0
            prim = max(np.max(np.abs(ev.e), initial=0.0), np.max(np.abs(ev.g + s), initial=0.0), abs(ev.c + sc))
            dl, du = dist_l(x), dist_u(x)
            comp = max(np.max(np.abs(s * z - mu), initial=0.0), abs(sc * zc - mu),
                       np.max(np.abs(np.where(has_l, dl * zl - mu, 0.0)), initial=0.0),
                       np.max(np.abs(np.where(has_u, du * zu - mu, 0.0)), initial=0.0))
            n_dual = y.size + z.size + 1 + int(has_l.sum()) + int(has_u.sum())
            s_d = max(100.0, (np.abs(y).sum() + z.sum() + zc + zl.sum() + zu.sum()) / n_dual) / 100.0
            s_c = max(100.0, (z.sum() + zc + zl.sum() + zu.sum()) / max(n_dual - y.size, 1)) / 100.0
            if detail:
                j = int(np.argmax(np.abs(r_d)))
                return (np.max(np.abs(r_d)) / s_d, j, prim, comp / s_c, s_d, s_c)
            return max(np.max(np.abs(r_d)) / s_d, prim, comp / s_c)

        def barrier(ev, x, s, sc, mu) -> float:
            with np.errstate(invalid="ignore", divide="ignore"):
                bar = (np.log(s).sum() + math.log(sc) + np.log(dist_l(x)[has_l]).sum()
                       + np.log(dist_u(x)[has_u]).sum())
            return ev.f - mu * bar

        def violation(ev, s, sc) -> float:
            return float(np.abs(ev.e).sum() + np.abs(ev.g + s).sum() + abs(ev.c + sc))

        def max_step(v, dv, tau):
            neg = dv < 0
            return min(1.0, float(np.min(-tau * v[neg] / dv[neg]))) if neg.any() else 1.0

        status, trace, it, err0 = "max_iter", [], 0, math.inf
        acceptable, f_prev = 0, math.inf
        for it in range(1, S.max_iter + 1):
            err0 = error(ev, x, s, sc, y, z, zc, zl, zu, 0.0)
            if err0 <= S.tol:
                status = "converged"
                break
            settled = abs(ev.f - f_prev) <= S.acceptable_obj_change * max(1.0, abs(ev.f))
            acceptable = acceptable + 1 if err0 <= S.acceptable_tol and mu <= S.tol and settled else 0
            f_prev = ev.f
            if acceptable >= S.acceptable_iter:
                status = "acceptable"
                break
            while error(ev, x, s, sc, y, z, zc, zl, zu, mu) <= S.kappa_eps * mu and mu > S.tol / 10:
                mu = max(S.tol / 10, min(S.kappa_mu * mu, mu ** S.theta_mu))
            tau = max(S.tau_min, 1.0 - mu)
            # ---- the Newton system: W dx + A' dy = rhs_x, A dx = -e (slacks and bound multipliers eliminated)
            sig = z / s
            sig_c = zc / sc
            dl, du = dist_l(x), dist_u(x)
            sig_x = np.where(has_l, zl / dl, 0.0) + np.where(has_u, zu / du, 0.0)
            hess = (np.einsum("kq,kqab->kab", z, ev.hess_g) + y[:, None, None] * ev.hess_e + zc * ev.hess_c
                    + np.einsum("kq,kqa,kqb->kab", sig, ev.grad_g, ev.grad_g))
            if ev.hess_f is not None:
                hess = hess + ev.hess_f
            m = self.np_ + 1
            blocks = np.zeros((N, m, m))
            blocks[:, :-1, :-1] = hess
            blocks[:, -1, :-1] = blocks[:, :-1, -1] = ev.grad_e
            grad_c = scatter(ev.grad_c)
            base_x = scatter(ev.grad_f + ev.grad_e * y[:, None]) - np.where(has_l, mu / dl, 0.0) + np.where(has_u, mu / du, 0.0)
            a_vec = self._to_kkt(np.where(fixed, 0.0, grad_c), np.zeros(N))

            def rhs(r_e, r_g, r_c):
                """The right-hand side for residuals r_e (equalities), r_g = g + s, r_c = c + sc."""
                rx = -(base_x + scatter(np.einsum("kqp,kq->kp", ev.grad_g, mu / s + sig * r_g))
                       + grad_c * (mu / sc + sig_c * r_c))
                rx[fixed] = 0.0
                return self._to_kkt(rx, -r_e)

            r_g0, r_c0 = ev.g + s, ev.c + sc
            first = rhs(ev.e, r_g0, r_c0)
            delta_w, delta_c = 0.0, 0.0
            for attempt in range(25):
                full = self._kkt(blocks, sig_x + delta_w, np.full(N, -delta_c))
                piv = np.empty(self.size, dtype=np.int64)
                info = kernels().band_factor(full, self.bw, self.bw, piv)
                if info == 0:
                    sol = np.column_stack([first, a_vec])
                    kernels().band_solve(full, self.bw, self.bw, piv, sol)
                    qv = sol[:, 1].copy()
                    denom = 1.0 + sig_c * _dot(a_vec, qv)

                    def direction(rv, sol=None):
                        """The Newton step for a right-hand side (the rank-one running-time term by
                        Sherman-Morrison on the factored banded part)."""
                        if sol is None:
                            sol = rv.reshape(-1, 1).copy()
                            kernels().band_solve(full, self.bw, self.bw, piv, sol)
                        pv = sol[:, 0]
                        return pv - qv * (sig_c * _dot(a_vec, pv) / denom)

                    d = direction(first, sol)
                    dx = d[self.pos_x]
                    if np.all(np.isfinite(d)):
                        dloc = dx[loc]
                        curv = (np.einsum("ka,kab,kb->", dloc, hess, dloc) + _dot(sig_x + delta_w, dx * dx)
                                + sig_c * _dot(grad_c, dx) ** 2)
                        if curv >= S.curvature * _dot(dx, dx):
                            break
                else:
                    delta_c = max(delta_c, 1e-8 * mu ** 0.25)
                delta_w = (max(1e-20, delta_w_last / 3) if delta_w == 0 and delta_w_last > 0
                           else 1e-4 if delta_w == 0 else 8.0 * delta_w)
            else:
                status = "singular"
                break
            delta_w_last = delta_w if delta_w > 0 else delta_w_last
            dy = d[self.pos_y]

            def others(dx, r_g, r_c):
                ds = -r_g - np.einsum("kqp,kp->kq", ev.grad_g, dx[loc])
                dsc = -r_c - _dot(grad_c, dx)
                return ds, dsc

            ds, dsc = others(dx, r_g0, r_c0)
            dz = mu / s - z - sig * ds
            dzc = mu / sc - zc - sig_c * dsc
            dzl = np.where(has_l, mu / dl - zl - (zl / dl) * dx, 0.0)
            dzu = np.where(has_u, mu / du - zu + (zu / du) * dx, 0.0)
            a_p = min(max_step(s.ravel(), ds.ravel(), tau), max_step(np.array([sc]), np.array([dsc]), tau),
                      max_step(dl[has_l], dx[has_l], tau), max_step(du[has_u], -dx[has_u], tau))
            a_d = min(max_step(z.ravel(), dz.ravel(), tau), max_step(np.array([zc]), np.array([dzc]), tau),
                      max_step(zl[has_l], dzl[has_l], tau), max_step(zu[has_u], dzu[has_u], tau))
            # ---- filter line search with second-order corrections (IPOPT's: Waechter and Biegler 2006)
            phi0, theta0 = barrier(ev, x, s, sc, mu), violation(ev, s, sc)
            if mu != filter_mu:  # a new barrier problem: a new filter
                filt, filter_mu = [], mu
                theta_max = 1e4 * max(1.0, theta0)
                theta_min = 1e-4 * max(1.0, theta0)
            dphi = (_dot(scatter(ev.grad_f), dx) - mu * (ds / s).sum() - mu * dsc / sc
                    - mu * np.sum(dx[has_l] / dl[has_l]) + mu * np.sum(dx[has_u] / du[has_u]))

            def acceptable_point(ev_t, x_t, s_t, sc_t, alpha):
                """(accepted, f-type) for a trial point: acceptable to the filter, and either an Armijo
                decrease of the barrier function (when the step is mostly an objective step) or a
                sufficient decrease of the violation or of the barrier function."""
                if not (np.isfinite(ev_t.f) and np.all(np.isfinite(ev_t.e)) and np.all(np.isfinite(ev_t.g))):
                    return False, False
                phi_t, theta_t = barrier(ev_t, x_t, s_t, sc_t, mu), violation(ev_t, s_t, sc_t)
                if not np.isfinite(phi_t) or theta_t > theta_max:
                    return False, False
                if any(theta_t >= th and phi_t >= ph for th, ph in filt):
                    return False, False
                f_type = dphi < 0 and alpha * (-dphi) ** 2.3 > theta0 ** 1.1 and theta0 <= theta_min
                if f_type:
                    return bool(phi_t <= phi0 + 1e-8 * alpha * dphi + 1e-14 * abs(phi0)), True
                return bool(theta_t <= (1 - 1e-5) * theta0 or phi_t <= phi0 - 1e-8 * theta0), False

            alpha, accepted, f_type = a_p, False, False
            for trial in range(40):
                xn, sn, scn = x + alpha * dx, s + alpha * ds, sc + alpha * dsc
                evn = p.evaluate(xn)
                accepted, f_type = acceptable_point(evn, xn, sn, scn, alpha)
                if accepted:
                    break
                if trial == 0 and S.max_soc > 0 and violation(evn, sn, scn) >= theta0:  # second-order corrections
                    c_e, c_g, c_c = alpha * ev.e + evn.e, alpha * r_g0 + (evn.g + sn), alpha * r_c0 + (evn.c + scn)
                    theta_soc = theta0
                    for _ in range(S.max_soc):
                        d_soc = direction(rhs(c_e, c_g, c_c))
                        dx_s = d_soc[self.pos_x]
                        ds_s, dsc_s = others(dx_s, c_g, c_c)
                        a_s = min(max_step(s.ravel(), ds_s.ravel(), tau), max_step(np.array([sc]), np.array([dsc_s]), tau),
                                  max_step(dl[has_l], dx_s[has_l], tau), max_step(du[has_u], -dx_s[has_u], tau))
                        xs_, ss_, scs_ = x + a_s * dx_s, s + a_s * ds_s, sc + a_s * dsc_s
                        evs = p.evaluate(xs_)
                        accepted, f_type = acceptable_point(evs, xs_, ss_, scs_, alpha)
                        if accepted:
                            xn, sn, scn, evn = xs_, ss_, scs_, evs
                            dy = d_soc[self.pos_y]
                            break
                        theta_new = violation(evs, ss_, scs_)
                        if theta_new > 0.99 * theta_soc:
                            break
                        theta_soc = theta_new
                        c_e, c_g, c_c = a_s * c_e + evs.e, a_s * c_g + (evs.g + ss_), a_s * c_c + (evs.c + scs_)
                    if accepted:
                        break
                alpha *= 0.5
            if not accepted:  # a short step anyway (IPOPT would restore feasibility here)
                alpha = min(a_p, 1e-3)
                xn, sn, scn = x + alpha * dx, s + alpha * ds, sc + alpha * dsc
                evn = p.evaluate(xn)
            if not f_type:  # the filter remembers this point's margin
                filt.append(((1 - 1e-5) * theta0, phi0 - 1e-8 * theta0))
            trace.append((err0, mu, alpha, a_d, delta_w, ev.f, a_p, theta0, dphi))
            x, s, sc, ev = xn, sn, scn, evn
            y = y + alpha * dy
            z, zc = z + a_d * dz, zc + a_d * dzc
            zl, zu = zl + a_d * dzl, zu + a_d * dzu
            # keep the multipliers near the central path (IPOPT's kappa_sigma safeguard)
            ks = 1e10
            z = np.clip(z, mu / (ks * s), ks * mu / s)
            zc = float(np.clip(zc, mu / (ks * sc), ks * mu / sc))
            dl, du = dist_l(x), dist_u(x)
            zl = np.where(has_l, np.clip(zl, mu / (ks * dl), ks * mu / dl), 0.0)
            zu = np.where(has_u, np.clip(zu, mu / (ks * du), ks * mu / du), 0.0)
        return IPMResult(x, y, z, float(zc), float(ev.f), status in ("converged", "acceptable"), it, float(err0), status,
                         trace)
