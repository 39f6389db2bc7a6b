"""The cycle DP's compiled loops (numba): a cell's step under a control, the air brake's applications and
recharges as exact paths, the backward and the forward pass.

``cycle_dp.py`` holds the method and its documentation; these are its inner loops, called through
``locoplan.sim.native`` (ahead-of-time compiled where possible, numba's JIT otherwise). The forces are
``locoplan.physics``' own, compiled in ``sim/kernel.py``: traction, the electric brake, the air brake,
resistance plus gravity; the step is the calculator's (forces at the mid-speed, two passes, dt = 2 h / (v0 + v1)).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..physics.units import KJ_PER_KWH
from ..sim.kernel import davis_kn, e_from_ms, kmh_from_e, ms_from_e
from .dp_kernel import _blend, _bracket, _interp1

CH, NA, AF = 0, 1, 2
"""Air-brake states at a node: released and charged (may apply), released with no application before the zone
ends (or outside every zone: no air brake there), applied at full with its least hold over (may release)."""
U_T, U_H, U_C, U_B, U_E = 0, 1, 2, 3, 4
"""A cell's control: full traction, hold the speed (traction, or braking up to what the state allows, at full
where that cannot hold it), coast, braking with the air brake applied (and the full electric brake), the full
electric brake alone. The first four are the calculator's condition codes (T, K, C, B)."""
M_APPLY, M_REC_H, M_REC_C, M_REC_E = 0, 1, 2, 3
N_MACROS = 4
"""Paths of several cells from one node: an application (braking, its force building up, until its least hold
and its build-up are over), and a release's recharge under one control (hold, coast, the electric brake)."""
OK, AIR, NO = 0, 1, 2
"""A step's verdict: possible as it is (or held at the next node's cap by the electric brake alone), possible
only with the air brake following that cap (a braking curve), not possible."""
AIR_OFF, AIR_CYCLE, AIR_RECHARGE, AIR_CURVE = 0, 1, 2, 3
"""The drive's air brake per cell: released (charged, or no application ahead in the zone), applied (an
application of its own, with its build-up and least hold), released and recharging, applied following a
braking curve (no least hold: released where the curve ends, as in the calculator)."""


@njit(cache=True, _nrt=False)
def _brake_force(vm, lvl, k, cc, fo):
    """Braking [kN] at vm in cell k: the electric brake where the catenary feeds it plus ``lvl`` x the air brake."""
    b = _interp1(vm, fo.ev, fo.ef) * cc.allowed[k]
    if lvl > 0.0:
        b += lvl * _interp1(vm, fo.av, fo.af)
    return b


@njit(cache=True, _nrt=False)
def _free_step(e, u, t0, t_b, k, cc, fo):
    """Cell k from e = v^2/2 under control u (not H), no cap: (e at its end, traction work [kJ]). With U_B the
    air brake's level is its build-up at the cell's middle time, ``t0`` [s] after the application at the cell's
    start (``t_b`` its build-up time; <= 0: full at once)."""
    h = cc.h[k]
    g_k = cc.grav[k]
    v0 = ms_from_e(max(e, 0.0))
    e1 = e
    f = 0.0
    for _ in range(2):
        vm = kmh_from_e(max(0.5 * (e + e1), 0.0))
        f = 0.0
        b = 0.0
        if u == U_T:
            f = _interp1(vm, fo.tv, fo.tf) * cc.allowed[k]
        elif u == U_E:
            b = _brake_force(vm, 0.0, k, cc, fo)
        elif u == U_B:
            lvl = 1.0
            if t_b > 0.0:
                t_mid = t0 + h / (v0 + ms_from_e(max(0.5 * (e + e1), 0.0)) + 1e-12)  # the calculator's mid-cell time
                lvl = min(max(t_mid / t_b, 0.0), 1.0)
            b = _brake_force(vm, lvl, k, cc, fo)
        load = davis_kn(vm, fo.ra, fo.rb, fo.rc) + g_k
        e1 = e + h / fo.m * (f - b - load)
    if u == U_T:
        vm = kmh_from_e(max(0.5 * (e + e1), 0.0))
        f = _interp1(vm, fo.tv, fo.tf) * cc.allowed[k]
    return e1, f * h


