"""The DP drive's compiled loops (numba): per-cell step, stall boundary, backward and forward passes.

``dp.py`` holds the method and its documentation; these are its inner loops, called through
``locoplan.sim.native`` (ahead-of-time compiled where possible, numba's JIT otherwise).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model.conditions import B as B_
from ..model.conditions import K as H_
from ..model.conditions import T as T_
from ..physics.units import KJ_PER_KWH
from ..sim.kernel import brake_kn, davis_kn, e_from_ms, kmh_from_e, locate, ms_from_e

# (controls: T_ full traction, H_ hold the speed (cruise, K), C coast, B_ full braking)


@njit(cache=True, _nrt=False)
def _interp1(x, xs, ys):
    """np.interp for one value, safe with infinite values (``_blend``)."""
    lo, hi, w = locate(x, xs)
    if lo == hi:
        return ys[lo]
    return _blend(ys[lo], ys[hi], w)


@njit(cache=True, _nrt=False)
def _blend(a, b, w):
    """a + w (b - a) for w in [0, 1], safe with infinite ends: w = 0 or 1 is exactly a or b (an
    infinite neighbour must not turn a reachable state into nan or -inf), strictly between it is
    infinite if either end is."""
    if w <= 0.0:
        return a
    if w >= 1.0:
        return b
    if math.isinf(a) or math.isinf(b):
        return np.inf
    return a + w * (b - a)


@njit(cache=True, _nrt=False)
def _interp_node(v1, v_grid, ctg_row, v_cap, v_low):
    """Cost-to-go at speed v1 on a node's grid: the shared speed grid below the node's cap, plus the cap
    itself as the last point (``ctg_row[-1]``), so that a state just under a limit or a braking curve is
    not lost to an infinite neighbour above the cap."""
    nv = v_grid.shape[0]
    if v1 > v_cap * (1.0 + 1e-9) + 1e-9:
        return np.inf
    # the last grid point below the cap
    top = min(int(v_cap / v_grid[1]) if nv > 1 else 0, nv - 1)
    while top > 0 and v_grid[top] > v_cap:
        top -= 1
    if v1 <= v_grid[top]:
        i0 = min(int(v1 / v_grid[1]) if nv > 1 else 0, top)
        if i0 < top and math.isinf(ctg_row[i0]) and not math.isinf(ctg_row[i0 + 1]) and v1 >= v_low:
            return ctg_row[i0 + 1]  # above the node's stall boundary: the lower grid point is below it
        return _interp1(v1, v_grid[: top + 1], ctg_row[: top + 1])
    span = v_cap - v_grid[top]
    if span <= 1e-12:
        return ctg_row[top]
    w = (v1 - v_grid[top]) / span
    if 0.0 < w < 1.0 and math.isinf(ctg_row[top]) and not math.isinf(ctg_row[nv]) and v1 >= v_low:
        return ctg_row[nv]  # above the stall boundary, under the cap: read as the backward pass reads it (_backward)
    return _blend(ctg_row[top], ctg_row[nv], w)


@njit(cache=True, _nrt=False)
def _step(e, u, h, g_k, allowed, fo):
    """One cell under control u from e = v^2/2: (e_end, traction work [kJ]); e_end < 0 = cannot."""
    v_kmh = kmh_from_e(e)
    load0 = davis_kn(v_kmh, fo.ra, fo.rb, fo.rc) + g_k
    if u == H_:
        f_max = _interp1(v_kmh, fo.tv, fo.tf) * allowed
        b_max = brake_kn(v_kmh, allowed, fo)
        if load0 > f_max or -load0 > b_max:
            return -1.0, 0.0
        return e, max(load0, 0.0) * h
    # predictor at the start speed, forces again at the mid-speed (the calculator's second-order step)
    e1 = e
    for _ in range(2):
        vm = kmh_from_e(max(0.5 * (e + e1), 0.0))  # at the mean of e and e1
        f = 0.0
        b = 0.0
        if u == T_:
            f = _interp1(vm, fo.tv, fo.tf) * allowed
        elif u == B_:
            b = brake_kn(vm, allowed, fo)
        load = davis_kn(vm, fo.ra, fo.rb, fo.rc) + g_k
        e1 = e + h / fo.m * (f - b - load)
    if u == T_:
        vm = kmh_from_e(max(0.5 * (e + e1), 0.0))
        return e1, _interp1(vm, fo.tv, fo.tf) * allowed * h
    return e1, 0.0


@njit(cache=True, _nrt=False)
def _bracket(v1, dv, nv, v_cap):
    """Where speed v1 lies on a node's grid (the uniform grid below the node's cap, then the cap itself as
    column nv): (i0, i1, w) with value = (1 - w) row[i0] + w row[i1]; i0 < 0 = above the cap."""
    if v1 > v_cap * (1.0 + 1e-9) + 1e-9:
        return -1, -1, 0.0
    top = min(int(v_cap / dv), nv - 1)
    while top > 0 and top * dv > v_cap:
        top -= 1
    if v1 <= top * dv:
        i0 = min(int(v1 / dv), nv - 1)
        if i0 >= top:
            return top, top, 0.0
        return i0, i0 + 1, (v1 - i0 * dv) / dv
    span = v_cap - top * dv
    if span <= 1e-12:
        return top, top, 0.0
    return top, nv, min((v1 - top * dv) / span, 1.0)  # v1 may pass the cap by the tolerance above


@njit(cache=True, _nrt=False)
def _capped_step(e, u, k, n, dp, fo):
    """One cell under control u, held under the next node's cap (a limit or braking curve) the way the
    calculator holds a train there (braking as needed, if full braking can): (e_end, work [kJ]), e_end < 0
    = not possible. The last cell ends at rest."""
    e1, w = _step(e, u, dp.h[k], dp.grav[k], dp.allowed[k], fo)
    cap = 0.0 if k == n - 1 else dp.e_cap[k + 1]
    if e1 > cap * (1.0 + 1e-9) + 1e-9:
        if u == B_:
            e_b = e1
        else:
            e_b, _ = _step(e, B_, dp.h[k], dp.grav[k], dp.allowed[k], fo)
        # full braking keeps the train at or under the cap (a tolerance for the envelope's finer steps)
        if e_b > cap + 0.02 * (e - cap if e > cap else 0.0) + 1e-3 * max(e, 1.0):
            return -1.0, 0.0
        return cap, w
    if e1 < 0.0:
        return (0.0, w) if k == n - 1 else (-1.0, 0.0)
    return e1, w


@njit(cache=True, _nrt=False)
def _move(e, v, u, k, n, dp, fo):
    """Control u over cell k from e (speed v): (e at its end, work [kJ], speed at its end); e < 0 = not
    possible (no hold from rest, a cap it cannot stay under, or no motion at all)."""
    if u == H_ and e <= 0.0:
        return -1.0, 0.0, 0.0
    e1, w = _capped_step(e, u, k, n, dp, fo)
    if e1 < 0.0:
        return -1.0, 0.0, 0.0
    v1 = ms_from_e(e1)
    if v + v1 <= 0.0:
        return -1.0, 0.0, 0.0
    return e1, w, v1


@njit(cache=True, _nrt=False)
def _arrives(e, k, n, dp, fo, e_low_next):
    """Full traction over cell k from e arrives at or above the next node's lowest (``_lowest_energy``)."""
    e1, _ = _capped_step(e, T_, k, n, dp, fo)
    return e1 >= 0.0 and e1 >= e_low_next * (1.0 - 1e-9) - 1e-12 and not (e <= 0.0 and e1 <= 0.0 and k < n - 1)


