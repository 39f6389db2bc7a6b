"""The interior-point method's vector work per iteration (``ocp/ipm.py``), compiled (numba, through
``sim/native.py``).

Each function is one pass over the cells or the variables doing what took the solver a dozen numpy
calls on arrays of a few thousand entries (a few microseconds each, most of an iteration's time): the
optimality errors, the Newton system's eliminated terms and right-hand side, the step's curvature test,
the slack and multiplier steps with the fraction-to-the-boundary rule, the barrier function and the
constraint violation of a trial point, and the multipliers' update. The layout (each cell's variables,
the bounds, the KKT ordering) is one record, ``sim/records.py``'s ``IPMLayout``; the functions read its
arrays once and pass no record on (that costs a reference count per array and call).

They divide as numpy does (``error_model="numpy"``, in the ahead-of-time build too): a trial point on a
bound gives an infinite or NaN barrier, which the line search rejects, not an exception.

Shapes: N cells of p variables, q inequalities each, m global inequalities, n variables, ``size`` = the
KKT system's unknowns (n + N). A variable without a lower (upper) bound has its distance to it 1 and its
bound multiplier 0.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def ipm_errors(lay, gf, ge, y, gg, z, gc, zc, zl, zu, e, g, s, c, sc, dl, du, r_d):
    """The pieces of IPOPT's scaled optimality error at a point, the dual residual left in ``r_d`` (n,):
    (dual error / s_d, primal error, largest and smallest complementarity product, s_c, the mean product).
    The error is ``max(dual, primal, largest / s_c)``, the barrier problem's for mu ``max(dual, primal,
    max(largest - mu, mu - smallest) / s_c)``."""
    loc, fixed, il, iu = lay.loc, lay.fixed, lay.il, lay.iu
    N, P = loc.shape
    q, m, n = gg.shape[1], gc.shape[0], r_d.shape[0]
    r_d[:] = 0.0
    for k in range(N):
        for a in range(P):
            v = gf[k, a] + ge[k, a] * y[k]
            for j in range(q):
                v += gg[k, j, a] * z[k, j]
            for j in range(m):
                v += gc[j, k, a] * zc[j]
            r_d[loc[k, a]] += v
    dual = 0.0
    duals = 0.0
    for i in range(n):
        r_d[i] = r_d[i] - zl[i] + zu[i]
        if fixed[i]:
            r_d[i] = 0.0
        dual = max(dual, abs(r_d[i]))
        duals += zl[i] + zu[i]
    prim = 0.0
    pmax, pmin, psum = -np.inf, np.inf, 0.0
    ysum = 0.0
    for k in range(N):
        prim = max(prim, abs(e[k]))
        ysum += abs(y[k])
        for j in range(q):
            prim = max(prim, abs(g[k, j] + s[k, j]))
            pr = s[k, j] * z[k, j]
            pmax, pmin, psum = max(pmax, pr), min(pmin, pr), psum + pr
            duals += z[k, j]
    for j in range(m):
        prim = max(prim, abs(c[j] + sc[j]))
        pr = sc[j] * zc[j]
        pmax, pmin, psum = max(pmax, pr), min(pmin, pr), psum + pr
        duals += zc[j]
    for i in il:
        pr = dl[i] * zl[i]
        pmax, pmin, psum = max(pmax, pr), min(pmin, pr), psum + pr
    for i in iu:
        pr = du[i] * zu[i]
        pmax, pmin, psum = max(pmax, pr), min(pmin, pr), psum + pr
    count = N * q + m + il.shape[0] + iu.shape[0]
    s_d = max(100.0, (ysum + duals) / (N + count)) / 100.0
    s_c = max(100.0, duals / max(count, 1)) / 100.0
    return dual / s_d, prim, pmax, pmin, s_c, psum / max(count, 1)


@njit(cache=True, error_model="numpy")
def ipm_newton(lay, gf, ge, y, gc, s, z, sc, zc, dl, du, zl, zu, sig, sig_c, sig_x, grad_f, base_x, bound_x,
               grad_c, a_mat):
    """The Newton system's terms at a point, written into the arrays after ``zu``: the slacks' and bounds'
    eliminated weights ``sig = z / s`` (N, q), ``sig_c`` (m,), ``sig_x`` (n,), the objective's gradient
    ``grad_f`` (n,), ``base_x`` = it + the equalities' gradients times their multipliers, ``bound_x`` (the
    bounds' barrier gradient per mu), the global inequalities' gradients ``grad_c`` (m, n) and the same in
    the KKT ordering, fixed variables left out, ``a_mat`` (size, m)."""
    loc, fixed, il, iu, pos_x = lay.loc, lay.fixed, lay.il, lay.iu, lay.pos_x
    N, P = loc.shape
    q, m, n = sig.shape[1], gc.shape[0], grad_f.shape[0]
    for k in range(N):
        for j in range(q):
            sig[k, j] = z[k, j] / s[k, j]
    for j in range(m):
        sig_c[j] = zc[j] / sc[j]
    sig_x[:] = 0.0
    bound_x[:] = 0.0
    for i in il:
        sig_x[i] += zl[i] / dl[i]
    for i in iu:
        sig_x[i] += zu[i] / du[i]
        bound_x[i] = 1 / du[i]
    for i in il:
        bound_x[i] = bound_x[i] - 1 / dl[i]
    grad_f[:] = 0.0
    base_x[:] = 0.0
    grad_c[:, :] = 0.0
    for k in range(N):
        for a in range(P):
            i = loc[k, a]
            grad_f[i] += gf[k, a]
            base_x[i] += ge[k, a] * y[k]
            for j in range(m):
                grad_c[j, i] += gc[j, k, a]
    a_mat[:, :] = 0.0
    for i in range(n):
        base_x[i] = grad_f[i] + base_x[i]
        if not fixed[i]:
            for j in range(m):
                a_mat[pos_x[i], j] = grad_c[j, i]


@njit(cache=True, error_model="numpy")
def ipm_rhs(lay, base_x, bound_x, gg, s, sig, r_g, grad_c, sc, sig_c, r_c, r_e, mu, out):
    """The Newton system's right-hand side ``out`` (size,) for the residuals ``r_e`` (the equalities),
    ``r_g = g + s``, ``r_c = c + sc`` and the barrier parameter ``mu``, the slacks eliminated."""
    loc, fixed, pos_x, pos_y = lay.loc, lay.fixed, lay.pos_x, lay.pos_y
    N, P = loc.shape
    q, m, n = gg.shape[1], grad_c.shape[0], base_x.shape[0]
    rx = np.zeros(n)
    for k in range(N):
        for j in range(q):
            w = mu / s[k, j] + sig[k, j] * r_g[k, j]
            for a in range(P):
                rx[loc[k, a]] += gg[k, j, a] * w
    wc = np.empty(m)
    for j in range(m):
        wc[j] = mu / sc[j] + sig_c[j] * r_c[j]
    out[:] = 0.0
    for i in range(n):
        v = 0.0
        if not fixed[i]:
            t = 0.0
            for j in range(m):
                t += grad_c[j, i] * wc[j]
            v = -(base_x[i] + mu * bound_x[i] + rx[i] + t)
        out[pos_x[i]] = v
    for k in range(N):
        out[pos_y[k]] = -r_e[k]


@njit(cache=True, error_model="numpy")
def ipm_curvature(lay, dx, hess, gg, sig, sig_x, delta_w, sig_c, grad_c):
    """(dx' W dx, dx' dx) for the step ``dx`` (n,): W the Hessian of the Lagrangian with the slacks' and the
    bounds' eliminated terms and the regularisation ``delta_w``."""
    loc = lay.loc
    N, P = loc.shape
    q, m, n = gg.shape[1], grad_c.shape[0], dx.shape[0]
    curv = 0.0
    d = np.empty(P)
    for k in range(N):
        for a in range(P):
            d[a] = dx[loc[k, a]]
        for a in range(P):
            for b in range(P):
                curv += d[a] * hess[k, a, b] * d[b]
        for j in range(q):
            jd = 0.0
            for a in range(P):
                jd += gg[k, j, a] * d[a]
            curv += sig[k, j] * jd * jd
    dd = 0.0
    for i in range(n):
        curv += (sig_x[i] + delta_w) * dx[i] * dx[i]
        dd += dx[i] * dx[i]
    for j in range(m):
        t = 0.0
        for i in range(n):
            t += grad_c[j, i] * dx[i]
        curv += sig_c[j] * t * t
    return curv, dd