@njit(cache=True, _nrt=False)
def _step(e, u, t0, t_b, k, cc, fo, full_hold):
    """Cell k under control u, uncapped: (e_end, work [kJ]); e_end < 0 = not possible (hold from rest). H holds
    the speed with traction or braking (the electric brake, or with ``full_hold`` full braking) where it can,
    else takes full traction (a climb) or that braking at full (a descent)."""
    if u != U_H:
        return _free_step(e, u, t0, t_b, k, cc, fo)
    if e <= 0.0:
        return -1.0, 0.0
    v_kmh = kmh_from_e(e)
    load0 = davis_kn(v_kmh, fo.ra, fo.rb, fo.rc) + cc.grav[k]
    f_max = _interp1(v_kmh, fo.tv, fo.tf) * cc.allowed[k]
    b_max = _brake_force(v_kmh, 1.0 if full_hold else 0.0, k, cc, fo)
    if load0 > f_max:
        return _free_step(e, U_T, t0, t_b, k, cc, fo)
    if -load0 > b_max:
        return _free_step(e, U_B if full_hold else U_E, 0.0, 0.0, k, cc, fo)
    return e, max(load0, 0.0) * cc.h[k]


@njit(cache=True, _nrt=False)
def cell(e, u, t0, t_b, k, cc, fo, full_hold):
    """Cell k under control u from e, held under the next node's cap the way the calculator holds a train
    there: (e_end, work [kJ], verdict OK / AIR / NO). Where the step would end above the cap, the train follows
    the cap if full braking from e keeps it there (the calculator's braking curves are full braking; a
    tolerance for their finer steps): by the electric brake alone (OK) or only with the air brake (AIR). The
    last cell ends at rest."""
    n = cc.h.shape[0]
    e1, w = _step(e, u, t0, t_b, k, cc, fo, full_hold)
    if e1 < 0.0 and u == U_H:
        return -1.0, 0.0, NO
    cap = 0.0 if k == n - 1 else cc.e_cap[k + 1]
    if e1 > cap * (1.0 + 1e-9) + 1e-9:
        tol = 0.02 * (e - cap if e > cap else 0.0) + 1e-3 * max(e, 1.0)
        if u == U_E or (u == U_B and t_b <= 0.0):
            e_el = e1
        else:
            e_el = _free_step(e, U_E, 0.0, 0.0, k, cc, fo)[0]
        if e_el <= cap + tol:
            return cap, w, OK if u != U_B else AIR
        e_f = _free_step(e, U_B, 0.0, 0.0, k, cc, fo)[0]
        if e_f <= cap + tol:
            return cap, w, AIR
        return -1.0, 0.0, NO
    if e1 < 0.0:
        return (0.0, w, OK if u != U_B else AIR) if k == n - 1 else (-1.0, 0.0, NO)
    return e1, w, OK if u != U_B else AIR


@njit(cache=True, _nrt=False)
def _cell_time(e, e1, h):
    """Time [s] of a cell from e to e1 (dt = 2 h / (v0 + v1)); inf when the train does not move."""
    s = ms_from_e(max(e, 0.0)) + ms_from_e(max(e1, 0.0))
    return 2.0 * h / s if s > 0.0 else np.inf


@njit(cache=True, _nrt=False)
def hold_s(k, cc):
    """The least hold [s] of an application made in cell k: the given one, else its build-up time."""
    return cc.t_hold if cc.t_hold >= 0.0 else cc.t_build[k]


@njit(cache=True, _nrt=False)
def apply_path(e, k, cc, fo, controls, air, v_nodes, t_nodes, t_start):
    """An application made at node k at e: the air brake (and the full electric brake) until both its least hold
    and its build-up are over, at the first node after (exact times, the calculator's linear build-up); a cap
    met on the way is followed with full braking, as the calculator does. Returns (end node, e there, time [s]);
    end node -1 = not possible (the train stops, or the zone ends first). With ``controls`` of the route's
    length (the forward pass) each cell is recorded from ``t_start`` [s]."""
    n = cc.h.shape[0]
    t_b = cc.t_build[k]
    need = max(hold_s(k, cc), t_b)
    t = 0.0
    j = k
    rec = controls.shape[0] == n
    while True:
        e1, w, ok = cell(e, U_B, t, t_b, j, cc, fo, False)
        if ok == NO:
            return -1, 0.0, 0.0
        dt = _cell_time(e, e1, cc.h[j])
        if not math.isfinite(dt):
            return -1, 0.0, 0.0
        t += dt
        if rec:
            controls[j] = U_B
            air[j] = AIR_CYCLE
            v_nodes[j + 1] = kmh_from_e(max(e1, 0.0))
            t_nodes[j + 1] = t_start + t
        j += 1
        e = e1
        if j == n:
            return j, e, t
        if cc.zone[j] == 0:
            return -1, 0.0, 0.0
        if t >= need - 1e-9:
            return j, e, t