@njit(cache=True, _nrt=False)
def _too_fast(e, k, n, dp, fo):
    """Full traction over cell k from e cannot be held under the next node's cap (not a stall: the uncapped
    step moves on)."""
    e1, _ = _step(e, T_, dp.h[k], dp.grav[k], dp.allowed[k], fo)
    return e1 >= 0.0 and _capped_step(e, T_, k, n, dp, fo)[0] < 0.0


@njit(cache=True, _nrt=False)
def _bisect(e_no, e_yes, k, n, dp, fo, e_low_next, arrives):
    """Where ``_arrives`` (or, with ``arrives`` False, ``_too_fast``) turns from false at ``e_no`` to true at
    ``e_yes``: both ends after 40 halvings."""
    for _ in range(40):
        mid = 0.5 * (e_no + e_yes)
        if _arrives(mid, k, n, dp, fo, e_low_next) if arrives else _too_fast(mid, k, n, dp, fo):
            e_yes = mid
        else:
            e_no = mid
    return e_no, e_yes


@njit(cache=True, _nrt=False)
def _lowest_energy(k, n, dp, fo, e_low_next):
    """The lowest e = v^2/2 at node k from which full traction over cell k arrives at or above the next
    node's lowest (``e_low_next``), by bisection (the step is monotone in e); inf when no speed up to the
    cap does. This continuous stall boundary keeps the speed grid from rounding it up cell after cell (on
    fine cells a slow climb would otherwise look impossible).

    The bisection's upper end is the cap, unless the cap is too fast to be braked under the next node's cap
    within the cell (a cell with no brake at all, as in a neutral span for a train whose only brake is
    electric; the DP's one step per cell against the braking curve's fine ones). Then it is the highest
    speed that can still be held under it, found by bisection as well (those speeds form an interval below
    the cap): slower states are feasible although the cap is not."""
    if not math.isfinite(e_low_next):
        return np.inf
    hi = max(dp.e_cap[k], 0.0)
    if _too_fast(hi, k, n, dp, fo):
        if _too_fast(0.0, k, n, dp, fo):
            return np.inf
        hi, _ = _bisect(0.0, hi, k, n, dp, fo, e_low_next, False)
    if not _arrives(hi, k, n, dp, fo, e_low_next):
        return np.inf
    if _arrives(0.0, k, n, dp, fo, e_low_next):
        return 0.0
    return _bisect(0.0, hi, k, n, dp, fo, e_low_next, True)[1]


