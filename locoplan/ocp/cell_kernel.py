"""E*'s cell problem (``ocp/cells.py``) evaluated cell by cell, compiled (numba, through ``sim/native.py``).

The same formulas as ``CellEnergyProblem.values`` / ``derivatives`` / ``hessian`` (their numpy form, kept
there as the reference), written per cell with scalars: a cell costs a few dozen floating-point
operations instead of a few dozen numpy calls over all cells. The physics is ``locoplan.physics``' own
functions, compiled here: the resistance and its slope, full braking (each force's cap is a curve fed by
the catenary plus one that works everywhere) and the rounded force curves (``backend.rounded_curve_at``,
the scalar twin of ``RoundedCurve``). ``tests/test_estar_cells.py`` holds the two forms to 1e-12.

The problem is one record (``sim/records.py``'s ``CellModel``); the variables are ``[v_0, f_0.., v_1,
...]``, ``nf`` forces per cell, scaled (speeds by ``v_ref``, forces by ``f_ref``).
"""

from __future__ import annotations

import math

from numba import njit

from ..physics import backend, braking, resistance, units
from ..physics.units import KJ_PER_KWH, KMH_PER_MS

rounded_curve_at = njit(cache=True, _nrt=False, error_model="numpy")(backend.rounded_curve_at)
full_brake_kn = njit(cache=True, error_model="numpy")(braking.full_brake_kn)
davis_kn = njit(cache=True, error_model="numpy")(resistance.davis_kn)
davis_slope_kn_per_kmh = njit(cache=True, error_model="numpy")(resistance.davis_slope_kn_per_kmh)
kmh = njit(cache=True, error_model="numpy")(units.kmh)

V_FLOOR_MS = 1e-6
"""As ``cells.V_FLOOR_MS`` (the mean speed's floor [m/s])."""
_D1 = KMH_PER_MS ** 1
_D2 = KMH_PER_MS ** 2
"""A curve's slope and curvature per km/h, in m/s (the numpy form's ``KMH_PER_MS ** i``)."""


@njit(cache=True, _nrt=False, error_model="numpy")
def _curve(cx, cy, cw, coff, i, v_kmh):
    """Rounded curve ``i`` of the model's curves at ``v_kmh``: (value, slope, curvature) per km/h; (0, 0, 0)
    for ``i`` < 0. (The helpers take the record's arrays, not the record: passing it costs a reference count
    on each of its arrays per call.)"""
    if i < 0:
        return 0.0, 0.0, 0.0
    return rounded_curve_at(v_kmh, cx, cy, cw[i], coff[i], coff[i + 1])


@njit(cache=True, _nrt=False, error_model="numpy")
def _cap(cx, cy, cw, coff, cat, free, on, v_kmh):
    """A force's cap at ``v_kmh``, its curve ``cat`` fed by the catenary (``on`` 1/0) plus ``free``: (value
    [kN], d/dvm, d2/dvm2 [per m/s])."""
    c0, c1, c2 = _curve(cx, cy, cw, coff, cat, v_kmh)
    f0, f1, f2 = _curve(cx, cy, cw, coff, free, v_kmh)
    return full_brake_kn(c0, f0, on), full_brake_kn(c1, f1, on) * _D1, full_brake_kn(c2, f2, on) * _D2


@njit(cache=True, error_model="numpy")
def _speeds(x, k, st, v_ref):
    """Cell ``k``'s node speeds p, q and mean speed vm [m/s], vm in km/h (``st`` variables per cell)."""
    p = x[st * k] * v_ref
    q = x[st * (k + 1)] * v_ref
    vm = math.sqrt(max(0.5 * (p * p + q * q), V_FLOOR_MS ** 2))
    return p, q, vm, kmh(vm)


@njit(cache=True, error_model="numpy")
def cell_values(cm, x, e, g, c, caps):
    """The objective (returned), each cell's equality ``e`` (N,), inequalities ``g`` (N, nf) and the global
    inequalities ``c`` (m,) at the scaled point ``x``; ``caps`` (N, nf, 3): each real cap's value, d/dvm
    and d2/dvm2 there (0 where the cap is not real), what ``cell_derivatives`` and ``cell_hessian`` read."""
    N, nf, st = cm.h.shape[0], cm.nf, cm.nf + 1
    fr, vr = cm.f_ref, cm.v_ref
    cx, cy, cw, coff, cap_cat, cap_free, allowed = cm.cx, cm.cy, cm.cw, cm.coff, cm.cap_cat, cm.cap_free, cm.allowed
    c[:] = 0.0
    obj = 0.0
    for k in range(N):
        p, q, vm, V = _speeds(x, k, st, vr)
        h = cm.h[k]
        net = x[st * k + 1] * fr
        for j in range(1, nf):  # traction less every brake
            net = net - x[st * k + 1 + j] * fr
        R = davis_kn(V, cm.ra, cm.rb, cm.rc)
        e[k] = (0.5 * cm.m * (q * q - p * p) - h * (net - R - cm.grav[k])) / (h * fr)
        work = 0.0
        for j in range(nf):
            f = x[st * k + 1 + j] * fr
            if cm.cost[j] != 0.0:
                work += cm.cost[j] * f
            if cm.active[k, j] != 0.0:
                c0, c1, c2 = _cap(cx, cy, cw, coff, cap_cat[j], cap_free[j], allowed[k], V)
                g[k, j] = (f - c0) / fr
            else:
                c0, c1, c2 = 0.0, 0.0, 0.0
                g[k, j] = -1.0
            caps[k, j, 0], caps[k, j, 1], caps[k, j, 2] = c0, c1, c2
        obj += h * work
        tau = 2 * h / max(p + q, V_FLOOR_MS)
        for i in range(c.shape[0]):
            c[i] += cm.cmask[i, k] * tau
    for i in range(c.shape[0]):
        c[i] = (c[i] + cm.cconst[i]) / cm.t_ref
    return obj / KJ_PER_KWH / cm.e_ref