@njit(cache=True, _nrt=False)
def recharge_path(e, k, u, cc, fo, controls, air, v_nodes, t_nodes, t_start):
    """A release at node k at e, then control u (H, C or E) while the air brake recharges, a cap followed by the
    electric brake alone (not charged: no air), until the recharge is over at a node (the brake is charged
    there), or the zone ends (outside it no application is made, and the next zone lies further than the
    recharge time covers), or the stop. Returns (end node, e there, time [s], traction work [kJ]); end node -1 =
    not possible. Records as ``apply_path``."""
    n = cc.h.shape[0]
    t = 0.0
    w_sum = 0.0
    j = k
    rec = controls.shape[0] == n
    while True:
        e1, w, ok = cell(e, u, 0.0, 0.0, j, cc, fo, False)
        if ok != OK:
            return -1, 0.0, 0.0, 0.0
        dt = _cell_time(e, e1, cc.h[j])
        if not math.isfinite(dt):
            return -1, 0.0, 0.0, 0.0
        t += dt
        w_sum += w
        if rec:
            controls[j] = u
            air[j] = AIR_RECHARGE
            v_nodes[j + 1] = kmh_from_e(max(e1, 0.0))
            t_nodes[j + 1] = t_start + t
        j += 1
        e = e1
        if j == n or cc.zone[j] == 0 or t >= cc.t_rec - 1e-9:
            return j, e, t, w_sum


N_U = 5
"""Single-cell controls: U_T .. U_E."""


@njit(cache=True, _nrt=False)
def _cells_at(e, k, cc, fo, se, sw, st, sok):
    """Each single-cell control's step from e at node k (``cell``): e at the cell's end, traction work [kJ], time
    [s] and verdict, into ``se``, ``sw``, ``st``, ``sok`` (NO also where the train would not move)."""
    for u in range(N_U):
        e1, w, ok = cell(e, u, 1e9, 0.0, k, cc, fo, cc.relaxed)
        dt = _cell_time(e, e1, cc.h[k]) if ok != NO else np.inf
        if not math.isfinite(dt):
            ok = NO
        se[u], sw[u], st[u], sok[u] = e1, w, dt, ok


@njit(cache=True, _nrt=False)
def _paths_at(e, k, cc, fo, mj, me, mt, mw, none_i, none_f):
    """The paths from e at node k (``apply_path``, ``recharge_path`` under H, C and E) into ``mj`` (end node, -1:
    none), ``me``, ``mt``, ``mw``."""
    mj[M_APPLY], me[M_APPLY], mt[M_APPLY] = apply_path(e, k, cc, fo, none_i, none_i, none_f, none_f, 0.0)
    mw[M_APPLY] = 0.0
    for m in range(1, N_MACROS):
        u = U_H if m == M_REC_H else (U_C if m == M_REC_C else U_E)
        mj[m], me[m], mt[m], mw[m] = recharge_path(e, k, u, cc, fo, none_i, none_i, none_f, none_f, 0.0)


@njit(cache=True)
def cycle_prepare(cc, fo, st_e, st_w, st_t, st_ok, mac_j, mac_e, mac_t, mac_w):
    """What does not depend on the price of time, once per grid: every node's single-cell steps from every grid
    speed (``st_*[k, j, u]``, ``_cells_at``) and, in the zones, its paths (``mac_*[k, j, m]``, ``_paths_at``; -1
    elsewhere)."""
    n = cc.h.shape[0]
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    none_i = np.zeros(1, dtype=np.int64)
    none_f = np.zeros(1)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    mj = np.zeros(N_MACROS, dtype=np.int64)
    me = np.zeros(N_MACROS)
    mt = np.zeros(N_MACROS)
    mw = np.zeros(N_MACROS)
    paths = mac_j.shape[0] == n
    for k in range(n):
        zone = cc.zone[k] != 0 and not cc.relaxed and paths
        for j in range(nv + 1):
            e = e_from_ms(v_grid[j]) if j < nv else max(cc.e_cap[k], 0.0)
            if e > cc.e_cap[k] * (1.0 + 1e-9) + 1e-9:
                for u in range(N_U):
                    st_ok[k, j, u] = NO
                if zone:
                    for m in range(N_MACROS):
                        mac_j[k, j, m] = -1
                continue
            _cells_at(e, k, cc, fo, se, sw, st, sok)
            for u in range(N_U):
                st_e[k, j, u], st_w[k, j, u], st_t[k, j, u], st_ok[k, j, u] = se[u], sw[u], st[u], sok[u]
            if zone:
                _paths_at(e, k, cc, fo, mj, me, mt, mw, none_i, none_f)
                for m in range(N_MACROS):
                    mac_j[k, j, m], mac_e[k, j, m], mac_t[k, j, m], mac_w[k, j, m] = mj[m], me[m], mt[m], mw[m]
            elif paths:
                for m in range(N_MACROS):
                    mac_j[k, j, m] = -1


