"""The cycle DP's compiled loops (numba): a cell's step under a control, the air brake's applications and
recharges as paths with exact times, the backward and the forward pass.

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
N_U = 5
"""A cell's control: full traction, hold the speed (traction, or braking up to what the state allows, at full
where that cannot hold it), coast, braking with the air brake applied (and the full electric brake), the full
electric brake alone. The first four are the calculator's condition codes (T, K, C, B)."""
P_A, P_AR_H, P_AR_C, P_AR_E, P_R_H, P_R_C, P_R_E, P_RA_H = 0, 1, 2, 3, 4, 5, 6, 7
N_P = 8
"""Paths of several cells from a node, made of phases whose ends come at exact times (inside a cell where they
fall there), each continued to the next node under its last phase's control:
- from a charged brake (CH): an application (``P_A``: the air brake builds up, held until both its least hold
  and its build-up are over; then AF), or that application released the instant it may be, and its recharge
  under H, C or E (``P_AR_*``; then CH);
- from an applied one (AF): a release at the node and the recharge under H, C or E (``P_R_*``; then CH), or the
  recharge under H and an application the instant it is over (``P_RA_H``; then AF)."""
OK, AIR, NO = 0, 1, 2
"""A step's verdict: possible as it is (or held at the next node's cap by the electric brake alone), possible
only with the air brake (applied, or following a braking curve), not possible."""
AIR_OFF, AIR_CYCLE, AIR_RECHARGE, AIR_CURVE = 0, 1, 2, 3
"""The drive's air brake at each cell's start: released (charged, or no application ahead in the zone), applied
(an application of its own, with its build-up and least hold), released and recharging, applied following a
braking curve (no least hold: released where the curve ends, as in the calculator)."""
EV_APPLY, EV_RELEASE, EV_CURVE = 1, 2, 3
"""The drive's events: an application, a release, an application following a braking curve."""
PH_APPLY, PH_REC = 0, 1


@njit(cache=True, _nrt=False)
def _brake_force(vm, lvl, k, cc, fo):
    """Braking [kN] at vm in cell k: the electric brake where the catenary feeds it plus ``lvl`` x the air brake."""
    b = _interp1(vm, fo.ev, fo.ef) * cc.allowed[k]
    if lvl > 0.0:
        b += lvl * _interp1(vm, fo.av, fo.af)
    return b


@njit(cache=True, _nrt=False)
def _free_part(e, u, t0, t_b, k, length, cc, fo):
    """``length`` [m] of cell k from e = v^2/2 under control u (not H), no cap: (e at its end, traction work
    [kJ]). With U_B the air brake's level is its linear build-up at the part's middle time, ``t0`` [s] after the
    application at the part's start (``t_b`` its build-up time; <= 0: full at once)."""
    g_k = cc.grav[k]
    v0 = ms_from_e(max(e, 0.0))
    e1 = e
    f = 0.0
    for _ in range(2):
        e_m = max(0.5 * (e + e1), 0.0)
        vm = kmh_from_e(e_m)
        f = 0.0
        b = 0.0
        if u == U_T:
            f = _interp1(vm, fo.tv, fo.tf) * cc.allowed[k]
        elif u == U_E:
            b = _brake_force(vm, 0.0, k, cc, fo)
        elif u == U_B:
            lvl = 1.0
            if t_b > 0.0:
                t_mid = t0 + length / (v0 + ms_from_e(e_m) + 1e-12)  # the calculator's mid-cell time
                lvl = min(max(t_mid / t_b, 0.0), 1.0)
            b = _brake_force(vm, lvl, k, cc, fo)
        load = davis_kn(vm, fo.ra, fo.rb, fo.rc) + g_k
        e1 = e + length / fo.m * (f - b - load)
    if u == U_T:
        f = _interp1(kmh_from_e(max(0.5 * (e + e1), 0.0)), fo.tv, fo.tf) * cc.allowed[k]
    return e1, f * length


@njit(cache=True, _nrt=False)
def _part(e, u, t0, t_b, k, length, cc, fo, full_hold):
    """As ``_free_part``, and H: the speed held with traction or braking (the electric brake, or with
    ``full_hold`` full braking) where it can be, else full traction (a climb) or that braking at full (a
    descent); from rest H is not possible (e_end -1)."""
    if u != U_H:
        return _free_part(e, u, t0, t_b, k, length, cc, fo)
    if e <= 0.0:
        return -1.0, 0.0
    v_kmh = kmh_from_e(e)
    load0 = davis_kn(v_kmh, fo.ra, fo.rb, fo.rc) + cc.grav[k]
    f_max = _interp1(v_kmh, fo.tv, fo.tf) * cc.allowed[k]
    b_max = _brake_force(v_kmh, 1.0 if full_hold else 0.0, k, cc, fo)
    if load0 > f_max:
        return _free_part(e, U_T, t0, t_b, k, length, cc, fo)
    if -load0 > b_max:
        return _free_part(e, U_B if full_hold else U_E, 0.0, 0.0, k, length, cc, fo)
    return e, max(load0, 0.0) * length


