"""The least energy of a drive that keeps the air brake's cycle: a DP over position, speed and the brake's state.

E* (``ocp/bound.py``) relaxes the wagons' air brake to a continuous force a run may modulate at will, so on a
descent the electric brake cannot hold it holds the limit exactly, and a plan's gap to it mixes what the planner
loses with what the cycle must cost: an application builds up over its build-up time, is held at least its least
hold, is released in full, may not be made again before the recharge time has passed (docs/model.md, "the air
brake's cycle"). This module finds the least traction energy of a drive that keeps those rules, and the
calculator's rules for them, on the calculator's train model, by dynamic programming at a price of time (as
``dp.py``), the price searched for the running time.

**The state** is (node, speed, air state), the air state one of
- CH: released and charged: may apply;
- AF: applied, its least hold and build-up over: may stay applied or be released (where the calculator would);
- R0 + b: released and recharging, b x 15 s (``REC_STEP_S``, the recharge in equal parts) since the release; charged
  at the first node where the recharge is over. Between two of these states a value is interpolated in time, and
  taken as none where the earlier state has none: a drive never counts on more time than has passed;
- NA: outside every zone (below): no air brake.
A single cell's controls (``cycle_kernel.U_*``): full traction (T), holding the speed (H: traction, or the electric
brake, at full where it cannot hold), coasting (C), the full electric brake (E), and with the brake applied: at full
(B: the air brake and the full electric brake) or kept on with the electric brake eased (K: the speed held with
braking between the air brake alone and it plus the full electric brake, the air brake alone where that slows the
train even so).

**The calculator's rules** (``sim/kernel.py``, ``run_plans`` and ``release_safe``) are the drive's: a released brake
is applied when the speed reaches the apply speed on a grade the electric brake cannot hold (``apply_speeds``; an
application starts where holding reaches it, inside the cell); an applied brake brakes at full above the speed at
which the calculator keeps an application on (``keep_speeds``: its release speed at the least release margin a plan
may carry, the highest of any plan) and at or below it may be kept on with the electric brake eased, or released;
every application, whatever made it (the apply speed, braking, a braking curve that needs the air brake), is held
its least hold; a release is made only where the recharge keeps the train ``LOOKAHEAD_MARGIN_KMH`` under the apply
speed (the calculator's look-ahead: a recharging train stays under ``e_rec``), and while it recharges on a descent
the electric brake holds the speed. A braking curve (to a lower limit, to the stop, along a descent full braking
cannot hold) is followed with up to full braking; where that needs the air brake it is an application like any
other. The nodes (``cycle_nodes``) fall on every change of the speed limit, so a curve's end is a node.

**Paths**: whatever the cycle does for a time of its own runs as a path of phases whose ends fall at their exact
times, inside a cell where they fall there (``cycle_kernel.P_*``): from CH an application (building up linearly
over its build-up time, at each cell's middle time as the calculator has it; at full down to the keep speed, kept on
from the point it is reached) until its least hold and build-up are over, then on to the next node (AF), or released
that very instant and recharged under H for exactly the recharge time (CH at the node after), or released that
instant and the rest of the cell under H, C or E (recharging at the next node, the time since the release known
exactly), or kept on and released at the first instant of that cell from which the recharge is possible; from AF a
release at the node, or kept on into the cell and released at the first instant from which the recharge is
possible (as the calculator releases at the first chance its look-ahead gives: on a descent, a release a node late
costs up to a cell's fall in speed every cycle), then the recharge under H for exactly the recharge time (CH), or
with an application the instant it is over (AF). So the least hold, the release and the recharge bind exactly where
they bind, and the drive the forward pass returns -- every step and path run again from the train's actual state,
the time since a release exact -- keeps the rules: no application within a recharge, no hold shorter than the
least. The backward pass reads the paths' whole cells off the one-cell tables, interpolated in speed; the forward
pass steps them.

**Where the state matters** (``air_zones``): around the cells where the air brake may be needed -- the descents
whose grade the electric brake cannot hold at the limit (``cycle_regions_m``), the braking curves that need the air
brake (``next_air_curve``), the descents full braking cannot hold -- extended by the distance covered at the top
speed in a recharge and two applications (before) and two applications (after), joined where less than a
recharge at the top speed lies between them. Outside the zones there is no air brake and no state: the drive brakes
electrically there and reaches the next zone charged (at least a recharge at the top speed lies between). A
restriction of the drives: the answer stays a drive's.

**Where the cycle cannot bind** (``cycle_binds``): without the cycle in the model (``--no-air-brake``,
``--point-mass``, ``ModelOptions.air_cycle`` off), or where nothing but the stop's braking curve needs the air
brake, the only application is the stop's, followed with up to full braking and kept on, as in the relaxation: the
cycle optimum is E* itself, and nothing is solved.

**What the number is** (``solve_cycle_optimum``): on each grid (``grid_optimum``) the cycle DP's drives that bracket
T, and the same DP without the cycle (``relaxed``: no state, the air brake a continuous force) at each drive's own
price of time; against those the cycle costs ``lost_s`` of running time and ``extra_kwh`` of traction energy
(weighted as the chord at T weighs the bracket's two ends). The cycle optimum is E*(T - lost_s) + extra_kwh: the
relaxed optimum with the time the cycle loses taken from the rest of the line, and the energy it spends added
(E* near T from the caller, a cubic between its values and slopes at T and T - lost_s: ``EstarCurve``), never
below E*(T). So the DP's own discretisation error, which its drives and its relaxed drives share, cancels: the DP's
energy at T (``dp_kwh``, on the chord between the drives that bracket T) lies above the optimum by about that error
(0.1-1 % on 50 m cells), the difference of the two DPs by much less. Grids: cells of ``coarse_cell_m`` and a speed
step of ``SPEED_STEP_KMH``, then both halved (``MAX_GRIDS``); the stated accuracy is the two grids' change in the
estimate, relative, plus E*'s own. It is an estimate, not a bound: the cycle's cost is measured on the DP's grid,
where a drive switches at nodes only and its speeds are interpolated, and the DP's cells are not the calculator's
(benchmarks/bench_cycle_optimum.py measures plans on the calculator against it).
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InfeasibleError
from ..physics.units import kinetic_e, kmh_from_e, kwh
from ..sim.calculator import TractionCalculator
from ..sim.constants import LOOKAHEAD_MARGIN_KMH
from ..sim.native import kernels
from ..sim.records import CycleCells, CycleTables, contiguous
from .cycle_kernel import N_P, N_U
from .dp import dp_cells
from .problem import MARGIN_MIN

CELL_M = 100.0
"""Target length of the coarser grid's cells [m] (the finer grid: half)."""
MIN_CELLS = 300
CELL_MIN_M = 10.0
"""On a short line the coarser grid has at least ``MIN_CELLS`` cells, of at least ``CELL_MIN_M``."""
SPEED_STEP_KMH = 1.0
"""The coarser grid's speed step [km/h] (the finer grid: half, with its cells)."""
MAX_GRIDS = 2
"""The grids solved: the coarser, then cells and speed step halved (each a first-order error of the DP's; halving
one alone leaves the other's, and two grids that differ by little may both be off by more). A third grid would
cost four times the second (twice the cells, twice the speeds)."""
PRICE_CLOSE = 1.002
PRICE_CLOSE_COARSE = 1.01
"""The price of time is bisected until the two prices whose drives bracket T are within this ratio (on the coarser
grid, whose bracket starts the finer grid's search, within the wider one)."""
PRICE_RANGE = (1e-5, 50.0)
"""Prices of time searched [kWh/s] (geometric bisection), beyond a hint's walk."""
MAX_SOLVES = 40
TIME_CLOSE_SHARE = 1e-3
TIME_SAME_S = 0.5
"""The search for T stops once the two drives that bracket it are within this share of T of each other, or twice in a
row a new price's drive ran within ``TIME_SAME_S`` [s] of the end it replaced (the drive's time jumps between them:
no drive lies between)."""
REC_STEP_S = 15.0
"""The recharge's states lie this far apart in time since the release [s] (at most: the recharge in equal parts)."""
HINT_STEP = 0.15
"""From a price hint the search steps 15 % of the price away (the cycle's price lies above E*'s slope), doubling,
until the time crosses T."""


