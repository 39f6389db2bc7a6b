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

CH, NA, AF, R0 = 0, 1, 2, 3
"""Air-brake states at a node: released and charged (may apply); released, outside every zone (no air brake
there: the next zone is reached charged); applied, its least hold and build-up over (may release); released and
recharging, R0 + b for b = 0 .. n_rec - 1 with b x the recharge / n_rec [s] since the release (a train in it
cannot apply; its value between two of them is interpolated in time, and taken as none where the one before is:
never earlier than the rules allow)."""
U_T, U_H, U_C, U_B, U_E, U_K = 0, 1, 2, 3, 4, 5
N_U = 6
"""A cell's control: full traction, hold the speed (traction, or braking up to what the state allows, at full
where that cannot hold it), coast, braking with the air brake applied (and the full electric brake), the full
electric brake alone, and the air brake kept on with the electric brake eased (``U_K``: braking between the air
brake alone and it plus the full electric brake, the speed held where that range holds it, as the calculator
holds a kept-on application; the air brake alone where it slows the train even so; full braking where even that
cannot hold). The first four are the calculator's condition codes (T, K, C, B)."""
P_A, P_AR_H, P_AX_H, P_AX_C, P_AX_E, P_AKR_H, P_R_H, P_RA_H, P_KR_H = 0, 1, 2, 3, 4, 5, 6, 7, 8
N_P = 9
N_CH = 6
"""Paths of several cells from a node, made of phases whose ends come at exact times (inside a cell where they
fall there):
- from a charged brake (CH): an application (at the apply speed, where a plan brakes, or where a braking curve
  needs the air brake: one kind, as the calculator holds every application its least hold), braking as the
  calculator brakes an applied train (``_applied_u``: at full above the speed it may be kept on at, else kept on
  with the electric brake eased; either way following the caps, with full braking where it must), held until both
  its least hold and its build-up are over, then on applied to the next node (``P_A``: AF there), or released that
  instant (where it may be released) and, under H, recharged for exactly the
  recharge time, on to the node after (``P_AR_H``: CH there), or released that instant and the rest of that cell
  under H, C or E (``P_AX_*``: recharging at the next node, the time since the release known exactly), or kept on
  and released at the first point of that cell from which the recharge under H is possible, recharged so for
  exactly the recharge time, on to the node after (``P_AKR_H``: CH; ``kept_release_path``);
- from an applied one (AF, where it may be released): released at the node and recharged under H for exactly the
  recharge time, on to the node after (``P_R_H``: CH), or with an application the instant the recharge is over
  (``P_RA_H``: AF); or kept on into the cell and released at the first instant from which that recharge is
  possible (``P_KR_H``: CH; ``kept_release_path``), as the calculator releases at the first chance its look-ahead
  gives: on a descent, where the recharge under the electric brake binds, a release a node late would cost up to
  a cell's fall in speed every cycle."""
