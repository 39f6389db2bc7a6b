"""The optimum with the air brake's cycle, bracketed, and a plan read off its drive.

E* (``ocp.bound``) is the least energy in a relaxed model (the air brake a continuous force): a lower bound.
``cycle_optimum`` gives the least energy of a drive that keeps the cycle (``optimize.cycle_dp``: a DP over
position, speed and the air brake's state), with its stated accuracy, so that a plan's place between the two
says how much a better plan could save and how much the cycle costs. E* comes first: its slope starts the search
for the DP's price of time and its value measures the DP's own grid on the line (the same DP without the cycle).
Both are cached in the process and on disk (``ocp.bound``'s cache, keyed by everything they depend on and a hash
of the code).

``plan_from_cycle_drive`` turns the DP's drive into a plan the calculator runs (a condition sequence with nominal
switching points, read as ``general_builder.sequence_from_drive`` reads the priced drive, and per descent the
release margin that puts the calculator's releases at the drive's release speeds): a start for the proposed
strategy's search.
"""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from types import SimpleNamespace

import numpy as np

from ..model.conditions import CODE
from ..model.plan import Plan
from ..model.route import Route
from ..model.train import Train
from ..optimize.cycle_dp import CycleDrive, CycleOptimum, cycle_binds, solve_cycle_optimum
from ..optimize.cycle_kernel import AIR_CYCLE, EV_APPLY, EV_RELEASE, U_B, U_C, U_E, U_H, U_K, U_T
from ..physics.units import kmh_from_e
from ..sim.calculator import ModelOptions, TractionCalculator
from ..sim.constants import CYCLE_MARGIN
from ..sim.result import AIR_RECHARGE
from .general_builder import DriveSequence, sequence_from_drive

MARGIN_RANGE = (0.25, 4.0)
"""The release margins a plan may carry (the proposed strategy's search range, ``optimize/problem.py``)."""
MARGIN_STEP = 1.25
MARGIN_REPAIRS = 8
"""A descent's margin refused for its recharge is deepened by this factor, at most this many times in a plan."""

PLAN_SEARCH_STEPS = 12
PLAN_MIN_TRIES = 4
"""At most ``PLAN_SEARCH_STEPS`` drives, at least ``PLAN_MIN_TRIES``, are tried for a start plan's running time
(``cycle_plan_start``)."""
CAP_KMH = 0.5
"""A drive's hold within this much of the cap [km/h] at both ends of its cell is a hold at the cap."""
MIN_RUN_CELLS = 2.5
"""A run of the drive shorter than this many of its cells joins its predecessor in the plan read off it."""

_OPTIMA: dict[tuple, CycleOptimum] = {}


def _code_digest() -> str:
    """A hash of every source this module imports (the DP, the calculator, the builder, E*'s, ...): a cached cycle
    optimum is only as good as the code."""
    from ..ocp import bound

    return bound.code_digest(("strategy/cycle_start.py",), bound.PACKAGE_DIR)


def _key(route: Route, train: Train, options: ModelOptions, time_s: float) -> tuple:
    from ..ocp.bound import _base_key

    return ("cycle-optimum", _base_key(route, train, options), repr(train.air_cycle), round(float(time_s), 2),
            _code_digest())


def _to_json(co: CycleOptimum) -> dict:
    out = {k: v for k, v in asdict(co).items() if k != "drive"}
    out["grids"] = [dict(g) for g in co.grids]
    d = co.drive
    out["drive"] = None if d is None else {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                           for k, v in d.__dict__.items()}
    return out