@dataclass(frozen=True)
class CycleDrive:
    """A drive of the cycle DP at one price: its nodes [m], per cell the control at its start
    (``cycle_kernel.U_*``: T, H, C, B, E) and the air brake's state there (``cycle_kernel.AIR_*``), per node the
    speed [km/h] and time [s]; the air brake's events: where [m], when [s], at what speed [km/h] and what
    (``cycle_kernel.EV_*``: applied, released, applied following a braking curve); its running time [s] and
    traction energy [kWh]."""

    price_kwh_per_s: float
    s_m: np.ndarray
    controls: np.ndarray
    air: np.ndarray
    speed_kmh: np.ndarray
    t_s: np.ndarray
    event_m: np.ndarray
    event_s: np.ndarray
    event_kmh: np.ndarray
    event_kind: np.ndarray
    time_s: float
    energy_kwh: float


def cycle_nodes(calc: TractionCalculator, cell_m: float) -> np.ndarray:
    """The cycle DP's nodes (indices of calculator nodes): the first and the last, every edge of a neutral span (as
    ``dp.dp_nodes``: a cell that straddled one would lose the catenary over its whole length), every change of the
    speed limit (where a braking curve to a lower limit ends, so an application may be released exactly there),
    and between them the calculator nodes nearest to equal cells of about ``cell_m`` [m]: the grids of ``cell_m``
    and ``cell_m / 2`` are then about halves of each other whatever the calculator's own spacing (the first
    calculator node at least ``cell_m`` on made cells of up to twice that on a grid with many breakpoints)."""
    s = calc.s_m
    n = len(s) - 1
    must = {0, n}
    must |= set((np.flatnonzero(np.diff(calc.traction_allowed) != 0) + 1).tolist())
    must |= set((np.flatnonzero(np.diff(calc.e_limit_cell) != 0) + 1).tolist())
    ends = sorted(must)
    keep = [0]
    for a, b in zip(ends[:-1], ends[1:]):
        m = max(1, int(round((s[b] - s[a]) / cell_m)))
        targets = s[a] + (s[b] - s[a]) * np.arange(1, m) / m
        i = np.clip(np.searchsorted(s, targets), 1, n)
        i = np.where(np.abs(s[i - 1] - targets) <= np.abs(s[i] - targets), i - 1, i)
        keep.extend(int(x) for x in np.unique(i) if a < x < b)
        keep.append(b)
    return np.array(keep)