RELEASE_ITERATIONS = 14
"""Bisections of a cell for the first instant a kept-on application may be released (``kept_release_path``), and of
the speed for the highest from which a release at a node may recharge (``release_threshold``)."""
OK, AIR, NO = 0, 1, 2
"""A step's verdict: possible as it is (or held at the next node's cap by the electric brake alone), possible
only with the air brake (applied, or following a braking curve), not possible."""
AIR_OFF, AIR_CYCLE, AIR_RECHARGE = 0, 1, 2
"""The drive's air brake at each cell's start: released (charged, or no application ahead in the zone), applied
(with its build-up and least hold, whatever made it: the apply speed, a plan's braking, a braking curve), released
and recharging."""
EV_APPLY, EV_RELEASE, EV_CHARGED = 1, 2, 3
"""The drive's events: an application, a release, a recharge over (where a recharge path's ends, or a recharging
train finds it over at a node)."""
PH_APPLY, PH_REC = 0, 1
APPLIED, RECHARGING, CHARGED = 0, 1, 2
"""What binds the rest of a cell after a path's last event (``_finish``): applied; released and recharging;
released and charged."""


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
    application at the part's start (``t_b`` its build-up time; <= 0: full at once), and the full electric brake;
    with U_K the air brake alone at that level (the electric brake eased to nothing)."""
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
        elif u == U_B or u == U_K:
            lvl = 1.0
            if t_b > 0.0:
                t_mid = t0 + length / (v0 + ms_from_e(e_m) + 1e-12)  # the calculator's mid-cell time
                lvl = min(max(t_mid / t_b, 0.0), 1.0)
            b = _brake_force(vm, lvl, k, cc, fo) if u == U_B else lvl * _interp1(vm, fo.av, fo.af)
        load = davis_kn(vm, fo.ra, fo.rb, fo.rc) + g_k
        e1 = e + length / fo.m * (f - b - load)
    if u == U_T:
        f = _interp1(kmh_from_e(max(0.5 * (e + e1), 0.0)), fo.tv, fo.tf) * cc.allowed[k]
    return e1, f * length


@njit(cache=True, _nrt=False)
def _part(e, u, t0, t_b, k, length, cc, fo, full_hold):
    """As ``_free_part``, and H: the speed held with traction or braking (the electric brake, or with
    ``full_hold`` full braking) where it can be, else full traction (a climb) or that braking at full (a
    descent); and U_K, the calculator's kept-on application: the speed held by braking between the air brake
    (at its level at the part's middle time, ``t0`` [s] after the application; ``t_b`` the build-up) and it plus
    the full electric brake where that range holds it, else the air brake alone (it slows the train even so) or
    both at full (they cannot hold it). From rest neither is possible (e_end -1)."""
    if u != U_H and u != U_K:
        return _free_part(e, u, t0, t_b, k, length, cc, fo)
    if e <= 0.0:
        return -1.0, 0.0
    v_kmh = kmh_from_e(e)
    load0 = davis_kn(v_kmh, fo.ra, fo.rb, fo.rc) + cc.grav[k]
    if u == U_K:
        lvl = 1.0
        if t_b > 0.0:  # (held: the part's middle time at this speed)
            lvl = min(max((t0 + 0.5 * length / ms_from_e(e)) / t_b, 0.0), 1.0)
        b_air = lvl * _interp1(v_kmh, fo.av, fo.af)
        if -load0 < b_air:
            return _free_part(e, U_K, t0, t_b, k, length, cc, fo)
        if -load0 > b_air + _brake_force(v_kmh, 0.0, k, cc, fo):
            return _free_part(e, U_B, t0, t_b, k, length, cc, fo)
        return e, 0.0
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
    brake (AIR). The last cell ends at rest. A step under U_B or U_K is AIR (the air brake is on)."""
    n = cc.h.shape[0]
    e1, w = _part(e, u, t0, t_b, k, length, cc, fo, full_hold)
    if e1 < 0.0 and u == U_H:
        return -1.0, 0.0, NO
    air = AIR if (u == U_B or u == U_K) else OK
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
def _split_speed(e, u, k, rest, e_to, cc, fo):
    """Where in the remaining ``rest`` [m] of cell k the train under control u (no air brake) reaches e_to (between
    e and the rest's end): (length [m], work [kJ], its time [s]); the speed there is e_to. e linear in distance
    first, then Newton on the part's own e."""
    e1 = _part(e, u, 0.0, 0.0, k, rest, cc, fo, False)[0]
    x = rest * (e_to - e) / (e1 - e) if e1 != e else rest
    x = min(max(x, 1e-9 * rest), rest)
    for _ in range(4):
        ex = _part(e, u, 0.0, 0.0, k, x, cc, fo, False)[0]
        if abs(ex - e_to) <= 1e-9 * max(e_to, 1.0):
            break
        slope = (ex - e) / x
        if slope == 0.0:
            break
        x = min(max(x + (e_to - ex) / slope, 1e-9 * rest), rest)
    ex, wx = _part(e, u, 0.0, 0.0, k, x, cc, fo, False)
    return x, wx, _part_time(e, ex, x)


@njit(cache=True, _nrt=False)
def _tab_cell(e, j, u, cc, tb):
    """Cell j under control u from e read off the one-cell tables (``cycle_prepare``), interpolated in speed
    between the two grid speeds around e: (e at its end, work [kJ], time [s], verdict); verdict -1 where the
    tables cannot say (no tables, above the grid, the two grid speeds' verdicts differ): step it exactly."""
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    dv = v_grid[1] - v_grid[0]
    v = ms_from_e(max(e, 0.0))
    top = tb.top[j]
    i0 = int(v / dv)
    if i0 < top:
        i1 = i0 + 1
        w = (v - i0 * dv) / dv
    else:  # between the last grid speed below the cap and the cap (the last column)
        v_cap = ms_from_e(max(cc.e_cap[j], 0.0))
        span = v_cap - top * dv
        if v > v_cap * (1.0 + 1e-9) + 1e-9 or span <= 1e-12:
            return 0.0, 0.0, 0.0, -1
        i0, i1 = top, nv
        w = min(max((v - top * dv) / span, 0.0), 1.0)
    ok = tb.sok[j, i0, u]
    if tb.sok[j, i1, u] != ok:
        return 0.0, 0.0, 0.0, -1
    if ok == NO:
        return 0.0, 0.0, 0.0, NO
    return (tb.se[j, i0, u] + w * (tb.se[j, i1, u] - tb.se[j, i0, u]),
            tb.sw[j, i0, u] + w * (tb.sw[j, i1, u] - tb.sw[j, i0, u]),
            tb.st[j, i0, u] + w * (tb.st[j, i1, u] - tb.st[j, i0, u]), ok)


@njit(cache=True, _nrt=False)
def _applied_u(e, j, u, cc):
    """The control an applied train at e in cell j is under when asked for ``u``: the calculator brakes at full
    (U_B) an application above the speed at which it may be kept on (``e_keep``: its release speed at the least
    release margin), and keeps it on with the electric brake eased (U_K) at or below it."""
    if u == U_K and e > cc.e_keep[j] * (1.0 + 1e-9):
        return U_B
    return u


@njit(cache=True, _nrt=False)
def _keep_point(e, t0, t_b, k, rest, cc, fo):
    """Where in the remaining ``rest`` [m] of cell k full braking (U_B, the air brake ``t0`` [s] into its build-up of
    ``t_b``) from e brings the train down to ``e_keep`` (bisection, ``RELEASE_ITERATIONS``); 0 where it does not
    within the rest."""
    if _part(e, U_B, t0, t_b, k, rest, cc, fo, False)[0] >= cc.e_keep[k]:
        return 0.0
    lo, hi = 0.0, rest
    for _ in range(RELEASE_ITERATIONS):
        mid = 0.5 * (lo + hi)
        if _part(e, U_B, t0, t_b, k, mid, cc, fo, False)[0] > cc.e_keep[k]:
            lo = mid
        else:
            hi = mid
    return hi


@njit(cache=True, _nrt=False)
def _phase(e, j, x, u, dur, t_b, is_rec, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes, t_start, part):
    """A phase of a path: control u from ``x`` [m] into cell j at e until it has lasted ``dur`` [s] (an
    application, u = U_K: braking as the calculator brakes an applied train, ``_applied_u``: at full down to the
    keep speed, kept on from the point it is reached; the air brake building up from the phase's start over
    ``t_b``; ``is_rec``: a recharge, whose
    caps only the electric brake may follow). Returns (j, x, e, time [s], work [kJ], status) where it ends: status
    0 = inside cell j, x metres in; 1 = the zone ended first, at node j (x = 0); 2 = the stop; -1 = not possible.
    With ``use_tab`` whole cells are read off the one-cell tables where they can be (``_tab_cell``: a recharge, an
    application whose build-up is over), else stepped; ``rec``: recorded from ``t_start`` [s]. Where it ends inside
    a cell, ``part`` gets the start of its part of that cell: (x [m], e, time, work)."""
    n = cc.h.shape[0]
    t = 0.0
    w_sum = 0.0
    while True:
        h = cc.h[j]
        ue = _applied_u(e, j, u, cc)
        if rec and x == 0.0:
            controls[j] = ue
            air[j] = AIR_RECHARGE if is_rec else AIR_CYCLE
        rest = h - x
        ok = -1
        if use_tab and x == 0.0 and (is_rec or t >= t_b):
            e1, w, dt, ok = _tab_cell(e, j, ue, cc, tb)
        if ok < 0:
            e1, w, ok = _to_node(e, ue, t, t_b, j, rest, cc, fo, False)
            dt = _part_time(e, e1, rest) if ok != NO else np.inf
        if ok == NO or (is_rec and ok != OK) or not math.isfinite(dt):
            return j, x, e, t, w_sum, -1
        r = dur - t
        if ue != u and e1 < cc.e_keep[j]:  # braking at full down to the keep speed, reached inside the cell:
            xk = _keep_point(e, t, t_b, j, rest, cc, fo)  # kept on from there (the rule, not a cell later)
            if xk > 0.0:
                ek, wk = _part(e, ue, t, t_b, j, xk, cc, fo, False)
                tk = _part_time(e, ek, xk)
                if tk < r:
                    e, x, t, w_sum = ek, x + xk, t + tk, w_sum + wk
                    continue
        if dt > r:
            xs, es, ws, ts = _split(e, ue, t, t_b, j, rest, r, cc, fo)
            if is_rec and es > cc.e_rec[j] * (1.0 + 1e-9):
                return j, x, e, t, w_sum, -1  # (recharging near the apply speed: the calculator would not release)
            # (where it ends, and the part of the cell it ends in: from there a path that goes on under the same
            # control steps the whole part, as a drive's record has it, not two pieces of it)
            part[0], part[1], part[2], part[3] = x, e, t, w_sum
            return j, x + xs, es, t + ts, w_sum + ws, 0
        if is_rec and e1 > cc.e_rec[j] * (1.0 + 1e-9):
            return j, x, e, t, w_sum, -1
        e = e1
        t += dt
        w_sum += w
        if rec:
            v_nodes[j + 1] = kmh_from_e(max(e, 0.0))
            t_nodes[j + 1] = t_start + t
        j += 1
        x = 0.0
        if j == n:
            return j, x, e, t, w_sum, 2
        if cc.zone[j] == 0:
            return j, x, e, t, w_sum, 1
        if is_rec and e >= cc.e_rec[j]:  # (near the apply speed before the recharge is over)
            return j, x, e, t, w_sum, -1


@njit(cache=True, _nrt=False)
def _descending(e, k, cc, fo):
    """Whether resistance plus gravity at e in cell k is negative (a descent at that speed): while the brake
    recharges there the calculator holds the speed with the electric brake (H), whatever the plan's condition."""
    return davis_kn(kmh_from_e(max(e, 0.0)), fo.ra, fo.rb, fo.rc) + cc.grav[k] < 0.0


@njit(cache=True, _nrt=False)
def _finish(e, j, x, u, t0, t_b, mode, cc, fo, tb, use_tab, rec, v_nodes, t_nodes, t_start):
    """The rest of cell j from ``x`` [m] under control u to its node: applied (``mode`` ``APPLIED``: an application
    ``t0`` [s] old, U_K as ``_applied_u`` has it), released and recharging (``RECHARGING``: without the air brake,
    under ``e_rec``) or released and charged (``CHARGED``: without the air brake, not past the apply speed).
    Returns (e there, time [s], work [kJ], ok False where not possible)."""
    u = _applied_u(e, j, u, cc)
    rest = cc.h[j] - x
    ok = -1
    if use_tab and x == 0.0 and (mode != APPLIED or t0 >= t_b):
        e1, w, dt, ok = _tab_cell(e, j, u, cc, tb)
    if ok < 0:
        e1, w, ok = _to_node(e, u, t0, t_b, j, rest, cc, fo, False)
        dt = _part_time(e, e1, rest) if ok != NO else np.inf
    bound = cc.e_rec[j] if mode == RECHARGING else cc.e_app[j]
    if ok == NO or (mode != APPLIED and (ok != OK or e1 > bound * (1.0 + 1e-9))) or not math.isfinite(dt):
        return e, 0.0, 0.0, False
    if rec:
        v_nodes[j + 1] = kmh_from_e(max(e1, 0.0))
        t_nodes[j + 1] = t_start + dt
    return e1, dt, w, True


@njit(cache=True, _nrt=False)
def _event(rec, ev, ev_k, n_ev, j, x, t, e, kind, cc):
    """Record an event (``rec``) of ``kind`` at x [m] into cell j, time t [s], e = v^2/2: ``ev[n_ev]`` = (node +
    fraction of its cell, time [s], speed [km/h]). Returns the events recorded."""
    if rec:
        ev[n_ev, 0] = float(j) + (x / cc.h[j] if j < cc.h.shape[0] else 0.0)
        ev[n_ev, 1] = t
        ev[n_ev, 2] = kmh_from_e(max(e, 0.0))
        ev_k[n_ev] = kind
        return n_ev + 1
    return n_ev



@njit(cache=True, _nrt=False)
def _recharge_on(e, j, x, u, t0, w0, m, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes, t_start, part, ev,
                 ev_k, n_ev, pj, pe, pt, pw):
    """Path m after a release at e, x [m] into cell j, t0 [s] and w0 [kWh] into the path: recharged under u for
    exactly the recharge time, then on under u to the node after (charged there; where the zone or the route ends
    during the recharge, there). Its end in ``pj``.. [m]; returns the events recorded."""
    j2, x2, er, tr, wr, st2 = _phase(e, j, x, u, cc.t_rec, 0.0, True, cc, fo, tb, use_tab, rec, controls, air,
                                     v_nodes, t_nodes, t_start + t0, part)
    if st2 < 0:
        return n_ev
    if st2 > 0:  # the zone, or the route, ended during the recharge
        pj[m], pe[m], pt[m], pw[m] = j2, er, t0 + tr, w0 + wr
        return n_ev
    n_ev = _event(rec, ev, ev_k, n_ev, j2, x2, t_start + t0 + tr, er, EV_CHARGED, cc)
    e1, dt, w, ok = _finish(er, j2, x2, u, 0.0, 0.0, CHARGED, cc, fo, tb, use_tab, rec, v_nodes, t_nodes,
                            t_start + t0 + tr)
    if ok:
        pj[m], pe[m], pt[m], pw[m] = j2 + 1, e1, t0 + tr + dt, w0 + wr + w
    return n_ev

@njit(cache=True, _nrt=False)
def _rec_u(m):
    """The control of path m after its release."""
    if m == P_AX_C:
        return U_C
    if m == P_AX_E:
        return U_E
    return U_H


@njit(cache=True, _nrt=False)
def apply_paths(e, k, first, last, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes, t_start, ev, ev_k,
                n_ev, pj, pe, pt, pw, pq, part):
    """The paths ``first`` .. ``last`` of ``P_A`` .. ``P_AX_E`` from a charged brake at node k at e, their
    application stepped once: the air brake from the node, its force building up linearly over the cell's build-up
    time (the calculator's), braking as the calculator brakes an applied train (``_applied_u``: at full above the
    speed it may be kept on at, kept on with the electric brake eased at or below it), until both its least hold
    and its build-up are over; then as the path says (``P_A``, ``P_AR_H``, ``P_AX_*``; a release only at or below
    that speed, as the calculator releases). Into ``pj`` (end node, -1: none), ``pe``,
    ``pt`` [s], ``pw`` [kJ] and ``pq`` (the time since the release at the end node [s], ``P_AX_*``); returns the
    events recorded (``rec``: one path). ``part``: a buffer of 4 (``_phase``)."""
    n = cc.h.shape[0]
    for m in range(first, last + 1):
        pj[m] = -1
        pq[m] = 0.0
    t_b = cc.t_build[k]
    dur = max(hold_s(k, cc), t_b)
    x0 = 0.0
    t0 = 0.0
    w0 = 0.0
    if e < cc.e_app[k]:  # where holding (H) would reach the apply speed inside this cell, applied there
        e1, w1, ok1 = _to_node(e, U_H, 0.0, 0.0, k, cc.h[k], cc, fo, False)
        if ok1 == OK and e1 > cc.e_app[k]:
            x0, w0, t0 = _split_speed(e, U_H, k, cc.h[k], cc.e_app[k], cc, fo)
            e = cc.e_app[k]
            if rec:
                controls[k] = U_H
                air[k] = AIR_OFF
    n_ev = _event(rec, ev, ev_k, n_ev, k, x0, t_start + t0, e, EV_APPLY, cc)
    j, x, ea, ta, wa, st = _phase(e, k, x0, U_K, dur, t_b, False, cc, fo, tb, use_tab, rec, controls, air, v_nodes,
                                  t_nodes, t_start + t0, part)
    ta += t0
    wa += w0
    if st < 0 or st == 1:
        return n_ev
    if st == 2:  # (the stop, braking)
        for m in range(first, last + 1):
            pj[m], pe[m], pt[m], pw[m] = n, ea, ta, wa
        return n_ev
    for m in range(first, last + 1):
        if m == P_AKR_H:  # kept on past the hold, released at the first chance in the rest of its cell
            n_ev = kept_release_path(ea, j, x, P_AKR_H, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes,
                                     t_start + ta, ev, ev_k, n_ev, pj, pe, pt, pw, part)
            if pj[m] >= 0:
                pt[m] += ta
                pw[m] += wa
            continue
        if m == P_A:  # (braking on: the part of the cell where the hold ends stepped whole)
            xp, ep, tp, wp = part[0], part[1], part[2], part[3]
            e1, dt, w, ok = _finish(ep, j, xp, U_K, tp, t_b, APPLIED, cc, fo, tb, use_tab, rec, v_nodes, t_nodes,
                                    t_start + t0 + tp)
            if ok:
                pj[m], pe[m], pt[m], pw[m] = j + 1, e1, t0 + tp + dt, w0 + wp + w
            continue
        if ea > cc.e_keep[j] * (1.0 + 1e-9) or ea >= cc.e_rec[j]:
            continue  # (above its release speed, or near the apply speed, the calculator keeps an application on)
        u = _rec_u(m)
        if u != U_H and _descending(ea, j, cc, fo):
            continue  # (recharging on a descent the calculator holds the speed electrically: H)
        n_ev = _event(rec, ev, ev_k, n_ev, j, x, t_start + ta, ea, EV_RELEASE, cc)
        if rec:
            controls[j] = u  # (the cell of the release: its control after it)
        if m != P_AR_H:  # released, the rest of the cell under u: recharging at the next node
            e1, dt, w, ok = _finish(ea, j, x, u, 0.0, 0.0, RECHARGING, cc, fo, tb, use_tab, rec, v_nodes, t_nodes,
                                    t_start + ta)
            if ok:
                pj[m], pe[m], pt[m], pw[m], pq[m] = j + 1, e1, ta + dt, wa + w, dt
            continue
        n_ev = _recharge_on(ea, j, x, u, ta, wa, m, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes,
                            t_start, part, ev, ev_k, n_ev, pj, pe, pt, pw)
    return n_ev


@njit(cache=True, _nrt=False)
def release_paths(e, k, first, last, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes, t_start, ev, ev_k,
                  n_ev, pj, pe, pt, pw, part):
    """``P_R_H`` and/or ``P_RA_H`` (``first`` .. ``last``) from an applied brake at node k at e: released at the node
    (where it may be: at or below ``e_keep``), recharged under H for exactly the recharge time, then on under H to the
    node after (CH there; NA where the zone ends first), or an application the instant the recharge is over (braking
    as ``apply_paths``' does), held until its least hold and build-up are over, on to the node after (AF there).
    Into ``pj``.. as ``apply_paths``; ``rec``: one path recorded."""
    n = cc.h.shape[0]
    for m in range(first, last + 1):
        pj[m] = -1
    if e >= cc.e_rec[k] or e > cc.e_keep[k] * (1.0 + 1e-9):
        return n_ev  # (above its release speed, or near the apply speed, the calculator keeps an application on)
    n_ev = _event(rec, ev, ev_k, n_ev, k, 0.0, t_start, e, EV_RELEASE, cc)
    j2, x2, er, tr, wr, st2 = _phase(e, k, 0.0, U_H, cc.t_rec, 0.0, True, cc, fo, tb, use_tab, rec, controls, air,
                                     v_nodes, t_nodes, t_start, part)
    if st2 < 0:
        return n_ev
    if st2 > 0:
        if first == P_R_H:
            pj[P_R_H], pe[P_R_H], pt[P_R_H], pw[P_R_H] = j2, er, tr, wr
        return n_ev
    if first == P_R_H:
        n_ev = _event(rec and last == P_R_H, ev, ev_k, n_ev, j2, x2, t_start + tr, er, EV_CHARGED, cc)
        e1, dt, w, ok = _finish(er, j2, x2, U_H, 0.0, 0.0, CHARGED, cc, fo, tb, use_tab, rec and last == P_R_H, v_nodes,
                                t_nodes, t_start + tr)
        if ok:
            pj[P_R_H], pe[P_R_H], pt[P_R_H], pw[P_R_H] = j2 + 1, e1, tr + dt, wr + w
    if last == P_RA_H:  # an application the instant the recharge is over
        n_ev = _event(rec, ev, ev_k, n_ev, j2, x2, t_start + tr, er, EV_APPLY, cc)
        t_b = cc.t_build[j2]
        dur = max(hold_s(j2, cc), t_b)
        j3, x3, ea, ta, wa, st3 = _phase(er, j2, x2, U_K, dur, t_b, False, cc, fo, tb, use_tab, rec, controls, air,
                                         v_nodes, t_nodes, t_start + tr, part)
        if st3 == 2:
            pj[P_RA_H], pe[P_RA_H], pt[P_RA_H], pw[P_RA_H] = n, ea, tr + ta, wr + wa
        elif st3 == 0:  # (braking on: the part of the cell where the hold ends stepped whole)
            xp, ep, tp, wp = part[0], part[1], part[2], part[3]
            e1, dt, w, ok = _finish(ep, j3, xp, U_K, tp, t_b, APPLIED, cc, fo, tb, use_tab, rec, v_nodes, t_nodes,
                                    t_start + tr + tp)
            if ok:
                pj[P_RA_H], pe[P_RA_H], pt[P_RA_H], pw[P_RA_H] = j3 + 1, e1, tr + tp + dt, wr + wp + w
    return n_ev


@njit(cache=True, _nrt=False)
def _recharges(e, k, x, cc, fo, tb, use_tab, ints, floats, part):
    """Whether a train released at e, ``x`` [m] into cell k, can be held by the electric brake (H) for exactly the
    recharge time (``_phase``, not recorded: ``ints``, ``floats`` any arrays; never near the apply speed, every cap
    followed without the air brake)."""
    if e >= cc.e_rec[k] or e > cc.e_keep[k] * (1.0 + 1e-9):
        return False
    return _phase(e, k, x, U_H, cc.t_rec, 0.0, True, cc, fo, tb, use_tab, False, ints, ints, floats, floats, 0.0,
                  part)[5] >= 0


@njit(cache=True, _nrt=False)
def release_threshold(k, cc, fo, tb, ints, floats, part):
    """The highest e = v^2/2 at node k from which an applied train may be released there and recharge under the
    electric brake (``_recharges``, bisected in speed, ``RELEASE_ITERATIONS``); -1 where none may (not even from a
    walking pace). On a descent the electric brake alone cannot hold, the lower the speed the longer the train
    takes to come near the apply speed."""
    hi = min(min(cc.e_rec[k], cc.e_keep[k]), max(cc.e_cap[k], 0.0))
    if hi > 0.0 and _recharges(hi * (1.0 - 1e-9), k, 0.0, cc, fo, tb, True, ints, floats, part):
        return hi * (1.0 - 1e-9)
    lo = e_from_ms(1.0)
    if lo >= hi or not _recharges(lo, k, 0.0, cc, fo, tb, True, ints, floats, part):
        return -1.0
    for _ in range(RELEASE_ITERATIONS):
        mid = 0.5 * (lo + hi)
        if _recharges(mid, k, 0.0, cc, fo, tb, True, ints, floats, part):
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, _nrt=False)
def kept_release_path(e, k, x0, m, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes, t_start, ev, ev_k,
                      n_ev, pj, pe, pt, pw, part):
    """Path m (``P_KR_H``, or ``P_AKR_H``'s end) from an applied brake, its build-up over, ``x0`` [m] into cell k at e
    above the release threshold there (``tb.ethr`` at the cell's two nodes, interpolated; at or below it, a release
    at once is ``P_R_H``'s, ``P_AR_H``'s): kept on as the calculator keeps it (``_applied_u``, decided at ``x0``) to
    the first point of the cell where its speed falls to the threshold (bisected), released there where the
    recharge under H then holds exactly (``_recharges``; else a little further on, twice), recharged so for exactly
    the recharge time and on under H to the node after (CH there; NA where the zone ends first). Into ``pj``.. as
    ``apply_paths``, time and work from ``x0``; ``rec``: recorded from ``t_start`` [s]."""
    n = cc.h.shape[0]
    pj[m] = -1
    if k + 1 >= n or cc.zone[k + 1] == 0 or cc.relaxed:
        return n_ev
    thr0, thr1 = tb.ethr[k], tb.ethr[k + 1]
    h = cc.h[k]
    if thr0 < 0.0 or thr1 < 0.0 or e <= thr0 + (x0 / h) * (thr1 - thr0):
        return n_ev
    u = _applied_u(e, k, U_K, cc)
    if _part(e, u, 1e9, 0.0, k, h - x0, cc, fo, False)[0] > thr1:
        return n_ev  # (not even at the node after)
    lo, hi = x0, h
    for _ in range(RELEASE_ITERATIONS):
        mid = 0.5 * (lo + hi)
        if _part(e, u, 1e9, 0.0, k, mid - x0, cc, fo, False)[0] <= thr0 + (mid / h) * (thr1 - thr0):
            hi = mid
        else:
            lo = mid
    found = False
    for _ in range(3):
        if _recharges(_part(e, u, 1e9, 0.0, k, hi - x0, cc, fo, False)[0], k, hi, cc, fo, tb, use_tab, controls,
                      v_nodes, part):
            found = True
            break
        hi += 0.5 * (h - hi)
    if not found:
        return n_ev
    x = hi
    ex, wx = _part(e, u, 1e9, 0.0, k, x - x0, cc, fo, False)
    tx = _part_time(e, ex, x - x0)
    if rec and x0 == 0.0:
        controls[k] = u
        air[k] = AIR_CYCLE
    n_ev = _event(rec, ev, ev_k, n_ev, k, x, t_start + tx, ex, EV_RELEASE, cc)
    return _recharge_on(ex, k, x, U_H, tx, wx, m, cc, fo, tb, use_tab, rec, controls, air, v_nodes, t_nodes, t_start,
                        part, ev, ev_k, n_ev, pj, pe, pt, pw)