@njit(cache=True, error_model="numpy")
def cell_derivatives(cm, x, caps, gf, ge, gg, gc):
    """The gradients on each cell's variables (v_k, its forces, v_k+1), scaled, with ``caps`` from
    :func:`cell_values` at ``x``: of the objective ``gf`` (N, p), the equality ``ge`` (N, p), the
    inequalities ``gg`` (N, nf, p) and the global ones ``gc`` (m, N, p)."""
    N, nf, st = cm.h.shape[0], cm.nf, cm.nf + 1
    n = nf + 2
    fr, vr, M = cm.f_ref, cm.v_ref, cm.m
    gf[:, :] = 0.0
    gg[:, :, :] = 0.0
    gc[:, :, :] = 0.0
    for k in range(N):
        p, q, vm, V = _speeds(x, k, st, vr)
        h = cm.h[k]
        vm_p, vm_q = p * (1 / (2 * vm)), q * (1 / (2 * vm))
        R_v = KMH_PER_MS * davis_slope_kn_per_kmh(V, cm.rb, cm.rc)
        ge[k, 0] = (-M * p + h * R_v * vm_p) / (h * fr) * vr
        ge[k, 1] = -1.0 / fr * fr
        for j in range(1, nf):
            ge[k, 1 + j] = 1.0 / fr * fr
        ge[k, n - 1] = (M * q + h * R_v * vm_q) / (h * fr) * vr
        for j in range(nf):
            if cm.active[k, j] != 0.0:
                cap1 = caps[k, j, 1]
                gg[k, j, 0] = -cap1 * vm_p / fr * vr
                gg[k, j, n - 1] = -cap1 * vm_q / fr * vr
                gg[k, j, j + 1] = 1.0 / fr * fr
            if cm.cost[j] != 0.0:
                gf[k, j + 1] = cm.cost[j] * h / KJ_PER_KWH / cm.e_ref * fr
        dtau = -2 * h / max(p + q, V_FLOOR_MS) ** 2 / cm.t_ref
        for i in range(gc.shape[0]):
            w = cm.cmask[i, k] * dtau * vr
            gc[i, k, 0] = w
            gc[i, k, n - 1] = w


@njit(cache=True, error_model="numpy")
def cell_hessian(cm, x, caps, y, z, zc, out):
    """The Lagrangian's Hessian on each cell's variables ``out`` (N, p, p), with ``caps`` from
    :func:`cell_values` at ``x``, for the equality multipliers ``y``, the inequalities' ``z`` (N, nf) and the
    global ones' ``zc``: only the two speeds enter nonlinearly."""
    N, nf, st = cm.h.shape[0], cm.nf, cm.nf + 1
    n = nf + 2
    fr, M, vr = cm.f_ref, cm.m, cm.v_ref
    vr2 = cm.v_ref ** 2
    R_vv = KMH_PER_MS ** 2 * 2.0 * cm.rc
    out[:, :, :] = 0.0
    for k in range(N):
        p, q, vm, V = _speeds(x, k, st, vr)
        h = cm.h[k]
        i2, i4 = 1 / (2 * vm), 1 / (4 * vm ** 3)
        vm_p, vm_q, vm_pp, vm_pq, vm_qq = p * i2, q * i2, i2 - p * p * i4, -p * q * i4, i2 - q * q * i4
        R_v = KMH_PER_MS * davis_slope_kn_per_kmh(V, cm.rb, cm.rc)
        e_pp = (-M + h * (R_vv * vm_p ** 2 + R_v * vm_pp)) / (h * fr)
        e_qq = (M + h * (R_vv * vm_q ** 2 + R_v * vm_qq)) / (h * fr)
        e_pq = (R_vv * vm_p * vm_q + R_v * vm_pq) / fr
        pp, pq, qq = y[k] * e_pp, y[k] * e_pq, y[k] * e_qq
        for j in range(nf):  # - cap(vm) in each inequality
            if cm.active[k, j] != 0.0:
                cap1, cap2 = caps[k, j, 1], caps[k, j, 2]
                w = z[k, j] / fr
                pp = pp - w * (cap2 * vm_p ** 2 + cap1 * vm_pp)
                qq = qq - w * (cap2 * vm_q ** 2 + cap1 * vm_qq)
                pq = pq - w * (cap2 * vm_p * vm_q + cap1 * vm_pq)
        zm = 0.0
        for i in range(zc.shape[0]):
            zm += zc[i] * cm.cmask[i, k]
        d2 = zm * 4 * h / max(p + q, V_FLOOR_MS) ** 3 / cm.t_ref  # the times
        out[k, 0, 0] = (pp + d2) * vr2
        out[k, n - 1, n - 1] = (qq + d2) * vr2
        out[k, 0, n - 1] = (pq + d2) * vr2
        out[k, n - 1, 0] = (pq + d2) * vr2
