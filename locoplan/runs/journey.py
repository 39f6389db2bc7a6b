"""A journey planned whole: the running time shared out among its legs for the least energy, every leg
planned at its share, and the allocation compared with the usual ones.

1. The line is cut at the stops into legs (``model.route.route_slice``); a timing point inside a leg is a
   node of that leg's grid.
2. The allocation: the joint minimum-energy problem of the legs (``ocp.journey_energy``) with the total
   running time and a window on the running time at every station (the timetable's clock less the
   dwells before it). At its optimum the marginal energy dE_i*/dT_i is equal on every leg not held by a
   window; each leg's time is read off it.
3. Each leg's E* at its time, solved on its own to E*'s tolerance (``ocp.bound.energy_bound``, or with the
   windows of its timing points); the journey's E* is their sum, its accuracy the sum of theirs.
4. Each strategy asked for (``proposed`` by default) plans the legs one after the other: a leg's plan is
   asked for a window inside the bounds that keep every station window ahead and the total
   (``arrival_bounds``), centred as near as they allow on the allocation's clock at the leg's end from where
   the plans so far have brought the train (``leg_window``), so that what one leg runs late the next makes
   up; a plan of a strategy that keeps time that still misses its bounds is planned again, asked for a time
   moved by its miss. Every station's clock in the plans is checked against its window, the legs' total against the
   journey's running time +- its tolerance (``total_tolerance``); every plan's gap to its leg's E*.
5. The same legs' E* at the equal-percentage allocation (every leg's fastest run times the same factor)
   and at the timetable's own leg times where it gives them: what the optimal allocation saves.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.journey import Journey
from ..model.route import Route, route_slice
from ..model.train import Train
from ..settings import RunSettings
from ..sim.calculator import ModelOptions, TractionCalculator

ALLOCATION_STEP_M = 40.0
"""The joint problem's first grid [m]; the allocation comes from it and from the grid of half its cells."""


@dataclass(frozen=True)
class Leg:
    """A stop-to-stop part of the journey: its stations (indices), route, start along the line [m], the
    timing points inside it (station indices and positions from its start) and its fastest run [s]."""

    index: int
    first: int
    last: int
    route: Route
    from_m: float
    points: list[tuple[int, float]]
    fastest_s: float


@dataclass
class JourneyResult:
    """Everything ``locoplan journey`` reports: the summary (``summary``, JSON-ready), the legs, each leg's
    plans (strategy -> runner.RunResult), and the whole run's profile pieces for the plot and the CSV."""

    summary: dict
    legs: list[Leg]
    dwells: list[float] = field(default_factory=list)
    """The dwell at each leg's last stop [s]."""
    runs: list[dict] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)


def legs_of(journey: Journey, route: Route, train: Train, options: ModelOptions) -> list[Leg]:
    stops = journey.stops
    legs = []
    for k, (a, b) in enumerate(zip(stops[:-1], stops[1:])):
        sa, sb = journey.stations[a], journey.stations[b]
        r = route_slice(route, sa.at_m, sb.at_m, f"{route.name}: {sa.name} - {sb.name}")
        points = [(i, journey.stations[i].at_m - sa.at_m) for i in range(a + 1, b)]
        calc = TractionCalculator(r, train, options)
        res = calc.evaluate(("T",), np.zeros((1, 0)))
        if not res.feasible[0]:
            raise InfeasibleError(f"{train.name} cannot run the leg {sa.name} - {sb.name}: {res.reason(0)}")
        legs.append(Leg(k, a, b, r, sa.at_m, points, float(res.running_time_s[0])))
    return legs


def dwell_before(journey: Journey, i: int) -> float:
    """Seconds stood at the stops between the departure and station ``i`` (its own dwell excluded)."""
    return float(sum(s.dwell_s for s in journey.stations[1:i] if s.stop))


def running_windows(journey: Journey) -> list[tuple[int, float | None, float | None]]:
    """Each station's window as running time since the departure (its clock less the dwells before it)."""
    out = []
    for i, st in enumerate(journey.stations[1:], start=1):
        lo, hi = st.earliest_s, st.latest_s
        if lo is None and hi is None:
            continue
        d = dwell_before(journey, i)
        out.append((i, None if lo is None else lo - d, None if hi is None else hi - d))
    return out


def total_running_time(journey: Journey, time_s: float | None, source: str) -> float:
    """``time_s`` (the command line's), else the journey's ``run_time_s``, else the last station's
    scheduled time less the dwells."""
    if time_s is not None:
        return float(time_s)
    if journey.run_time_s is not None:
        return float(journey.run_time_s)
    last = journey.stations[-1]
    if last.time_s is not None:
        return float(last.time_s - dwell_before(journey, len(journey.stations) - 1))
    raise InputError(Problem(source, "run_time_s", "the journey gives no running time (no run_time_s, no time_s at "
                             "its last station): give --time as seconds (3000), a factor of the fastest run (1.15x) "
                             "or a supplement on it (+10%)"))