@njit(cache=True, _nrt=False)
def run_path(e, k, m, cc, fo, tb, controls, air, v_nodes, t_nodes, t_start, ev, ev_k, n_ev, pj, pe, pt, pw, pq,
             part):
    """Path m alone from node k at e, stepped exactly and recorded (the forward pass): its end in ``pj``.. [m];
    returns the events recorded."""
    if m < N_CH:
        return apply_paths(e, k, m, m, cc, fo, tb, False, True, controls, air, v_nodes, t_nodes, t_start, ev, ev_k,
                           n_ev, pj, pe, pt, pw, pq, part)
    pq[m] = 0.0
    if m == P_KR_H:
        return kept_release_path(e, k, 0.0, P_KR_H, cc, fo, tb, False, True, controls, air, v_nodes, t_nodes, t_start,
                                 ev, ev_k, n_ev, pj, pe, pt, pw, part)
    return release_paths(e, k, m, m, cc, fo, tb, False, True, controls, air, v_nodes, t_nodes, t_start, ev, ev_k,
                         n_ev, pj, pe, pt, pw, part)


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
def _paths_at(e, k, s, cc, fo, tb, use_tab, pj, pe, pt, pw, pq, none_i, none_f, none_f2, part):
    """The paths from e at node k in state s (CH: ``P_A`` .. ``P_AX_E``; AF: ``P_R_H``, ``P_RA_H``, ``P_KR_H``;
    others -1)
    into ``pj`` (end node, -1: none), ``pe``, ``pt``, ``pw``, ``pq``; ``use_tab``: whole cells off the tables."""
    for m in range(N_P):
        pj[m] = -1
        pq[m] = 0.0
    if s == CH:
        apply_paths(e, k, P_A, N_CH - 1, cc, fo, tb, use_tab, False, none_i, none_i, none_f, none_f, 0.0, none_f2,
                    none_i, 0, pj, pe, pt, pw, pq, part)
    elif s == AF:
        release_paths(e, k, P_R_H, P_RA_H, cc, fo, tb, use_tab, False, none_i, none_i, none_f, none_f, 0.0, none_f2,
                      none_i, 0, pj, pe, pt, pw, part)
        kept_release_path(e, k, 0.0, P_KR_H, cc, fo, tb, use_tab, False, none_i, none_i, none_f, none_f, 0.0, none_f2,
                          none_i, 0, pj, pe, pt, pw, part)