def _stored_problem(data, time_s: float) -> str | None:
    """What is wrong with a cycle optimum read back from the disk cache (None: usable): its numbers must be finite,
    its energies, accuracy and solve time non-negative, its time the one its key names, its drive's lists numbers; a
    damaged or foreign file is solved again."""

    if not isinstance(data, dict) or not isinstance(data.get("cycles"), bool):
        return "not a cycle optimum"
    t = data.get("time_s")
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or round(float(t), 2) != time_s:
        return f"time_s {t!r} is not the time {time_s:g} s its key names"
    for name in ("energy_kwh", "accuracy", "estar_kwh", "dp_kwh", "lost_s", "extra_kwh", "price_kwh_per_s", "solve_time_s"):
        v = data.get(name)
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return f"{name} is not a finite number ({v!r})"
        if v < 0 and name in ("energy_kwh", "accuracy", "estar_kwh", "dp_kwh", "solve_time_s"):
            return f"{name} is negative ({v!r})"
    if data["cycles"] and data.get("energy_kwh") is None:
        return "energy_kwh is missing"
    drive = data.get("drive")
    if drive is not None:
        if not isinstance(drive, dict):
            return "drive is not an object"
        for name, v in drive.items():
            if isinstance(v, list):
                try:
                    np.asarray(v, dtype=float)
                except (TypeError, ValueError):
                    return f"drive.{name} is not a list of numbers"
    return None


def _from_json(data: dict) -> CycleOptimum:
    d = data.pop("drive", None)
    drive = None
    if d is not None:
        ints = {"controls", "air", "event_kind"}
        drive = CycleDrive(**{k: (np.asarray(v, dtype=np.int64 if k in ints else float) if isinstance(v, list) else v)
                              for k, v in d.items()})
    data["grids"] = tuple(data.get("grids", ()))
    return CycleOptimum(**data, drive=drive)


def cycle_optimum(route: Route, train: Train, options: ModelOptions | None = None, time_s: float | None = None, *,
                  calc: TractionCalculator | None = None) -> CycleOptimum:
    """The least traction energy [kWh] of a drive of ``train`` on ``route`` that keeps the air brake's cycle, in
    ``time_s`` seconds (default: the route's schedule), with its accuracy (``optimize.cycle_dp.CycleOptimum``).
    Where the model has no cycle (``--no-air-brake``, ``--point-mass``, ``ModelOptions.air_cycle`` off) or the
    cycle cannot bind on the line, nothing is solved and ``cycles`` is False: the cycle optimum is E* itself.
    ``calc``: a calculator of the same route, train and options to reuse. Raises ``InfeasibleError`` where E* or
    the drives have no run in ``time_s``."""
    from ..ocp.bound import cache_load, cache_store, energy_bound

    options = options or ModelOptions()
    time_s = float(time_s if time_s is not None else route.schedule.run_time_s)
    from ..ocp.train_energy import check_runnable

    key = _key(route, train, options, time_s)
    calc = calc if calc is not None and calc.options == options and calc.route == route else TractionCalculator(
        route, train, options)
    check_runnable(calc, time_s)  # first: the key rounds the time, so no kept optimum answers a time below the fastest run
    if key in _OPTIMA:
        return replace(_OPTIMA[key], solve_time_s=0.0)
    data = cache_load(key)
    if data is not None and _stored_problem(data, key[3]) is None:
        try:
            _OPTIMA[key] = _from_json(data)
            return replace(_OPTIMA[key], solve_time_s=0.0)
        except (TypeError, ValueError, KeyError):
            pass
    if not cycle_binds(calc):
        co = CycleOptimum(time_s, False, method="relaxed E* (the cycle cannot bind)")
    else:
        def estar(t: float) -> tuple[float, float, float]:
            b = energy_bound(route, train, options, t)
            return (float(b.energy_kwh), 0.0 if b.slope_kwh_per_s is None else float(b.slope_kwh_per_s),
                    0.0 if b.accuracy is None else float(b.accuracy))

        hint = -estar(time_s)[1]
        co = solve_cycle_optimum(calc, time_s, estar=estar, price_hint=hint if hint > 0.0 else None)
    _OPTIMA[key] = co
    cache_store(key, _to_json(co))
    return co