def fastest_clock(journey: Journey, legs: list[Leg], train: Train, options: ModelOptions) -> dict[int, float]:
    """The fastest run's running time at every station (stops and timing points) [s]."""
    out, t = {0: 0.0}, 0.0
    for leg in legs:
        if leg.points:
            calc = TractionCalculator(leg.route, train, options)
            prof = calc.evaluate(("T",), np.zeros((1, 0)), profile=True).profile
            for i, at in leg.points:
                out[i] = t + float(np.interp(at, prof.s_m, prof.t_s[0]))
        t += leg.fastest_s
        out[leg.last] = t
    return out


def check_windows(journey: Journey, legs: list[Leg], total_s: float, fastest: dict[int, float], source: str) -> None:
    """Refuse, naming the station, a window no run can meet: its latest running time before the fastest
    run gets there, or its earliest so late that the rest cannot be run in what is left."""
    problems = []
    fastest_total = sum(leg.fastest_s for leg in legs)
    if total_s < fastest_total - 1e-6:
        raise InfeasibleError(f"the journey's running time {total_s:.1f} s is below its fastest run, "
                              f"{fastest_total:.1f} s (dwells excluded)")
    for i, lo, hi in running_windows(journey):
        st = journey.stations[i]
        d = dwell_before(journey, i)
        if hi is not None and hi < fastest[i] - 1e-6:
            problems.append(f"{st.name}: latest_s {st.latest_s:g} s is before the fastest run gets there "
                            f"({fastest[i] + d:.1f} s, dwells included)")
        rest = fastest_total - fastest[i]
        if lo is not None and lo > total_s - rest + 1e-6:
            problems.append(f"{st.name}: earliest_s {st.earliest_s:g} s leaves {total_s - lo:.1f} s of running for the "
                            f"rest of the journey, whose fastest run takes {rest:.1f} s")
    if problems:
        raise InfeasibleError("no run keeps the journey's windows: " + "; ".join(problems))


@dataclass(frozen=True)
class LegBound:
    """A leg's E* at a running time: [kWh], its relative accuracy, dE*/dT [kWh/s], the cells it was solved on."""

    time_s: float
    energy_kwh: float
    accuracy: float | None
    slope_kwh_per_s: float | None
    converged: bool


def leg_bound(leg: Leg, train: Train, options: ModelOptions, time_s: float, depart_run_s: float,
              journey: Journey) -> LegBound:
    """E* of one leg in ``time_s``; with timing points inside it, with their windows (running time since the
    journey's departure less ``depart_run_s``, the running time when the leg starts)."""
    from ..ocp.bound import E_STAR_TOL, energy_bound, percent_floor_kwh

    if not leg.points:
        b = energy_bound(leg.route, train, options, time_s)
        return LegBound(time_s, b.energy_kwh, b.accuracy, b.slope_kwh_per_s, b.converged)
    from ..ocp.journey_energy import journey_estar

    wins = {i: (lo, hi) for i, lo, hi in running_windows(journey)}
    windows = [(at, None if wins.get(i, (None, None))[0] is None else wins[i][0] - depart_run_s,
                None if wins.get(i, (None, None))[1] is None else wins[i][1] - depart_run_s)
               for i, at in leg.points if i in wins]
    e = journey_estar([leg.route], [0.0], train, options, time_s, windows, tol=E_STAR_TOL,
                      floor_kwh=percent_floor_kwh(leg.route, train), points_m=[[at for _, at in leg.points]])
    return LegBound(time_s, e.energy_kwh, e.accuracy, e.finest.solution.slope_kwh_per_s, e.converged)


def allocate(journey: Journey, legs: list[Leg], train: Train, options: ModelOptions, total_s: float):
    """The joint optimum's running time for each leg [s] and at every station (running time) [s]."""
    from ..ocp.journey_energy import journey_estar

    windows = [(journey.stations[i].at_m, lo, hi) for i, lo, hi in running_windows(journey)]
    e = journey_estar([leg.route for leg in legs], [leg.from_m for leg in legs], train, options, total_s, windows,
                      tol=0.0, points_m=[[at for _, at in leg.points] for leg in legs],
                      coarse_step_m=ALLOCATION_STEP_M, finest_step_m=ALLOCATION_STEP_M / 2)
    at = {i: e.time_at(st.at_m) for i, st in enumerate(journey.stations)}
    return np.array(e.leg_time_s), at


def allocation_energy(journey, legs, train, options, times) -> tuple[float, list[LegBound]]:
    """Σ E_i*(T_i) for fixed leg times, each leg solved on its own."""
    bounds, run = [], 0.0
    for leg, t in zip(legs, times):
        bounds.append(leg_bound(leg, train, options, float(t), run, journey))
        run += float(t)
    return float(sum(b.energy_kwh for b in bounds)), bounds


WINDOW_SLACK_S = 0.05
"""A clock within this of a window's bound keeps the window: half the 0.1 s the times are reported to, so that a
clock shown inside its window is inside it."""