@njit(cache=True, _nrt=False)
def _grid_e(k, j, cc):
    """e = v^2/2 of grid speed j at node k (j = len(v_grid): the node's cap)."""
    nv = cc.v_grid.shape[0]
    return e_from_ms(cc.v_grid[j]) if j < nv else max(cc.e_cap[k], 0.0)


@njit(cache=True, _nrt=False)
def _land(e1, k1, cc):
    """Where e1 lands on node k1's grid: (lower grid index, -1 above the cap; the upper one's weight, negative
    where the state lies above k1's stall boundary: there a lower grid point below it does not count)."""
    n = cc.h.shape[0]
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    if k1 == n:
        return (0, 0.0) if e1 <= 1e-9 else (-1, 0.0)
    v1 = ms_from_e(max(e1, 0.0))
    i0, i1, w = _bracket(v1, v_grid[1] - v_grid[0], nv, ms_from_e(max(cc.e_cap[k1], 0.0)))
    if i0 < 0:
        return -1, 0.0
    low = cc.e_low[k1]
    if 0.0 < w < 1.0 and math.isfinite(low) and v1 >= ms_from_e(low):
        w = -w
    return i0, w


@njit(cache=True)
def cycle_prepare(cc, fo, tb):
    """What does not depend on the price of time, once per grid, into ``tb`` (``records.CycleTables``): every
    node's single-cell steps from every grid speed (``_cells_at``), then in the zones each node's release threshold
    (``release_threshold``) and its paths from CH and from AF (``_paths_at``, whole cells read off the first
    tables), and where each lands on its node's grid."""
    n = cc.h.shape[0]
    v_grid = cc.v_grid
    nv = v_grid.shape[0]
    dv = v_grid[1] - v_grid[0]
    none_i = np.zeros(1, dtype=np.int64)
    none_f = np.zeros(1)
    none_f2 = np.zeros((1, 3))
    part = np.zeros(4)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    pj = np.zeros(N_P, dtype=np.int64)
    pe = np.zeros(N_P)
    pt = np.zeros(N_P)
    pw = np.zeros(N_P)
    pq = np.zeros(N_P)
    for k in range(n + 1):
        v_cap = ms_from_e(max(cc.e_cap[k], 0.0))
        top = min(int(v_cap / dv), nv - 1)
        while top > 0 and top * dv > v_cap:
            top -= 1
        tb.top[k] = top
    for k in range(n):
        for j in range(nv + 1):
            e = _grid_e(k, j, cc)
            if e > cc.e_cap[k] * (1.0 + 1e-9) + 1e-9:
                for u in range(N_U):
                    tb.sok[k, j, u] = NO
                continue
            _cells_at(e, k, cc, fo, se, sw, st, sok)
            for u in range(N_U):
                tb.se[k, j, u], tb.sw[k, j, u], tb.st[k, j, u], tb.sok[k, j, u] = se[u], sw[u], st[u], sok[u]
                i0, wx = _land(se[u], k + 1, cc) if sok[u] != NO else (-1, 0.0)
                tb.si[k, j, u], tb.sx[k, j, u] = i0, wx
    for k in range(n + 1):  # (the release thresholds first: a kept-on release path reads its cell's two)
        tb.ethr[k] = release_threshold(k, cc, fo, tb, none_i, none_f, part) if k < n and tb.zmap[k] >= 0 else -1.0
    for k in range(n):
        z = tb.zmap[k]
        if z < 0:
            continue
        for j in range(nv + 1):
            e = _grid_e(k, j, cc)
            if e > cc.e_cap[k] * (1.0 + 1e-9) + 1e-9:
                for m in range(N_P):
                    tb.pj[z, j, m] = -1
                continue
            _paths_at(e, k, CH, cc, fo, tb, True, pj, pe, pt, pw, pq, none_i, none_f, none_f2, part)
            for m in range(N_CH):
                tb.pj[z, j, m], tb.pe[z, j, m], tb.pt[z, j, m], tb.pw[z, j, m], tb.pq[z, j, m] = (pj[m], pe[m], pt[m],
                                                                                                 pw[m], pq[m])
            _paths_at(e, k, AF, cc, fo, tb, True, pj, pe, pt, pw, pq, none_i, none_f, none_f2, part)
            for m in range(N_CH, N_P):
                tb.pj[z, j, m], tb.pe[z, j, m], tb.pt[z, j, m], tb.pw[z, j, m], tb.pq[z, j, m] = (pj[m], pe[m], pt[m],
                                                                                                 pw[m], 0.0)
            for m in range(N_P):
                i0, wx = _land(tb.pe[z, j, m], tb.pj[z, j, m], cc) if tb.pj[z, j, m] >= 0 else (-1, 0.0)
                tb.pi[z, j, m], tb.px[z, j, m] = i0, wx