@njit(cache=True, _nrt=False)
def _to_node(e, u, t0, t_b, k, length, cc, fo, full_hold):
    """The last ``length`` [m] of cell k under control u from e, held under the next node's cap the way the
    calculator holds a train there: (e_end, work [kJ], verdict OK / AIR / NO). Where the step would end above the
    cap, the train follows the cap if full braking from e keeps it there (the calculator's braking curves are
    full braking; a tolerance for their finer steps): by the electric brake alone (OK) or only with the air
    brake (AIR). The last cell ends at rest. A step under U_B is AIR (the air brake is on)."""
    n = cc.h.shape[0]
    e1, w = _part(e, u, t0, t_b, k, length, cc, fo, full_hold)
    if e1 < 0.0 and u == U_H:
        return -1.0, 0.0, NO
    air = AIR if u == U_B else OK
    cap = 0.0 if k == n - 1 else cc.e_cap[k + 1]
    if e1 > cap * (1.0 + 1e-9) + 1e-9:
        fall = 0.02 * (e - cap if e > cap else 0.0)
        tol = fall + 1e-3 * max(e, 1.0)
        e_el = e1 if u == U_E else _free_part(e, U_E, 0.0, 0.0, k, length, cc, fo)[0]
        # (the electric brake follows a falling curve within 2 % of its fall, and no more: a tolerance in e
        # would let it hold, cell after cell, a limit it cannot hold on a descent)
        if e_el <= cap + fall + 1e-9 * max(e, 1.0):
            return cap, w, air
        e_f = _free_part(e, U_B, 0.0, 0.0, k, length, cc, fo)[0]
        if e_f <= cap + tol:
            return cap, w, AIR
        return -1.0, 0.0, NO
    if e1 < 0.0:
        return (0.0, w, air) if k == n - 1 else (-1.0, 0.0, NO)
    return e1, w, air


@njit(cache=True, _nrt=False)
def cell(e, u, k, cc, fo, full_hold):
    """Cell k under control u from e (the air brake, with U_B, at full): ``_to_node`` over the whole cell."""
    return _to_node(e, u, 1e9, 0.0, k, cc.h[k], cc, fo, full_hold)


@njit(cache=True, _nrt=False)
def _part_time(e, e1, length):
    """Time [s] of ``length`` [m] from e to e1 (2 length / (v0 + v1)); inf when the train does not move."""
    s = ms_from_e(max(e, 0.0)) + ms_from_e(max(e1, 0.0))
    return 2.0 * length / s if s > 0.0 else np.inf


@njit(cache=True, _nrt=False)
def hold_s(k, cc):
    """The least hold [s] of an application made in cell k: the given one, else its build-up time."""
    return cc.t_hold if cc.t_hold >= 0.0 else cc.t_build[k]


@njit(cache=True, _nrt=False)
def _split(e, u, t0, t_b, k, rest, r, cc, fo):
    """Where in the remaining ``rest`` [m] of cell k the train under control u reaches ``r`` [s] (less than the
    time of the whole rest): (length [m], e there, work [kJ], its time, >= r by at most a rounding: a phase never
    ends early). Constant acceleration first (x = v0 r + a r^2 / 2), then Newton on the part's own time."""
    e1 = _part(e, u, t0, t_b, k, rest, cc, fo, False)[0]
    v0 = ms_from_e(max(e, 0.0))
    a = (e1 - e) / rest  # de/ds = dv/dt
    x = v0 * r + 0.5 * a * r * r
    x = min(max(x, 1e-9 * rest), rest * (1.0 - 1e-12))
    ex = e
    wx = 0.0
    tx = 0.0
    for _ in range(6):
        ex, wx = _part(e, u, t0, t_b, k, x, cc, fo, False)
        tx = _part_time(e, ex, x)
        if tx >= r and tx - r < 1e-9:
            break
        x = min(max(x + (r - tx) * ms_from_e(max(ex, 0.0)) + (1e-10 if tx < r else 0.0), 1e-9 * rest),
                rest * (1.0 - 1e-12))
    return x, ex, wx, tx