def outside_window(station, clock_s: float) -> bool:
    """The clock [s since departure] at ``station`` misses its window (by more than ``WINDOW_SLACK_S``)."""
    return (station.earliest_s is not None and clock_s < station.earliest_s - WINDOW_SLACK_S) or (
        station.latest_s is not None and clock_s > station.latest_s + WINDOW_SLACK_S)


def window_misses(journey: Journey, legs: list[Leg], times) -> list[str]:
    """Stops whose window an allocation of leg times misses (arrival clock against the window)."""
    out, run = [], 0.0
    for leg, t in zip(legs, times):
        run += float(t)
        st = journey.stations[leg.last]
        clock = run + dwell_before(journey, leg.last)
        if outside_window(st, clock):
            out.append(f"{st.name} at {clock:.1f} s")
    return out


def timetable_times(journey: Journey, legs: list[Leg]) -> list[float] | None:
    """The timetable's own leg times where it schedules every stop: arrival less the previous departure."""
    sched = [journey.stations[leg.last].time_s for leg in legs]
    if any(t is None for t in sched):
        return None
    out, depart = [], 0.0
    for leg, t in zip(legs, sched):
        out.append(float(t) - depart)
        depart = float(t) + journey.stations[leg.last].dwell_s
    return out


def _window_text(st) -> str:
    return f"{'' if st.earliest_s is None else f'{st.earliest_s:g}'} .. {'' if st.latest_s is None else f'{st.latest_s:g}'} s"


def timing_passes(leg: Leg, run, journey: Journey, clock_at_departure: float) -> list[tuple[int, float]]:
    """When a leg's plan passes the timing points inside it (clock, dwells included) [s]."""
    if not leg.points or not run.summary.get("feasible") or run.result.profile is None:
        return []
    prof = run.result.profile
    return [(i, clock_at_departure + float(np.interp(at, prof.s_m, prof.t_s[0]))) for i, at in leg.points]


JOURNEY_TOLERANCE_SHARE = 0.01
"""Without a tolerance given, the legs' plans add up to the journey's running time within +- this share of its
mean leg's time (at least 1 s): the window one leg of average length gets on its own, so that the legs' errors
cannot add up over the journey."""
MIN_LEG_TOLERANCE_S = 0.5
"""The narrowest punctuality window a leg's plan is asked to keep, +- [s] (a leg squeezed between a late
departure and a station's latest time gets this around the middle of what is left)."""
MAX_REPLANS = 2
"""A timetabled strategy's leg plan that ends outside its leg's bounds (or passes a timing point inside it out
of its window) is planned again, at most this many times, each time asked for a time moved by the miss (and
half its new window inside), the window halved; the plan that misses least is kept."""


def total_tolerance(total_s: float, n_legs: int, tolerance_s: float | None = None) -> float:
    """The journey's punctuality window on its total running time, +- [s]: ``tolerance_s`` where given, else
    ``JOURNEY_TOLERANCE_SHARE`` of its mean leg's running time, at least 1 s."""
    if tolerance_s is not None:
        return float(tolerance_s)
    return max(1.0, JOURNEY_TOLERANCE_SHARE * total_s / max(n_legs, 1))


def arrival_bounds(journey: Journey, legs: list[Leg], k: int, fastest: dict[int, float], total_s: float,
                   total_tol_s: float) -> tuple[float, float]:
    """Where leg ``k`` may end on the running clock (running time since the departure, dwells excluded) [s]:
    inside its stop's window; early enough that the fastest run from there still keeps every later station's
    latest time and the total's tolerance; late enough for the earliest time of a timing point inside it with
    the fastest run from there; the last leg within the total's tolerance. ``fastest``: :func:`fastest_clock`."""
    leg = legs[k]
    lo, hi = -math.inf, math.inf
    for i, w_lo, w_hi in running_windows(journey):
        if i == leg.last:
            lo = lo if w_lo is None else max(lo, w_lo)
            hi = hi if w_hi is None else min(hi, w_hi)
        elif i > leg.last and w_hi is not None:
            hi = min(hi, w_hi - (fastest[i] - fastest[leg.last]))
        elif leg.first < i < leg.last and w_lo is not None:
            lo = max(lo, w_lo + (fastest[leg.last] - fastest[i]))
    hi = min(hi, total_s + total_tol_s - sum(x.fastest_s for x in legs[k + 1:]))
    if k == len(legs) - 1:
        lo = max(lo, total_s - total_tol_s)
    return lo, hi


@dataclass(frozen=True)
class LegWindow:
    """What a leg's plan is asked for, in the leg's own running time [s]: ``t0_s`` +- ``tolerance_s``, inside the
    bounds ``lo_s`` .. ``hi_s`` (:func:`arrival_bounds` less the departure) and as near as they allow to
    ``target_s``, the time that brings the clock back to the allocation's at the leg's end."""

    lo_s: float
    hi_s: float
    target_s: float
    t0_s: float
    tolerance_s: float


