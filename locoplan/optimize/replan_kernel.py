"""The re-planner's compiled loop (numba): the priced drive's forward pass from any state.

``replan.py`` holds the method and its documentation. The DP's backward pass (``dp_kernel._backward``) gives the
cost-to-go over (node, condition, speed) at a price of time; this forward pass reads it from the train's actual
state: position (inside a cell: the first step covers the rest of it), speed and the condition in progress, and
may switch from one price's cost-to-go to another's at a node (``m``), which is how a re-plan meets an arrival time
between two prices' drives.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model.conditions import B as B_
from ..model.conditions import K as H_
from ..physics.units import KJ_PER_KWH
from ..sim.kernel import kmh_from_e, ms_from_e
from .dp_kernel import _interp_node, _step


@njit(cache=True, _nrt=False)
def capped_step(e, u, h, g, allowed, cap, last, fo):
    """One step of length ``h`` under control u from e, held under ``cap`` as ``dp_kernel._capped_step`` holds it:
    (e_end, work [kJ]); e_end < 0 = not possible. ``last`` (1/0): the step ends at the stop (at rest)."""
    e1, w = _step(e, u, h, g, allowed, fo)
    if e1 > cap * (1.0 + 1e-9) + 1e-9:
        if u == B_:
            e_b = e1
        else:
            e_b, _ = _step(e, B_, h, g, allowed, fo)
        if e_b > cap + 0.02 * (e - cap if e > cap else 0.0) + 1e-3 * max(e, 1.0):
            return -1.0, 0.0
        return cap, w
    if e1 < 0.0:
        return (0.0, w) if last != 0 else (-1.0, 0.0)
    return e1, w


@njit(cache=True, _nrt=False)
def forward_from(dp, fo, prices, V, e_low, first, second, m, k0, h0, g0, e0, prev0, penalty,
                 controls, speeds, times, works):
    """The drive from ``e0`` (= v^2/2) at ``h0`` [m] before node ``k0 + 1`` (the rest of cell ``k0``, of mean
    gravity ``g0`` [kN]), the condition in progress ``prev0`` (-1: none, the first choice free): at each cell the
    control that minimises its cost plus the cost-to-go of price ``prices[first]`` (``V[first]``) before node ``m``
    and of ``prices[second]`` from it. Fills per cell its control and per node (from ``k0 + 1``) speed [km/h], time
    [s] and work [kJ] since the state; returns (time [s], work [kJ]), inf when no drive reaches the stop."""
    h_all, grav, allowed, e_cap, v_grid = dp.h, dp.grav, dp.allowed, dp.e_cap, dp.v_grid
    n = h_all.shape[0]
    e = e0
    t = 0.0
    work = 0.0
    prev = prev0
    for k in range(k0, n):
        h = h0 if k == k0 else h_all[k]
        g = g0 if k == k0 else grav[k]
        p = first if k < m else second
        price = prices[p]
        v = ms_from_e(e)
        last = k == n - 1
        cap = 0.0 if last else e_cap[k + 1]
        v_cap = ms_from_e(max(cap, 0.0))
        v_low = ms_from_e(e_low[k + 1]) if math.isfinite(e_low[k + 1]) else np.inf
        best = np.inf
        best_u = -1
        best_e = 0.0
        best_w = 0.0
        for u in range(4):
            if u == H_ and e <= 0.0:
                continue
            e1, w = capped_step(e, u, h, g, allowed[k], cap, 1 if last else 0, fo)
            if e1 < 0.0:
                continue
            v1 = ms_from_e(e1)
            if v + v1 <= 0.0:
                continue
            rest = 0.0 if last else _interp_node(v1, v_grid, V[p, k + 1, u, 0], v_cap, v_low)
            c = w / KJ_PER_KWH + price * 2.0 * h / (v + v1) + rest + (penalty if (prev >= 0 and u != prev) else 0.0)
            if c < best:
                best, best_u, best_e, best_w = c, u, e1, w
        if best_u < 0 or not math.isfinite(best):
            return np.inf, np.inf
        controls[k] = best_u
        prev = best_u
        t += 2.0 * h / (v + ms_from_e(best_e))
        work += best_w
        e = best_e
        speeds[k + 1] = kmh_from_e(e)
        times[k + 1] = t
        works[k + 1] = work
    return t, work