@njit(cache=True, _nrt=False)
def run_path(e, k, kind, cc, fo, rec, controls, air, v_nodes, t_nodes, t_start, ev_s, ev_t, ev_k, n_ev):
    """Path ``kind`` (``P_*``) from node k at e: its phases (an application: the air brake building up linearly
    from its instant, with the full electric brake, for the longer of its least hold and its build-up; a
    recharge: H, C or E for the recharge time) one after the other, each ending at its exact time, inside a cell
    if it falls there; the last phase's control on to the next node. Returns (end node, e there, time [s],
    traction work [kJ], events recorded); end node -1 = not possible: the train stops, a cap the phase cannot
    follow (a recharging brake cannot), an application or the recharge before one not over where the zone ends.
    A recharge that reaches the end of the zone ends there (the next zone lies further than a recharge). With
    ``rec`` each cell's control and air state (at its start), node speeds and times (from ``t_start``) and the
    events (position, time, kind) are recorded."""
    n = cc.h.shape[0]
    # the phases: (kind, control) x 2
    if kind == P_A:
        n_ph, ph0, u0, ph1, u1 = 1, PH_APPLY, U_B, PH_APPLY, U_B
    elif kind <= P_AR_E:
        n_ph, ph0, u0, ph1 = 2, PH_APPLY, U_B, PH_REC
        u1 = U_H if kind == P_AR_H else (U_C if kind == P_AR_C else U_E)
    elif kind <= P_R_E:
        n_ph, ph0, ph1, u1 = 1, PH_REC, PH_REC, U_B
        u0 = U_H if kind == P_R_H else (U_C if kind == P_R_C else U_E)
    else:
        n_ph, ph0, u0, ph1, u1 = 2, PH_REC, U_H, PH_APPLY, U_B
    ph = 0
    t_ph = 0.0
    t_b = cc.t_build[k]
    dur = max(hold_s(k, cc), t_b) if ph0 == PH_APPLY else cc.t_rec
    t = 0.0
    w_sum = 0.0
    j = k
    if rec:
        ev_s[n_ev], ev_t[n_ev], ev_k[n_ev] = float(k), t_start, EV_APPLY if ph0 == PH_APPLY else EV_RELEASE
        n_ev += 1
    while True:
        h = cc.h[j]
        x = 0.0
        if rec:
            cur = ph0 if ph == 0 else ph1
            controls[j] = u0 if ph == 0 else u1
            air[j] = AIR_CYCLE if cur == PH_APPLY else AIR_RECHARGE
        while True:
            last = ph >= n_ph
            p_cur = ph0 if (ph == 0) else ph1
            u = u0 if ph == 0 else u1
            if last:
                p_cur = ph1 if n_ph == 2 else ph0
                u = u1 if n_ph == 2 else u0
            rest = h - x
            e1, w, ok = _to_node(e, u, t_ph, t_b, j, rest, cc, fo, False)
            if ok == NO or (p_cur == PH_REC and ok != OK):
                return -1, 0.0, 0.0, 0.0, n_ev
            dt = _part_time(e, e1, rest)
            if not math.isfinite(dt):
                return -1, 0.0, 0.0, 0.0, n_ev
            r = dur - t_ph
            if last or dt <= r:
                e = e1
                t += dt
                t_ph += dt
                w_sum += w
                break
            xs, es, ws, ts = _split(e, u, t_ph, t_b, j, rest, r, cc, fo)
            e = es
            t += ts
            w_sum += ws
            x += xs
            ph += 1
            t_ph = 0.0
            if ph < n_ph:  # the next phase begins here, at its exact time
                if ph1 == PH_APPLY:
                    t_b = cc.t_build[j]
                    dur = max(hold_s(j, cc), t_b)
                else:
                    dur = cc.t_rec
                if rec:  # (where: node j and the fraction x / h of its cell)
                    ev_s[n_ev], ev_t[n_ev] = float(j) + x / h, t_start + t
                    ev_k[n_ev] = EV_APPLY if ph1 == PH_APPLY else EV_RELEASE
                    n_ev += 1
        if rec:
            v_nodes[j + 1] = kmh_from_e(max(e, 0.0))
            t_nodes[j + 1] = t_start + t
        j += 1
        if j == n:
            return j, e, t, w_sum, n_ev
        if ph >= n_ph:
            return j, e, t, w_sum, n_ev
        if cc.zone[j] == 0:
            cur = ph0 if ph == 0 else ph1
            if cur == PH_REC and (n_ph == 1 or ph1 == PH_REC):
                return j, e, t, w_sum, n_ev  # recharging as the zone ends: it ends in the gap
            return -1, 0.0, 0.0, 0.0, n_ev