def leg_window(lo_s: float, hi_s: float, target_s: float, fastest_s: float, half_s: float) -> LegWindow:
    """The window ``t0_s`` +- ``tolerance_s`` (at most ``half_s``, at least ``MIN_LEG_TOLERANCE_S``) inside
    ``lo_s`` .. ``hi_s``, centred as near ``target_s`` as it fits, never below the fastest run ``fastest_s``. Where
    the bounds leave no room (an earlier leg ran late), the window sits at the latest end that keeps the stations
    ahead, or at the fastest run."""
    b = max(hi_s, fastest_s)
    a = min(max(lo_s, fastest_s), b)
    tol = max(MIN_LEG_TOLERANCE_S, min(half_s, (b - a) / 2))
    t0 = min(max(target_s, a + tol), b - tol) if b - a >= 2 * tol else (a + b) / 2
    return LegWindow(lo_s, hi_s, target_s, max(t0, fastest_s), tol)


def _leg_misses(leg: Leg, run, w: LegWindow, depart_run_s: float, wins: dict,
                margin_s: float) -> tuple[float, float | None]:
    """How far a leg's plan misses [s] (its end outside the bounds of ``w``, a timing point inside the leg outside
    its window; inf: no feasible plan), and by how much to move the time asked of the plan made again [s]: the
    least shift that would bring each miss ``margin_s`` inside (with the plan's own offset from what it was asked
    unchanged) and keep its end inside the bounds; None where no shift does (nothing to plan again)."""
    s = run.summary
    if not s.get("feasible"):
        return math.inf, None
    p = float(run.result.running_time_s[0])
    miss = max(0.0, p - w.hi_s) + max(0.0, w.lo_s - p)
    room = 0.5 * (w.hi_s - w.lo_s)
    m = min(margin_s, room) if room >= 0 else 0.0
    lo, hi = w.lo_s + m - p, w.hi_s - m - p  # shifts that keep the end inside, ``m`` from its bounds
    prof = run.result.profile
    for i, at in leg.points:
        if i not in wins or prof is None:
            continue
        w_lo, w_hi = wins[i]
        passes = depart_run_s + float(np.interp(at, prof.s_m, prof.t_s[0]))
        late = 0.0 if w_hi is None else passes - w_hi
        early = 0.0 if w_lo is None else w_lo - passes
        if late > 0:  # the whole leg a little faster passes the point earlier too
            miss, hi = miss + late, min(hi, -late - margin_s)
        if early > 0:
            miss, lo = miss + early, max(lo, early + margin_s)
    if miss <= 0 or hi < lo:
        return miss, None
    return miss, min(max(0.0, lo), hi)


@dataclass
class LegPlan:
    """One strategy's plan of one leg: the run (``runner.RunResult``), the window it was asked to keep, how many
    times it was planned again, its departure clock [s, dwells included] (None after a leg without a feasible
    plan) and the JSON row."""

    run: object
    window: LegWindow
    replans: int
    departs_s: float | None
    row: dict


@dataclass
class StrategyPlans:
    """One strategy's plans of every leg, each station's clock in them (arrival at a stop, passing at a timing
    point; None where unknown) and what fails the journey's job."""

    name: str
    must_keep_time: bool
    legs: list[LegPlan] = field(default_factory=list)
    clock: dict[int, float | None] = field(default_factory=dict)
    missed: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)

    @property
    def feasible(self) -> bool:
        return all(lp.run.summary.get("feasible") for lp in self.legs)

    def station(self, journey: Journey, i: int) -> dict:
        """Station ``i``'s clock in the plans [s] and whether it keeps the station's window (None: no window)."""
        t = self.clock.get(i)
        st = journey.stations[i]
        held = st.earliest_s is not None or st.latest_s is not None
        return {"clock_s": None if t is None else round(t, 1),
                "in_window": None if t is None or not held else not outside_window(st, t)}

    def summary(self, total_s: float, total_tol_s: float, pct) -> dict:
        """The plans' totals: energies, running time against the journey's (``punctuality_error_s``), the gap to
        the legs' E* at the plans' own times, ``punctual`` (the total within its tolerance and every window kept),
        the windows missed."""
        ok = self.feasible
        s = [lp.run.summary for lp in self.legs]
        e = sum(float(x["traction_energy_kwh"]) for x in s) if ok else math.nan
        rec = [x.get("recovered_energy_kwh") for x in s]
        rec_sum = math.nan if not ok or any(r is None for r in rec) else float(sum(rec))
        gaps = [x.get("gap_to_optimum_kwh") for x in s]
        gap = math.nan if not ok or any(g is None for g in gaps) else float(sum(gaps))
        t = sum(float(x["running_time_s"]) for x in s) if ok else math.nan
        return {"traction_energy_kwh": None if math.isnan(e) else round(e, 3),
                "recovered_energy_kwh": None if math.isnan(rec_sum) else round(rec_sum, 3),
                "net_energy_kwh": None if math.isnan(rec_sum) else round(e - rec_sum, 3),
                "running_time_s": None if math.isnan(t) else round(t, 1),
                "punctuality_error_s": None if math.isnan(t) else round(t - total_s, 1),
                "window_s": [round(total_s - total_tol_s, 1), round(total_s + total_tol_s, 1)],
                "punctual": None if not ok else bool(abs(t - total_s) <= total_tol_s + 1e-6 and not self.missed),
                "windows_missed": list(self.missed),
                "gap_to_optimum_kwh": None if math.isnan(gap) else round(gap, 3),
                "gap_to_optimum_percent": None if math.isnan(gap) else pct(e, e - gap)}