@njit(cache=True, _nrt=False)
def look(V, k, s, e1, cc):
    """The cost-to-go at node k in state s at e1, interpolated in speed on the node's grid (the shared grid
    below its cap, the cap itself as the last column); above the node's stall boundary a lower grid point
    below it does not count (as the priced DP reads it). At the stop: 0 at rest."""
    if k == cc.h.shape[0]:
        return 0.0 if e1 <= 1e-9 else np.inf
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    v1 = ms_from_e(max(e1, 0.0))
    v_cap = ms_from_e(max(cc.e_cap[k], 0.0))
    i0, i1, w = _bracket(v1, v_grid[1] - v_grid[0], nv, v_cap)
    if i0 < 0:
        return np.inf
    a = V[k, s, i0]
    z = V[k, s, i1]
    if 0.0 < w < 1.0 and math.isinf(a) and not math.isinf(z):
        low = cc.e_low[k]
        if math.isfinite(low) and v1 >= ms_from_e(low):
            return z
    return _blend(a, z, w)


@njit(cache=True, _nrt=False)
def _zone_start(k, cc):
    return cc.zone[k] != 0 and (k == 0 or cc.zone[k - 1] == 0)


@njit(cache=True, _nrt=False)
def _arrive(k1, s, cc):
    """The state a train in state s arrives in at node k1 (outside a zone, and at the stop: NA)."""
    if k1 == cc.h.shape[0] or cc.zone[k1] == 0:
        return NA
    return s


@njit(cache=True, _nrt=False)
def _options(k, s, price, V, cc, se, sw, st, sok, mj, me, mt, mw, best):
    """The best way on from node k in state s at ``price`` [kWh/s], given the single-cell steps (``se``..) and
    the paths (``mj``..) from the train's speed: its cost [kWh]; ``best`` gets (option, state after it) with
    options 0..4 a single cell under control U_T..U_E (U_B: staying applied), 5 + m the path m (an application,
    a release and its recharge under H, C or E); option -1: none."""
    relaxed = cc.relaxed
    c_best = np.inf
    best[0] = -1
    best[1] = NA
    for u in range(N_U):
        ok = sok[u]
        if ok == NO:
            continue
        if relaxed:
            if u == U_E:
                continue
            s1 = NA
        elif s == AF:
            # applied: stays applied (B), or is released at this node and runs on under u with no application
            # before the zone ends (NA; an application after a release needs its recharge path first)
            if u == U_B:
                s1 = AF
            elif ok == OK:
                s1 = NA
            else:
                continue
        elif u == U_B:
            continue
        elif s == CH:
            if ok == OK:
                s1 = CH
            elif cc.curve_ok[k]:
                s1 = AF  # a braking curve followed with the air brake: an application (no least hold)
            else:
                continue
        elif ok == OK:
            s1 = NA
        else:
            continue
        s1 = _arrive(k + 1, s1, cc)
        c = sw[u] / KJ_PER_KWH + price * st[u] + look(V, k + 1, s1, se[u], cc)
        if c < c_best:
            c_best = c
            best[0] = u
            best[1] = s1
    if cc.zone[k] != 0 and not relaxed and s != NA:
        first = M_APPLY if s == CH else M_REC_H
        last = M_APPLY if s == CH else M_REC_E
        for m in range(first, last + 1):
            jn = mj[m]
            if jn < 0:
                continue
            s1 = _arrive(jn, AF if m == M_APPLY else CH, cc)
            c = mw[m] / KJ_PER_KWH + price * mt[m] + look(V, jn, s1, me[m], cc)
            if c < c_best:
                c_best = c
                best[0] = 5 + m
                best[1] = s1
    return c_best


