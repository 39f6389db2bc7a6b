"""Re-planning on board: the least-energy rest of a run from the train's actual state, by look-up.

**The method.** The priced drive's DP (``dp.py``) minimises traction energy + lambda x time over (node, speed,
condition in progress); its backward pass leaves the cost-to-go of every state to the stop. The re-planner solves
that backward pass once, at set-up, for a ladder of prices of time around the departure's (``LADDER_FINE`` steps of
``LADDER_RATIO`` each way, then doubling out to the prices of a nearly-least-energy and a nearly-fastest run), and
keeps every price's cost-to-go. A re-plan is then forward passes only (``replan_kernel.forward_from``): from the
state (position, possibly inside a cell, whose rest is the first step; speed; the condition in progress, if known)
the drive at one price's cost-to-go is a look-up per cell. The prices are searched (bisection on the ladder) for the
lowest whose drive arrives no later than planned; between that price and the next lower one (whose drive arrives
late) the drive follows the higher price's cost-to-go up to a node ``m`` and the lower one's from it, ``m``
bisected so that the drive arrives on time (the running time moves in steps of a cell's time at most, instead of
the jump between two prices' drives). No search runs at a re-plan, and the set-up is paid once.

**Same optimum.** The drive from any state is the DP's optimum from that state at the price(s) used: from a
state on a re-plan's own drive, the same prices and the same switch node give back that drive's remainder
(``tests/test_replan.py`` checks it along the departure plan).

**The remaining optimum.** Each price's drive is optimal for energy + lambda x time, so for the remaining time
T_rem no drive on the grid uses less than E_lambda + lambda (T_lambda - T_rem) (the Lagrangian bound); the
larger of the two bracketing prices' bounds is ``remaining_optimum_kwh``: the DP's estimate of E* for the rest of
the run, which the re-plan's energy approaches from above (it is E* on the DP's grid, not the cells' E*).

**Model.** The calculator's (``TractionCalculator``: its cells, braking envelope, forces, train length), on the
priced DP's cells of about ``CELL_M`` and its speed grid. The wagons' air brake, where the model has it, is a
continuous force here (as in E*): where the consist's cycle binds (``cycle_dp.cycle_binds``) the re-plan says so
and does not track the brake's state.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.conditions import CONDITIONS
from ..model.route import Route
from ..model.train import Train
from ..physics.units import KJ_PER_KWH, kinetic_e, kmh_from_e, ms_from_e
from ..sim.calculator import ModelOptions, TractionCalculator, limit_kmh_at
from ..sim.native import kernels
from .dp import PricedDriveSolver

CELL_M = 100.0
"""The DP's cells [m] (``dp.DP_CELL_M``)."""
SPEED_STEP_KMH = 0.5
"""The DP's speed grid [km/h]."""
SWITCH_PENALTY_SHARE = 0.0005
"""A change of condition costs this share of the fastest run's energy (no chattering between cells; small, so
that the advice follows the optimum)."""
LADDER_RATIO = 1.2
LADDER_FINE = 5
"""The prices next to the departure's: ``LADDER_FINE`` steps of ``LADDER_RATIO`` each way."""
PRICE_RANGE = (1e-4, 50.0)
"""Beyond them, doubling steps out to these prices [kWh/s] (about the least-energy and the fastest run)."""
PRICE_CLOSE = 1.05
"""Where the air brake cycles, the departure's price is bisected to within this ratio (the cycle DP's drives)."""
ON_TIME_S = 0.05
"""A drive arriving no more than this [s] after the planned arrival is on time (the DP's running times are sums
of cell times: the search stops at the first drive within it)."""
CLOSE_S = 0.3
"""A drive arriving no more than this [s] before the planned arrival is close enough (the search for the switch
node stops there)."""

SPLIT_SHARES = 8
SPLIT_BISECT = 5
"""A switch inside a cell: tried at ``1 / SPLIT_SHARES`` .. of the cell, then refined by ``SPLIT_BISECT`` halvings."""
TOO_FAST_KMH = 0.5
"""A state faster than the limit by more than this [km/h] is refused (the train over the limit); the braking
envelope likewise (the train beyond a braking curve: it cannot stop in time)."""


@dataclass(frozen=True)
class TrainState:
    """The train's state: head position [m], speed [km/h], time since departure [s], and the condition in
    progress (``T``, ``K``, ``C``, ``B``), if known (a change from it costs the switch penalty)."""

    s_m: float
    v_kmh: float
    t_s: float
    condition: str | None = None
    air: str | None = None
    """The air brake's state where the model has its cycle: ``charged`` (released and charged, the default),
    ``applied`` (its least hold over: it may be released), ``recharging`` (released ``recharge_left_s`` [s] before
    the recharge is over: no application before)."""
    recharge_left_s: float | None = None


AIR_STATES = ("charged", "applied", "recharging")