@njit(cache=True, error_model="numpy")
def _ftb(a, v, dv, sign, tau):
    """The fraction-to-the-boundary rule for one entry: the step ``a`` limited so that ``v + a sign dv >=
    (1 - tau) v``."""
    d = sign * dv
    if d < 0.0:
        r = -tau * v / d
        if r < a:
            return r
    return a


@njit(cache=True, error_model="numpy")
def ipm_steps(lay, d, gg, r_g, r_c, grad_c, s, sc, z, zc, zl, zu, dl, du, sig, sig_c, grad_f, mu, tau, dual,
              dx, dy, ds, dsc, dz, dzc, dzl, dzu):
    """From the Newton solution ``d`` (size,): the primal step ``dx``, ``dy``, the slacks' ``ds`` = -r_g - J_g
    dx and ``dsc``, with ``dual`` the multipliers' steps for ``mu`` (``dz``, ``dzc``, ``dzl``, ``dzu``, 0
    where there is no bound); returns (the largest primal step, the largest dual step (1 without
    ``dual``) under the fraction-to-the-boundary rule with ``tau``, the barrier function's directional
    derivative along the primal step)."""
    loc, il, iu, pos_x, pos_y = lay.loc, lay.il, lay.iu, lay.pos_x, lay.pos_y
    N, P = loc.shape
    q, m, n = gg.shape[1], grad_c.shape[0], dx.shape[0]
    for i in range(n):
        dx[i] = d[pos_x[i]]
    for k in range(N):
        dy[k] = d[pos_y[k]]
    a_p, a_d, dphi = 1.0, 1.0, 0.0
    for i in range(n):
        dphi += grad_f[i] * dx[i]
    for k in range(N):
        for j in range(q):
            t = 0.0
            for a in range(P):
                t += gg[k, j, a] * dx[loc[k, a]]
            ds[k, j] = -r_g[k, j] - t
            a_p = _ftb(a_p, s[k, j], ds[k, j], 1.0, tau)
            dphi -= mu * (ds[k, j] / s[k, j])
    for j in range(m):
        t = 0.0
        for i in range(n):
            t += grad_c[j, i] * dx[i]
        dsc[j] = -r_c[j] - t
        a_p = _ftb(a_p, sc[j], dsc[j], 1.0, tau)
        dphi -= mu * (dsc[j] / sc[j])
    for i in il:
        a_p = _ftb(a_p, dl[i], dx[i], 1.0, tau)
        dphi -= mu * (dx[i] / dl[i])
    for i in iu:
        a_p = _ftb(a_p, du[i], dx[i], -1.0, tau)
        dphi += mu * (dx[i] / du[i])
    if dual:
        for k in range(N):
            for j in range(q):
                dz[k, j] = mu / s[k, j] - z[k, j] - sig[k, j] * ds[k, j]
                a_d = _ftb(a_d, z[k, j], dz[k, j], 1.0, tau)
        for j in range(m):
            dzc[j] = mu / sc[j] - zc[j] - sig_c[j] * dsc[j]
            a_d = _ftb(a_d, zc[j], dzc[j], 1.0, tau)
        dzl[:] = 0.0
        dzu[:] = 0.0
        for i in il:
            dzl[i] = mu / dl[i] - zl[i] - (zl[i] / dl[i]) * dx[i]
            a_d = _ftb(a_d, zl[i], dzl[i], 1.0, tau)
        for i in iu:
            dzu[i] = mu / du[i] - zu[i] + (zu[i] / du[i]) * dx[i]
            a_d = _ftb(a_d, zu[i], dzu[i], 1.0, tau)
    return a_p, a_d, dphi


