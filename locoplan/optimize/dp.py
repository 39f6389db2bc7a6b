"""The drive that minimises E + lambda T, by dynamic programming on a (position, speed) grid.

Used by the general sequence builder (``strategy/general_builder.py``) to find which condition to use where:
pricing time at lambda [kWh/s] turns the timetabled minimum-energy problem into an unconstrained one
whose optimum is found globally on a grid (the running time falls as lambda rises, so bisection on
lambda lands on the planned time). The model is the calculator's: its cells (each with one gradient,
limit and traction permission), its braking envelope (a state above it cannot stop in time), the same
force, resistance and gravity values, and the same step (forces at the mid-speed, dt = 2 ds / (v0 + v1)).

In each cell the train may apply full traction (T), coast (C), brake fully (B) or hold its speed (H: the
force that keeps it, traction or braking, if the consist has it). Backward pass: the cost-to-go at
every grid speed of every node and for each condition of the previous cell, interpolated linearly in
speed between grid points; forward pass: from rest, each cell's best control at the train's actual
speed. Costs: traction work [kWh] + lambda x time + a small penalty per change of condition. A run may
end only once it is half a train long (the ISSA paper's eq. 3: the sequence's runs respect it by construction);
the state therefore also holds the condition in progress and its length so far (in buckets). The
departure run is exempt: on a falling start the least energy may power for a few tens of metres and
coast (CH_Stadelhofen_Altstetten: 60 m of traction, then coasting to the stop), and a driver can do so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..sim.native import kernels
from ..physics.units import kmh_from_e, kwh, ms
from ..sim.calculator import TractionCalculator
from ..sim.records import DPCells, contiguous

T_, H_, C_, B_ = 0, 1, 2, 3
SPEED_STEP_KMH = 0.5
"""Speed grid of the cost-to-go [km/h]."""
DP_CELL_M = 100.0
"""Target length of the DP's cells [m]."""
RUN_BUCKETS = 6
"""Resolution of the run-length state: a run's length so far in sixths of the minimum run (more on fine
cells: a bucket is never longer than the shortest cell, up to ``MAX_RUN_BUCKETS``)."""
MAX_RUN_BUCKETS = 32
HINT_STEP = 0.02
HINT_WALK = 8
HINT_CLOSE = 1.005
"""A priced-drive search from a hint (``PricedDriveSolver.for_time``): steps of 2 % of the price away from
it, doubling, at most ``HINT_WALK`` of them, until the drive's time crosses the target; then bisection
until the two prices that bracket it are within 0.5 % of each other."""
SWITCH_PENALTY_SHARE = 0.002
"""A change of condition costs this share of the fastest run's energy in the DP: drivers (and the ISSA paper's
eq. 3) do not switch every few metres, and the drive's runs become the sequence's conditions."""


@dataclass(frozen=True)
class PricedDrive:
    """The E + lambda T optimum on the grid: the DP's nodes [m], per-cell controls (indices into
    ``model.conditions.CONDITIONS``: the DP's hold is the calculator's K), node speeds [km/h], and its own running time [s] and traction energy [kWh]."""

    price_kwh_per_s: float
    s_m: np.ndarray
    controls: np.ndarray
    speed_kmh: np.ndarray
    time_s: float
    energy_kwh: float


def dp_caps(calc: TractionCalculator, idx: np.ndarray) -> np.ndarray:
    """The cap e = v^2/2 at each DP node (calculator nodes ``idx``): the lowest envelope since the previous
    node, so that a short restriction inside a DP cell is not jumped over. Where the envelope rises along a
    descent full braking cannot hold (the train speeds up under full braking, following it), that rise is
    reachable within the cell, so it is added back: at the node the cap is the envelope there, not the
    lower value a cell-length behind it (which would make the drive brake where it need not)."""
    env = calc.e_envelope
    rise = np.where(~calc.brake_holds_limit, np.maximum(np.diff(env), 0.0), 0.0)
    climb = np.concatenate([[0.0], np.cumsum(rise)])  # saturated rise from node 0 to each node
    shifted = env - climb  # env[j] + (climb[b] - climb[j]) = shifted[j] + climb[b]
    return np.array([env[idx[0]]] + [shifted[a + 1:b + 1].min() + climb[b] if rise[a:b].any() else env[a + 1:b + 1].min()
                                     for a, b in zip(idx[:-1], idx[1:])])