def _condition(u: int, air: int, in_region: bool, at_cap: bool, descending: bool) -> str:
    """The calculator's condition for a drive's cell: T, K (holding), C, E (the full electric brake alone), and an
    application: B, or K on a descent the electric brake cannot hold, where
    the calculator cycles by itself and the plan's release margins place its releases. A hold at the cap (the
    limit, a braking curve) is the condition that reaches it there, C on a descent, T elsewhere: the calculator
    holds a train at a limit it reaches, whereas its K holds the speed at which it begins."""
    if u == U_T:
        return "T"
    if u == U_C:
        return "C"
    if u == U_K:
        return "K"
    if u == U_E and air != AIR_CYCLE:
        return "E"
    if u == U_B or air == AIR_CYCLE:
        return "K" if in_region else "B"
    if u == U_H and at_cap:
        return "C" if descending else "T"
    return "K"


def drive_sequence(calc: TractionCalculator, drive: CycleDrive, min_run_m: float | None = None) -> DriveSequence:
    """The drive's cells as a condition sequence with nominal switching points (``sequence_from_drive``: runs
    shorter than ``min_run_m`` [m] join their predecessor, the last braking run is the stop's). The DP has no
    least run (the priced DP of the general builder has half a train): by default a run shorter than
    ``MIN_RUN_CELLS`` of its cells joins its predecessor (a hold nudged for a cell, a coast of one cell)."""
    regions = calc.cycle_regions_m
    mid = 0.5 * (drive.s_m[1:] + drive.s_m[:-1])
    in_region = np.zeros(len(mid), dtype=bool)
    for a, b in regions:
        in_region |= (mid >= a) & (mid < b)
    cap_kmh = kmh_from_e(np.maximum(np.interp(drive.s_m, calc.s_m, calc.e_envelope), 0.0))
    at_cap = (drive.speed_kmh[:-1] >= cap_kmh[:-1] - CAP_KMH) & (drive.speed_kmh[1:] >= cap_kmh[1:] - CAP_KMH)
    k_calc = np.clip(np.searchsorted(calc.s_m, mid) - 1, 0, len(calc.h_m) - 1)
    v_mid = 0.5 * (drive.speed_kmh[1:] + drive.speed_kmh[:-1])
    load = np.array([float(calc.forces_kn(np.float64(v / 3.6), int(k))[2]) for v, k in zip(v_mid, k_calc)])
    names = [_condition(int(u), int(a), bool(r), bool(c), bool(g < 0.0))
             for u, a, r, c, g in zip(drive.controls, drive.air, in_region, at_cap, load)]
    codes = np.array([CODE[c] for c in names], dtype=np.int64)
    if min_run_m is None:
        min_run_m = MIN_RUN_CELLS * float(np.max(np.diff(drive.s_m)))
    codes = chatter_as_hold(drive.s_m, codes, min_run_m, drive.speed_kmh)
    view = SimpleNamespace(s_m=drive.s_m, controls=codes, time_s=drive.time_s, energy_kwh=drive.energy_kwh,
                           price_kwh_per_s=drive.price_kwh_per_s)
    return sequence_from_drive(calc, view, min_run_m=min_run_m)


CHATTER_RUNS = 3
CHATTER_KMH = 3.0
"""``chatter_as_hold``: at least this many short runs in a row make a chatter, read as a hold where the speed gains
no more than this over it [km/h]."""