def air_zones(calc: TractionCalculator, idx: np.ndarray, e_cap: np.ndarray) -> np.ndarray:
    """Per DP cell (between calculator nodes ``idx``): whether the air brake's state is tracked there (see the
    module docstring). ``e_cap``: the DP's caps at its nodes (e = v^2/2)."""
    cyc = calc.air_cycle
    n = len(idx) - 1
    if cyc is None:
        return np.zeros(n, dtype=bool)
    own = np.arange(len(calc.h_m))
    need = (calc.next_short == own) | (calc.next_air_curve == own) | ~calc.brake_holds_limit
    cell = np.add.reduceat(need.astype(np.int64), idx[:-1]) > 0
    if not cell.any():
        return cell
    s = calc.s_m[idx]
    v_top = float(np.sqrt(2.0 * max(float(np.max(e_cap)), 0.0)))
    t_app = max(float(np.max(calc.t_build_s)), cyc.min_hold_s or 0.0)
    before = v_top * (cyc.recharge_s + 2.0 * t_app)
    after = v_top * 2.0 * t_app
    join = v_top * cyc.recharge_s
    spans: list[list[float]] = []
    on = np.flatnonzero(cell)
    for k in on:
        a, b = s[k] - before, s[k + 1] + after
        if spans and a <= spans[-1][1] + join:
            spans[-1][1] = max(spans[-1][1], b)
        else:
            spans.append([a, b])
    zone = np.zeros(n, dtype=bool)
    for a, b in spans:
        zone |= (s[1:] > a) & (s[:-1] < b)
    _join_short_gaps(zone, s, e_cap, cyc.recharge_s)
    return zone


def _join_short_gaps(zone: np.ndarray, s: np.ndarray, e_cap: np.ndarray, t_rec: float) -> None:
    """Fill (in place) every gap between two zones that a train at its top speed there crosses in less than the
    recharge time: leaving a zone in any state, the brake must be charged at the next."""
    n = len(zone)
    k = 0
    while k < n:
        if zone[k]:
            k += 1
            continue
        j = k
        while j < n and not zone[j]:
            j += 1
        if 0 < k and j < n:  # a gap between two zones: cells k .. j-1
            v = float(np.sqrt(2.0 * max(float(np.max(e_cap[k:j + 1])), 0.0)))
            if s[j] - s[k] < v * t_rec * (1.0 + 1e-9):
                zone[k:j] = True
        k = j


def apply_speeds(calc: TractionCalculator, idx: np.ndarray) -> np.ndarray:
    """Per DP cell (between calculator nodes ``idx``) the speed (as e = v^2/2) at which the calculator applies the
    air brake of a released train on a grade the electric brake cannot hold at the limit (``kernel.cycle_speeds``:
    below the limit by the build-up's overshoot, 1 km/h at least): the lowest of its calculator cells; inf where
    none is such a grade."""
    n_calc = len(calc.h_m)
    e = np.full(n_calc, np.inf)
    short = np.flatnonzero(calc.next_short == np.arange(n_calc))
    for k in short:
        e[k] = calc.cycle_speeds(calc.e_limit_cell[k], int(k))[0]
    return np.minimum.reduceat(e, idx[:-1])


def keep_speeds(calc: TractionCalculator, idx: np.ndarray) -> np.ndarray:
    """Per DP cell (between calculator nodes ``idx``) the speed (as e = v^2/2) at or below which an applied air brake
    may be kept on with the electric brake eased, and released: on a grade the electric brake cannot hold at the
    limit, the calculator's release speed there (``kernel.cycle_speeds``) at the least release margin a plan
    carries (``problem.MARGIN_MIN``: the highest release speed any plan has; above it the calculator brakes an
    application at full); inf elsewhere (there it keeps an application on, or releases it, at any speed). The
    highest of its calculator cells': what one of them allows, the DP cell allows."""
    n_calc = len(calc.h_m)
    e = np.full(n_calc, np.inf)
    short = np.flatnonzero(calc.next_short == np.arange(n_calc))
    for k in short:
        e[k] = calc.cycle_speeds(calc.e_limit_cell[k], int(k), MARGIN_MIN)[1]
    return np.maximum.reduceat(e, idx[:-1])