def dp_nodes(calc: TractionCalculator, cell_m: float) -> np.ndarray:
    """The DP's nodes (indices of calculator nodes): calculator nodes at least ``cell_m`` apart (the first and the
    last always), and every edge of a neutral span: a cell that straddled one would lose the catenary (traction
    and the electric brake) over its whole length, while its start node's cap, the calculator's braking curve,
    counts on the electric brake up to the edge, and no state could follow that curve into a span where it can
    only coast."""
    edges = set((np.flatnonzero(np.diff(calc.traction_allowed) != 0) + 1).tolist())
    keep = [0]
    for i in range(1, len(calc.s_m) - 1):
        if i in edges or calc.s_m[i] - calc.s_m[keep[-1]] >= cell_m - 1e-9:
            keep.append(i)
    if calc.s_m[-1] - calc.s_m[keep[-1]] < 0.5 * cell_m and len(keep) > 1 and keep[-1] not in edges:
        keep.pop()
    keep.append(len(calc.s_m) - 1)
    return np.array(keep)


def dp_cells(calc: TractionCalculator, idx: np.ndarray, speed_step_kmh: float) -> DPCells:
    """The DP's cells between the calculator nodes ``idx``: lengths [m], the length-weighted mean gravity [kN]
    (exact work), traction allowed (0 if anywhere in the cell it is not), the cap at each node (``dp_caps``) and
    the speed grid [m/s] from rest to the envelope's top in steps of ``speed_step_kmh``."""
    s = calc.s_m[idx]
    h = np.diff(s)
    work = np.concatenate([[0.0], np.cumsum(calc.gravity_kn * calc.h_m)])
    gravity = np.diff(work[idx]) / h
    allowed = np.array([calc.traction_allowed[a:b].min() for a, b in zip(idx[:-1], idx[1:])])
    top = float(kmh_from_e(max(calc.e_envelope.max(), 0.0)))
    v_grid = ms(np.arange(0.0, top + speed_step_kmh, speed_step_kmh))
    return DPCells(h, gravity, allowed, dp_caps(calc, idx), v_grid)