def chatter_as_hold(s_m: np.ndarray, codes: np.ndarray, min_run_m: float, v_kmh: np.ndarray) -> np.ndarray:
    """Per-cell condition codes ``codes`` (cells between the nodes ``s_m``) with each chatter read as a hold (K): a
    DP holds a speed its grid has no node for by alternating controls cell by cell (T, C, T, C up a climb: the
    mean of the two is the partial force that holds the speed), and a plan that read each short run as its
    predecessor's condition would coast up the climb. A chatter is ``CHATTER_RUNS`` or more runs in a row each
    shorter than ``min_run_m`` [m], traction or holding among them and no braking (B, E), over which the speed
    (``v_kmh`` at the nodes) gains no more than ``CHATTER_KMH``; it becomes one run of K, which holds the speed at
    which it begins (a chatter that gains more, a partial force accelerating the train, would be held too slow: it
    is left to the runs' own reading)."""
    codes = np.asarray(codes).copy()
    n = len(codes)
    if n == 0:
        return codes
    cut = np.flatnonzero(np.diff(codes)) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [n]])
    short = (s_m[ends] - s_m[starts]) < min_run_m
    drive = (CODE["T"], CODE["K"])
    j = 0
    while j < len(starts):
        if not short[j]:
            j += 1
            continue
        k = j
        while k + 1 < len(starts) and short[k + 1]:
            k += 1
        seg = codes[starts[j]:ends[k]]
        if (k - j + 1 >= CHATTER_RUNS and np.isin(seg, drive).any()
                and not np.isin(seg, (CODE["B"], CODE["E"])).any()
                and float(v_kmh[ends[k]]) - float(v_kmh[starts[j]]) <= CHATTER_KMH):
            codes[starts[j]:ends[k]] = CODE["K"]
        j = k + 1
    return codes


def release_margins(calc: TractionCalculator, drive: CycleDrive) -> tuple[tuple[float, float, float], ...]:
    """Per descent where the air brake cycles (``calc.cycle_regions_m``) the release margin that puts the
    calculator's release speed (``kernel.cycle_speeds``: the apply speed less margin x 3.6 a_up x the recharge)
    at the median of the drive's release speeds there, within ``MARGIN_RANGE``; descents where the drive makes
    no application of its own are left to the rule (not listed)."""
    out = []
    if calc.air_cycle is None:
        return ()
    ev_m, ev_k, v_ev = drive.event_m, drive.event_kind, drive.event_kmh
    mid = 0.5 * (calc.s_m[1:] + calc.s_m[:-1])
    for a, b in calc.cycle_regions_m:
        rel = [i for i, (x, k) in enumerate(zip(ev_m, ev_k))
               if k == EV_RELEASE and a <= x < b and i > 0 and ev_k[i - 1] == EV_APPLY]
        if not rel:
            continue
        margins = []
        for i in rel:
            x = ev_m[i]
            k = int(np.clip(np.searchsorted(mid, x), 0, len(mid) - 1))
            v_rel = float(v_ev[i])
            e_app, e_one = calc.cycle_speeds(calc.e_limit_cell[k], k, 1.0)
            v_app, v_one = float(kmh_from_e(e_app)), float(kmh_from_e(e_one))
            if not (math.isfinite(v_app) and v_app - v_one > 1e-9):
                continue
            margins.append((v_app - v_rel) / (v_app - v_one))
        if margins:  # (the median release; deepened where the calculator refuses it: repair_margins)
            out.append((float(a), float(b), float(np.clip(np.median(margins), *MARGIN_RANGE))))
    return tuple(out)


def repair_margins(calc: TractionCalculator, plan: Plan) -> Plan:
    """``plan`` with the release margin of each descent where the calculator refuses it for applying the air brake
    again before its recharge is over deepened (x ``MARGIN_STEP``, within ``MARGIN_RANGE``) until it runs, at most
    ``MARGIN_REPAIRS`` times; a refusal elsewhere, or none, leaves it as it is."""
    for _ in range(MARGIN_REPAIRS):
        res = calc.evaluate(plan.conditions, plan.switches_m, **plan.cycle_kwargs())
        if res.reason_code[0] != AIR_RECHARGE:
            return plan
        x = float(res.failure_m[0])
        margins = list(plan.release_margins)
        hit = [i for i, (a, b, _) in enumerate(margins) if a <= x < b]
        if hit:
            a, b, m = margins[hit[0]]
            margins[hit[0]] = (a, b, float(min(m * MARGIN_STEP, MARGIN_RANGE[1])))
        else:  # a descent the plan left to the rule: its margin deepened from the rule's
            regions = [(float(a), float(b)) for a, b in calc.cycle_regions_m if a <= x < b]
            if not regions:
                return plan
            margins.append((*regions[0], CYCLE_MARGIN * MARGIN_STEP))
            margins.sort()
        plan = Plan(plan.conditions, plan.starts_m, tuple(margins))
    return plan