def cycle_binds(calc: TractionCalculator) -> bool:
    """Whether the air brake's cycle can make a drive dearer than the relaxation on this line (module
    docstring): a model with the cycle, and a place that needs the air brake (a descent the electric brake cannot
    hold at the limit, a braking curve the electric brake cannot follow, a descent full braking cannot hold).
    One such place besides the stop's braking curve is enough: an application lasts at least its least hold (its
    build-up), so a short braking curve leaves the train under the limit after it, which the relaxation never
    does; the stop's application stays on (the train stops)."""
    if calc.air_cycle is None:
        return False
    if len(calc.cycle_regions_m):
        return True
    own = np.arange(len(calc.h_m))
    need = (calc.next_air_curve == own) | ~calc.brake_holds_limit
    n = len(need)
    last = n
    while last > 0 and need[last - 1]:  # (the stop's own curve: the run of such cells that reaches the end)
        last -= 1
    return bool(need[:last].any())


class CycleDPSolver:
    """The cycle DP over one calculator's route on cells of about ``cell_m`` [m] and a speed grid of
    ``speed_step_kmh``; ``solve(price)`` gives the priced optimum. ``relaxed``: the same DP with the air brake a
    continuous force (no state), the relaxation's grid optimum."""

    def __init__(self, calc: TractionCalculator, cell_m: float = CELL_M, speed_step_kmh: float = SPEED_STEP_KMH,
                 relaxed: bool = False):
        cyc = calc.air_cycle
        if cyc is None and not relaxed:
            raise InfeasibleError("the cycle DP needs a model with the air brake's cycle (the air brake, its cycle on)")
        self.calc, self.relaxed = calc, relaxed
        self.owner = calc  # (the calculator it was asked for: ``cycle_solver``'s cache key)
        self.cell_m, self.speed_step_kmh = float(cell_m), float(speed_step_kmh)
        idx = cycle_nodes(calc, cell_m)
        base = contiguous(dp_cells(calc, idx, speed_step_kmh))
        n = len(idx) - 1
        e_low = np.zeros(n + 1)
        kernels().stall_boundary(base, calc.forces, e_low)
        zone_cells = np.zeros(n, dtype=bool) if relaxed else air_zones(calc, idx, base.e_cap)
        zone = np.concatenate([zone_cells, zone_cells[-1:]]).astype(np.int64)
        # an application's build-up (and least hold) in a DP cell: the longest of its calculator cells' (a hold that
        # is never shorter than the calculator would ask wherever in the cell the application is made)
        t_build = np.maximum.reduceat(calc.t_build_s, idx[:-1]) if cyc is not None else np.zeros(n)
        e_app = apply_speeds(calc, idx) if cyc is not None and not relaxed else np.full(n, np.inf)
        e_keep = keep_speeds(calc, idx) if cyc is not None and not relaxed else np.full(n, np.inf)
        # (the calculator's look-ahead releases only where the train stays this far under the apply speed)
        e_rec = np.where(np.isfinite(e_app), kinetic_e(np.maximum(kmh_from_e(np.minimum(e_app, 1e12))
                                                                  - LOOKAHEAD_MARGIN_KMH, 0.0)), np.inf)
        self.s_m = calc.s_m[idx]
        t_rec = float(cyc.recharge_s) if cyc else 0.0
        n_rec = max(1, int(math.ceil(t_rec / REC_STEP_S - 1e-9))) if t_rec > 0 else 1
        self.cells = contiguous(CycleCells(base.h, base.grav, base.allowed, base.e_cap, base.v_grid, zone,
                                           t_build, e_app, e_keep, e_rec, e_low, t_rec,
                                           float(cyc.min_hold_s) if cyc and cyc.min_hold_s is not None else -1.0,
                                           n_rec, bool(relaxed)))
        nv = len(base.v_grid)
        self._V = np.empty((n + 1, 3 + n_rec, nv + 1))
        zmap = np.full(n + 1, -1, dtype=np.int64)
        if not relaxed:
            zmap[np.flatnonzero(zone[:-1])] = np.arange(int(np.count_nonzero(zone[:-1])))
        nz = max(int(zmap.max()) + 1, 1)
        s3, p3 = (n, nv + 1, N_U), (nz, nv + 1, N_P)
        self.tables = CycleTables(np.zeros(s3), np.zeros(s3), np.zeros(s3), np.zeros(s3, dtype=np.int8),
                                  np.zeros(s3, dtype=np.int32), np.zeros(s3), np.full(p3, -1, dtype=np.int32),
                                  np.zeros(p3), np.zeros(p3), np.zeros(p3), np.zeros(p3), np.zeros(p3, dtype=np.int32),
                                  np.zeros(p3),
                                  np.zeros(n + 1, dtype=np.int64), zmap, np.zeros((n + 1, nv + 1)), np.zeros(n + 1))
        kernels().cycle_prepare(self.cells, calc.forces, self.tables)
        self.n_solves = 0
        self.drives: list[CycleDrive] = []

    @property
    def zone_m(self) -> float:
        """Length of the line where the air brake's state is tracked [m]."""
        return float(np.sum(self.cells.h[self.cells.zone[:-1] != 0]))

    def solve(self, price_kwh_per_s: float) -> CycleDrive | None:
        """The drive that minimises traction energy + ``price_kwh_per_s`` x time, or None when none reaches the stop."""
        n = len(self.s_m) - 1
        k = kernels()
        k.cycle_backward(self.cells, self.calc.forces, float(price_kwh_per_s), self._V, self.tables)
        controls = np.zeros(n, dtype=np.int64)
        air = np.zeros(n, dtype=np.int64)
        v = np.zeros(n + 1)
        t_nodes = np.zeros(n + 1)
        ev, ev_k = np.zeros((4 * n + 16, 3)), np.zeros(4 * n + 16, dtype=np.int64)
        t, work, n_ev = k.cycle_forward(self.cells, self.calc.forces, float(price_kwh_per_s), self._V, self.tables,
                                        controls, air, v, t_nodes, ev, ev_k)
        self.n_solves += 1
        if not math.isfinite(t):
            return None
        m = int(n_ev)
        return CycleDrive(float(price_kwh_per_s), self.s_m, controls, air, v, t_nodes, self._where(ev[:m, 0]),
                          ev[:m, 1].copy(), ev[:m, 2].copy(), ev_k[:m].copy(), float(t), kwh(float(work)))

    def _where(self, at: np.ndarray) -> np.ndarray:
        """Positions [m] of events given as node + the fraction of its cell."""
        i = np.minimum(np.floor(at).astype(np.int64), len(self.s_m) - 1)
        nxt = self.s_m[np.minimum(i + 1, len(self.s_m) - 1)]
        return self.s_m[i] + (at - i) * (nxt - self.s_m[i])

    def bracket(self, t0_s: float, price_hint: float | None = None, seed: tuple[float, float] | None = None,
                close: float = PRICE_CLOSE) -> tuple[CycleDrive | None, CycleDrive | None]:
        """The two drives whose running times bracket ``t0_s``: (the fastest found slower than it, the slowest found
        no slower), their prices within ``close`` of each other. The running time falls as the price rises; the
        search starts from ``seed`` (two prices [kWh/s] that bracketed ``t0_s`` on another grid) or from
        ``price_hint`` [kWh/s] (e.g. E*'s slope), walks out in doubling steps until the time crosses ``t0_s``, then
        bisects geometrically. The first is None where even the lowest price drives no slower than ``t0_s`` (the
        least energy comes within the time), the second where no price reaches it. Every drive solved is kept in
        ``drives``."""
        slow: CycleDrive | None = None
        fast: CycleDrive | None = None

        def too_slow(x: float) -> bool:
            nonlocal slow, fast
            d = self.solve(math.exp(x))
            if d is not None:
                self.drives.append(d)
            if d is None or d.time_s > t0_s:  # (none: too cheap a price to reach the stop at all)
                if d is not None and (slow is None or d.time_s < slow.time_s):
                    slow = d
                return True
            if fast is None or d.time_s > fast.time_s:
                fast = d
            return False

        bottom, top = (math.log(p) for p in PRICE_RANGE)
        x_slow = x_fast = None
        starts = [math.log(p) for p in seed if PRICE_RANGE[0] < p < PRICE_RANGE[1]] if seed else []
        if not starts and price_hint is not None and PRICE_RANGE[0] < price_hint < PRICE_RANGE[1]:
            starts = [math.log(price_hint)]
        if starts:
            for x in sorted(starts):
                if too_slow(x):
                    x_slow = x if x_slow is None else max(x_slow, x)
                elif x_fast is None:
                    x_fast = x
            up = x_fast is None
            x = max(starts) if up else min(starts)
            step = HINT_STEP if len(starts) < 2 else max(abs(starts[1] - starts[0]), 0.2 * HINT_STEP)
            while (x_slow is None or x_fast is None) and self.n_solves < MAX_SOLVES:
                nx = min(top, x + step) if up else max(bottom, x - step)
                if nx == x:
                    break
                x, step = nx, 2.0 * step
                if too_slow(x):
                    x_slow = x
                else:
                    x_fast = x
        else:
            x_slow = bottom if too_slow(bottom) else None
            x_fast = None if too_slow(top) else top
            if x_slow is None:
                x_fast = bottom
        if x_slow is None or x_fast is None:
            return slow, fast
        # regula falsi on the log price (Illinois: an end kept twice counts half), bisection where the times of the
        # bracket's ends are not both known; until the prices are within ``close`` or the two drives' times within
        # ``TIME_CLOSE_SHARE`` of t0_s
        t_s = slow.time_s if slow is not None else None
        t_f = fast.time_s if fast is not None else None
        w_s = w_f = 1.0
        last = 0
        stalls = 0  # new drives that only repeat an end's time: the running time jumps there (a staircase)
        while x_fast - x_slow > math.log(close) and self.n_solves < MAX_SOLVES and stalls < 2:
            if slow is not None and fast is not None and slow.time_s - fast.time_s <= TIME_CLOSE_SHARE * t0_s:
                break
            if t_s is not None and t_f is not None and t_s > t_f:
                a, b = w_s * (t_s - t0_s), w_f * (t0_s - t_f)
                mid = x_slow + (x_fast - x_slow) * a / (a + b)
                span = x_fast - x_slow  # (kept off the ends: the staircase of times)
                mid = min(max(mid, x_slow + 0.05 * span), x_fast - 0.05 * span)
            else:
                mid = 0.5 * (x_slow + x_fast)
            before = (t_s, t_f)
            if too_slow(mid):
                x_slow = mid
                t_s = slow.time_s if slow is not None else None
                w_f, w_s = (0.5 * w_f if last == -1 else w_f), 1.0
                last = -1
            else:
                x_fast = mid
                t_f = fast.time_s
                w_s, w_f = (0.5 * w_s if last == 1 else w_s), 1.0
                last = 1
            moved = [abs(a - b) for a, b in zip(before, (t_s, t_f)) if a is not None and b is not None]
            stalls = stalls + 1 if moved and min(moved) <= TIME_SAME_S else 0
        return slow, fast


