"""The calculator's distance loop, compiled (numba, cached on disk once per machine).

Written per plan and per cell with scalar branches: a cell costs a few dozen floating-point operations.
``tests/test_kernel.py`` holds it to a fine-step integration of the same plans that shares none of its code
(``tests/fastest_oracle.py``) and, where the air brake cycles, to the energy balance of every run.

Inputs are records of arrays (``records.py``: the train's ``Forces``, the grid's ``Cells``, the batch's
``Plans`` and its ``Outputs``); per plan the kernel walks its condition runs alongside the cells, so the
(plans x cells) condition shares are never materialised. The physics is ``locoplan.physics``' own
functions, compiled here: resistance, full braking and the units.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model.conditions import B, C, E, K, N_CONDITIONS, T
from ..physics import braking, resistance, units
from ..physics.units import KMH2_PER_E
from .constants import (AIR_APPLIED, AIR_OFF, AIR_ON, AIR_RELEASED, APPLY_MIN_KMH, ARRIVE_AFTER_S, CRAWL_STEP_M,
                        CYCLE_MARGIN, E_CRAWL, E_FLOOR, ELECTRIC_CURVE_SHARE, LOOKAHEAD_MARGIN_KMH, RELEASE_FLOOR)

# the physics functions, compiled (plain arithmetic: the same source the numpy callers run)
full_brake_kn = njit(cache=True)(braking.full_brake_kn)
running_load_kn = njit(cache=True)(resistance.running_load_kn)
davis_kn = njit(cache=True)(resistance.davis_kn)
kmh_from_e = njit(cache=True)(units.kmh_from_e)
ms_from_e = njit(cache=True)(units.ms_from_e)
e_from_ms = njit(cache=True)(units.e_from_ms)
kmh = njit(cache=True)(units.kmh)
kinetic_e = njit(cache=True)(units.kinetic_e)


@njit(cache=True, _nrt=False)
def brake_kn(v_kmh, allowed_k, fo):
    """Full braking [kN] at ``v_kmh`` (the calculator's ``brake_kn_at``): the electric brake where the
    catenary feeds it (``allowed_k`` 0 in a neutral section's span) plus the air brake everywhere."""
    return full_brake_kn(_interp(v_kmh, fo.ev, fo.ef), _interp(v_kmh, fo.av, fo.af), allowed_k)


@njit(cache=True, _nrt=False)
def load_kn(v_kmh, g_k, fo):
    """Resistance plus gravity [kN] at ``v_kmh`` in a cell of gravity force ``g_k``."""
    return running_load_kn(v_kmh, fo.ra, fo.rb, fo.rc, g_k)


@njit(cache=True, _nrt=False)
def _crawl(e, hk, fT, fK, g_k, allowed_k, fo, last):
    """A slowing cell at crawling speed, integrated again in sub-steps of at most ``CRAWL_STEP_M``
    (midpoint rule in e = v^2/2): whether a weak train makes it over a crest, or coasting up to the stop
    reaches it, is decided here; one step over the whole cell misjudges it. Returns (e at the cell's
    end, time, traction work); e <= E_FLOOR = came to rest inside the cell, except in the route's ``last``
    cell within its last sub-step: that is arriving (e = 0)."""
    n_sub = int(math.ceil(hk / CRAWL_STEP_M - 1e-9))
    hs = hk / n_sub
    t = 0.0
    w = 0.0
    for j in range(n_sub):
        v0 = ms_from_e(e)
        e_half = e + 0.5 * hs * _crawl_accel(e, fT, fK, g_k, allowed_k, fo)[0]
        a, tr = _crawl_accel(max(e_half, 0.0), fT, fK, g_k, allowed_k, fo)
        e1 = e + hs * a
        w += tr * hs
        if e1 <= E_FLOOR:
            if last and j == n_sub - 1:
                return 0.0, t + 2.0 * hs / (v0 + 1e-12), w
            return E_FLOOR, t, w
        v1 = ms_from_e(e1)
        t += 2.0 * hs / (v0 + v1 + 1e-12)
        e = e1
    return e, t, w


@njit(cache=True, _nrt=False)
def _crawl_accel(e, fT, fK, g_k, allowed_k, fo):
    """de/ds and the traction force [kN] at e under a cell's traction / cruise shares (no braking)."""
    v_kmh = kmh_from_e(e)
    f_max = _interp(v_kmh, fo.tv, fo.tf) * allowed_k
    b_max = brake_kn(v_kmh, allowed_k, fo)
    load = load_kn(v_kmh, g_k, fo)
    hold = min(max(load, -b_max), f_max)
    return (fT * f_max + fK * hold - load) / fo.m, fT * f_max + fK * max(hold, 0.0)


@njit(cache=True, _nrt=False)
def cycle_speeds(e_hold, g_k, allowed_k, t_b, t_rec, margin, fo):
    """The air brake's cycle under a speed ``e_hold`` (a limit, a cruise speed) in a cell of gravity force
    ``g_k``: (e at which to apply, e at which to release). With a_up the train's acceleration at that speed
    under the full electric brake and a_air the air brake's deceleration, the apply speed lies below it by
    the build-up's overshoot a_up^2 t_b / (2 a_air) (a_up t_b if the air cannot stop the rise) times
    ``CYCLE_MARGIN``, at least ``APPLY_MIN_KMH``; the release speed lies ``margin`` x a_up x ``t_rec`` below the
    apply speed (the train regains the apply speed in ``margin`` recharge times; the rule, ``margin`` <= 0:
    ``CYCLE_MARGIN``), at least ``RELEASE_FLOOR`` x the apply speed. Where the electric brake holds that speed
    (a_up <= 0) nothing needs applying: (inf, e_hold)."""
    v_h = kmh_from_e(e_hold)
    a_up = -(load_kn(v_h, g_k, fo) + _interp(v_h, fo.ev, fo.ef) * allowed_k) / fo.m
    if a_up <= 0.0:
        return np.inf, e_hold
    a_air = _interp(v_h, fo.av, fo.af) / fo.m
    over = a_up * a_up * t_b / (2.0 * a_air) if a_air > a_up else a_up * t_b
    v_app = max(v_h - max(APPLY_MIN_KMH, CYCLE_MARGIN * 3.6 * over), 0.0)
    drop = (margin if margin > 0.0 else CYCLE_MARGIN) * 3.6 * a_up * t_rec
    v_rel = max(v_app - drop, RELEASE_FLOOR * v_app)
    return kinetic_e(v_app), kinetic_e(v_rel)


@njit(cache=True, _nrt=False)
def _judge_recharge(wait, t_rec, i, k, air_margin, air_at, air_wait):
    """An application by plan ``i`` in cell ``k``, ``wait`` [s] after its last release: its recharge margin
    into the plan's least, and the plan refused (``air_at``, ``air_wait``) the first time it comes too early."""
    if wait - t_rec < air_margin[i]:
        air_margin[i] = wait - t_rec
    if wait < t_rec - 1e-9 and air_at[i] < 0:
        air_at[i] = k
        air_wait[i] = wait


@njit(cache=True, _nrt=False)
def release_safe(k, e, t_rec, ce_, fo, codes, starts, ends, j0, cruise_e, sh, s_air):
    """Whether the air brake may be released at cell ``k``'s start at e = v^2/2 [m^2/s^2] and recharge before it
    is needed again, by looking ``t_rec`` seconds ahead along the plan (its runs ``codes``, ``starts``,
    ``ends`` from run ``j0``; its cruise speed's e, inf: none; ``sh`` a scratch array of ``N_CONDITIONS``): on a descent the
    train is held by the electric brake alone (``run_plans``: whatever the plan's condition while the brake
    recharges), holding the speed where it can, at full where it cannot; elsewhere it drives the plan's own
    condition. Unsafe: the plan brakes (B, an application), the train reaches the apply speed of a grade the
    electric brake cannot hold (``cycle_speeds``), or a braking curve it cannot follow on the electric brake
    (``ce_.next_air``, or on such a grade). ``s_air`` [m] (inf: none): a braking curve that needs the air brake
    near enough at the release that, recharging, the train is capped as ``run_plans`` caps it (by the electric
    brake's own curves, or the speed that reaches ``s_air`` after the recharge, slowed to it by the electric
    brake)."""
    h, s, env, next_air, allowed, grav = ce_.h, ce_.s, ce_.e_env, ce_.next_air, ce_.allowed, ce_.grav
    n = h.shape[0]
    t = 0.0
    j = k
    while j < n and t < t_rec:
        j0 = _shares(s[j], s[j + 1], codes, starts, ends, j0, sh)
        if sh[B] > 0.0:
            return False
        e1 = e
        b_el, load = 0.0, 0.0
        for _ in range(2):  # the forces at the cell's start, then at its middle (the calculator's second-order step)
            v_kmh = kmh_from_e(max(0.5 * (e + e1), 0.0))
            b_el = _interp(v_kmh, fo.ev, fo.ef) * allowed[j]
            load = load_kn(v_kmh, grav[j], fo)
            if load < 0.0:  # a descent: the electric brake alone
                gain = -(b_el + load)
                if gain < 0.0:
                    gain = 0.0
            else:
                f_max = _interp(v_kmh, fo.tv, fo.tf) * allowed[j]
                gain = sh[T] * f_max + sh[K] * min(max(load, -b_el), f_max) - sh[E] * b_el - load
            e1 = e + (h[j] / fo.m) * gain
        if e1 <= E_FLOOR:  # at rest: no application ahead (the plan fails on its own)
            return True
        if sh[T] + sh[K] > 0.0 and e1 > cruise_e:
            e1 = max(cruise_e, min(e, e1))
        if s_air < np.inf:  # waiting for the curve ahead on the electric brake (run_plans' cap while recharging)
            e_time = 0.0
            if s_air > s[j]:
                e_time = 0.5 * ((s_air - s[j]) / (t_rec + ARRIVE_AFTER_S - t)) ** 2
            a_el = (ELECTRIC_CURVE_SHARE * b_el + load) / fo.m
            cap1 = max(ce_.e_env_el[j + 1], max(e_time, e - h[j] * a_el))
            if e1 > cap1:
                e1 = cap1
        if b_el + load < 0.0:  # a grade the electric brake cannot hold: below its apply speed, with a margin
            e_hold = ce_.e_limit_cell[j]
            if sh[C] == 0.0 and cruise_e < e_hold:
                e_hold = cruise_e
            e_app = cycle_speeds(e_hold, grav[j], allowed[j], ce_.t_build[j], t_rec, 0.0, fo)[0]
            if kmh_from_e(e1) >= kmh_from_e(e_app) - LOOKAHEAD_MARGIN_KMH:
                return False
        if e1 > env[j + 1] * (1.0 + 1e-9) + 1e-9:
            if next_air[j] == j or b_el + load < 0.0:
                return False
            e1 = env[j + 1]  # a braking curve the electric brake follows
        t += 2.0 * h[j] / (ms_from_e(e) + ms_from_e(e1) + 1e-12)
        e = e1
        j += 1
    return True


@njit(cache=True, _nrt=False)
def late_enough(v, d, a, t_need):
    """Whether a train at ``v`` [m/s], slowing at up to ``a`` [m/s^2] (the electric brake), can cover ``d`` [m]
    in no less than ``t_need`` [s]: where it can stop within ``d``, always; else the slowest way,
    (v - sqrt(v^2 - 2 a d)) / a; where it cannot slow (a <= 0: it gains -a even so), if v t + (-a) t^2 / 2
    reaches no further than ``d`` in ``t_need``."""
    if a <= 0.0:
        return d >= v * t_need - 0.5 * a * t_need * t_need
    if v * v <= 2.0 * a * d:
        return True
    return (v - math.sqrt(v * v - 2.0 * a * d)) / a >= t_need


@njit(cache=True, _nrt=False)
def locate(x, xs):
    """Where x lies in the rising knots xs, by bisection: (lo, hi, w) with x = xs[lo] + w (xs[hi] - xs[lo]);
    beyond the ends the end knot itself (lo = hi, w = 0: flat, as np.interp)."""
    n = xs.shape[0]
    if x <= xs[0]:
        return 0, 0, 0.0
    if x >= xs[n - 1]:
        return n - 1, n - 1, 0.0
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if xs[mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo, hi, (x - xs[lo]) / (xs[hi] - xs[lo])


@njit(cache=True, _nrt=False)
def _interp(x, xs, ys):
    """np.interp for one value (flat beyond the ends)."""
    lo, hi, w = locate(x, xs)
    if lo == hi:
        return ys[lo]
    return ys[lo] + w * (ys[hi] - ys[lo])


@njit(cache=True, _nrt=False)
def _shares(s0, s1, codes, starts, ends, j0, out):
    """Share of cell [s0, s1] under each condition (out[N_CONDITIONS]); runs j0.. of the plan; returns the first
    run that may still overlap the next cell."""
    for c in range(N_CONDITIONS):
        out[c] = 0.0
    h = s1 - s0
    j = j0
    n_runs = codes.shape[0]
    while j < n_runs:
        a, b = starts[j], ends[j]
        if a >= s1:
            break
        lo = a if a > s0 else s0
        hi = b if b < s1 else s1
        if hi > lo:
            out[codes[j]] += (hi - lo) / h
        if b <= s1:
            j += 1
        else:
            break
    # the runs before j ended inside this cell; the next cell starts with run j (or later)
    while j0 < n_runs and ends[j0] <= s1:
        j0 += 1
    return j0


@njit(cache=True, _nrt=False)
def _start_plan(i, out):
    """A plan's outputs before its run: no failure yet, no application, no recharge judged."""
    out.over_at[i] = -1
    out.stop_at[i] = -1
    out.hold_at[i] = -1
    out.fb_at[i] = 0
    out.air_at[i] = -1
    out.air_wait[i] = np.nan
    out.air_apps[i] = 0
    out.air_margin[i] = np.inf


@njit(cache=True, _nrt=False)
def _start_slope(fT, fK, fB, fE, allowed_0, g_0, fo):
    """de/ds at the start, from rest, to extrapolate the first cell's mid-speed."""
    f0 = _interp(0.0, fo.tv, fo.tf) * allowed_0
    b0 = brake_kn(0.0, allowed_0, fo)
    l0 = load_kn(0.0, g_0, fo)
    hold0 = min(max(l0, -b0), f0)
    return max((fT * f0 - fB * b0 - fE * _interp(0.0, fo.ev, fo.ef) * allowed_0 + fK * hold0 - l0) / fo.m, 0.0)


@njit(cache=True, _nrt=False)
def _cruise_caps(e, c0, c1, fT, fK, fC, has_cruise, cruise_e_i):
    """The cell's caps at its two ends (``c0``, ``c1``: the envelope) under the papers' cruise speed, which caps T
    and K, not C; and traction or cruise sharing the cell with coasting at the cruise speed already: they hold it
    (the cap that would keep them there is off for the coasting share). Returns (c0, c1, fT, fK)."""
    ce = np.inf
    if has_cruise and fC == 0.0:
        ce = cruise_e_i
    if ce < c0:
        c0 = ce
    if ce < c1:
        c1 = ce
    if has_cruise and fC > 0.0 and fT + fK > 0.0 and e >= cruise_e_i * (1.0 - 1e-9):
        fK += fT
        fT = 0.0
    return c0, c1, fT, fK


# The air brake's cycle, the rules run_plans keeps through the helpers below.
# With ``pl.cycle`` the wagons' air brake is an application of its own (docs/model.md, 'the air brake's cycle'):
# made where a plan brakes (B), where the speed reaches the apply speed on a grade the electric brake alone cannot
# hold (``cycle_speeds``), or where following a limit or a braking curve takes more than the electric brake; its
# force builds up linearly over the cell's ``t_build``; while it is on the train brakes with it and the full
# electric brake, whatever the plan's condition (and between its release and the apply speed on such a grade, or
# while it recharges on a descent, with the electric brake alone, holding the speed where that suffices); it is
# released in full (at a cell's start, held at least ``min_hold_s``, no longer braking nor on a cap) at the release
# speed, or where the electric brake alone holds and no grade it cannot hold (``next_short``) lies within the
# distance the train covers in the recharge time (else at that grade's release speed); applied again (in a cycle,
# or to brake) before ``recharge_s`` has passed since the release, the plan is refused (``air_at``). Holding a
# limit or following a braking curve is bounded by full braking as without the cycle; such an application is
# counted, judged by the recharge like any other, and released where the curve ends, not held. Where a braking
# curve that needs the air brake (``next_air``) lies within the distance covered at the limit in the recharge time,
# an application is released only under the electric brake's own braking curves (``e_env_el``), or where the
# electric brake can slow the train enough to reach that curve no sooner than the recharge is over
# (``late_enough``; it is kept on until then), and until the recharge is over the train is capped by the higher of
# the two.


@njit(cache=True, _nrt=False)
def _cycle_speeds_at(k, i, short, air_on, v, fC, has_cruise, cruise_e_i, t_rec, margin, mreg, ce_, fo):
    """The cycle's speeds in cell k: (apply speed, release speed, the speed an application is released at now).
    Where the electric brake alone holds (not ``short``) there is no apply speed, and an application on may be
    released at any speed, unless a grade it cannot hold lies within the recharge (``next_short``): then not
    above that grade's release speed."""
    e_hold = ce_.e_limit_cell[k]  # the speed the cycle keeps: the limit, or the plan's cruise speed
    if has_cruise and fC == 0.0 and cruise_e_i < e_hold:
        e_hold = cruise_e_i
    e_app = np.inf
    e_r = 0.0
    if short:
        e_app, e_r = cycle_speeds(e_hold, ce_.grav[k], ce_.allowed[k], ce_.t_build[k], t_rec, margin[i, mreg[k]], fo)
    e_rel_now = e_r if short else np.inf
    j = ce_.next_short[k]
    if not short and air_on and j >= 0 and ce_.s[j] - ce_.s[k] < v * t_rec:
        e_hold_j = ce_.e_limit_cell[j]
        if has_cruise and fC == 0.0 and cruise_e_i < e_hold_j:
            e_hold_j = cruise_e_i
        e_rel_now = cycle_speeds(e_hold_j, ce_.grav[j], ce_.allowed[j], ce_.t_build[j], t_rec, margin[i, mreg[j]],
                                 fo)[1]
    return e_app, e_r, e_rel_now


@njit(cache=True, _nrt=False)
def _may_release(k, e, t, fB, curve_prev, t_app, hold_app, e_rel_now, near, late, s_near, t_rec, ce_, fo, codes,
                 starts_i, ends_i, j0_cell, cruise_e_i, ahead):
    """An application on may be released at the start of cell k: the plan does not brake, a braking curve's
    application is past its curve (released as soon as the envelope needs no air brake, not a cell later), its
    least hold is over, the speed is at most the release speed, under the electric brake's own braking curves
    where a curve that needs the air brake is ``near`` (or the electric brake reaches it ``late`` enough), and
    the run ahead is safe without it (``release_safe``; ``s_near`` that curve's start)."""
    return (fB == 0.0 and (not curve_prev or ce_.next_air[k] != k) and t - t_app >= hold_app - 1e-9
            and e <= e_rel_now
            and (not near or (e <= ce_.e_env_el[k] and e <= ce_.e_env_el[k + 1]) or late)
            and release_safe(k, e, t_rec, ce_, fo, codes, starts_i, ends_i, j0_cell, cruise_e_i, ahead, s_near))


@njit(cache=True, _nrt=False)
def _apply_air(released, t_x, t_rel, t_rec, i, k, tb_k, min_hold, air_margin, air_at, air_wait, air_apps):
    """An application at ``t_x`` [s] in cell k, judged by the recharge since the last release and counted:
    (its time, its build-up time, its least hold)."""
    if released:
        _judge_recharge(t_x - t_rel, t_rec, i, k, air_margin, air_at, air_wait)
    air_apps[i] += 1
    return t_x, tb_k, (min_hold if min_hold >= 0.0 else tb_k)


@njit(cache=True, _nrt=False)
def _air_level(t, hk, v, e_mid, t_app, tb_app):
    """The applied air brake's share of its full force at the cell's middle (built up over ``tb_app`` [s])."""
    t_mid = t + hk / (v + ms_from_e(max(e_mid, 0.0)) + 1e-12)
    return 1.0 if tb_app <= 0.0 else min(max((t_mid - t_app) / tb_app, 0.0), 1.0)


@njit(cache=True, _nrt=False)
def _cycle_conditions(fT, fK, fC, fB, fE, on_cycle, e, e_rel_now, in_band):
    """The cell's condition shares (T, K, C, B, E) under the cycle, whatever the plan's: an application of the
    cycle (``on_cycle``: on, not made for the plan's braking in this cell nor for a curve) brakes the whole cell at full down to its
    release speed (or where the plan brakes), and below it is kept on (its least hold, or no safe release yet):
    the speed held, the electric brake eased to the air brake alone; released, ``in_band`` (the cycle's band, or
    recharging on a descent), the train is held by the electric brake alone (at full where it cannot hold).
    Returns (the shares, the air brake applied, in the band, kept on)."""
    if on_cycle:
        if e > e_rel_now or fB > 0.0:
            return 0.0, 0.0, 0.0, 1.0, 0.0, True, False, False
        return 0.0, 1.0, 0.0, 0.0, 0.0, True, False, True
    if in_band:
        return 0.0, 1.0, 0.0, 0.0, 0.0, False, True, False
    return fT, fK, fC, fB, fE, False, False, False


@njit(cache=True, _nrt=False)
def _on_cap(capped, phi, cap_work, hk, b_el):
    """Following a limit or a braking curve takes more than the electric brake: an application too."""
    if capped and phi < 1.0:
        need = -cap_work / (hk * (1.0 - phi))
        return need > b_el * (1.0 + 1e-9) + 1e-6
    return False


@njit(cache=True, _nrt=False)
def _recharge_caps(k, e, t, hk, t_rel, t_rec, s_air, a_el, c0, c1, ce_):
    """Recharging, with a braking curve that needs the air brake near at the release: the caps ``c0``, ``c1``
    lowered to the electric brake's own braking curves, or to the speed that reaches that curve (at ``s_air``)
    no sooner than the recharge is over, slowed to it by the electric brake (whichever is higher)."""
    e_time = 0.0
    if s_air > ce_.s[k]:
        e_time = 0.5 * ((s_air - ce_.s[k]) / (t_rel + t_rec + ARRIVE_AFTER_S - t)) ** 2
    cap0 = max(ce_.e_env_el[k], max(e_time, e))
    cap1 = max(ce_.e_env_el[k + 1], max(e_time, e - hk * a_el))
    if cap0 < c0:
        c0 = cap0
    if cap1 < c1:
        c1 = cap1
    return c0, c1


@njit(cache=True, _nrt=False)
def _capped_end(i, k, e, e_pred, c0, c1, c1_env, hk, b_max, load, has_cruise, ce_, fo, hold_at):
    """A step that meets the cap: (the share phi of the cell before it, e there, e at the cell's end). The train
    follows the cap, unless full braking cannot hold it (where the cell holds the limit, or under a cruise
    cap): then full braking where it holds the limit (``hold_at`` records a slip over the envelope), else
    capped by the envelope, under which full braking keeps every limit ahead."""
    gap = max(c0 - e, 0.0)
    phi = gap / (e_pred - c1 + gap)
    e_phi = e + (e_pred - e) * phi
    e_new = c1
    if ce_.holds_limit[k] or has_cruise:
        e_fb = e_phi + (hk * (1.0 - phi) / fo.m) * (-b_max - load)
        if e_fb > c1 and (ce_.holds_limit[k] or c1 < c1_env):
            if ce_.brake_holds[k]:
                e_new = e_fb
                if hold_at[i] < 0 and e_fb > ce_.e_env[k + 1] * (1 + 1e-9) + 1e-9:
                    hold_at[i] = k
            else:
                e_new = min(e_fb, c1_env)
    return phi, e_phi, e_new


@njit(cache=True, _nrt=False)
def _advance(i, k, e, hk, fT, fK, fC, fB, fE, f_max, b_use, b_max, el_k, air_k, lvl, kept, band, load, c0, c1, c1_env,
             strict, last, has_cruise, ce_, fo, out):
    """Cell k's motion from e under the shares: the holding force (what holding the speed takes, within the
    brake and traction, or the air brake alone where an application is kept on), the end without a cap, then
    capped (``_capped_end``) or crawling (``_crawl``); records the first cell over the limit (``strict``) and where
    the train comes to rest. Returns (holding force, traction force, capped, crawling, phi, e at phi, e and v at
    the end, the crawl's time and work)."""
    hold = min(max(load, -b_use), -lvl * air_k if kept else f_max)
    full = fT * f_max
    tr = full + fK * max(hold, 0.0)
    e_pred = e + (hk / fo.m) * (full - fB * b_use - fE * el_k * ce_.allowed[k] + fK * hold - load)
    if strict and out.over_at[i] < 0:
        if e_pred > ce_.e_limit_cell[k] * (1 + 1e-9) + 1e-9 and (fC + fK > 0.0) and fT == 0.0 and not band:
            out.over_at[i] = k
    capped = e_pred > c1
    # crawling: slowing at low speed under traction, cruise or coasting (a weak train over a crest)
    # (in the last cell too: coasting up to the stop must reach it)
    # (not for a plan already at rest: its verdict is made, the rest of its run only kept finite)
    # never braking: an application kept on slows the train by the air brake alone, as at any speed
    crawl = ((not capped) and k > 0 and fB == 0.0 and fE == 0.0 and e_pred < e and min(e, e_pred) < E_CRAWL
             and out.stop_at[i] < 0 and not band and not kept)
    t_crawl = 0.0
    w_crawl = 0.0
    if crawl:
        e_pred, t_crawl, w_crawl = _crawl(e, hk, fT, fK, ce_.grav[k], ce_.allowed[k], fo, k == last)
    phi = 1.0
    e_phi = e_pred
    if capped:
        phi, e_phi, e_new = _capped_end(i, k, e, e_pred, c0, c1, c1_env, hk, b_max, load, has_cruise, ce_, fo,
                                        out.hold_at)
    else:
        e_new = e_pred
    if k < last or (crawl and e_new == E_FLOOR):  # (at rest before the end of the last cell too)
        if e_new <= E_FLOOR:
            if out.stop_at[i] < 0:
                out.stop_at[i] = k
                out.fb_at[i] = 2 if kept else (1 if fB + fE > 0.0 else 0)  # (2: an application kept on)
            e_new = E_FLOOR
        v_new = ms_from_e(e_new)
    else:
        v_new = ms_from_e(max(e_new, 0.0))
    return hold, tr, capped, crawl, phi, e_phi, e_new, v_new, t_crawl, w_crawl


@njit(cache=True, _nrt=False)
def _time_and_work(capped, crawl, phi, e_phi, e_new, v, v_new, hk, load, tr, t_crawl, w_crawl, m):
    """The cell's time [s], traction work [kJ] and the work done holding the cap (negative where braking)."""
    if capped:
        om = 1.0 - phi
        v_phi = ms_from_e(max(e_phi, 0.0))
        dt = (2.0 * hk) * (phi / (v + v_phi + 1e-12) + om / (v_phi + v_new + 1e-12))
        cap_work = m * (e_new - e_phi) + (hk * om) * load
        return dt, (tr * hk) * phi + max(cap_work, 0.0), cap_work
    if crawl:
        return t_crawl, w_crawl, 0.0
    return (2.0 * hk) / (v + v_new + 1e-12), tr * hk, 0.0


@njit(cache=True, _nrt=False)
def _record_cell(out, i, k, t, v_new, w_tr, hk, fK, fB, fE, b_use, el_k, allowed_k, hold, phi, cap_work, shares, ov,
                 band, capped, c0, c1, brake_holds_k, s_k):
    """The profile of plan i in cell k: time and speed at its end, traction and braking force, its condition
    (the dominant share; B where the air brake is applied; K in a cycle's band, on a level cap; B on a falling
    braking curve), and where it meets a cap."""
    out.t_nodes[i, k + 1] = t
    out.v_nodes[i, k + 1] = kmh(v_new)
    out.trac[i, k] = w_tr / hk
    out.brk[i, k] = (fB * b_use + fE * el_k * allowed_k - fK * min(hold, 0.0)) * phi + max(-cap_work, 0.0) / hk
    dom = 0
    best = shares[0]
    for c in range(1, N_CONDITIONS):
        if shares[c] > best:
            best = shares[c]
            dom = c
    if allowed_k == 0.0 and dom == T:  # no traction in a neutral section: coasting
        dom = C
    if ov:  # the air brake applied: braking
        dom = B
    elif band and allowed_k > 0.0:  # in a cycle's band, held by the electric brake: cruise
        dom = K
    if capped and phi < 0.5:
        # on a falling braking curve, or on a descent full braking cannot hold, the train brakes
        # (B); on a level cap it holds the limit (K)
        braking = c1 < c0 - 1e-5 * max(c0, 1.0) or not brake_holds_k
        out.cond[i, k] = B if braking else K
    else:
        out.cond[i, k] = dom
    if capped and 0.0 < phi < 1.0:
        out.event[i, k] = s_k + phi * hk
    else:
        out.event[i, k] = np.nan


@njit(cache=True)
def run_plans(ce_, fo, pl, out):
    """Integrate every plan of ``pl`` (``Plans``) over the grid ``ce_`` (``Cells``) with the train's
    forces ``fo`` (``Forces``), into ``out`` (``Outputs``): per plan its time, work and the first cell
    where each failure happens (-1 = never).

    The cruise speed (``pl.cruise_e`` with ``has_cruise``): the papers' cruise, T and K capped at that speed
    and held there by braking if need be. The electric brake is cut with traction where ``allowed`` is 0
    (a neutral section's span). ``brake_holds`` (per cell): full braking holds the limit there (else the
    envelope, which the train follows under full braking, lies below it).

    With ``pl.cycle`` the wagons' air brake is an application of its own, by the rules written above its
    helpers (``_cycle_speeds_at`` ...; docs/model.md, 'the air brake's cycle').
    """
    s, h, e_env, e_limit_cell, allowed, grav = ce_.s, ce_.h, ce_.e_env, ce_.e_limit_cell, ce_.allowed, ce_.grav
    m, tv, tf = fo.m, fo.tv, fo.tf
    codes, starts, ends, cruise_e, has_cruise, strict = pl.codes, pl.starts, pl.ends, pl.cruise_e, pl.has_cruise, pl.strict
    cycle, t_rec, min_hold, t_build = pl.cycle, pl.recharge_s, pl.min_hold_s, ce_.t_build
    air_at, air_wait, air_apps, air_margin = out.air_at, out.air_wait, out.air_apps, out.air_margin
    n_cells = h.shape[0]
    last = n_cells - 1
    shares = np.zeros(N_CONDITIONS)
    ahead = np.zeros(N_CONDITIONS)
    for i in range(starts.shape[0]):
        e = v = t = work = slope = 0.0
        j0 = 0
        _start_plan(i, out)
        cruise_e_i = cruise_e[i] if has_cruise else np.inf
        # the air brake's cycle: on, released (once), capped by the electric brake's curves after a release near
        # one that needs the air brake (el_cap, that curve at s_air), its times of application and release, its
        # build-up time and least hold, the last cell's application on a curve, an application for a curve
        air_on = released = el_cap = curve_prev = curve_kind = False
        s_air = t_app = t_rel = tb_app = hold_app = b_el = 0.0
        for k in range(n_cells):
            j0_cell = j0
            j0 = _shares(s[k], s[k + 1], codes, starts[i], ends[i], j0, shares)
            fT, fK, fC, fB, fE = shares[T], shares[K], shares[C], shares[B], shares[E]
            hk = h[k]
            c1_env = e_env[k + 1]
            if k == 0:
                slope = _start_slope(fT, fK, fB, fE, allowed[0], grav[0], fo)
            e_mid = min(e + (0.5 * hk) * slope, 0.5 * (e + c1_env))
            c0, c1, fT, fK = _cruise_caps(e, e_env[k], c1_env, fT, fK, fC, has_cruise, cruise_e_i)
            v_kmh = math.sqrt(max(e_mid, 0.0) * KMH2_PER_E)
            f_max = _interp(v_kmh, tv, tf) * allowed[k]
            el_k = _interp(v_kmh, fo.ev, fo.ef)
            air_k = _interp(v_kmh, fo.av, fo.af)
            b_max = full_brake_kn(el_k, air_k, allowed[k])  # (brake_kn, its two curves kept for the cycle)
            load = load_kn(v_kmh, grav[k], fo)
            b_use = b_max  # what braking and holding may use
            state = AIR_OFF
            ov = band = kept = False
            lvl = 0.0
            if cycle:
                b_el = el_k * allowed[k]
                short = b_el + load < 0.0  # the electric brake alone cannot hold the speed here
                e_app, e_r, e_rel_now = _cycle_speeds_at(k, i, short, air_on, v, fC, has_cruise, cruise_e_i, t_rec,
                                                         pl.release_margin, pl.margin_region, ce_, fo)
                # a braking curve that needs the air brake within reach of the recharge (at the limit's speed):
                # released only under the electric brake's own curves, which the train then follows
                ja = ce_.next_air[k]
                near = ja >= 0 and s[ja] - s[k] < ms_from_e(e_limit_cell[k]) * t_rec
                a_el = (ELECTRIC_CURVE_SHARE * b_el + load) / m  # -de/ds under the electric brake's share
                late = near and late_enough(v, s[ja] - s[k], a_el, t_rec + ARRIVE_AFTER_S)
                if air_on and _may_release(k, e, t, fB, curve_prev, t_app, hold_app, e_rel_now, near, late,
                                           s[ja] if near else np.inf, t_rec, ce_, fo, codes, starts[i], ends[i],
                                           j0_cell, cruise_e_i, ahead):  # release
                    air_on = False
                    released = True
                    t_rel = t
                    el_cap = near
                    s_air = s[ja] if near else 0.0
                    state = AIR_RELEASED
                elif air_on and curve_kind and not curve_prev:  # past its curve and still needed: a cycle's now
                    curve_kind = False
                applied_b = False
                if not air_on and (fB > 0.0 or e >= e_app):  # apply: the plan brakes, or the apply speed
                    t_app, tb_app, hold_app = _apply_air(released, t, t_rel, t_rec, i, k, t_build[k], min_hold,
                                                         air_margin, air_at, air_wait, air_apps)
                    air_on = True
                    curve_kind = False
                    applied_b = fB > 0.0
                    state = AIR_APPLIED
                if air_on:
                    if state != AIR_APPLIED:
                        state = AIR_ON
                    lvl = _air_level(t, hk, v, e_mid, t_app, tb_app)
                fT, fK, fC, fB, fE, ov, band, kept = _cycle_conditions(
                    fT, fK, fC, fB, fE, air_on and not applied_b and not curve_kind, e, e_rel_now,
                    not air_on and ((short and e >= e_r) or (released and t - t_rel < t_rec and load < 0.0)))
                b_use = b_el + lvl * air_k
                if el_cap and released and not air_on and t - t_rel < t_rec:
                    c0, c1 = _recharge_caps(k, e, t, hk, t_rel, t_rec, s_air, a_el, c0, c1, ce_)
            hold, tr, capped, crawl, phi, e_phi, e_new, v_new, t_crawl, w_crawl = _advance(
                i, k, e, hk, fT, fK, fC, fB, fE, f_max, b_use, b_max, el_k, air_k, lvl, kept, band, load, c0, c1, c1_env,
                strict, last, has_cruise, ce_, fo, out)
            t_start = t
            dt, w_tr, cap_work = _time_and_work(capped, crawl, phi, e_phi, e_new, v, v_new, hk, load, tr, t_crawl,
                                                w_crawl, m)
            t += dt
            work += w_tr
            if cycle:
                on_cap = _on_cap(capped, phi, cap_work, hk, b_el)
                if on_cap and not air_on:  # judged by the recharge like any application, held as any
                    t_app, tb_app, hold_app = _apply_air(released, t_start, t_rel, t_rec, i, k, t_build[k], min_hold,
                                                         air_margin, air_at, air_wait, air_apps)
                    air_on = True
                    curve_kind = True
                    state = AIR_APPLIED
                curve_prev = on_cap
                if pl.want_profile:
                    out.air[i, k] = state
            if pl.want_profile:
                _record_cell(out, i, k, t, v_new, w_tr, hk, fK, fB, fE, b_use, el_k, allowed[k], hold, phi, cap_work,
                             shares, ov, band, capped, c0, c1, ce_.brake_holds[k], s[k])
            slope = (e_new - e) / hk
            e = e_new
            v = v_new
        out.t[i] = t
        out.work[i] = work


@njit(cache=True)
def braking_envelope(ce_, fo, n_sub, e_env, entries, reset):
    """The calculator's braking envelope (``TractionCalculator._braking_envelope``, the same arithmetic):
    from the stop and every limit drop backwards, full braking (the electric brake where traction is
    allowed, the air brake everywhere) in ``n_sub`` RK2 sub-steps per cell. Writes ``e_env`` (starting
    from ``e_limit_node``) and the entry points where a braking curve rises through its cell's limit
    into ``entries``; returns their count. (``ce_.e_env`` is not read: ``e_env`` is the output.) A cell
    with ``reset`` (!= 0) bounds nothing: its start node is inf, and no curve runs back through it (the
    electric brake's own envelope, with ``fo`` the electric brake alone, on the grades it cannot hold)."""
    s, h, e_limit_node, e_limit_cell, brake_holds = ce_.s, ce_.h, ce_.e_limit_node, ce_.e_limit_cell, ce_.brake_holds
    n_entries = 0
    for j in range(e_env.shape[0]):
        e_env[j] = e_limit_node[j]
    for k in range(h.shape[0] - 1, -1, -1):
        if reset[k] != 0:
            e_env[k] = np.inf
            continue
        e = e_env[k + 1]
        cap = e_limit_cell[k]
        holds = brake_holds[k]  # full braking holds the limit in this cell (the calculator's brake_holds_limit)
        if e >= cap:
            if holds:  # no braking curve runs through this cell: the limit itself bounds it
                continue
            e = cap  # full braking cannot hold the limit here: the train must enter the cell slower
        d = h[k] / n_sub
        for i in range(n_sub):
            e_mid = e + 0.5 * d * _decel(e, k, ce_, fo)
            e_next = e + d * _decel(e_mid, k, ce_, fo)
            if holds and e < cap <= e_next:  # the curve rises through the limit: its entry point
                entries[n_entries] = s[k + 1] - d * (i + (cap - e) / (e_next - e))
                n_entries += 1
                e = e_next
                break
            # (where braking cannot hold, the curve falls backwards: it is kept under the limit and at or
            # above rest, 0 = not even a train at rest here keeps every limit ahead)
            e = min(max(e_next, 0.0), cap) if not holds else e_next
        e_env[k] = min(e_env[k], max(e, 0.0))
    return n_entries


@njit(cache=True, _nrt=False)
def _decel(e, k, ce_, fo):
    """-de/ds under full braking at e in cell k [m/s^2]."""
    v_kmh = kmh_from_e(max(e, 0.0))
    return (brake_kn(v_kmh, ce_.allowed[k], fo) + (davis_kn(v_kmh, fo.ra, fo.rb, fo.rc) + ce_.grav[k])) / fo.m