@njit(cache=True, _nrt=False)
def _grid_pair(V, k1, s, i0, wx, tb):
    """The cost-to-go at node k1 in state s at the two grid speeds around where a state lands (``_land``: i0 >= 0,
    wx), and the weight of the upper: (lower, upper, weight); the upper is the node's cap after its last grid point
    below it, and the lower itself where the state lands on it (weight 0)."""
    a = V[k1, s, i0]
    w = abs(wx)
    if w <= 0.0:
        return a, a, 0.0
    i1 = V.shape[2] - 1 if i0 == tb.top[k1] else i0 + 1
    return a, V[k1, s, i1], w


@njit(cache=True, _nrt=False)
def _value(V, k1, s, i0, wx, tb):
    """The cost-to-go at node k1 in state s where a state lands (``_land``: i0, wx): interpolated in speed between
    grid point i0 and the next (the node's cap after its last grid point below it)."""
    if i0 < 0:
        return np.inf
    a, z, w = _grid_pair(V, k1, s, i0, wx, tb)
    if wx < 0.0 and math.isinf(a) and not math.isinf(z):
        return z
    return _blend(a, z, w)


@njit(cache=True, _nrt=False)
def _deadline(k1, i0, wx, tb):
    """The recharge's deadline (``tb.dl``) at node k1 where a state lands (``_land``: i0, wx): the later of the two
    grid speeds' around it (the earlier where it lies above the stall boundary and the lower one has none), so that
    a drive never counts on a release the exact speed would not allow. (On a descent it rises by the time the train
    takes to gain a speed step, 11 s per 0.5 km/h on 12 per mille: a release there is found to the instant by
    ``kept_release_path`` instead.)"""
    if i0 < 0:
        return np.inf
    d0 = tb.dl[k1, i0]
    w = abs(wx)
    if w <= 0.0:
        return d0
    d1 = tb.dl[k1, tb.dl.shape[1] - 1 if i0 == tb.top[k1] else i0 + 1]
    if wx < 0.0 and math.isinf(d0):
        return d1
    return max(d0, d1)


@njit(cache=True, _nrt=False)
def _value_soft(V, k1, s, i0, wx, tb):
    """As ``_value``, but where one of the two grid speeds has no value, the other's: for a recharging train whose
    deadline says it goes on, a neighbour that cannot (a speed step faster, too near the apply speed) says nothing
    of it."""
    if i0 < 0:
        return np.inf
    a, z, w = _grid_pair(V, k1, s, i0, wx, tb)
    if math.isinf(a):
        return z
    if math.isinf(z):
        return a
    return _blend(a, z, w)


@njit(cache=True, _nrt=False)
def _value_rec(V, k1, tau, i0, wx, cc, tb):
    """The cost-to-go at node k1 of a released brake ``tau`` [s] into its recharge: charged once the recharge is
    over (CH); outside a zone NA; none before the recharge's deadline there (``_deadline``: the time since the
    release exact, never rounded); else interpolated in time between the recharge states around ``tau`` (the later
    one's where the earlier has none: the deadline, not the states, says what is possible)."""
    n = cc.h.shape[0]
    if k1 == n or cc.zone[k1] == 0:
        return _value(V, k1, NA, i0, wx, tb)
    if tau >= cc.t_rec - 1e-9:
        return _value(V, k1, CH, i0, wx, tb)
    if tau < _deadline(k1, i0, wx, tb) - 1e-9:
        return np.inf
    q = tau / (cc.t_rec / cc.n_rec)
    b = min(int(q), cc.n_rec - 1)
    f = q - b
    v0 = _value_soft(V, k1, R0 + b, i0, wx, tb)
    v1 = _value_soft(V, k1, R0 + b + 1 if b + 1 < cc.n_rec else CH, i0, wx, tb)
    if math.isinf(v0):
        return v1
    if f <= 1e-12 or math.isinf(v1):
        return v0
    return v0 + f * (v1 - v0)


@njit(cache=True, _nrt=False)
def look(V, k1, s, e1, cc, tb):
    """The cost-to-go at node k1 in state s at e1 (``_land``, ``_value``). At the stop: 0 at rest."""
    i0, wx = _land(e1, k1, cc)
    return _value(V, k1, s, i0, wx, tb)


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
def _path_state(m):
    return AF if (m == P_A or m == P_RA_H) else CH