def plan_from_cycle_drive(calc: TractionCalculator, drive: CycleDrive, min_run_m: float | None = None) -> Plan:
    """A plan the calculator runs, read off a cycle DP drive: its condition sequence and nominal switching points
    (``drive_sequence``; the final B where the stop's braking curve begins) and its release margins
    (``release_margins``, deepened where the calculator would refuse them: ``repair_margins``)."""
    seq = drive_sequence(calc, drive, min_run_m)
    plan = Plan(seq.conditions, (0.0, *[float(x) for x in seq.nominal_m], float("nan")), release_margins(calc, drive))
    return repair_margins(calc, plan)


def cycle_plan_start(route: Route, train: Train, options: ModelOptions | None, time_s: float, *,
                     calc: TractionCalculator | None = None, tolerance_s: float | None = None) -> Plan | None:
    """A plan read off a cycle DP drive whose run on ``calc`` takes ``time_s`` [s] (within ``tolerance_s``, default
    0.5 % of it) or as near as the DP's prices reach: the cycle optimum's finest grid (``cycle_optimum``) with the
    price of time bisected on the plan's own running time on ``calc`` (the DP's cells are coarser than the
    calculator's, its drive's plan runs a little faster or slower than the drive); of the plans tried that run on
    time, the one with the least energy. None where the cycle cannot bind, or no plan read off a drive reaches the
    stop."""
    from ..optimize.cycle_dp import cycle_solver

    options = options or ModelOptions()
    calc = calc if calc is not None and calc.options == options and calc.route == route else TractionCalculator(
        route, train, options)
    co = cycle_optimum(route, train, options, time_s, calc=calc)
    if not co.cycles or co.drive is None or not co.grids:
        return None
    cell = float(co.grids[-1]["cell_m"])  # (the finest grid's)
    solver = cycle_solver(calc, cell, float(co.grids[-1]["speed_step_kmh"]))
    tol = 0.005 * time_s if tolerance_s is None else float(tolerance_s)
    tried: list[tuple[float, float, Plan]] = []  # (time [s], energy [kWh], plan) of every plan that ran

    def plan_time(price: float) -> float:
        d = solver.solve(price)
        if d is None:
            return math.inf
        plan = plan_from_cycle_drive(calc, d)
        res = calc.evaluate(plan.conditions, plan.switches_m, **plan.cycle_kwargs())
        if not res.feasible[0]:
            return math.inf
        t = float(res.running_time_s[0])
        tried.append((t, float(res.traction_energy_kwh[0]), plan))
        return t

    x = math.log(co.drive.price_kwh_per_s)
    lo = hi = None  # log prices whose plans run slower / no slower than time_s
    step = 0.05
    for _ in range(PLAN_SEARCH_STEPS):
        t = plan_time(math.exp(x))
        if abs(t - time_s) <= tol and len(tried) >= PLAN_MIN_TRIES:
            break
        if t > time_s:
            lo = x
        else:
            hi = x
        if lo is not None and hi is not None:
            x = 0.5 * (lo + hi)
        else:
            x, step = (x + step, 2 * step) if hi is None else (x - step, 2 * step)
    if not tried:
        return None
    # the least energy among the plans on time (a drive's plan can lose more than its time says: a crawl over a
    # crest, a hold at another speed), else the one nearest the time
    on_time = [p for p in tried if abs(p[0] - time_s) <= tol]
    return min(on_time, key=lambda p: p[1])[2] if on_time else min(tried, key=lambda p: abs(p[0] - time_s))[2]