@dataclass
class Replan:
    """A re-plan's result: the advice (the condition now, where it next changes and the speed there), the drive
    as runs of conditions and per node, its arrival and energy."""

    state: TrainState
    planned_arrival_s: float
    arrival_s: float
    late_s: float
    """Arrival after the planned one [s], 0 when on time or early."""
    on_time: bool
    """Arrives inside the window (planned +- the tolerance)."""
    next_condition: str | None
    next_switch_m: float | None
    target_speed_kmh: float | None
    remaining_energy_kwh: float
    remaining_optimum_kwh: float | None
    runs: list[tuple[str, float]]
    """The remainder as (condition, where it begins [m]) from the state on."""
    s_m: np.ndarray = field(repr=False)
    v_kmh: np.ndarray = field(repr=False)
    t_s: np.ndarray = field(repr=False)
    """The drive at the state and every later node: position [m], speed [km/h], clock since departure [s]."""
    energy_kwh: np.ndarray = field(repr=False)
    """Traction energy from the state to each of those points [kWh] (where the air brake cycles: nan at the nodes
    an application's or a recharge's path passes, whose ends alone the cycle DP's drive records)."""
    controls: np.ndarray = field(repr=False)
    """Each step's condition code (``model.conditions``), the first the rest of the state's cell."""
    prices_kwh_per_s: tuple[float, float]
    switch_node_m: float | None
    solve_time_s: float
    air_events: list | None = None
    """Where the model's air brake cycles (the cycle DP's drive): its events from the state on, each
    ``(position [m], clock since departure [s], speed [km/h], "apply" | "release" | "charged")``; None otherwise."""

    @property
    def plan(self) -> str:
        """The remainder as a ``--sequence`` string (each condition with where it begins; a final bare ``B``: the
        stop's braking curve, which every condition follows when it comes to it)."""
        runs = [f"{c}:{s:.1f}" for c, s in self.runs]
        return ",".join(runs + (["B"] if runs and self.runs[-1][0] != "B" else []))

    def condition_at(self, s_m: float) -> str | None:
        """The drive's condition at position ``s_m`` (None past the stop)."""
        i = int(np.searchsorted(self.s_m, s_m, side="right")) - 1
        if i < 0 or i >= len(self.controls):
            return None
        return CONDITIONS[int(self.controls[i])]


def _ladder(p0: float) -> np.ndarray:
    lo, hi = PRICE_RANGE
    p0 = min(max(p0, lo * LADDER_RATIO ** LADDER_FINE), hi / LADDER_RATIO ** LADDER_FINE)
    prices = [p0 * LADDER_RATIO ** k for k in range(-LADDER_FINE, LADDER_FINE + 1)]
    while prices[-1] < hi:
        prices.append(min(hi, 2.0 * prices[-1]))
    while prices[0] > lo * 1.0001:
        prices.insert(0, max(lo, 0.5 * prices[0]))
    return np.array(prices)