@njit(cache=True)
def cycle_backward(cc, fo, price, V, tb):
    """V[k, s, j]: least traction energy + ``price`` x time [kWh] from node k in air state s at grid speed j
    (j = len(v_grid): at the node's cap) to the stop (inf = none), from ``cycle_prepare``'s tables. A cell's
    options (the forward pass takes the same ones): outside a zone (NA) T, H, C, E, a cap followed by the electric
    brake alone; charged (CH) T, H, C, E (a cap followed by the electric brake alone: one that needs the air brake
    is an application, a path), or a path ``P_A`` .. ``P_AX_E``; applied (AF) stay applied, braking at full (B) or,
    at or below ``e_keep``, kept on with the electric brake eased (K), or there a release (the recharge's state at
    this node) or a path ``P_R_H``, ``P_RA_H``; recharging (R0 + b) T, H, C, E, no air brake, charged once the
    recharge is over at a node. In the relaxed DP (no zones) NA has T, H and B at will."""
    n = cc.h.shape[0]
    nv = cc.v_grid.shape[0]
    n_s = V.shape[1]
    dtau = cc.t_rec / cc.n_rec
    for s in range(n_s):
        for j in range(nv + 1):
            V[n, s, j] = 0.0 if j == 0 or (j == nv and cc.e_cap[n] <= 1e-12) else np.inf
    for j in range(nv + 1):
        tb.dl[n, j] = 0.0
    cost = np.zeros(N_U)
    for k in range(n - 1, -1, -1):
        zone = cc.zone[k] != 0 and not cc.relaxed
        z = tb.zmap[k]
        k1 = k + 1
        na1 = _arrive(k1, NA, cc)
        ch1 = _arrive(k1, CH, cc)
        af1 = _arrive(k1, AF, cc)
        for j in range(nv + 1):
            b_na = np.inf
            b_ch = np.inf
            b_af = np.inf
            e = _grid_e(k, j, cc)
            must_apply = zone and e >= cc.e_app[k]  # released at the apply speed: the calculator applies
            rec_bad = zone and e >= cc.e_rec[k]  # (no recharge from here: the look-ahead keeps it on)
            desc = zone and _descending(e, k, cc, fo)
            keep = zone and e <= cc.e_keep[k] * (1.0 + 1e-9)  # applied: may be kept on (K), or released
            for u in range(N_U):
                ok = tb.sok[k, j, u]
                cost[u] = np.inf
                if ok == NO:
                    continue
                c = tb.sw[k, j, u] / KJ_PER_KWH + price * tb.st[k, j, u]
                i0, wx = tb.si[k, j, u], tb.sx[k, j, u]
                if cc.relaxed:
                    if u != U_E and u != U_K:
                        b_na = min(b_na, c + _value(V, k1, na1, i0, wx, tb))
                    continue
                if u == U_B or u == U_K:
                    if zone and (u == U_B or keep):
                        b_af = min(b_af, c + _value(V, k1, af1, i0, wx, tb))
                    continue
                if ok == OK:
                    # (a released train on a grade the electric brake cannot hold is applied at the apply speed: it
                    # does not pass it within the cell)
                    passes = zone and tb.se[k, j, u] > cc.e_app[k] * (1.0 + 1e-9)
                    if not (desc and u != U_H) and not rec_bad and tb.se[k, j, u] <= cc.e_rec[k] * (1.0 + 1e-9):
                        cost[u] = c  # (a recharging train's step)
                    b_na = min(b_na, c + _value(V, k1, na1, i0, wx, tb))
                    if zone and not must_apply and not passes:
                        b_ch = min(b_ch, c + _value(V, k1, ch1, i0, wx, tb))
            if zone:
                # the recharge's deadline here: charged (where CH goes on), or the earliest any step of a recharging
                # train reaches the next node in time for its deadline there
                dl = cc.t_rec if math.isfinite(b_ch) else np.inf
                if not rec_bad:
                    for u in range(N_U):
                        if math.isfinite(cost[u]):
                            i0, wx = tb.si[k, j, u], tb.sx[k, j, u]
                            if k1 == n or cc.zone[k1] == 0:  # (no air brake beyond: no deadline, if it goes on)
                                d1 = 0.0 if math.isfinite(_value(V, k1, NA, i0, wx, tb)) else np.inf
                            else:
                                d1 = _deadline(k1, i0, wx, tb)
                            if math.isfinite(d1):
                                dl = min(dl, max(d1 - tb.st[k, j, u], 0.0))
                tb.dl[k, j] = dl
                for b in range(cc.n_rec):  # recharging, b x dtau since the release
                    best = np.inf
                    for u in range(N_U):
                        if math.isfinite(cost[u]):
                            best = min(best, cost[u] + _value_rec(V, k1, b * dtau + tb.st[k, j, u], tb.si[k, j, u],
                                                                  tb.sx[k, j, u], cc, tb))
                    V[k, R0 + b, j] = best
                if keep:
                    b_af = min(b_af, V[k, R0, j])  # released here
                if z >= 0:
                    for m in range(N_P):
                        jn = tb.pj[z, j, m]
                        if jn < 0:
                            continue
                        c = tb.pw[z, j, m] / KJ_PER_KWH + price * tb.pt[z, j, m]
                        if m == P_AX_H or m == P_AX_C or m == P_AX_E:
                            c += _value_rec(V, jn, tb.pq[z, j, m], tb.pi[z, j, m], tb.px[z, j, m], cc, tb)
                        else:
                            c += _value(V, jn, _arrive(jn, _path_state(m), cc), tb.pi[z, j, m], tb.px[z, j, m], tb)
                        if m < N_CH:
                            b_ch = min(b_ch, c)
                        else:
                            b_af = min(b_af, c)
                V[k, NA, j] = b_na
                V[k, CH, j] = b_ch
                V[k, AF, j] = b_af
            else:
                for s in range(n_s):
                    V[k, s, j] = b_na
                tb.dl[k, j] = 0.0
        if zone and _zone_start(k, cc):
            for j in range(nv + 1):
                V[k, NA, j] = V[k, CH, j]  # (arriving from outside the zone: charged)


@njit(cache=True)
def cycle_forward(cc, fo, price, V, tb, controls, air, v_nodes, t_nodes, ev, ev_k):
    """The drive from rest: at each node the best option at the train's actual speed and air state (the time
    since a release exact), its steps and paths run exactly from there (so the drive keeps the rules); per cell
    its control and air state (at its start), per node speed [km/h] and time [s], and the events (``ev[i]``: where,
    as node + the fraction of its cell, time [s], speed [km/h]; ``ev_k[i]`` ``EV_*``). Returns (time [s], traction
    work [kJ], the number of events); time inf when no drive reaches the stop."""
    s0 = CH if cc.zone[0] != 0 and not cc.relaxed else NA
    w_nodes = np.empty(cc.h.shape[0] + 1)
    nodes = np.empty((cc.h.shape[0] + 1, 4))
    return _forward(cc, fo, price, V, tb, price, V, tb, cc.h.shape[0], 0, 0.0, 0.0, s0, 0.0, 0.0, 0, controls, air,
                    v_nodes, t_nodes, w_nodes, nodes, ev, ev_k)


@njit(cache=True)
def cycle_forward_from(cc, fo, price1, V1, tb1, price2, V2, tb2, m, k0, x0, e0, s0, tau0, hold0, at_node, controls,
                       air, v_nodes, t_nodes, w_nodes, nodes, ev, ev_k):
    """The drive from a train's state (on-board re-planning): ``x0`` [m] into cell ``k0`` at e0 = v^2/2, in air state
    ``s0`` (``CH`` charged, ``AF`` applied, ``R0`` recharging ``tau0`` [s] since its release; outside a zone any of
    them is ``NA``), an applied brake held at least ``hold0`` [s] more (its least hold); at the nodes before ``m``
    the options are priced at ``price1`` with ``V1``, ``tb1`` (a backward pass's cost-to-go and tables, the
    recharge's deadlines its own), from ``m`` on at ``price2`` with ``V2``, ``tb2``. The rest of cell ``k0`` is one
    step under one control (``_to_node`` over the rest: from a charged brake, an application at the state is one,
    held its least hold on). As ``cycle_forward`` otherwise, times and work from the state; ``v_nodes``,
    ``t_nodes`` [k] for k > k0, ``controls``, ``air`` [k] for k >= k0; ``w_nodes`` [k] the traction work [kJ] from
    the state to node k where a step or a path ends there (the nodes a path passes keep what they held).
    ``nodes`` [k] the drive's state at each node where it decides (not inside a path): (air state, time since a
    release [s], the applied brake's least hold ends at [s], e), the air state -1 at the other nodes. ``at_node`` 1:
    the state (``x0`` 0) is one a drive decided at (``nodes``' row of node ``k0``, the hold's end relative to it):
    the drive goes on from it as that drive would have (a re-plan's probe of a switch at node ``k0``)."""
    return _forward(cc, fo, price1, V1, tb1, price2, V2, tb2, m, k0, x0, e0, s0, tau0, hold0, at_node, controls, air,
                    v_nodes, t_nodes, w_nodes, nodes, ev, ev_k)