def energy_at(drives: list[CycleDrive], t0_s: float) -> float:
    """Traction energy in at most ``t0_s`` [kWh] from the drives found: the lowest chord at ``t0_s`` between a
    drive slower and one no slower than it (a point on the energy-time curve's lower hull, as E*'s curve is convex);
    where every drive is no slower than ``t0_s``, the least energy among them (the least energy comes within the
    time). Raises ``InfeasibleError`` where no drive runs within ``t0_s``."""
    fast = [d for d in drives if d.time_s <= t0_s]
    slow = [d for d in drives if d.time_s > t0_s]
    if not fast:
        raise InfeasibleError(f"no drive keeping the air brake's cycle runs in {t0_s:.1f} s"
                              + (f" (the fastest found takes {min(d.time_s for d in slow):.1f} s)" if slow else ""))
    best = min(d.energy_kwh for d in fast)
    for a in slow:
        for b in fast:
            if a.time_s - b.time_s > 1e-9:
                w = (a.time_s - t0_s) / (a.time_s - b.time_s)
                best = min(best, a.energy_kwh + w * (b.energy_kwh - a.energy_kwh))
    return best


@dataclass(frozen=True)
class GridOptimum:
    """The cycle DP on one grid at a running time T: cell length [m], speed step [km/h]; the DP's own energy at T
    [kWh] (``energy_at``); the drives that bracket T (their times [s] and prices [kWh/s]); the cycle's cost against
    the same DP without the cycle at the same prices (``lost_s`` [s], ``extra_kwh`` [kWh]: time and traction energy
    more than the relaxed drive, weighted as the bracket's chord weighs its ends); ``estimate_kwh`` the cycle
    optimum it gives (``CycleOptimum``); the solves it took and the wall time [s]."""

    cell_m: float
    speed_step_kmh: float
    energy_kwh: float
    times_s: tuple[float, ...]
    prices_kwh_per_s: tuple[float, ...]
    lost_s: float
    extra_kwh: float
    estimate_kwh: float
    solves: int
    wall_s: float