class Replanner:
    """The set-up of re-planning on one route, train and model: the DP's cost-to-go at a ladder of prices around
    the price of ``planned_s`` [s] (the running time planned; ``tolerance_s`` its window, +-), and the look-up of
    :meth:`replan`. ``prices``: the ladder to use (e.g. from another replanner on the same line: a restriction's
    re-build skips the search for the departure's price)."""

    def __init__(self, route: Route, train: Train, options: ModelOptions | None = None, *, planned_s: float,
                 tolerance_s: float = 0.0, prices: np.ndarray | None = None, calc: TractionCalculator | None = None,
                 cycle: bool = True):
        t_start = time.perf_counter()
        self.route, self.train = route, train
        self.options = options or ModelOptions()
        self.planned_s, self.tolerance_s = float(planned_s), float(tolerance_s)
        self.calc = calc if calc is not None else TractionCalculator(route, train, self.options)
        calc = self.calc
        from .cycle_dp import cycle_binds

        binds = bool(calc.air_cycle is not None and cycle_binds(calc))
        self.cycle_relaxed = binds and not cycle
        """The cycle binds on the line but is not tracked (``cycle=False``: the air brake a continuous force)."""
        self.cyc: CycleReplanner | None = None
        if binds and cycle:
            self.cyc = CycleReplanner(calc, self.planned_s, prices)
            self.prices = self.cyc.prices
            self._hint = len(self.prices) // 2
            self.setup_s = time.perf_counter() - t_start
            return
        fastest = calc.evaluate(("T",), np.zeros((1, 0))).traction_energy_kwh[0]
        penalty = SWITCH_PENALTY_SHARE * float(fastest) if np.isfinite(fastest) else 0.0
        self.solver = PricedDriveSolver(calc, speed_step_kmh=SPEED_STEP_KMH, switch_penalty_kwh=penalty,
                                        min_run_m=0.0, run_buckets=0, cell_m=CELL_M)
        self.penalty_kwh = penalty
        self.cells = self.solver._cells
        self.s_nodes = self.solver.s_m
        self.e_low = self.solver._low
        if prices is None:
            d = self.solver.for_time(self.planned_s, n_bisect=8)
            prices = _ladder(d.price_kwh_per_s if d is not None else 0.05)
        self.prices = np.ascontiguousarray(prices, dtype=float)
        shape = self.solver._ctg.shape
        self.V = np.empty((len(self.prices),) + shape)
        k = kernels()
        for i, p in enumerate(self.prices):
            k.backward(self.cells, calc.forces, float(p), penalty, 0.0, self.V[i], self.e_low)
        # cumulative gravity work along the calculator's cells, for the rest of a cell from any position
        self._work_s = calc.s_m
        self._work = np.concatenate([[0.0], np.cumsum(calc.gravity_kn * calc.h_m)])
        n = len(self.s_nodes) - 1
        self._controls = np.zeros(n, dtype=np.int64)
        self._speeds = np.zeros(n + 1)
        self._times = np.zeros(n + 1)
        self._works = np.zeros(n + 1)
        self._scratch = (np.zeros(n, dtype=np.int64), np.zeros(n + 1), np.zeros(n + 1), np.zeros(n + 1))
        self._hint = len(self.prices) // 2
        self.setup_s = time.perf_counter() - t_start

    # ------------------------------------------------------------------ the state
    def check(self, st: TrainState) -> None:
        """Refuse a state the train cannot be in, or the plan cannot start from: off the line, over the limit,
        beyond the braking curve (InputError with the reason)."""
        L = self.route.length_m
        where = f"state at {st.s_m:g} m, {st.v_kmh:g} km/h, {st.t_s:g} s"
        if not (math.isfinite(st.s_m) and math.isfinite(st.v_kmh) and math.isfinite(st.t_s)):
            raise InputError(Problem(where, "state", "position, speed and time must be numbers"))
        if not -1e-6 <= st.s_m <= L + 1e-6:
            raise InputError(Problem(where, "s_m", f"off the line (0 .. {L:g} m)"))
        if st.v_kmh < 0:
            raise InputError(Problem(where, "v_kmh", "a speed is never negative"))
        if st.t_s < 0:
            raise InputError(Problem(where, "t_s", "the time since departure is never negative"))
        if st.condition is not None and st.condition not in CONDITIONS[:4]:
            raise InputError(Problem(where, "condition", f"one of T, K, C, B (got {st.condition!r})"))
        self._check_air(st, where)
        s = min(max(st.s_m, 0.0), L)
        lim = float(min(limit_kmh_at(self.route, s, self.train.length_m if self.options.strip else None),
                        self.train.max_speed_kmh))
        if st.v_kmh > lim + TOO_FAST_KMH:
            raise InputError(Problem(where, "v_kmh", f"over the speed limit: {lim:g} km/h here; brake"))
        env = float(np.interp(s, self.calc.s_m, self.calc.e_envelope))
        v_env = float(kmh_from_e(max(env, 0.0)))
        if st.v_kmh > v_env + TOO_FAST_KMH:
            ahead = "the stop" if s >= L - 1e-6 or env <= 0 else "a lower limit or the stop ahead"
            raise InputError(Problem(where, "v_kmh", f"beyond the braking curve: at most {v_env:.1f} km/h here to "
                                                     f"stop in time for {ahead}; brake"))

    def _check_air(self, st: TrainState, where: str) -> None:
        if st.air is not None and st.air not in AIR_STATES:
            raise InputError(Problem(where, "air", f"one of {', '.join(AIR_STATES)} (got {st.air!r})"))
        if st.recharge_left_s is not None:
            if st.air != "recharging":
                raise InputError(Problem(where, "recharge_left_s", "only with the air brake recharging (air: "
                                                                   "recharging)"))
            if not math.isfinite(st.recharge_left_s) or st.recharge_left_s < 0:
                raise InputError(Problem(where, "recharge_left_s", "a time left is a number, never negative"))
        elif st.air == "recharging":
            raise InputError(Problem(where, "recharge_left_s", "a recharging air brake needs the time left of its "
                                                               "recharge [s]"))
        if st.air is not None and self.calc.air_cycle is None:
            raise InputError(Problem(where, "air", "this model has no air brake's cycle (--no-air-brake, "
                                                   "--point-mass or the cycle off): leave out the air brake's state"))
        t_rec = float(self.calc.air_cycle.recharge_s) if self.calc.air_cycle is not None else 0.0
        if st.recharge_left_s is not None and st.recharge_left_s > t_rec + 1e-9:
            raise InputError(Problem(where, "recharge_left_s", f"the consist's recharge takes {t_rec:g} s: at most "
                                                               "that is left"))

    # ------------------------------------------------------------------ the look-up
    def _drive(self, k0: int, h0: float, g0: float, e0: float, prev: int, first: int, second: int, m: int,
               out: tuple | None = None):
        c, v, t_, w_ = out if out is not None else (self._controls, self._speeds, self._times, self._works)
        return kernels().replan_forward(self.cells, self.calc.forces, self.prices, self.V, self.e_low, first, second,
                                        m, k0, h0, g0, e0, prev, self.penalty_kwh, c, v, t_, w_)

    def replan(self, st: TrainState, planned_arrival_s: float | None = None) -> Replan:
        """The rest of the run from ``st``, arriving at ``planned_arrival_s`` (clock since departure; default the
        planned running time) or as soon after as the train can."""
        t_start = time.perf_counter()
        self.check(st)
        planned = self.planned_s if planned_arrival_s is None else float(planned_arrival_s)
        if self.cyc is not None:
            return self._replan_cycle(st, planned, t_start)
        L = self.route.length_m
        s = min(max(st.s_m, 0.0), L)
        n = len(self.s_nodes) - 1
        e0 = float(kinetic_e(st.v_kmh))
        if s >= L - 1e-6 or (n == 0):
            return self._at_stop(st, planned, t_start)
        k0 = int(np.searchsorted(self.s_nodes, s, side="right")) - 1
        k0 = min(max(k0, 0), n - 1)
        h0 = float(self.s_nodes[k0 + 1] - s)
        if h0 <= 1e-6:  # (at a node: its whole cell)
            k0 += 1
            if k0 >= n:
                return self._at_stop(st, planned, t_start)
            h0 = float(self.s_nodes[k0 + 1] - self.s_nodes[k0])
        w_at = np.interp([s, self.s_nodes[k0 + 1]], self._work_s, self._work)
        g0 = float((w_at[1] - w_at[0]) / h0)
        prev = -1 if st.condition is None else CONDITIONS.index(st.condition)
        t_rem = planned - st.t_s
        P = len(self.prices)
        cache: dict[int, tuple[float, float]] = {}

        def pure(i: int) -> float:
            if i not in cache:
                cache[i] = self._drive(k0, h0, g0, e0, prev, i, i, n)
            return cache[i][0]

        lo, hi = lowest_on_time(pure, t_rem, self._hint, P)
        m = n
        a = b = -1
        t_a = t_b = math.inf
        if hi == P:  # late whatever the price: the fastest
            first = second = P - 1
            if not math.isfinite(pure(P - 1)):
                raise InfeasibleError(f"no drive reaches the stop from {s:.1f} m at {st.v_kmh:.1f} km/h: even full "
                                      "traction stalls on the climb ahead")
        elif lo < 0:  # on time even at the lowest price: the least energy
            first = second = 0
        else:
            self._hint = hi
            first, second = hi, lo  # the faster price to node m, the slower one from it
            if math.isfinite(pure(lo)) and pure(hi) < t_rem - CLOSE_S:
                # the first node from which the slower price's drive still arrives on time: the faster drive to
                # node m (run once), the slower from its state there; stops within CLOSE_S of the time
                fast = self._scratch
                self._drive(k0, h0, g0, e0, prev, hi, hi, n, fast)
                a, b = k0, n  # m = a: the slow drive (late); m = b: the fast one (on time)
                t_a, t_b = pure(lo), pure(hi)
                while b - a > 1 and t_b < t_rem - CLOSE_S:
                    mid = (a + b) // 2
                    t_rest = self._drive(mid, float(self.cells.h[mid]), float(self.cells.grav[mid]),
                                         float(kinetic_e(fast[1][mid])), int(fast[0][mid - 1]), lo, lo, n)[0]
                    t_mid = fast[2][mid] + t_rest if math.isfinite(t_rest) else math.inf
                    if t_mid <= t_rem + ON_TIME_S:
                        b, t_b = mid, t_mid
                    else:
                        a, t_a = mid, t_mid
                # the drive's time moves in steps (a cell more of traction before a long coast is seconds): of the
                # two drives either side of the planned arrival, the closer, if it keeps the window
                m = b
        bound = (self._optimum({i: cache[i] for i in (first, second) if i in cache}, t_rem) if hi < P
                 else None)  # (late whatever the price: no drive keeps the time)
        split = None
        if first != second and b - a == 1 and t_rem - t_b > CLOSE_S and math.isfinite(t_a):
            split = self._split(a, k0, s, h0, g0, e0, prev, hi, lo, t_rem)
            if split is not None:
                return self._result(st, planned, split, first, second, float(split[0][a - k0 + 1]), bound, t_start)
        t, w = self._drive(k0, h0, g0, e0, prev, first, second, m)
        if not math.isfinite(t):
            raise InfeasibleError(f"no drive reaches the stop from {s:.1f} m at {st.v_kmh:.1f} km/h")
        arrays = (np.concatenate([[s], self.s_nodes[k0 + 1:]]), np.concatenate([[st.v_kmh], self._speeds[k0 + 1:]]),
                  np.concatenate([[0.0], self._times[k0 + 1:]]), np.concatenate([[0.0], self._works[k0 + 1:]]),
                  self._controls[k0:n].copy())
        return self._result(st, planned, arrays, first, second,
                            float(self.s_nodes[m]) if first != second and m < n else None, bound, t_start)

    def _replan_cycle(self, st: TrainState, planned: float, t_start: float) -> Replan:
        """``replan`` where the air brake cycles: the cycle DP's look-up (``CycleReplanner``), the price searched as
        in ``replan`` and the switch from the faster price to the slower at a node bisected (no switch inside a
        cell: the drive arrives at most a cell's time early)."""
        cy = self.cyc
        L = self.route.length_m
        s = min(max(st.s_m, 0.0), L)
        if s >= L - 1e-6:
            return self._at_stop(st, planned, t_start)
        n = cy.n
        k0 = min(max(int(np.searchsorted(cy.s_nodes, s, side="right")) - 1, 0), n - 1)
        x0 = float(s - cy.s_nodes[k0])
        if x0 <= 1e-6:
            x0 = 0.0
        e0 = float(kinetic_e(st.v_kmh))
        s0, tau0 = cy.air_state(st)
        t_rem = planned - st.t_s
        P = len(self.prices)
        cache: dict[int, tuple[float, float]] = {}

        def run(first: int, second: int, m: int) -> tuple[float, float]:
            return cy.drive(k0, x0, e0, s0, tau0, first, second, m)[:2]

        kept: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # per price: its drive's node times and states

        def pure(i: int) -> float:
            if i not in cache:
                cache[i] = run(i, i, n)
                kept[i] = (cy.t.copy(), cy.nodes.copy())
            return cache[i][0]

        lo, hi = lowest_on_time(pure, t_rem, self._hint, P)
        m = n
        if hi == P:
            first = second = P - 1
            if not math.isfinite(pure(P - 1)):
                raise InfeasibleError(f"no drive that keeps the air brake's cycle reaches the stop from {s:.1f} m at "
                                      f"{st.v_kmh:.1f} km/h with the air brake {st.air or 'charged'}")
        elif lo < 0:
            first = second = 0
        else:
            self._hint = hi
            first, second = hi, lo
            if math.isfinite(pure(lo)) and pure(hi) < t_rem - CLOSE_S:
                # the faster price's drive (kept), with its state at each node it decides at; a switch at such a node
                # is that drive to it and the slower price's on from its state there (a switch inside a path acts
                # at the path's end): bisected over those nodes, each probe a pass over the rest of the line alone
                t_fast, nodes = kept[hi]
                decides = np.flatnonzero(nodes[k0 + 1:n, 0] >= 0.0) + k0 + 1
                rows = nodes[decides]

                def switched(j: int) -> float:
                    t_on = cy.drive_on(int(decides[j]), (rows[j], t_fast[decides[j]]), lo)[0]
                    return t_fast[decides[j]] + t_on if math.isfinite(t_on) else math.inf

                a, b = -1, len(decides)  # j = a: the slower price's drive (late); j = b: the faster one's (on time)
                t_b = pure(hi)
                while b - a > 1 and t_b < t_rem - CLOSE_S:
                    mid = (a + b) // 2
                    t_mid = switched(mid)
                    if math.isfinite(t_mid) and t_mid <= t_rem + ON_TIME_S:
                        b, t_b = mid, t_mid
                    else:
                        a = mid
                m = int(decides[b]) if b < len(decides) else n
        bound = self._optimum({i: cache[i] for i in (first, second) if i in cache}, t_rem) if hi < P else None
        t, w, n_ev = cy.drive(k0, x0, e0, s0, tau0, first, second, m)
        if not math.isfinite(t):
            raise InfeasibleError(f"no drive that keeps the air brake's cycle reaches the stop from {s:.1f} m")
        pos = np.concatenate([[s], cy.s_nodes[k0 + 1:]])
        speeds = cy.v[k0:].copy()
        times = cy.t[k0:].copy()
        works = cy.w[k0:].copy()  # (nan at the nodes a path of the air brake's cycle passes)
        works[-1] = w
        controls = CYCLE_CONDITION[cy.controls[k0:n]]
        events = cy.events(int(n_ev), st.t_s)
        res = self._result(st, planned, (pos, speeds, times, works, controls), first, second,
                           float(cy.s_nodes[m]) if first != second and m < n else None, bound, t_start)
        res.air_events = events
        return res

    def _split(self, a: int, k0: int, s: float, h0: float, g0: float, e0: float, prev: int, hi: int, lo: int,
               t_rem: float):
        """The switch from the faster price's drive to the slower one's inside cell ``a`` (between the two nodes
        whose switches bracket the time): the faster drive's condition in that cell held for a share f of it, then
        the slower price's drive from there, f bisected so that the drive arrives on time. The arrays of
        :meth:`_result` (positions, speeds, times, works from the state, controls), or None."""
        n = len(self.s_nodes) - 1
        fast = self._scratch
        if a == k0:
            x_a, e_a, h_a, g_a, p_a, t_a0, w_a0 = s, e0, h0, g0, prev, 0.0, 0.0
        else:
            x_a, e_a = float(self.s_nodes[a]), float(kinetic_e(fast[1][a]))
            h_a, g_a, p_a = float(self.cells.h[a]), float(self.cells.grav[a]), int(fast[0][a - 1])
            t_a0, w_a0 = float(fast[2][a]), float(fast[3][a])
        u = int(fast[0][a])
        kern = kernels()
        fo = self.calc.forces
        allowed = float(self.cells.allowed[a])
        # the slower drive's own condition in cell a (its drive with the switch at node a)
        self._drive(a, h_a, g_a, e_a, p_a, lo, lo, n)
        u_s = int(self._controls[a])
        last = a == n - 1
        cap_end = 0.0 if last else float(self.cells.e_cap[a + 1])

        def at(f: float):
            """The faster drive's condition for f of the cell, the slower's for the rest, the slower drive on."""
            hf = f * h_a
            cap = float(np.interp(x_a + hf, self.calc.s_m, self.calc.e_envelope))
            e_f, w_f = kern.replan_step(e_a, u, hf, g_a, allowed, cap, 0, fo)
            if e_f < 0:
                return math.inf, None
            e_2, w_2 = kern.replan_step(e_f, u_s, h_a - hf, g_a, allowed, cap_end, int(last), fo)
            v_a, v_f, v_2 = (float(ms_from_e(max(x, 0.0))) for x in (e_a, e_f, e_2))
            if e_2 < 0 or v_a + v_f <= 0 or v_f + v_2 <= 0:
                return math.inf, None
            t_1, t_2 = 2.0 * hf / (v_a + v_f), 2.0 * (h_a - hf) / (v_f + v_2)
            t_r = 0.0
            if not last:
                t_r, _ = self._drive(a + 1, float(self.cells.h[a + 1]), float(self.cells.grav[a + 1]), e_2, u_s,
                                     lo, lo, n)
            return t_a0 + t_1 + t_2 + t_r, (e_f, e_2, w_f, w_2, t_1, t_2)

        # the drive's time is not monotone in f (its decisions jump with the state): the best of a few shares that
        # arrives on time, refined by bisection towards its late neighbour
        grid = [k / SPLIT_SHARES for k in range(1, SPLIT_SHARES)]
        times_f = [at(f)[0] for f in grid]
        ok = [i for i, t_f in enumerate(times_f) if t_f <= t_rem + ON_TIME_S]
        if not ok:
            return None
        i = max(ok, key=lambda j: times_f[j])
        f_early = grid[i]
        late = [j for j in (i - 1, i + 1) if 0 <= j < len(grid) and times_f[j] > t_rem + ON_TIME_S]
        if late and t_rem - times_f[i] > CLOSE_S:
            f_late = grid[late[0]]
            for _ in range(SPLIT_BISECT):
                f = 0.5 * (f_late + f_early)
                t_f, _ = at(f)
                if t_f <= t_rem + ON_TIME_S:
                    f_early = f
                    if t_rem - t_f <= CLOSE_S:
                        break
                else:
                    f_late = f
        t_f, parts = at(f_early)
        if parts is None or not t_f <= t_rem + ON_TIME_S:
            return None
        e_f, e_2, w_f, w_2, t_1, t_2 = parts
        x_f = x_a + f_early * h_a
        t1, t2 = t_a0 + t_1, t_a0 + t_1 + t_2
        w1, w2 = w_a0 + w_f, w_a0 + w_f + w_2
        pos = np.concatenate([[s], self.s_nodes[k0 + 1:a + 1], [x_f], self.s_nodes[a + 1:]])
        speeds = np.concatenate([[float(kmh_from_e(e0))], fast[1][k0 + 1:a + 1],
                                 [float(kmh_from_e(e_f)), float(kmh_from_e(max(e_2, 0.0)))], self._speeds[a + 2:]])
        times = np.concatenate([[0.0], fast[2][k0 + 1:a + 1], [t1, t2], t2 + self._times[a + 2:]])
        works = np.concatenate([[0.0], fast[3][k0 + 1:a + 1], [w1, w2], w2 + self._works[a + 2:]])
        controls = np.concatenate([fast[0][k0:a], [u, u_s], self._controls[a + 1:n]]).astype(np.int64)
        return pos, speeds, times, works, controls

    def _optimum(self, drives: dict, t_rem: float) -> float:
        """The Lagrangian bound at the remaining time from the bracketing prices' drives (``remaining_optimum_kwh``):
        each is the least energy + lambda x time, so no drive uses less than E_i + lambda_i (T_i - T_rem)."""
        best = 0.0
        for i, (t_i, w_i) in drives.items():
            if math.isfinite(t_i):
                best = max(best, w_i / KJ_PER_KWH + float(self.prices[i]) * (t_i - max(t_rem, 0.0)))
        return best

    def inside(self, arrival_s: float, planned_s: float) -> bool:
        """``arrival_s`` keeps the window around ``planned_s`` (+- the tolerance, at least ``ON_TIME_S``)."""
        return abs(arrival_s - planned_s) <= max(self.tolerance_s, ON_TIME_S) + 1e-9

    def _at_stop(self, st: TrainState, planned: float, t_start: float) -> Replan:
        late = max(st.t_s - planned, 0.0)
        L = self.route.length_m
        return Replan(st, planned, float(st.t_s), late, self.inside(st.t_s, planned), None, None, None, 0.0, 0.0, [],
                      np.array([L]), np.array([st.v_kmh]), np.array([st.t_s]), np.array([0.0]),
                      np.zeros(0, dtype=np.int64), (0.0, 0.0), None, time.perf_counter() - t_start)

    def _result(self, st, planned, drive, first, second, switch_m, bound, t_start) -> Replan:
        """The replan of the drive from ``st``: ``drive`` is its (positions, speeds, times, works, controls)."""
        pos, speeds, times, works, controls = drive
        speeds = np.asarray(speeds, float).copy()
        speeds[0] = st.v_kmh
        runs: list[tuple[str, float]] = []
        for i, u in enumerate(controls):
            c = CONDITIONS[int(u)]
            if not runs or runs[-1][0] != c:
                runs.append((c, float(pos[i])))
        nxt = next((i for i in range(1, len(controls)) if controls[i] != controls[0]), None)
        t, w = float(times[-1]), float(works[-1])
        arrival = st.t_s + t
        late = max(arrival - planned, 0.0)
        return Replan(st, planned, float(arrival), float(late), self.inside(arrival, planned),
                      CONDITIONS[int(controls[0])], None if nxt is None else float(pos[nxt]),
                      float(speeds[nxt]) if nxt is not None else 0.0, w / KJ_PER_KWH, bound, runs, pos, speeds,
                      st.t_s + times, works / KJ_PER_KWH, controls,
                      (float(self.prices[first]), float(self.prices[second])), switch_m,
                      time.perf_counter() - t_start)