@njit(cache=True, error_model="numpy")
def _add_log(v, logs, prod):
    """Sum of logarithms by products: ``v`` multiplied into ``prod``, which goes into ``logs`` as one logarithm
    before it could leave [1e-300, 1e300] (a logarithm costs twenty multiplications); a ``v`` that is not
    in [1e-150, 1e150] (zero, negative, NaN among them) is taken alone. Returns (logs, prod); the sum is
    ``logs + log(prod)``."""
    if not (1e-150 <= v <= 1e150):
        return logs + np.log(v), prod
    if not (1e-150 <= prod <= 1e150):
        logs += np.log(prod)
        prod = 1.0
    return logs, prod * v


@njit(cache=True, error_model="numpy")
def ipm_merit(lay, x, s, sc, e, g, c):
    """(the barrier terms' sum of logarithms, the constraint violation) at the point ``x`` with slacks ``s``,
    ``sc`` and the constraints' values ``e``, ``g``, ``c`` there: the barrier function is f - mu * the first
    (-inf or NaN where a slack or a distance to a bound is 0 or negative: off the domain)."""
    il, iu, lb, ub = lay.il, lay.iu, lay.lb, lay.ub
    N, q = s.shape
    logs, prod, theta = 0.0, 1.0, 0.0
    for k in range(N):
        theta += abs(e[k])
        for j in range(q):
            logs, prod = _add_log(s[k, j], logs, prod)
            theta += abs(g[k, j] + s[k, j])
    for j in range(sc.shape[0]):
        logs, prod = _add_log(sc[j], logs, prod)
        theta += abs(c[j] + sc[j])
    for i in il:
        logs, prod = _add_log(x[i] - lb[i], logs, prod)
    for i in iu:
        logs, prod = _add_log(ub[i] - x[i], logs, prod)
    return logs + np.log(prod), theta