@dataclass(frozen=True)
class _Allocation:
    """What a journey's legs are planned by: its legs and train, the allocated leg times with their E* bounds
    (:func:`allocation_energy`), the fastest clock, the total running time and its window +-."""

    journey: Journey
    legs: list[Leg]
    train: Train
    times: object
    bounds: list[LegBound]
    fastest: dict[int, float]
    total_s: float
    total_tol_s: float


def _plan_legs(alloc: _Allocation, name: str, settings: RunSettings, *, inputs, with_fitness: bool,
               strict: bool | None, shared: dict, step) -> StrategyPlans:
    """Plan every leg with strategy ``name``, one after the other. Each leg's plan is asked for a window inside
    the bounds that keep every station window ahead and the total (:func:`arrival_bounds`), aimed at the
    allocation's clock at the leg's end from where the plans so far have brought the train: what an earlier leg
    ran late or early, the next one makes up, and the windows' slack left is what the next legs' bounds see.
    A timetabled strategy's plan that misses its bounds is made again (``MAX_REPLANS``). ``settings``: the run's,
    each leg's at its own planned time and window. ``shared``: leg index ->
    (calculators, priced-drive DP) of the strategies planned before, reused (a DP solve rewrites its work arrays,
    so reuse cannot change a result)."""
    from ..runner import DEFAULT_TOLERANCE_SHARE, make_context, run_strategy, summarize
    from ..strategy import registry

    journey, legs, train, times, bounds = alloc.journey, alloc.legs, alloc.train, alloc.times, alloc.bounds
    fastest, total_s, total_tol_s = alloc.fastest, alloc.total_s, alloc.total_tol_s
    steer = registry.is_timetabled(name)
    out = StrategyPlans(name, (steer and settings.window) if strict is None else bool(strict))
    wins = {i: (lo, hi) for i, lo, hi in running_windows(journey)}
    alloc_end = np.cumsum(np.asarray(times, dtype=float))
    run_clock, known = 0.0, True  # the running time at the leg's departure; False after a leg without a plan
    out.clock[0] = 0.0
    given = settings.tolerance_s
    for leg, b in zip(legs, bounds):
        k = leg.index
        sa, sb = journey.stations[leg.first], journey.stations[leg.last]
        step(f"leg {k + 1}: {name}")
        lo, hi = arrival_bounds(journey, legs, k, fastest, total_s, total_tol_s)
        target = float(alloc_end[k]) - run_clock
        half = given if given is not None else max(1.0, DEFAULT_TOLERANCE_SHARE * target)
        first = leg_window(lo - run_clock, hi - run_clock, target, leg.fastest_s, half)
        calcs, dp = shared.get(k, (None, None))  # the leg's calculators and DP, as another strategy left them
        w, best = first, None
        for attempt in range(1 + (MAX_REPLANS if steer else 0)):
            ctx = make_context(leg.route, train, settings.replace(time_s=w.t0_s, tolerance_s=w.tolerance_s,
                                                                  yardstick=False), calculators=calcs)
            calcs = (ctx.calc, ctx.search)
            if dp is not None:
                ctx.priced_drive = dp
            ctx.inputs.update(dict(inputs))
            if b.slope_kwh_per_s is not None and b.slope_kwh_per_s < 0:  # the leg's price of time: where its drive is
                ctx.price_hint_kwh_per_s = -b.slope_kwh_per_s
            run = run_strategy(ctx, name, with_fitness=with_fitness)
            dp = ctx.priced_drive if ctx.priced_drive is not None else dp
            tol = max(MIN_LEG_TOLERANCE_S, w.tolerance_s / 2)  # the window of a plan made again
            miss, shift = _leg_misses(leg, run, first, run_clock, wins, margin_s=tol)
            if best is None or miss < best[0]:
                best = (miss, run, ctx, w, attempt)
            if miss <= 0 or not steer or shift is None:
                break
            w = replace(w, t0_s=max(w.t0_s + shift, leg.fastest_s), tolerance_s=tol)
        shared[k] = (calcs, dp)
        miss, run, ctx, w, attempt = best
        ctx.yardstick = True  # the gap to E* of the plan kept only (each is an E* at the plan's own time)
        run = replace(run, summary=summarize(ctx, name, run.outcome, run.result, with_fitness))
        s = run.summary
        departs = run_clock + dwell_before(journey, leg.first) + (sa.dwell_s if leg.first else 0.0) if known else None
        row = {key: s.get(key) for key in ("feasible", "running_time_s", "traction_energy_kwh", "gap_to_optimum_kwh",
                                           "gap_to_optimum_percent", "reason", "recovered_energy_kwh", "net_energy_kwh")
               if key in s}
        row.update(planned_time_s=round(w.t0_s, 1), tolerance_s=round(w.tolerance_s, 2), replans=attempt,
                   departs_s=None if departs is None else round(departs, 1))
        if not s.get("feasible"):
            out.failures.append(f"leg {k + 1} ({sa.name} - {sb.name}): {name}: no feasible plan ({s.get('reason')})")
            known = False
            run_clock = float(alloc_end[k])  # the legs after it are planned from the allocation's clock
        else:
            if known:
                for i, t in timing_passes(leg, run, journey, clock_at_departure=departs):
                    out.clock[i] = t
                    row.setdefault("passes_s", {})[journey.stations[i].name] = round(t, 1)
            run_clock += float(run.result.running_time_s[0])
            if known:
                out.clock[leg.last] = run_clock + dwell_before(journey, leg.last)
                row["arrives_s"] = round(out.clock[leg.last], 1)
        out.legs.append(LegPlan(run, w, attempt, departs, row))
    for i, st in enumerate(journey.stations):
        t = out.clock.get(i)
        if t is None or not outside_window(st, t):
            continue
        out.missed.append(f"{st.name} at {t:.1f} s")
        if out.must_keep_time:
            k = next(leg.index for leg in legs if leg.first < i <= leg.last)
            a, b = journey.stations[legs[k].first].name, journey.stations[legs[k].last].name
            out.failures.append(f"leg {k + 1} ({a} - {b}): {name} {'arrives at' if st.stop else 'passes'} {st.name} at "
                                f"{t:.1f} s, outside its window {_window_text(st)} (clock since the departure, dwells "
                                "included)")
    if out.must_keep_time and out.feasible:
        t = sum(float(lp.run.summary["running_time_s"]) for lp in out.legs)
        if abs(t - total_s) > total_tol_s + 1e-6:
            out.failures.append(f"{name}: the legs' plans run {t:.1f} s in all, outside the journey's running time "
                                f"{total_s:g} +- {total_tol_s:.1f} s (dwells excluded)")
    return out