@njit(cache=True, _nrt=False)
def _first_part(cc, fo, price, V, tb, k, x0, e, s, tau, t, hold_until):
    """The rest of cell k from x0 [m] at e in air state s (``cycle_forward_from``): the best single control over it
    (the rules of ``_forward``'s cells; from a charged brake also an application at the state, U_B or U_K, held
    its least hold on). Returns (control, e at the node, work [kJ], time [s], state there, since a release there
    [s], the applied brake's least hold ends at [s]); control -1 where none is possible."""
    rest = cc.h[k] - x0
    zone = cc.zone[k] != 0 and not cc.relaxed
    must_apply = zone and e >= cc.e_app[k]
    desc = zone and _descending(e, k, cc, fo)
    keep = zone and e <= cc.e_keep[k] * (1.0 + 1e-9)
    held = s == AF and t < hold_until - 1e-9
    best = np.inf
    o, e_o, w_o, t_o, s_o, tau_o, hold_o = -1, 0.0, 0.0, 0.0, NA, 0.0, hold_until
    for u in range(N_U):
        if cc.relaxed and (u == U_E or u == U_K):
            continue
        on = u == U_B or u == U_K
        apply_now = zone and on and s == CH
        if apply_now:
            e1, w, ok = _to_node(e, u, 0.0, cc.t_build[k], k, rest, cc, fo, False)
        else:
            e1, w, ok = _to_node(e, u, 1e9, 0.0, k, rest, cc, fo, cc.relaxed)
        if ok == NO:
            continue
        dt = _part_time(e, e1, rest)
        if not math.isfinite(dt):
            continue
        if must_apply and not (s == AF and u == U_B) and not apply_now:
            continue
        if held and not on:
            continue
        rec = s == R0 or (s == AF and not on)
        if desc and rec and u != U_H:
            continue
        if zone and not on and ok == OK and e1 > cc.e_app[k] * (1.0 + 1e-9):
            continue
        if zone and rec and (e >= cc.e_rec[k] or e1 > cc.e_rec[k] * (1.0 + 1e-9)):
            continue
        s1, value, tau1 = _successor(V, tb, cc, k, s, u, ok, keep, apply_now, e1, tau, dt)
        c = w / KJ_PER_KWH + price * dt + value
        hold1 = t + max(hold_s(k, cc), cc.t_build[k]) if apply_now else hold_until
        if s1 >= 0 and c < best:
            best = c
            o, e_o, w_o, t_o, s_o, tau_o, hold_o = u, e1, w, dt, s1, tau1, hold1
    if not math.isfinite(best):
        o = -1
    return o, e_o, w_o, t_o, s_o, tau_o, hold_o, best


@njit(cache=True, _nrt=False)
def _successor(V, tb, cc, k, s, u, ok, keep, apply_now, e1, tau, dt):
    """The state a step under control ``u`` from air state ``s`` arrives in at node k + 1 (at e1 = v^2/2, after
    ``dt`` [s]; ``ok`` the step's outcome, ``keep`` the speed low enough to keep an application on, ``apply_now`` an
    application made at the step's start from a charged brake), and that state's cost-to-go: (state, value, time
    since the release there [s]); state -1 where the rules allow no such step (a released brake is applied, an
    applied one stays on or is released, a recharging one recharges, outside the zones no state)."""
    i0, wx = _land(e1, k + 1, cc)
    on = u == U_B or u == U_K
    if cc.relaxed or s == NA:
        if ok == OK or cc.relaxed:
            s1 = _arrive(k + 1, NA, cc)
            return s1, _value(V, k + 1, s1, i0, wx, tb), 0.0
    elif on:
        if (s == AF or apply_now) and (u == U_B or keep):
            s1 = _arrive(k + 1, AF, cc)
            return s1, _value(V, k + 1, s1, i0, wx, tb), 0.0
    elif s == CH:
        if ok == OK:
            s1 = _arrive(k + 1, CH, cc)
            return s1, _value(V, k + 1, s1, i0, wx, tb), 0.0
    elif ok == OK and (s == R0 or keep):  # recharging, or released here from AF
        tau1 = (tau if s == R0 else 0.0) + dt
        return R0, _value_rec(V, k + 1, tau1, i0, wx, cc, tb), tau1
    return -1, 0.0, 0.0


@njit(cache=True, _nrt=False)
def _recharge_rest(e, k, x0, tau, price, V, tb, cc, fo, rec, controls, air, v_nodes, t_nodes, t_start, ev, ev_k, n_ev,
                   part):
    """A recharging train ``tau`` [s] since its release, ``x0`` [m] into cell k at e: held under H (the electric
    brake, as the calculator holds a recharging train) until the recharge is over, then on under H to the node after,
    charged there (``P_AR_H``'s rest: a state inside a recharge path, whose speed the grid's recharge deadlines would
    not let go on). Returns (cost [kWh] incl. the cost-to-go there, end node, e there, time [s], work [kJ], the state
    there, events recorded); cost inf where not possible; ``rec``: recorded from ``t_start``."""
    j2, x2, er, tr, wr, st2 = _phase(e, k, x0, U_H, max(cc.t_rec - tau, 0.0), 0.0, True, cc, fo, tb, False, rec,
                                     controls, air, v_nodes, t_nodes, t_start, part)
    if st2 < 0:
        return np.inf, -1, 0.0, 0.0, 0.0, NA, n_ev
    if st2 > 0:  # (the zone, or the route, ended during the recharge)
        i0, wx = _land(er, j2, cc)
        return wr / KJ_PER_KWH + price * tr + _value(V, j2, NA, i0, wx, tb), j2, er, tr, wr, NA, n_ev
    n_ev = _event(rec, ev, ev_k, n_ev, j2, x2, t_start + tr, er, EV_CHARGED, cc)
    e1, dt, w, ok = _finish(er, j2, x2, U_H, 0.0, 0.0, CHARGED, cc, fo, tb, False, rec, v_nodes, t_nodes,
                            t_start + tr)
    if not ok:
        return np.inf, -1, 0.0, 0.0, 0.0, NA, n_ev
    s1 = _arrive(j2 + 1, CH, cc)
    i0, wx = _land(e1, j2 + 1, cc)
    c = (wr + w) / KJ_PER_KWH + price * (tr + dt) + _value(V, j2 + 1, s1, i0, wx, tb)
    return c, j2 + 1, e1, tr + dt, wr + w, s1, n_ev


@njit(cache=True, _nrt=False)
def _record_first_part(o, k, x0, s, t, e, cc, controls, air, ev, ev_k, n_ev):
    """The rest of cell k from ``x0`` [m] under control ``o`` from air state s, recorded: its control, its air
    state, and a release or an application at the state. Returns the events recorded."""
    controls[k] = o
    on = o == U_B or o == U_K
    if cc.relaxed or not on:
        air[k] = AIR_RECHARGE if (s == R0 or (s == AF and not cc.relaxed)) else AIR_OFF
        if s == AF and not cc.relaxed:  # released at the state
            n_ev = _event(True, ev, ev_k, n_ev, k, x0, t, e, EV_RELEASE, cc)
    else:
        air[k] = AIR_CYCLE
        if s == CH:  # applied at the state
            n_ev = _event(True, ev, ev_k, n_ev, k, x0, t, e, EV_APPLY, cc)
    return n_ev


@njit(cache=True, _nrt=False)
def _node_air_state(k, s, tau, t, e, cc, ev, ev_k, n_ev):
    """The air state a drive has at node k: none outside a zone, charged where a zone starts or where the
    recharge is over (recorded). Returns (state, events recorded)."""
    if cc.relaxed or cc.zone[k] == 0:
        s = NA
    elif s == NA and _zone_start(k, cc):
        s = CH
    elif s == R0 and tau >= cc.t_rec - 1e-9:
        s = CH
        n_ev = _event(True, ev, ev_k, n_ev, k, 0.0, t, e, EV_CHARGED, cc)
    return s, n_ev


@njit(cache=True, _nrt=False)
def _best_cell(e, k, s, tau, held, cc, fo, price, V, tb, se, sw, st, sok):
    """The best step of one cell from node k at e in air state s (``tau`` [s] since the release; ``held``: an
    application whose least hold is not over) among the cells' outcomes ``se``, ``sw``, ``st``, ``sok``
    (``_cells_at``), under the air brake's rules: (cost [kWh] incl. the cost-to-go, control, next state);
    control -1 where none is allowed."""
    c_best = np.inf
    o = -1
    s_next = NA
    zone = cc.zone[k] != 0 and not cc.relaxed
    must_apply = zone and e >= cc.e_app[k]
    desc = zone and _descending(e, k, cc, fo)
    keep = zone and e <= cc.e_keep[k] * (1.0 + 1e-9)
    for u in range(N_U):
        if sok[u] == NO or (cc.relaxed and (u == U_E or u == U_K)):
            continue
        on = u == U_B or u == U_K  # (the air brake applied through the cell)
        if must_apply and not (s == AF and u == U_B):
            continue  # (at the apply speed a released brake is applied: a path from CH, or AF staying on)
        if held and not on:
            continue
        rec = s == R0 or (s == AF and not on)  # (recharging through the cell)
        if desc and rec and u != U_H:
            continue
        if zone and not on and sok[u] == OK and se[u] > cc.e_app[k] * (1.0 + 1e-9):
            continue  # (released, it would pass the apply speed within the cell)
        if zone and rec and (e >= cc.e_rec[k] or se[u] > cc.e_rec[k] * (1.0 + 1e-9)):
            continue  # (recharging, it would come near the apply speed: the calculator would not release)
        s1, value, _ = _successor(V, tb, cc, k, s, u, sok[u], keep, False, se[u], tau, st[u])
        c = sw[u] / KJ_PER_KWH + price * st[u] + value
        if s1 >= 0 and c < c_best:
            c_best, o, s_next = c, u, s1
    return c_best, o, s_next