_SOLVERS: OrderedDict[tuple, CycleDPSolver] = OrderedDict()
SOLVER_CACHE = 4
"""Prepared solvers kept in the process, the least recently used dropped first: their tables depend neither on the
running time nor on the price, so a second cycle optimum of the same line (a plan's own running time, a start's)
solves again without preparing again (the preparation is most of a grid's time). About 100 MB each for 60 km on
50 m cells."""


def cycle_solver(calc: TractionCalculator, cell_m: float, speed_step_kmh: float = SPEED_STEP_KMH,
                 relaxed: bool = False) -> CycleDPSolver:
    """``CycleDPSolver`` of ``calc``'s route, train and model on cells of ``cell_m`` (``grid_calculator``), from the
    process's cache where it was prepared before (its drives forgotten)."""
    key = (id(calc), float(cell_m), float(speed_step_kmh), bool(relaxed))
    solver = _SOLVERS.get(key)
    if solver is None or solver.owner is not calc:
        # the relaxed DP runs in E*'s model (``ocp.bound.relaxed``: no cycle, so no braking envelope the cycle's
        # recharge shapes either): its drives then differ from E*'s by the DP's grid alone, which the estimate cancels
        base = TractionCalculator(calc.route, calc.train, replace(calc.options, air_cycle=False)) if relaxed else calc
        solver = CycleDPSolver(grid_calculator(base, cell_m), cell_m, speed_step_kmh, relaxed=relaxed)
        solver.owner = calc  # (held: the key's id stays this calculator's while the solver is cached)
        _SOLVERS[key] = solver
        while len(_SOLVERS) > SOLVER_CACHE:
            _SOLVERS.popitem(last=False)
    else:
        _SOLVERS.move_to_end(key)
        solver.drives, solver.n_solves = [], 0
    return solver