@njit(cache=True)
def _stall_boundary(dp, fo, e_low):
    """Every node's lowest feasible e (``_lowest_energy``), from the stop backwards; it depends on the
    route and the train only, not on the price, so it is computed once per solver."""
    n = dp.h.shape[0]
    e_low[n] = 0.0
    for k in range(n - 1, -1, -1):
        e_low[k] = _lowest_energy(k, n, dp, fo, e_low[k + 1])


@njit(cache=True, _nrt=False)
def _run_bucket(r, min_run, n_buckets):
    """Index of a run length [m] (0 .. n_buckets; the last = at least ``min_run``, free to switch)."""
    if r >= min_run - 1e-9:
        return n_buckets
    return min(int(r / min_run * n_buckets), n_buckets - 1)


@njit(cache=True)
def _backward(dp, fo, price, penalty, min_run, cost_to_go, e_low):  # e_low: _stall_boundary's
    """cost_to_go[k, c, b, j]: least E + price T [kWh] (+ ``penalty`` per change of condition) from node k
    at speed v_grid[j] (j = len(v_grid): at the node's cap, the limit or braking curve), the run in
    progress being condition c, its length so far in bucket b (``_run_bucket``), to the stop (inf =
    none). A run may end only once it is ``min_run`` long (the ISSA paper's eq. 3), except the final braking."""
    h, e_cap, v_grid = dp.h, dp.e_cap, dp.v_grid
    n = h.shape[0]
    nv = v_grid.shape[0]
    nb = cost_to_go.shape[2] - 1
    for c in range(4):
        for b in range(nb + 1):
            for j in range(nv + 1):
                cost_to_go[n, c, b, j] = 0.0 if j == 0 or (j == nv and e_cap[n] <= 1e-12) else np.inf
    step_cost = np.empty(4)
    step_next = np.empty(4)
    lo_i = np.zeros(4, dtype=np.int64)
    hi_i = np.zeros(4, dtype=np.int64)
    w_i = np.zeros(4)
    dv = v_grid[1] - v_grid[0]
    for k in range(n - 1, -1, -1):
        v_cap_next = ms_from_e(max(e_cap[k + 1], 0.0))
        v_low_next = ms_from_e(e_low[k + 1]) if math.isfinite(e_low[k + 1]) else np.inf
        for j in range(nv + 1):
            if j < nv:
                v = v_grid[j]
                e = e_from_ms(v)
                if e > e_cap[k] * (1.0 + 1e-9) + 1e-9:
                    for c in range(4):
                        for b in range(nb + 1):
                            cost_to_go[k, c, b, j] = np.inf
                    continue
            else:
                e = max(e_cap[k], 0.0)
                v = ms_from_e(e)
            for u in range(4):
                step_cost[u] = np.inf
                step_next[u] = -1.0
                e1, w, v1 = _move(e, v, u, k, n, dp, fo)
                if e1 < 0.0:
                    continue
                step_cost[u] = w / KJ_PER_KWH + price * 2.0 * h[k] / (v + v1)
                step_next[u] = v1
            for u in range(4):
                if step_next[u] >= 0.0 and k < n - 1:
                    i0, i1, wgt = _bracket(step_next[u], dv, nv, v_cap_next)
                    lo_i[u], hi_i[u], w_i[u] = i0, i1, wgt
            for c in range(4):
                for b in range(nb + 1):
                    best = np.inf
                    for u in range(4):
                        if step_next[u] < 0.0:
                            continue
                        if u == c:
                            # at least one bucket per cell: with cells shorter than a bucket the floor would
                            # never advance and a run could never end (see PricedDriveSolver: buckets >= cells)
                            b1 = max(b + 1, _run_bucket(b * min_run / nb + h[k], min_run, nb)) if b < nb else nb
                            extra = 0.0
                        else:
                            if b < nb and k > 0:
                                continue  # the run in progress is too short to end
                            b1 = _run_bucket(h[k], min_run, nb)
                            extra = penalty
                        if k < n - 1:
                            if lo_i[u] < 0:
                                continue
                            row = cost_to_go[k + 1, u, b1]
                            a, z = row[lo_i[u]], row[hi_i[u]]
                            if (0.0 < w_i[u] < 1.0 and math.isinf(a) and not math.isinf(z) and step_next[u] >= v_low_next
                                    and (u == T_ or b1 == nb)):
                                # above the next node's stall boundary, free to take full traction there:
                                # the lower grid point is below the boundary, the state is not
                                rest = z
                            else:
                                rest = _blend(a, z, w_i[u])
                        else:
                            rest = 0.0
                        cc = step_cost[u] + rest + extra
                        if cc < best:
                            best = cc
                    cost_to_go[k, c, b, j] = best