class PricedDriveSolver:
    """DP over one calculator's route; ``solve(price)`` gives the priced optimum.

    The DP's cells join the calculator's (which split at every route breakpoint, down to a few metres on
    real lines) into cells of about ``cell_m``, split at every edge of a neutral span: gravity is their
    length-weighted mean (exact work), a cell is in a span or outside it (no traction nor electric brake in
    one, in case a calculator cell inside it is), and the cap at a node is the lowest
    braking envelope since the previous node (a short restriction is not jumped over). The drive is a
    guess for the sequence; the exact calculator checks every plan made of it."""

    def __init__(self, calc: TractionCalculator, speed_step_kmh: float = SPEED_STEP_KMH,
                 switch_penalty_kwh: float | None = None, min_run_m: float | None = None,
                 run_buckets: int | None = None, cell_m: float = DP_CELL_M):
        self.calc = calc
        self.min_run_m = calc.train.length_m / 2 if min_run_m is None else float(min_run_m)
        if switch_penalty_kwh is None:  # a change of condition costs a little: no chattering between cells
            fastest = calc.evaluate(("T",), np.zeros((1, 0))).traction_energy_kwh[0]
            switch_penalty_kwh = SWITCH_PENALTY_SHARE * float(fastest) if np.isfinite(fastest) else 0.0
        self.switch_penalty_kwh = float(switch_penalty_kwh)
        idx = dp_nodes(calc, cell_m)
        self.s_m = calc.s_m[idx]
        self._cells = contiguous(dp_cells(calc, idx, speed_step_kmh))
        self.v_grid = self._cells.v_grid
        h = self._cells.h
        if run_buckets is None:  # a bucket no longer than the shortest cell (a run advances a bucket per cell)
            run_buckets = int(min(MAX_RUN_BUCKETS, max(RUN_BUCKETS, math.ceil(self.min_run_m / max(h.min(), 1e-9) - 1e-9))))
        self._ctg = np.empty((len(h) + 1, 4, run_buckets + 1, len(self.v_grid) + 1))
        self._low = np.zeros(len(h) + 1)  # each node's lowest feasible e = v^2/2 under full traction
        kernels().stall_boundary(self._cells, calc.forces, self._low)

    def solve(self, price_kwh_per_s: float) -> PricedDrive | None:
        n = len(self.s_m) - 1
        kernels().backward(self._cells, self.calc.forces, float(price_kwh_per_s), self.switch_penalty_kwh, self.min_run_m, self._ctg, self._low)
        controls = np.zeros(n, dtype=np.int64)
        speeds = np.zeros(n + 1)
        t, work = kernels().forward(self._cells, self.calc.forces, float(price_kwh_per_s), self.switch_penalty_kwh, self.min_run_m, self._ctg,
                           self._low, controls, speeds)
        if not math.isfinite(t):
            return None
        return PricedDrive(float(price_kwh_per_s), self.s_m, controls, speeds, float(t), kwh(float(work)))

    def for_time(self, t0_s: float, n_bisect: int = 12, price_range=(1e-4, 50.0), timer=None,
                 close_s: float = 0.0, price_hint: float | None = None) -> PricedDrive | None:
        """The priced optimum whose running time is closest to ``t0_s``: geometric bisection on lambda;
        when even the cheapest time is too fast (a falling line where the least energy comes with speed),
        a negative price (time rewarded: holding lower speeds by braking) is bisected as well.
        ``timer(drive)`` [s], if given, replaces the drive's own time (e.g. its plan on the exact calculator);
        the search stops as soon as a drive is within ``close_s`` of ``t0_s``. ``price_hint`` [kWh/s]: where
        the price is expected (E*'s -dE*/dT at ``t0_s``, the same problem's multiplier of the running time):
        the search begins there and walks away from it until the time crosses ``t0_s``, then bisects until
        the two prices that bracket it are within ``HINT_CLOSE`` of each other (the drive's time is a
        staircase in the price: a narrower bracket finds hardly another drive); a hint from which no
        walk brackets ``t0_s`` falls back to the whole range."""
        best = None
        best_t = math.inf
        slower_seen = False  # a drive slower than t0_s: then the slowest one is slower still (time falls with price)

        def consider(d):
            nonlocal best, best_t, slower_seen
            if d is None:
                return
            t = timer(d) if timer is not None else d.time_s
            d = PricedDrive(d.price_kwh_per_s, d.s_m, d.controls, d.speed_kmh, t, d.energy_kwh) if timer is not None else d
            if best is None or abs(t - t0_s) < abs(best_t - t0_s):
                best, best_t = d, t
            if t > t0_s:
                slower_seen = True
            return d

        def bisect(lo, hi, steps, width, sign=1.0) -> bool:
            """Geometric bisection on the price ``sign`` x exp(x) between log prices ``lo`` and ``hi`` (a higher
            price drives faster; with ``sign`` -1, a reward for time, a larger one drives slower), for ``steps``
            steps or until the bracket is ``width`` wide; True when a drive came within ``close_s``."""
            k = 0
            while k < steps and hi - lo > width:
                k += 1
                mid = 0.5 * (lo + hi)
                d = consider(self.solve(sign * math.exp(mid)))
                if d is not None and abs(d.time_s - t0_s) <= close_s:
                    return True
                if (d is None or d.time_s > t0_s) == (sign > 0):
                    lo = mid
                else:
                    hi = mid
            return False

        if price_hint is not None and price_range[0] < price_hint < price_range[1]:
            # from the hint, steps away from it (doubling) until the time crosses t0_s, then bisection
            bottom, top = math.log(price_range[0]), math.log(price_range[1])
            x, lo, hi = math.log(price_hint), None, None
            for k in range(HINT_WALK + 1):
                d = consider(self.solve(math.exp(x)))
                if d is not None and abs(d.time_s - t0_s) <= close_s:
                    return best
                slow = d is None or d.time_s > t0_s
                if slow:
                    lo = x
                else:
                    hi = x
                if lo is not None and hi is not None:
                    break
                x = min(top, x + HINT_STEP * 2 ** k) if slow else max(bottom, x - HINT_STEP * 2 ** k)
                if x in (bottom, top):
                    break
            if lo is not None and hi is not None:
                bisect(lo, hi, math.inf, math.log(HINT_CLOSE))
                return best
        if bisect(*(math.log(p) for p in price_range), n_bisect, 0.0):
            return best
        # even the lowest price drives too fast? (the bisection never reaches its lower end exactly)
        slowest = (consider(self.solve(price_range[0])) if best is not None and best.time_s < t0_s - 1e-6
                   and not slower_seen else None)
        if slowest is not None and slowest.time_s < t0_s - 1e-6:
            # reward time (a negative price): slower drives, holding lower speeds by braking. The running
            # time changes fastest just below zero, so bisect on log |price| (from -1e-8 to -0.1 kWh/s)
            bisect(math.log(price_range[0] * 1e-4), math.log(price_range[0] * 1e3), 2 * n_bisect, 0.0, sign=-1.0)
        return best