@njit(cache=True)
def cycle_backward(cc, fo, price, V, st_e, st_w, st_t, st_ok, mac_j, mac_e, mac_t, mac_w):
    """V[k, s, j]: least traction energy + ``price`` x time [kWh] from node k in air state s at grid speed j
    (j = len(v_grid): at the node's cap) to the stop (inf = none), from ``cycle_prepare``'s tables."""
    n = cc.h.shape[0]
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    for s in range(3):
        for j in range(nv + 1):
            V[n, s, j] = 0.0 if j == 0 or (j == nv and cc.e_cap[n] <= 1e-12) else np.inf
    best = np.zeros(2, dtype=np.int64)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    mj = np.zeros(N_MACROS, dtype=np.int64)
    me = np.zeros(N_MACROS)
    mt = np.zeros(N_MACROS)
    mw = np.zeros(N_MACROS)
    for k in range(n - 1, -1, -1):
        zone = cc.zone[k] != 0 and not cc.relaxed
        for j in range(nv + 1):
            for u in range(N_U):
                se[u], sw[u], st[u], sok[u] = st_e[k, j, u], st_w[k, j, u], st_t[k, j, u], st_ok[k, j, u]
            V[k, NA, j] = _options(k, NA, price, V, cc, se, sw, st, sok, mj, me, mt, mw, best)
            if zone:
                for m in range(N_MACROS):
                    mj[m], me[m], mt[m], mw[m] = mac_j[k, j, m], mac_e[k, j, m], mac_t[k, j, m], mac_w[k, j, m]
                V[k, CH, j] = _options(k, CH, price, V, cc, se, sw, st, sok, mj, me, mt, mw, best)
                V[k, AF, j] = _options(k, AF, price, V, cc, se, sw, st, sok, mj, me, mt, mw, best)
            else:
                V[k, CH, j] = V[k, NA, j]
                V[k, AF, j] = V[k, NA, j]
        if zone and _zone_start(k, cc):
            for j in range(nv + 1):
                V[k, NA, j] = V[k, CH, j]  # (arriving from outside the zone: charged)


@njit(cache=True)
def cycle_forward(cc, fo, price, V, controls, air, v_nodes, t_nodes):
    """The drive from rest: at each node the best option at the train's actual speed and air state, its steps
    and paths run from there (exact times: the drive keeps the rules); per cell its control and air state, per
    node speed [km/h] and time [s]. Returns (time [s], traction work [kJ]); inf when no drive reaches the stop."""
    n = cc.h.shape[0]
    best = np.zeros(2, dtype=np.int64)
    none_i = np.zeros(1, dtype=np.int64)
    none_f = np.zeros(1)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    mj = np.zeros(N_MACROS, dtype=np.int64)
    me = np.zeros(N_MACROS)
    mt = np.zeros(N_MACROS)
    mw = np.zeros(N_MACROS)
    e = 0.0
    t = 0.0
    work = 0.0
    v_nodes[0] = 0.0
    t_nodes[0] = 0.0
    s = CH if cc.zone[0] != 0 and not cc.relaxed else NA
    k = 0
    while k < n:
        if cc.relaxed or cc.zone[k] == 0:
            s = NA
        elif s == NA and _zone_start(k, cc):
            s = CH
        _cells_at(e, k, cc, fo, se, sw, st, sok)
        for m in range(N_MACROS):
            mj[m] = -1
        if cc.zone[k] != 0 and not cc.relaxed and s != NA:
            _paths_at(e, k, cc, fo, mj, me, mt, mw, none_i, none_f)
        c = _options(k, s, price, V, cc, se, sw, st, sok, mj, me, mt, mw, best)
        o = best[0]
        if o < 0 or not math.isfinite(c):
            return np.inf, np.inf
        if o < N_U:
            controls[k] = o
            if cc.relaxed or not (o == U_B or (s == CH and sok[o] == AIR)):
                air[k] = AIR_OFF
            elif s == CH or (k > 0 and air[k - 1] == AIR_CURVE):
                air[k] = AIR_CURVE
            else:
                air[k] = AIR_CYCLE
            t += st[o]
            work += sw[o]
            e = se[o]
            k += 1
            v_nodes[k] = kmh_from_e(max(e, 0.0))
            t_nodes[k] = t
        elif o == 5 + M_APPLY:
            jn, e_new, dt = apply_path(e, k, cc, fo, controls, air, v_nodes, t_nodes, t)
            t += dt
            e = e_new
            k = jn
        else:
            u = U_H if o == 5 + M_REC_H else (U_C if o == 5 + M_REC_C else U_E)
            jn, e_new, dt, w = recharge_path(e, k, u, cc, fo, controls, air, v_nodes, t_nodes, t)
            t += dt
            work += w
            e = e_new
            k = jn
        s = best[1]
    return t, work