@njit(cache=True, _nrt=False)
def _best_path(k, cc, price, V, tb, pj, pe, pt, pw, pq, c_best, o, s_next):
    """The best of (cost, option, next state) so far and the air brake's paths from node k (``_paths_at``: path m
    as option ``N_U + m``)."""
    for m in range(N_P):
        if pj[m] < 0:
            continue
        c = pw[m] / KJ_PER_KWH + price * pt[m]
        i0, wx = _land(pe[m], pj[m], cc)
        if m == P_AX_H or m == P_AX_C or m == P_AX_E:
            c += _value_rec(V, pj[m], pq[m], i0, wx, cc, tb)
            s1 = R0
        else:
            s1 = _arrive(pj[m], _path_state(m), cc)
            c += _value(V, pj[m], s1, i0, wx, tb)
        if c < c_best:
            c_best, o, s_next = c, N_U + m, s1
    return c_best, o, s_next


@njit(cache=True, _nrt=False)
def _take_cell(o, k, s, s_next, e, t, tau, work, se, sw, st, cc, controls, air, v_nodes, t_nodes, w_nodes, ev, ev_k,
               n_ev):
    """Cell k driven under control ``o`` from air state s to ``s_next``, recorded: its control and air state, a
    release at the node; the speed, time and work at node k + 1. Returns (e, t, tau, work, k + 1, events)."""
    controls[k] = o
    if cc.relaxed or not (o == U_B or o == U_K):
        air[k] = AIR_RECHARGE if (s == R0 or (s == AF and not cc.relaxed)) else AIR_OFF
        if s == AF and not cc.relaxed:  # released at this node
            n_ev = _event(True, ev, ev_k, n_ev, k, 0.0, t, e, EV_RELEASE, cc)
            tau = 0.0
        if s_next == R0:
            tau += st[o]
    else:
        air[k] = AIR_CYCLE
    t += st[o]
    work += sw[o]
    e = se[o]
    k += 1
    v_nodes[k] = kmh_from_e(max(e, 0.0))
    t_nodes[k] = t
    w_nodes[k] = work
    return e, t, tau, work, k, n_ev


@njit(cache=True)
def _forward(cc, fo, price1, V1, tb1, price2, V2, tb2, m_switch, k0, x0, e0, s0, tau0, hold0, at_node, controls, air,
             v_nodes, t_nodes, w_nodes, nodes, ev, ev_k):
    """``cycle_forward`` and ``cycle_forward_from``'s loop."""
    n = cc.h.shape[0]
    none_i = np.zeros(1, dtype=np.int64)
    none_f = np.zeros(1)
    none_f2 = np.zeros((1, 3))
    part = np.zeros(4)
    se = np.zeros(N_U)
    sw = np.zeros(N_U)
    st = np.zeros(N_U)
    sok = np.zeros(N_U, dtype=np.int64)
    pj = np.full(N_P, -1, dtype=np.int64)
    pe = np.zeros(N_P)
    pt = np.zeros(N_P)
    pw = np.zeros(N_P)
    pq = np.zeros(N_P)
    e = e0
    t = 0.0
    tau = tau0  # since the last release [s], in a recharge state (R0)
    hold_until = hold0  # an applied brake's least hold ends then [s]
    work = 0.0
    n_ev = 0
    v_nodes[k0] = kmh_from_e(max(e0, 0.0))
    t_nodes[k0] = 0.0
    w_nodes[k0] = 0.0
    s = s0
    k = k0
    o = -3  # (the first step: -3 none taken here, -2 the recharge held on)
    e1, w1, dt1, s1, tau1, hold1, c1 = 0.0, 0.0, 0.0, NA, 0.0, hold0, np.inf
    for j in range(k0, n + 1):
        nodes[j, 0] = -1.0
    if at_node == 0 and (cc.relaxed or (k < n and cc.zone[k] == 0)):
        s = NA
    if at_node == 0 and k < n and s == R0 and tau >= cc.t_rec - 1e-9:
        s = CH
    if at_node == 0 and k < n and (x0 > 0.0 or s == R0):
        price, V, tb = (price1, V1, tb1) if k < m_switch else (price2, V2, tb2)
        o, e1, w1, dt1, s1, tau1, hold1, c1 = _first_part(cc, fo, price, V, tb, k, x0, e, s, tau, t, hold_until)
        if s == R0:  # (or the recharge held on to its end: a state inside a recharge path)
            c2, j2, e2, t2, w2, s2, _ = _recharge_rest(e, k, x0, tau, price, V, tb, cc, fo, False, controls, air,
                                                       v_nodes, t_nodes, 0.0, ev, ev_k, 0, part)
            if c2 < c1:
                if x0 > 0.0:
                    controls[k] = U_H
                    air[k] = AIR_RECHARGE
                n_ev = _recharge_rest(e, k, x0, tau, price, V, tb, cc, fo, True, controls, air, v_nodes, t_nodes, 0.0,
                                      ev, ev_k, n_ev, part)[6]
                o = -2
                t, work, e, k, s = t2, w2, e2, j2, s2
                v_nodes[k] = kmh_from_e(max(e, 0.0))
                t_nodes[k] = t
                w_nodes[k] = work
        if o == -1:
            return np.inf, np.inf, float(n_ev)
    if o >= 0:
        n_ev = _record_first_part(o, k, x0, s, t, e, cc, controls, air, ev, ev_k, n_ev)
        tau, hold_until = tau1, hold1
        t += dt1
        work += w1
        e = e1
        k += 1
        v_nodes[k] = kmh_from_e(max(e, 0.0))
        t_nodes[k] = t
        w_nodes[k] = work
        s = s1
        if k < n and (cc.zone[k] == 0 or cc.relaxed) and s == R0:
            s = NA
    while k < n:
        price, V, tb = (price1, V1, tb1) if k < m_switch else (price2, V2, tb2)
        nodes[k, 0] = float(s)
        nodes[k, 1] = tau
        nodes[k, 2] = hold_until
        nodes[k, 3] = e
        s, n_ev = _node_air_state(k, s, tau, t, e, cc, ev, ev_k, n_ev)
        held = s == AF and t < hold_until - 1e-9  # (an application at the state: its least hold not over)
        _cells_at(e, k, cc, fo, se, sw, st, sok)
        for m in range(N_P):
            pj[m] = -1
        zone = cc.zone[k] != 0 and not cc.relaxed
        if zone and (s == CH or (s == AF and not held)):
            _paths_at(e, k, s, cc, fo, tb, False, pj, pe, pt, pw, pq, none_i, none_f, none_f2, part)
        c_best, o, s_next = _best_cell(e, k, s, tau, held, cc, fo, price, V, tb, se, sw, st, sok)
        if zone:
            c_best, o, s_next = _best_path(k, cc, price, V, tb, pj, pe, pt, pw, pq, c_best, o, s_next)
        if o < 0 or not math.isfinite(c_best) or n_ev > ev.shape[0] - 4:
            return np.inf, np.inf, float(n_ev)
        if o < N_U:
            e, t, tau, work, k, n_ev = _take_cell(o, k, s, s_next, e, t, tau, work, se, sw, st, cc, controls, air,
                                                  v_nodes, t_nodes, w_nodes, ev, ev_k, n_ev)
        else:
            m = o - N_U
            n_ev = run_path(e, k, m, cc, fo, tb, controls, air, v_nodes, t_nodes, t, ev, ev_k, n_ev, pj, pe, pt, pw, pq,
                            part)
            if pj[m] < 0:  # (the path chosen, run again: cannot happen)
                return np.inf, np.inf, float(n_ev)
            t += pt[m]
            work += pw[m]
            e = pe[m]
            k = pj[m]
            tau = pq[m]
            w_nodes[k] = work
        s = s_next
        if k < n and (cc.zone[k] == 0 or cc.relaxed) and s == R0:
            s = NA
    if s == AF and not cc.relaxed:  # (the stop's application, released at rest)
        n_ev = _event(True, ev, ev_k, n_ev, n, 0.0, t, e, EV_RELEASE, cc)
    return t, work, float(n_ev)