CYCLE_CONDITION = np.array([0, 1, 2, 3, 4, 1], dtype=np.int64)
"""The cycle DP's controls (``cycle_kernel.U_*``: T, H, C, B, E, K) as condition codes (T, K, C, B, E, K: the air
brake kept on while the speed is held is a hold, K)."""


class CycleReplanner:
    """The look-up where the air brake cycles (``cycle_dp``): the cycle DP (``CycleDPSolver``, on cells of about
    ``CELL_M`` and a speed grid of ``SPEED_STEP_KMH``) solved backward at a ladder of prices around the one whose
    drive from rest takes ``planned_s``; every price's cost-to-go and recharge deadlines kept; a drive from any
    state (position, speed, the air brake's state and time since its release) is ``cycle_kernel``'s forward pass
    from it (``cycle_forward_from``), the faster price's cost-to-go to a node, the slower one's from it."""

    def __init__(self, calc: TractionCalculator, planned_s: float, prices: np.ndarray | None = None):
        from .cycle_dp import CycleDPSolver, grid_calculator

        self.solver = CycleDPSolver(grid_calculator(calc, CELL_M), CELL_M, SPEED_STEP_KMH)
        sv = self.solver
        self.t_rec = float(sv.cells.t_rec)
        if prices is None:
            prices = _ladder(self._price_for(float(planned_s)))
        self.prices = np.ascontiguousarray(prices, dtype=float)
        self.s_nodes = sv.s_m
        self.n = len(self.s_nodes) - 1
        P = len(self.prices)
        self.V = np.empty((P,) + sv._V.shape)
        self.DL = np.empty((P,) + sv.tables.dl.shape)
        k = kernels()
        for i, p in enumerate(self.prices):
            k.cycle_backward(sv.cells, sv.calc.forces, float(p), self.V[i], sv.tables)
            self.DL[i] = sv.tables.dl
        self.tables = [sv.tables._replace(dl=self.DL[i]) for i in range(P)]
        n = self.n
        self.controls = np.zeros(n, dtype=np.int64)
        self.air = np.zeros(n, dtype=np.int64)
        self.v = np.zeros(n + 1)
        self.t = np.zeros(n + 1)
        self.w = np.zeros(n + 1)
        self.nodes = np.zeros((n + 1, 4))
        self.ev = np.zeros((4 * n + 16, 3))
        self.ev_k = np.zeros(4 * n + 16, dtype=np.int64)

    def _price_for(self, t_s: float) -> float:
        """The lowest price of time (within ``PRICE_CLOSE``) whose drive from rest takes no more than ``t_s``:
        geometric bisection over ``PRICE_RANGE`` (the drive's time falls as the price rises, in steps)."""
        lo, hi = PRICE_RANGE
        d = self.solver.solve(hi)
        if d is None or d.time_s > t_s:
            return hi
        d = self.solver.solve(lo)
        if d is not None and d.time_s <= t_s:
            return lo
        while hi / lo > PRICE_CLOSE:
            mid = math.sqrt(lo * hi)
            d = self.solver.solve(mid)
            if d is not None and d.time_s <= t_s:
                hi = mid
            else:
                lo = mid
        return hi

    def air_state(self, st: TrainState) -> tuple[int, float]:
        """The kernel's air state (``cycle_kernel.CH``, ``AF``, ``R0``) and the time since the release [s]."""
        from .cycle_kernel import AF, CH, R0

        if st.air == "applied":
            return AF, 0.0
        if st.air == "recharging" and st.recharge_left_s is not None and st.recharge_left_s > 1e-9:
            return R0, max(self.t_rec - float(st.recharge_left_s), 0.0)
        return CH, 0.0

    def drive(self, k0: int, x0: float, e0: float, s0: int, tau0: float, first: int, second: int, m: int):
        """The forward pass from the state (``cycle_forward_from``): (time [s], traction work [kJ], events)."""
        sv = self.solver
        self.w.fill(np.nan)
        t, w, n_ev = kernels().cycle_forward_from(sv.cells, sv.calc.forces, float(self.prices[first]), self.V[first],
                                                  self.tables[first], float(self.prices[second]), self.V[second],
                                                  self.tables[second], m, k0, x0, e0, s0, tau0, 0.0, 0, self.controls,
                                                  self.air, self.v, self.t, self.w, self.nodes, self.ev, self.ev_k)
        return float(t), float(w), n_ev

    def drive_on(self, k: int, state, price: int) -> tuple[float, float]:
        """The drive at price index ``price`` on from node ``k`` in the state another drive decided at there
        (``state``: its row of ``nodes`` and its time at k [s]): (time [s], traction work [kJ]) from node k."""
        sv = self.solver
        (s, tau, hold, e), t_k = state
        self.w.fill(np.nan)
        p, V, tb = float(self.prices[price]), self.V[price], self.tables[price]
        t, w, _ = kernels().cycle_forward_from(sv.cells, sv.calc.forces, p, V, tb, p, V, tb, k, k, 0.0, float(e),
                                               int(s), float(tau), float(hold - t_k), 1, self.controls, self.air,
                                               self.v, self.t, self.w, self.nodes, self.ev, self.ev_k)
        return float(t), float(w)

    def events(self, n_ev: int, t0_s: float) -> list:
        """The last drive's air brake events as (position [m], clock [s], speed [km/h], kind)."""
        from .cycle_kernel import EV_APPLY, EV_CHARGED, EV_RELEASE

        names = {EV_APPLY: "apply", EV_RELEASE: "release", EV_CHARGED: "charged"}
        m = int(n_ev)
        where = self.solver._where(self.ev[:m, 0])
        return [(float(where[i]), t0_s + float(self.ev[i, 1]), float(self.ev[i, 2]), names[int(self.ev_k[i])])
                for i in range(m)]


def lowest_on_time(time_of, t_rem: float, hint: int, n_prices: int) -> tuple[int, int]:
    """The lowest price index whose drive (``time_of(i)``: its running time [s]) arrives within ``t_rem`` [s]
    (time falls as the price rises), as the bracket (lo, hi) with hi that index: from ``hint`` (the last
    re-plan's), galloping out, then bisection; lo = -1: every price's drive does, hi = ``n_prices``: none does."""

    def on_time(i: int) -> bool:
        t_i = time_of(i)
        return math.isfinite(t_i) and t_i <= t_rem + ON_TIME_S

    j = min(max(hint, 0), n_prices - 1)
    step = 1
    if on_time(j):
        hi, lo = j, j - 1
        while lo >= 0 and on_time(lo):
            hi, lo, step = lo, lo - step, 2 * step
        lo = max(lo, -1)
    else:
        lo, hi = j, j + 1
        while hi < n_prices and not on_time(hi):
            lo, hi, step = hi, hi + step, 2 * step
        hi = min(hi, n_prices)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if on_time(mid):
            hi = mid
        else:
            lo = mid
    return lo, hi