@njit(cache=True)
def _forward(dp, fo, price, penalty, min_run, cost_to_go, e_low, controls, speeds):
    """The drive from rest: each cell's best control at the actual speed and run; returns (time [s], work [kJ])."""
    h, e_cap, v_grid = dp.h, dp.e_cap, dp.v_grid
    n = h.shape[0]
    nb = cost_to_go.shape[2] - 1
    e = 0.0
    t = 0.0
    work = 0.0
    speeds[0] = 0.0
    prev = 0
    run = min_run  # before the first cell any condition may start
    first = True
    for k in range(n):
        v = ms_from_e(e)
        best = np.inf
        best_u = -1
        best_e = 0.0
        best_w = 0.0
        best_run = 0.0
        for u in range(4):
            if k > 0 and u != prev and run < min_run - 1e-9:
                continue
            e1, w, v1 = _move(e, v, u, k, n, dp, fo)
            if e1 < 0.0:
                continue
            r1 = (run + h[k]) if (k > 0 and u == prev) else h[k]
            if first and (k == 0 or u == prev):
                r1 = min_run  # the departure run may end anywhere (see the module docstring)
            b1 = _run_bucket(r1, min_run, nb)
            # the stall boundary holds for a state that may take full traction next (_stall_boundary)
            v_low = ms_from_e(e_low[k + 1]) if math.isfinite(e_low[k + 1]) and (u == T_ or b1 == nb) else np.inf
            rest = _interp_node(v1, v_grid, cost_to_go[k + 1, u, b1], ms_from_e(max(e_cap[k + 1], 0.0)),
                                v_low) if k < n - 1 else 0.0
            c = w / KJ_PER_KWH + price * 2.0 * h[k] / (v + v1) + rest + (penalty if (k > 0 and u != prev) else 0.0)
            if c < best:
                best, best_u, best_e, best_w, best_run = c, u, e1, w, r1
        if best_u < 0:
            return np.inf, np.inf
        if k > 0 and best_u != prev:
            first = False
        controls[k] = best_u
        prev = best_u
        run = best_run
        t += 2.0 * h[k] / (v + ms_from_e(best_e))
        work += best_w
        e = best_e
        speeds[k + 1] = kmh_from_e(e)
    return t, work