def plan_journey(journey: Journey, route: Route, train: Train, settings: RunSettings | None = None, *,
                 strategies: tuple[str, ...] = ("proposed",), strict: bool | None = None, inputs=(),
                 with_fitness: bool = True, source: str = "", step=lambda text: None) -> JourneyResult:
    """Plan ``journey`` (see the module docstring); ``settings.time_s``: the total running time (dwells excluded),
    default the journey's; ``step(text)`` is told what is being done. ``settings`` are a single run's
    (``runner.make_context``), applied to every leg at the leg's planned time and window; ``settings.tolerance_s``
    is the total's punctuality window +- (default :func:`total_tolerance`) and the widest a leg's plan is asked to
    keep. ``inputs`` and ``with_fitness`` go to every leg's run; ``strict`` as ``runner.schedule_verdict``'s:
    whether a missed window or total fails every strategy (True), none (False), or the timetabled ones (None)."""
    from ..ocp.bound import percent_digits, percent_floor_kwh

    t_start = _time.perf_counter()
    settings = settings if settings is not None else RunSettings()
    options = settings.options
    legs = legs_of(journey, route, train, options)
    total = total_running_time(journey, settings.time_s, source)
    fastest = fastest_clock(journey, legs, train, options)
    check_windows(journey, legs, total, fastest, source)
    step("allocation")
    times, at = allocate(journey, legs, train, options, total)
    step("E* of the legs")
    e_opt, bounds = allocation_energy(journey, legs, train, options, times)
    floor = sum(percent_floor_kwh(leg.route, train) for leg in legs)
    abs_acc = sum((b.accuracy if b.accuracy is not None else math.inf) * max(abs(b.energy_kwh), percent_floor_kwh(leg.route, train))
                  for b, leg in zip(bounds, legs))
    accuracy = abs_acc / max(abs(e_opt), floor, 1e-9)
    slopes = [b.slope_kwh_per_s for b in bounds]
    # comparisons
    fast = np.array([leg.fastest_s for leg in legs])
    comparisons = []
    step("equal supplements")
    eq = fast * (total / fast.sum())
    e_eq, _ = allocation_energy(journey, legs, train, options, eq)
    comparisons.append(("equal supplements", eq, e_eq))
    tt = timetable_times(journey, legs)
    if tt is not None and all(t >= f - 1e-6 for t, f in zip(tt, fast)):
        scale = total / sum(tt)
        tts = np.array(tt) * scale
        step("timetable's leg times")
        e_tt, _ = allocation_energy(journey, legs, train, options, tts)
        comparisons.append(("timetable's leg times" if abs(scale - 1) < 1e-9 else "timetable's shares of the time", tts, e_tt))
    result = JourneyResult({}, legs, [journey.stations[leg.last].dwell_s for leg in legs])
    total_tol = total_tolerance(total, len(legs), settings.tolerance_s)
    shared: dict = {}
    alloc = _Allocation(journey, legs, train, times, bounds, fastest, total, total_tol)
    plans = {name: _plan_legs(alloc, name, settings, inputs=inputs, with_fitness=with_fitness, strict=strict,
                              shared=shared, step=step)
             for name in strategies}
    leg_rows = []
    for leg, t, b in zip(legs, times, bounds):
        sa, sb = journey.stations[leg.first], journey.stations[leg.last]
        leg_rows.append({"leg": leg.index + 1, "from": sa.name, "to": sb.name, "length_m": round(leg.route.length_m, 1),
                         "fastest_s": round(leg.fastest_s, 1), "allocated_time_s": round(float(t), 1),
                         "optimum_kwh": round(b.energy_kwh, 3),
                         "optimum_accuracy_percent": None if b.accuracy is None else float(f"{100 * b.accuracy:.2g}"),
                         "marginal_kwh_per_s": None if b.slope_kwh_per_s is None else round(b.slope_kwh_per_s, 4),
                         "arrival_s": round(at[leg.last] + dwell_before(journey, leg.last), 1),
                         "window_s": [sb.earliest_s, sb.latest_s],
                         "plans": {name: plans[name].legs[leg.index].row for name in strategies}})
    for leg in legs:  # the runs in the order the legs are driven, each strategy's in turn
        for name in strategies:
            lp = plans[name].legs[leg.index]
            result.runs.append({"leg": leg.index, "strategy": name, "run": lp.run, "clock_s": lp.departs_s})
    for name in strategies:
        result.failures.extend(plans[name].failures)
    stations = []
    for i, st in enumerate(journey.stations):
        stations.append({"station": st.name, "at_m": st.at_m, "stop": st.stop, "dwell_s": st.dwell_s,
                         "scheduled_s": st.time_s, "window_s": [st.earliest_s, st.latest_s],
                         "optimum_s": round(at[i] + dwell_before(journey, i), 1),
                         "fastest_s": round(fastest[i] + dwell_before(journey, i), 1) if i in fastest else None,
                         "plans": {name: plans[name].station(journey, i) for name in strategies}})
    digits = percent_digits(100 * accuracy)

    def pct(e: float, base: float | None = None) -> float | None:
        """``e`` over ``base`` (the journey's E*) in per cent, to the digit E*'s accuracy allows (None: none)."""
        base = e_opt if base is None else base
        return None if digits is None or base <= 0 or math.isnan(e) else round(100 * (e - base) / base, digits)

    summary = {
        "journey": journey.name, "route": route.name, "consist": train.name,
        "legs": len(legs), "stops": len(journey.stops), "timing_points": sum(len(leg.points) for leg in legs),
        "running_time_s": round(total, 1), "dwell_s": round(dwell_before(journey, len(journey.stations) - 1), 1),
        "fastest_running_time_s": round(float(fast.sum()), 1),
        "optimum_kwh": round(e_opt, 3), "optimum_accuracy_percent": float(f"{100 * accuracy:.2g}"),
        "marginal_kwh_per_s": {"min": round(min(slopes), 4), "max": round(max(slopes), 4)} if all(
            x is not None for x in slopes) else None,
        "legs_table": leg_rows, "stations": stations,
        "allocations": [{"allocation": "optimal (equal marginal energy)", "optimum_kwh": round(e_opt, 3),
                         "leg_times_s": [round(float(x), 1) for x in times], "vs_optimal_kwh": 0.0,
                         "vs_optimal_percent": 0.0, "missed_windows": window_misses(journey, legs, times)}]
        + [{"allocation": name, "optimum_kwh": round(e, 3), "leg_times_s": [round(float(x), 1) for x in ts],
            "vs_optimal_kwh": round(e - e_opt, 3),
            "vs_optimal_percent": pct(e),
            "missed_windows": window_misses(journey, legs, ts)} for name, ts, e in comparisons],
        "tolerance_s": round(total_tol, 2),
        "plans": {name: plans[name].summary(total, total_tol, pct) for name in strategies},
        "solve_time_s": round(_time.perf_counter() - t_start, 2),
    }
    result.summary = summary
    return result