@njit(cache=True, _nrt=False)
def _cells_at(e, k, cc, fo, se, sw, st, sok):
    """Each single-cell control's step from e at node k (``cell``): e at the cell's end, traction work [kJ], time
    [s] and verdict, into ``se``, ``sw``, ``st``, ``sok`` (NO also where the train would not move)."""
    for u in range(N_U):
        e1, w, ok = cell(e, u, k, cc, fo, cc.relaxed)
        dt = _part_time(e, e1, cc.h[k]) if ok != NO else np.inf
        if not math.isfinite(dt):
            ok = NO
        se[u], sw[u], st[u], sok[u] = e1, w, dt, ok


@njit(cache=True, _nrt=False)
def _paths_at(e, k, s, cc, fo, pj, pe, pt, pw, none_i, none_f):
    """The paths from e at node k in state s (CH: ``P_A`` .. ``P_AR_E``; AF: ``P_R_H`` .. ``P_RA_H``; others -1)
    into ``pj`` (end node, -1: none), ``pe``, ``pt``, ``pw``."""
    for m in range(N_P):
        pj[m] = -1
        if (s == CH and m <= P_AR_E) or (s == AF and m >= P_R_H):
            pj[m], pe[m], pt[m], pw[m], _ = run_path(e, k, m, cc, fo, False, none_i, none_i, none_f, none_f, 0.0,
                                                     none_f, none_f, none_i, 0)


@njit(cache=True)
def cycle_prepare(cc, fo, st_e, st_w, st_t, st_ok, pa_j, pa_e, pa_t, pa_w):
    """What does not depend on the price of time, once per grid: every node's single-cell steps from every grid
    speed (``st_*[k, j, u]``, ``_cells_at``) and, in the zones, its paths from CH and from AF
    (``pa_*[k, j, m]``, ``_paths_at``; -1 elsewhere)."""
    n = cc.h.shape[0]
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    none_i = np.zeros(1, dtype=np.int64)
    none_f = np.zeros(1)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    pj = np.zeros(N_P, dtype=np.int64)
    pe = np.zeros(N_P)
    pt = np.zeros(N_P)
    pw = np.zeros(N_P)
    paths = pa_j.shape[0] == n
    for k in range(n):
        zone = cc.zone[k] != 0 and not cc.relaxed and paths
        for j in range(nv + 1):
            e = e_from_ms(v_grid[j]) if j < nv else max(cc.e_cap[k], 0.0)
            if e > cc.e_cap[k] * (1.0 + 1e-9) + 1e-9:
                for u in range(N_U):
                    st_ok[k, j, u] = NO
                if paths:
                    for m in range(N_P):
                        pa_j[k, j, m] = -1
                continue
            _cells_at(e, k, cc, fo, se, sw, st, sok)
            for u in range(N_U):
                st_e[k, j, u], st_w[k, j, u], st_t[k, j, u], st_ok[k, j, u] = se[u], sw[u], st[u], sok[u]
            if zone:
                _paths_at(e, k, CH, cc, fo, pj, pe, pt, pw, none_i, none_f)
                for m in range(P_R_H):
                    pa_j[k, j, m], pa_e[k, j, m], pa_t[k, j, m], pa_w[k, j, m] = pj[m], pe[m], pt[m], pw[m]
                _paths_at(e, k, AF, cc, fo, pj, pe, pt, pw, none_i, none_f)
                for m in range(P_R_H, N_P):
                    pa_j[k, j, m], pa_e[k, j, m], pa_t[k, j, m], pa_w[k, j, m] = pj[m], pe[m], pt[m], pw[m]
            elif paths:
                for m in range(N_P):
                    pa_j[k, j, m] = -1


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
def _options(k, s, price, V, cc, se, sw, st, sok, pj, pe, pt, pw, best):
    """The best way on from node k in state s at ``price`` [kWh/s], given the single-cell steps (``se``..) and
    the paths (``pj``..) from the train's speed: its cost [kWh]; ``best`` gets (option, state after it) with
    options 0..4 a single cell under control U_T..U_E (U_B: staying applied), N_U + m the path m; -1: none."""
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
        for m in range(N_P):
            jn = pj[m]
            if jn < 0:
                continue
            s1 = _arrive(jn, AF if (m == P_A or m == P_RA_H) else CH, cc)
            c = pw[m] / KJ_PER_KWH + price * pt[m] + look(V, jn, s1, pe[m], cc)
            if c < c_best:
                c_best = c
                best[0] = N_U + m
                best[1] = s1
    return c_best