@njit(cache=True, error_model="numpy")
def ipm_mean_complementarity(lay, ap, ad, x, dx, s, ds, sc, dsc, z, dz, zc, dzc, zl, dzl, zu, dzu):
    """The mean complementarity product at the point a primal step ``ap`` and a dual step ``ad`` along the
    given steps away (Mehrotra's probing)."""
    il, iu, lb, ub = lay.il, lay.iu, lay.lb, lay.ub
    N, q = s.shape
    tot = 0.0
    for k in range(N):
        for j in range(q):
            tot += (s[k, j] + ap * ds[k, j]) * (z[k, j] + ad * dz[k, j])
    for j in range(sc.shape[0]):
        tot += (sc[j] + ap * dsc[j]) * (zc[j] + ad * dzc[j])
    for i in il:
        tot += ((x[i] + ap * dx[i]) - lb[i]) * (zl[i] + ad * dzl[i])
    for i in iu:
        tot += (ub[i] - (x[i] + ap * dx[i])) * (zu[i] + ad * dzu[i])
    count = N * q + sc.shape[0] + il.shape[0] + iu.shape[0]
    return tot / max(count, 1)


@njit(cache=True, error_model="numpy")
def ipm_update(lay, x, s, sc, alpha, dy, a_d, dz, dzc, dzl, dzu, mu, y, z, zc, zl, zu, dl, du):
    """The multipliers after a step (``y`` by ``alpha``, the rest by ``a_d``), in place, kept near the central
    path (IPOPT's kappa_sigma safeguard: each product within a factor 1e10 of mu), at the new point ``x``,
    ``s``, ``sc``; and the new point's distances to its bounds ``dl``, ``du`` (1 where none)."""
    il, iu, lb, ub = lay.il, lay.iu, lay.lb, lay.ub
    N, q = s.shape
    ks = 1e10
    for k in range(N):
        y[k] = y[k] + alpha * dy[k]
        for j in range(q):
            v = z[k, j] + a_d * dz[k, j]
            z[k, j] = min(max(v, mu / (ks * s[k, j])), ks * mu / s[k, j])
    for j in range(sc.shape[0]):
        v = zc[j] + a_d * dzc[j]
        zc[j] = min(max(v, mu / (ks * sc[j])), ks * mu / sc[j])
    dl[:] = 1.0
    du[:] = 1.0
    for i in il:  # (zl, zu are 0 where there is no bound, and stay so)
        dl[i] = x[i] - lb[i]
        v = zl[i] + a_d * dzl[i]
        zl[i] = min(max(v, mu / (ks * dl[i])), ks * mu / dl[i])
    for i in iu:
        du[i] = ub[i] - x[i]
        v = zu[i] + a_d * dzu[i]
        zu[i] = min(max(v, mu / (ks * du[i])), ks * mu / du[i])