class EstarCurve:
    """E* [kWh] near a running time, from ``estar(t) -> (E* [kWh], dE*/dT [kWh/s], its relative accuracy)``: at
    ``t0_s`` and, once asked for a time further than ``NEAR_S`` from it, at that time too (one solve), a cubic
    between the two with their slopes (Hermite); near ``t0_s`` alone, its tangent. Times are solved at 0.1 s."""

    NEAR_S = 1.0

    def __init__(self, estar, t0_s: float):
        self.estar = estar
        self.points = {round(float(t0_s), 1): estar(float(t0_s))}

    def __call__(self, t_s: float) -> float:
        t0 = min(self.points, key=lambda t: abs(t - t_s))
        if abs(t_s - t0) > self.NEAR_S and len(self.points) < 2:
            t1 = round(float(t_s), 1)
            try:
                self.points[t1] = self.estar(t1)
            except InfeasibleError:
                pass
        (a, (ea, sa, _)), *rest = sorted(self.points.items())
        if not rest:
            return ea + sa * (t_s - a)
        b, (eb, sb, _) = rest[0]
        h = b - a
        x = (t_s - a) / h
        h00, h10, h01, h11 = 2 * x**3 - 3 * x**2 + 1, x**3 - 2 * x**2 + x, -2 * x**3 + 3 * x**2, x**3 - x**2
        return h00 * ea + h10 * h * sa + h01 * eb + h11 * h * sb


def grid_optimum(calc: TractionCalculator, t0_s: float, cell_m: float, speed_step_kmh: float,
                 price_hint: float | None = None, seed: tuple[float, float] | None = None,
                 close: float = PRICE_CLOSE, estar: EstarCurve | None = None) -> tuple[GridOptimum, CycleDrive]:
    """The cycle DP at ``t0_s`` on one grid (``cycle_solver``, bracketed to ``t0_s``: ``CycleDPSolver.bracket``):
    its energy there (``energy_at``), the cycle's cost against the relaxed DP at each bracketing drive's own price,
    and the cycle optimum that gives (``estar``: E* near ``t0_s``; without it, the DP's own energy); and the drive
    nearest ``t0_s`` no slower than it (or the slowest found, where all are slower)."""
    t = time.perf_counter()
    solver = cycle_solver(calc, cell_m, speed_step_kmh)
    slow, fast = solver.bracket(t0_s, price_hint, seed, close)
    e = energy_at(solver.drives, t0_s)
    ends = [d for d in (slow, fast) if d is not None]
    rel = cycle_solver(calc, cell_m, speed_step_kmh, relaxed=True)
    costs = []
    for d in ends:  # (the same DP without the cycle at the drive's own price: what the cycle costs there)
        r = rel.solve(d.price_kwh_per_s)
        costs.append((d.time_s - r.time_s, d.energy_kwh - r.energy_kwh) if r is not None else (0.0, 0.0))
    if slow is not None and fast is not None and slow.time_s > fast.time_s:
        w = (slow.time_s - t0_s) / (slow.time_s - fast.time_s)  # (the fast end's weight, as on the chord)
        weights = (1.0 - w, w)
    else:
        weights = (1.0,) * len(ends)
    lost = sum(w * c[0] for w, c in zip(weights, costs))
    extra = sum(w * c[1] for w, c in zip(weights, costs))
    if estar is None:
        estimate = e
    elif slow is None:  # (every drive within the time: the least energy comes sooner than it)
        estimate = estar(fast.time_s - costs[-1][0]) + costs[-1][1]
    else:
        estimate = sum(w * (estar(t0_s - c[0]) + c[1]) for w, c in zip(weights, costs))
    return (GridOptimum(cell_m, speed_step_kmh, e, tuple(d.time_s for d in ends),
                        tuple(d.price_kwh_per_s for d in ends), lost, extra, estimate, solver.n_solves + rel.n_solves,
                        time.perf_counter() - t),
            fast if fast is not None else slow)


def coarse_cell_m(calc: TractionCalculator) -> float:
    """The coarser grid's cell length [m]: ``CELL_M``, and on a short line at least ``MIN_CELLS`` cells."""
    return max(CELL_MIN_M, min(CELL_M, calc.route.length_m / MIN_CELLS))