@njit(cache=True)
def cycle_backward(cc, fo, price, V, st_e, st_w, st_t, st_ok, pa_j, pa_e, pa_t, pa_w):
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
    pj = np.full(N_P, -1, dtype=np.int64)
    pe = np.zeros(N_P)
    pt = np.zeros(N_P)
    pw = np.zeros(N_P)
    nj = np.full(N_P, -1, dtype=np.int64)
    for k in range(n - 1, -1, -1):
        zone = cc.zone[k] != 0 and not cc.relaxed
        for j in range(nv + 1):
            for u in range(N_U):
                se[u], sw[u], st[u], sok[u] = st_e[k, j, u], st_w[k, j, u], st_t[k, j, u], st_ok[k, j, u]
            V[k, NA, j] = _options(k, NA, price, V, cc, se, sw, st, sok, nj, pe, pt, pw, best)
            if zone:
                for m in range(N_P):
                    pj[m], pe[m], pt[m], pw[m] = pa_j[k, j, m], pa_e[k, j, m], pa_t[k, j, m], pa_w[k, j, m]
                    nj[m] = pj[m] if m <= P_AR_E else -1
                V[k, CH, j] = _options(k, CH, price, V, cc, se, sw, st, sok, nj, pe, pt, pw, best)
                for m in range(N_P):
                    nj[m] = pj[m] if m >= P_R_H else -1
                V[k, AF, j] = _options(k, AF, price, V, cc, se, sw, st, sok, nj, pe, pt, pw, best)
                for m in range(N_P):
                    nj[m] = -1
            else:
                V[k, CH, j] = V[k, NA, j]
                V[k, AF, j] = V[k, NA, j]
        if zone and _zone_start(k, cc):
            for j in range(nv + 1):
                V[k, NA, j] = V[k, CH, j]  # (arriving from outside the zone: charged)


@njit(cache=True)
def cycle_forward(cc, fo, price, V, controls, air, v_nodes, t_nodes, ev_s, ev_t, ev_k):
    """The drive from rest: at each node the best option at the train's actual speed and air state, its steps
    and paths run from there (exact times: the drive keeps the rules); per cell its control and air state (at
    its start), per node speed [km/h] and time [s], and the events (``ev_s``: where, as node + the fraction of
    its cell, ``ev_t`` their time [s], ``ev_k`` ``EV_*``). Returns (time [s], traction work [kJ], the number of
    events); time inf when no drive reaches the stop."""
    n = cc.h.shape[0]
    best = np.zeros(2, dtype=np.int64)
    none_i = np.zeros(1, dtype=np.int64)
    none_f = np.zeros(1)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    pj = np.full(N_P, -1, dtype=np.int64)
    pe = np.zeros(N_P)
    pt = np.zeros(N_P)
    pw = np.zeros(N_P)
    e = 0.0
    t = 0.0
    work = 0.0
    n_ev = 0
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
        for m in range(N_P):
            pj[m] = -1
        if cc.zone[k] != 0 and not cc.relaxed and s != NA:
            _paths_at(e, k, s, cc, fo, pj, pe, pt, pw, none_i, none_f)
        c = _options(k, s, price, V, cc, se, sw, st, sok, pj, pe, pt, pw, best)
        o = best[0]
        if o < 0 or not math.isfinite(c) or n_ev > ev_s.shape[0] - 4:
            return np.inf, np.inf, float(n_ev)
        if o < N_U:
            controls[k] = o
            curve = s == CH and sok[o] == AIR
            if cc.relaxed or not (o == U_B or curve):
                air[k] = AIR_OFF
                if s == AF and not cc.relaxed:  # released at this node
                    ev_s[n_ev], ev_t[n_ev], ev_k[n_ev] = float(k), t, EV_RELEASE
                    n_ev += 1
            elif curve:
                air[k] = AIR_CURVE
                ev_s[n_ev], ev_t[n_ev], ev_k[n_ev] = float(k), t, EV_CURVE
                n_ev += 1
            elif k > 0 and air[k - 1] == AIR_CURVE:
                air[k] = AIR_CURVE
            else:
                air[k] = AIR_CYCLE
            t += st[o]
            work += sw[o]
            e = se[o]
            k += 1
            v_nodes[k] = kmh_from_e(max(e, 0.0))
            t_nodes[k] = t
        else:
            jn, e_new, dt, w, n_ev = run_path(e, k, o - N_U, cc, fo, True, controls, air, v_nodes, t_nodes, t, ev_s,
                                              ev_t, ev_k, n_ev)
            t += dt
            work += w
            e = e_new
            k = jn
        s = best[1]
    if s == AF and not cc.relaxed:  # (the stop's application, released at rest)
        ev_s[n_ev], ev_t[n_ev], ev_k[n_ev] = float(n), t, EV_RELEASE
        n_ev += 1
    return t, work, float(n_ev)