def journey_fastest_s(journey: Journey, route: Route, train: Train, options: ModelOptions) -> float:
    """The journey's fastest running time, dwells excluded [s]: its legs' fastest runs one after the other
    (what ``1.15x`` and ``+10%`` of a total running time are factors of)."""
    return float(sum(leg.fastest_s for leg in legs_of(journey, route, train, options)))


def journey_optimum(journey: Journey, route: Route, train: Train, options: ModelOptions,
                    total_s: float) -> tuple[float, float]:
    """(the journey's E* for a total running time ``total_s`` [kWh], the energy below which a percentage of it
    means nothing [kWh]): the least-energy allocation of ``total_s`` under the windows, each leg's E* solved
    to tolerance at its share, summed, as ``plan_journey`` reports it. Raises ``InfeasibleError`` when no run
    keeps the time and the windows."""
    from ..ocp.bound import percent_floor_kwh

    legs = legs_of(journey, route, train, options)
    check_windows(journey, legs, total_s, fastest_clock(journey, legs, train, options), "")
    times, _ = allocate(journey, legs, train, options, total_s)
    energy, _ = allocation_energy(journey, legs, train, options, times)
    return energy, float(sum(percent_floor_kwh(leg.route, train) for leg in legs))


def journey_run_summary(result: JourneyResult, journey: Journey, strategy: str) -> dict:
    """A batch's record of one strategy's journey run: the fields every run's record has (``route``,
    ``strategy``, ``planned_time_s`` the total running time asked, ``running_time_s`` and
    ``traction_energy_kwh`` the plan's totals, ``punctual`` the total within its tolerance (``tolerance_s``) and
    every station's window kept, ``gap_to_optimum_percent``
    against the legs' E* at the plan's own leg times), then the journey's: ``optimum_kwh`` (its E*), the legs
    with their allocated times and this strategy's plans, every station's clock in the plan against its
    window (``windows_missed``), the allocations compared and the failures ``locoplan journey`` names."""
    s = result.summary
    runs = [r for r in result.runs if r["strategy"] == strategy]
    legs = [r["run"].summary for r in runs]
    feasible = all(x.get("feasible") for x in legs)
    totals = s["plans"][strategy]
    leg_rows = [{**{k: v for k, v in row.items() if k != "plans"},
                 "plan": {**row["plans"][strategy], "plan": r["run"].summary.get("plan")}}
                for r, row in zip(runs, s["legs_table"])]
    stations = []
    for row in s["stations"]:
        p = row["plans"][strategy]
        stations.append({**{k: v for k, v in row.items() if k != "plans"}, "plan_s": p["clock_s"],
                         "in_window": p["in_window"]})
    windows = sum(1 for st in journey.stations if st.earliest_s is not None or st.latest_s is not None)
    equal = next((a for a in s["allocations"] if a["allocation"] == "equal supplements"), None)
    first = legs[0] if legs else {}
    return {
        "kind": "journey", "journey": s["journey"], "route": s["route"], "consist": s["consist"],
        "strategy": strategy, "algorithm": first.get("algorithm"), "seed": first.get("seed"),
        "feasible": feasible,
        "reason": None if feasible else next(f"leg {k + 1}: {x.get('reason')}" for k, x in enumerate(legs)
                                             if not x.get("feasible")),
        "planned_time_s": s["running_time_s"], "tolerance_s": s["tolerance_s"],
        "running_time_s": totals["running_time_s"] if feasible else None,
        "punctuality_error_s": totals["punctuality_error_s"],
        "traction_energy_kwh": totals["traction_energy_kwh"],
        "punctual": totals["punctual"],
        "optimum_kwh": s["optimum_kwh"], "optimum_accuracy_percent": s["optimum_accuracy_percent"],
        "gap_to_optimum_kwh": totals["gap_to_optimum_kwh"], "gap_to_optimum_percent": totals["gap_to_optimum_percent"],
        "equal_supplements_kwh": None if equal is None else equal["optimum_kwh"],
        "legs": s["legs"], "stops": s["stops"], "timing_points": s["timing_points"], "dwell_s": s["dwell_s"],
        "fastest_running_time_s": s["fastest_running_time_s"], "marginal_kwh_per_s": s["marginal_kwh_per_s"],
        "windows": windows, "windows_missed": totals["windows_missed"], "failures": list(result.failures),
        "plan": " | ".join(str(x.get("plan") or "-") for x in legs),
        "legs_table": leg_rows, "stations": stations, "allocations": s["allocations"],
        "solve_time_s": s["solve_time_s"],
    }


def infeasible_journey_summary(journey: Journey, route: Route, train: Train, strategy: str, time_s: float | None,
                               reason: str) -> dict:
    """The record of a journey run with no feasible plan (its time below the fastest run, windows no run keeps,
    a leg the train cannot run): the fields of :func:`journey_run_summary` with nothing measured."""
    try:
        planned = total_running_time(journey, time_s, "")
    except InputError:
        planned = None
    return {"kind": "journey", "journey": journey.name, "route": route.name, "consist": train.name, "strategy": strategy,
            "algorithm": None, "seed": None, "feasible": False, "reason": reason,
            "planned_time_s": None if planned is None else round(planned, 1), "running_time_s": None,
            "traction_energy_kwh": None, "punctual": None, "optimum_kwh": None, "gap_to_optimum_percent": None,
            "legs": len(journey.stops) - 1, "stops": len(journey.stops), "windows_missed": [], "failures": [], "plan": None}