@dataclass(frozen=True)
class CycleOptimum:
    """The least traction energy of a drive that keeps the air brake's cycle, at one running time.

    ``cycles``: whether the cycle can bind on the line (``cycle_binds``); without it the cycle optimum is the
    relaxed E* itself and nothing is solved (``energy_kwh`` None). ``energy_kwh`` [kWh]: E* (``estar_kwh``) moved by
    what the cycle costs on the finest of the nested grids (``grids``: per grid its ``GridOptimum`` as a dict): the
    cycle DP's drives that bracket T against the same DP without the cycle at the same prices of time lose
    ``lost_s`` [s] and use ``extra_kwh`` [kWh] more, so the optimum is E*(T - lost_s) + extra_kwh (on E*'s own
    curve; never below E*(T)); where E* is not given, the finest grid's own DP energy. ``accuracy``: its change from
    the grid before, relative. ``dp_kwh``: the finest grid's own DP energy at T; ``price_kwh_per_s`` the price of
    time of its drive nearest T, ``drive`` that drive (``CycleDrive``); ``solve_time_s`` the wall time of it all
    [s]."""

    time_s: float
    cycles: bool
    energy_kwh: float | None = None
    accuracy: float | None = None
    estar_kwh: float | None = None
    dp_kwh: float | None = None
    lost_s: float | None = None
    extra_kwh: float | None = None
    price_kwh_per_s: float | None = None
    grids: tuple = ()
    solve_time_s: float = 0.0
    drive: CycleDrive | None = None
    method: str = "cycle DP"

    @property
    def accuracy_percent(self) -> float | None:
        return None if self.accuracy is None else 100.0 * self.accuracy


def grid_calculator(calc: TractionCalculator, cell_m: float) -> TractionCalculator:
    """``calc``, or one of the same route, train and model on a grid fine enough for DP cells of ``cell_m``."""
    if calc.options.step_m <= cell_m + 1e-9:
        return calc
    return TractionCalculator(calc.route, calc.train, replace(calc.options, step_m=cell_m))


def solve_cycle_optimum(calc: TractionCalculator, time_s: float, *, estar=None, price_hint: float | None = None,
                        cell_m: float | None = None, speed_step_kmh: float = SPEED_STEP_KMH) -> CycleOptimum:
    """The cycle optimum of ``calc``'s route, train and model in ``time_s`` [s] (module docstring): the cycle DP and
    the same DP without the cycle on cells of ``cell_m`` (default ``coarse_cell_m``) and a speed step of
    ``speed_step_kmh``, then both halved (``MAX_GRIDS`` grids); the price of time searched
    for ``time_s`` from ``price_hint`` [kWh/s] (E*'s -dE*/dT there: the cycle's price lies above it), on each finer
    grid from the coarser one's bracket. ``estar(t) -> (E* [kWh], dE*/dT [kWh/s], E*'s relative accuracy)``: E* at
    a running time (at ``time_s`` and, where the cycle costs time, once more near ``time_s`` less that); the optimum
    is E* moved by the cycle's cost on the finest grid, its accuracy the change from the grid before plus E*'s own
    (without ``estar``: the finest grid's own DP energy). Where the cycle cannot bind, nothing is solved (``cycles``
    False). Raises ``InfeasibleError`` where no drive that keeps the cycle runs in ``time_s``."""
    t_wall = time.perf_counter()
    if not cycle_binds(calc):
        e0 = None if estar is None else float(estar(float(time_s))[0])  # (E* itself)
        return CycleOptimum(float(time_s), False, estar_kwh=e0, method="relaxed E* (the cycle cannot bind)")
    curve = None if estar is None else EstarCurve(estar, time_s)
    cell = coarse_cell_m(calc) if cell_m is None else float(cell_m)
    step = float(speed_step_kmh)
    g, drive = grid_optimum(calc, time_s, cell, step, price_hint, close=PRICE_CLOSE_COARSE, estar=curve)
    found = [g]
    while len(found) < MAX_GRIDS:
        cell, step = cell / 2, step / 2
        g, drive = grid_optimum(calc, time_s, cell, step, price_hint, seed=found[-1].prices_kwh_per_s, estar=curve)
        found.append(g)
    e_star = None if curve is None else float(curve.points[round(float(time_s), 1)][0])
    e = g.estimate_kwh if e_star is None else max(g.estimate_kwh, e_star)
    acc = abs(found[-1].estimate_kwh - found[-2].estimate_kwh) / max(abs(e), 1e-9)
    if curve is not None:
        acc += max(p[2] for p in curve.points.values())  # (E*'s own, where the optimum stands on it)
    grids = tuple({"cell_m": x.cell_m, "speed_step_kmh": x.speed_step_kmh, "dp_kwh": x.energy_kwh,
                   "lost_s": x.lost_s, "extra_kwh": x.extra_kwh, "estimate_kwh": x.estimate_kwh, "solves": x.solves,
                   "wall_s": x.wall_s} for x in found)
    return CycleOptimum(float(time_s), True, e, acc, e_star, g.energy_kwh, g.lost_s, g.extra_kwh,
                        drive.price_kwh_per_s, grids, time.perf_counter() - t_wall, drive)
