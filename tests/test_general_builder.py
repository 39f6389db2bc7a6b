"""The general sequence builder (issue 8): the priced-drive DP against exhaustive search, its drives as
condition sequences, and the proposed strategy on lines the seed 002 builder could not drive."""

import itertools
import math

import numpy as np
import pytest

from locoplan.io.load import load_route, load_train
from locoplan.model.conditions import CONDITIONS
from locoplan.optimize.dp import PricedDriveSolver
from locoplan.runner import make_context, run_strategy, schedule_verdict
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from locoplan.strategy.general_builder import sequence_from_drive
from routes import hand_made_route


@pytest.fixture(scope="module")
def hilly(freight):
    """6 km: a climb, a crest, a descent steep enough to coast down, level to the stop."""
    _, train = freight
    return hand_made_route([(6000, 80)], [(1000, 0.0), (2500, 8.0), (4000, -9.0), (6000, 0.0)], 6000), train


def test_dp_beats_every_one_and_two_switch_plan(hilly):
    """On a coarse grid the DP's E + lambda T is at most that of every plan T-C-B and T-K-C-B with switches
    on its own cell edges, simulated by the exact calculator (up to the DP's speed-grid error, 1 %)."""
    route, train = hilly
    calc = TractionCalculator(route, train, ModelOptions(step_m=200.0))
    solver = PricedDriveSolver(calc, cell_m=200.0, switch_penalty_kwh=0.0, min_run_m=1.0)
    price = 0.3  # kWh/s
    d = solver.solve(price)
    assert d is not None and set(np.unique(d.controls)) <= set(range(4))
    best = math.inf
    edges = calc.s_m[1:-1]
    for x in edges:
        res = calc.evaluate(("T", "C", "B"), [[x, np.nan]])
        if res.feasible[0]:
            best = min(best, res.traction_energy_kwh[0] + price * res.running_time_s[0])
    for x, y in itertools.combinations(edges[::2], 2):
        res = calc.evaluate(("T", "K", "C", "B"), [[x, y, np.nan]])
        if res.feasible[0]:
            best = min(best, res.traction_energy_kwh[0] + price * res.running_time_s[0])
    assert d.energy_kwh + price * d.time_s <= best * 1.01


def test_dp_price_trades_energy_for_time(hilly):
    """A dearer hour buys a faster drive with more energy; the cheapest drive is the least energy."""
    route, train = hilly
    calc = TractionCalculator(route, train)
    solver = PricedDriveSolver(calc)
    drives = [solver.solve(p) for p in (1e-4, 0.1, 0.5, 2.0)]
    times = [d.time_s for d in drives]
    energies = [d.energy_kwh for d in drives]
    assert times == sorted(times, reverse=True) and energies == sorted(energies)
    assert drives[-1].time_s < 1.3 * calc.fastest_time_s
    target = 0.5 * (times[1] + times[2])
    close = solver.for_time(target)
    assert abs(close.time_s - target) < 0.05 * target


@pytest.mark.parametrize("model", ["default", "point_mass", "no_air_brake"])
def test_a_search_from_e_stars_price_finds_the_drive_in_fewer_solves(hilly, model):
    """E*'s multiplier of the running time is the price of time the DP needs: from it the priced-drive search
    lands as near the target as the bisection over the whole range (within the staircase of the drives'
    times: no drive lies between the two it ends on), with at most half the DP solves; a hint 50 times off
    still finds it (the walk doubles its steps)."""
    from locoplan.ocp.bound import energy_bound

    route, train = hilly
    options = {"default": ModelOptions(), "point_mass": ModelOptions(point_mass=True),
               "no_air_brake": ModelOptions(air_brake=False)}[model]
    calc = TractionCalculator(route, train, options)
    target = 1.15 * calc.fastest_time_s
    price = -energy_bound(route, train, options, target).slope_kwh_per_s
    assert price > 0
    counts = {}
    for name, hint in (("whole range", None), ("hint", price), ("far hint", 50 * price)):
        solver = PricedDriveSolver(calc)
        solve, n = solver.solve, [0]

        def counted(p, solve=solve, n=n):
            n[0] += 1
            return solve(p)
        solver.solve = counted
        d = solver.for_time(target, price_hint=hint)
        counts[name] = (n[0], d.time_s)
    base_n, base_t = counts["whole range"]
    hint_n, hint_t = counts["hint"]
    assert hint_n <= base_n / 2
    assert abs(hint_t - target) <= abs(base_t - target) + 1e-9
    assert abs(counts["far hint"][1] - target) <= abs(base_t - target) + 1e-9


def test_every_run_but_the_departure_is_half_a_train_long(freight):
    """Seed 002 eq. 3 (S >= L/2) holds by construction: the DP's runs, hence the sequence's."""
    route, train = freight
    calc = TractionCalculator(route, train, ModelOptions(step_m=100.0))
    solver = PricedDriveSolver(calc)
    d = solver.for_time(1500.0)
    runs = []
    for k, u in enumerate(d.controls):
        if runs and runs[-1][2] == u:
            runs[-1][1] = d.s_m[k + 1]
        else:
            runs.append([d.s_m[k], d.s_m[k + 1], u])
    inner = runs[1:-1]  # the departure run and the final braking are exempt
    assert all(b - a >= train.length_m / 2 - 1e-6 for a, b, _ in inner)
    seq = sequence_from_drive(calc, d)
    assert seq.conditions[-1] == "B" and len(seq.nominal_m) == len(seq.conditions) - 2
    assert np.all(seq.lower_m <= seq.nominal_m + 1e-9) and np.all(seq.nominal_m <= seq.upper_m + 1e-9)
    assert set(seq.conditions) <= set(CONDITIONS)


@pytest.mark.slow
def test_proposed_on_a_line_the_seed_builder_could_not_drive(root):
    """CH_StGallen_Wil with 3200 t: no climb is long-up at the limit speed, so seed 002's sequence collapsed
    to T-C-B and every coast stalled; the general builder drives it on time, below four-stage."""
    route = load_route(root / "routes/real/CH_StGallen_Wil.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x30.yaml")
    fastest = TractionCalculator(route, train).fastest_time_s
    t0 = round(1.2 * fastest)
    ctx = make_context(route, train, RunSettings(time_s=t0, tolerance_s=0.01 * t0,
                                                 params_path=str(root / "tests/data/optimizers/issa.yaml")))
    prop = run_strategy(ctx, "proposed")
    four = run_strategy(ctx, "four-stage")
    assert schedule_verdict(ctx, prop) is None
    s = prop.summary
    assert s["feasible"] and abs(s["running_time_s"] - t0) <= 0.01 * t0
    assert s["traction_energy_kwh"] < four.summary["traction_energy_kwh"]
    assert ctx.e_min() <= s["traction_energy_kwh"]  # E_min is a lower bound, as eq. 11 needs


def test_a_falling_line_slower_than_its_least_energy(root):
    """CH_Stadelhofen_Altstetten leg 1 falls 38 per mille: asked for more time than coasting takes, the
    plan spends it holding lower speeds by braking (no extra traction), and is on time."""
    route = load_route(root / "routes/real/CH_Stadelhofen_Altstetten-leg1.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x30.yaml")
    fastest = TractionCalculator(route, train).fastest_time_s
    t0 = round(1.6 * fastest, 1)
    ctx = make_context(route, train, RunSettings(time_s=t0, tolerance_s=0.01 * t0))
    prop = run_strategy(ctx, "proposed")
    assert schedule_verdict(ctx, prop) is None, prop.summary


def test_blend_is_safe_with_infinite_neighbours():
    """The DP interpolates cost-to-go between grid speeds; a neighbour that cannot reach the stop (inf)
    must not turn a reachable state into nan or -inf (a weight at 1 + 1e-12 once gave (1 - w) inf = -inf,
    which poisoned every state behind it)."""
    from locoplan.optimize.dp_kernel import _blend

    assert _blend(5.0, math.inf, 0.0) == 5.0 and _blend(math.inf, 7.0, 1.0) == 7.0
    assert _blend(1.0, 3.0, 0.25) == pytest.approx(1.5)
    assert _blend(math.inf, 7.0, 0.5) == math.inf and _blend(2.0, math.inf, 0.5) == math.inf


@pytest.mark.slow
def test_dp_drives_a_heavy_train_through_neutral_sections_near_its_top_speed(root):
    """HXD1 + 50 x C80 on the reconstructed high-speed leg (290 km/h allowed, the train's 100 km/h caps it;
    three neutral sections, a -10 per mille descent held at the cap by braking): the fastest run drives it,
    so the DP must find a drive at every price, and optimize must meet a timetable on it."""
    route, train = load_route(root / "routes/hsr-leg2-ns.yaml"), load_train(root / "configs/consists/HXD1-C80x50.yaml")
    calc = TractionCalculator(route, train, ModelOptions(step_m=100))
    solver = PricedDriveSolver(calc)
    times = [solver.solve(p).time_s for p in (50.0, 1.0, 1e-2)]
    # (the DP drives with the air brake as a continuous force, as E* does: its fastest drive is bounded by
    # that relaxation's fastest run; the calculator's own, cycling the air brake down the descent, is slower)
    relaxed = TractionCalculator(route, train, ModelOptions(step_m=100, air_cycle=False))
    assert times[0] < times[1] < times[2] and times[0] >= relaxed.fastest_time_s - 1.0
    ctx = make_context(route, train, RunSettings(time_s=1500.0))
    run = run_strategy(ctx, "proposed")
    assert run.summary["feasible"] and schedule_verdict(ctx, run) is None


@pytest.mark.parametrize("leg", ["CH_Stadelhofen_Altstetten-leg2", "CN_Songjiazhuang_Yizhuang-leg11"])
def test_a_heavy_train_that_barely_climbs_a_steep_grade(root, leg):
    """5200 t on +28 / +23.5 per mille: the fastest run crawls up. On the DP's fine cells (short lines) the
    speed grid used to round the stall boundary up at every cell until the climb looked impossible
    ("no drive reaches the stop" while the fastest run did); the continuous boundary keeps it, and
    optimize meets 1.15 x the fastest run."""
    route = load_route(root / f"routes/real/{leg}.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x50.yaml")
    fastest = TractionCalculator(route, train).fastest_time_s
    ctx = make_context(route, train, RunSettings(time_s=round(1.15 * fastest, 1)))
    run = run_strategy(ctx, "proposed")
    assert run.summary["feasible"] and schedule_verdict(ctx, run) is None
    least = run_strategy(ctx, "energy-saving").summary
    assert least["feasible"] and least["traction_energy_kwh"] <= run.summary["traction_energy_kwh"] + 1e-6


@pytest.mark.slow
def test_a_climb_a_weak_train_crawls_over(root):
    """Fr100 (V 90 + 10 ore wagons) on the 102 km railtoolkit line crawls over +18.1 per mille at 2,000 m
    at about 3 km/h. One step per cell decided stall or no stall by the cell size (it stalled on the
    optimisers' 100 m cells and passed on the 50 m ones, so every candidate plan stalled in the search:
    "could not find 50 feasible candidates"); slowing cells at crawling speed are now sub-stepped, so
    every grid agrees, the times converge, and optimize meets 1.15 x the fastest run."""
    route = load_route(root / "routes/railtoolkit/realworld.yaml")
    train = load_train("Fr100")
    runs = {step: TractionCalculator(route, train, ModelOptions(step_m=step)).evaluate(("T",), np.zeros((1, 0)),
                                                                                     profile=True)
            for step in (100.0, 50.0, 25.0)}
    for r in runs.values():
        crest = (r.profile.s_m > 1500) & (r.profile.s_m < 2600)
        assert r.feasible[0] and np.nanmin(r.profile.v_kmh[0][crest]) < 5.0  # it crawls, and makes it
    assert runs[50.0].running_time_s[0] == pytest.approx(runs[25.0].running_time_s[0], rel=5e-4)
    fastest = float(runs[50.0].running_time_s[0])
    ctx = make_context(route, train, RunSettings(time_s=round(1.15 * fastest, 1)))
    assert ctx.search.evaluate(("T",), np.zeros((1, 0))).feasible[0]
    run = run_strategy(ctx, "proposed")
    assert run.summary["feasible"] and schedule_verdict(ctx, run) is None


def test_coasting_up_to_the_stop_must_reach_it(root):
    """A plan that coasts up a +10.4 per mille grade into the stop came to rest about 40 m short of it; one
    step over the last 50 m cell let it 'arrive' at 0 km/h (and plans that exploited this were 0.5 % under
    E*). The last cell's crawl sub-steps see it stop short (generated line, benchmarks/random_lines.py
    case 37); on 25 m and 10 m cells it was always short."""
    route = load_route(root / "tests/data/routes/crawl-to-stop.yaml")
    train = load_train(root / "tests/data/consists/V90-8xFacs124.yaml")
    conds = tuple("TCKCBKCKTCB")
    x = np.array([[543.5, 3928.1, 6256.6, 7594.8, 8640.0, 18706.6, 22242.8, 26669.8, 27451.4, np.nan]])
    for step in (50.0, 25.0, 10.0):
        r = TractionCalculator(route, train, ModelOptions(step_m=step)).evaluate(conds, x)
        assert not r.feasible[0] and r.reason(0).startswith(("did not stop at the end", "stalled at 27,6")), r.reason(0)


def test_a_falling_line_with_rises_spends_its_spare_time_braking_not_pulling(root):
    """A 40 km line HXD1 + 30 x C80 coasts from rest in 2,155.8 s (no traction at all), asked for 3 % more:
    the extra minute must come from holding lower speeds by braking. Holds that ran on to the stop held
    their speed with traction up every later rise (about 220 kWh for a lighter train); holds that end and
    coast again cost 5.4 kWh here, under 1 % of the fastest run's 553 kWh."""
    route = load_route(root / "tests/data/routes/falling-40km.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x30.yaml")
    calc = TractionCalculator(route, train)
    coast = calc.evaluate(("C", "B"), np.array([[np.nan]]))
    assert coast.feasible[0] and coast.traction_energy_kwh[0] == 0.0  # it coasts the line from rest
    t0 = round(float(coast.running_time_s[0]) * 1.03, 1)
    ctx = make_context(route, train, RunSettings(time_s=t0, tolerance_s=0.01 * t0))
    run = run_strategy(ctx, "proposed")
    assert schedule_verdict(ctx, run) is None, run.summary
    assert run.summary["traction_energy_kwh"] < 0.01 * calc.evaluate(("T",), np.zeros((1, 0))).traction_energy_kwh[0]


def _near_stop(kmh: float, length: float, before_stop: float, coast_s: float):
    """A 1.4 km level line with one neutral section ``length`` long ending ``before_stop`` before the stop."""
    from locoplan.model.route import Route

    data = hand_made_route([(1400, kmh)], [(1400, 0.0)], 1400).model_dump(by_alias=True)
    data["neutral_sections"] = [{"from_m": 1400 - before_stop - length, "to_m": 1400 - before_stop,
                                 "coast_before_s": coast_s, "coast_after_s": coast_s}]
    return Route.model_validate(data)


NEAR_STOP = list(itertools.product((60, 80), (20, 150), (0, 100, 300), (0.0, 10.0)))


def test_neutral_sections_near_the_stop_have_a_drive(root):
    """A neutral section near the stop, whose span (with its coasting margins and the train's length) may reach
    the stop, for a 284 t train whose only brake is electric (none in the span): the fastest run coasts in
    along the braking curve, so the DP must find a drive at every price and the least-energy strategy a plan.
    (The DP once lost every drive: its cell across the span's start had no catenary over its whole length,
    while that node's cap, the calculator's braking curve, braked electrically up to the span; and the forward
    pass read a state just under a cap as unreachable where the backward pass had reached it.)"""
    train = load_train("HXD1-C64-seed000")
    from locoplan.strategy.strategies import drive_solver

    for kmh, length, before_stop, coast_s in NEAR_STOP:
        ctx = make_context(_near_stop(kmh, length, before_stop, coast_s), train, RunSettings(time_s=300.0,
                                                                                             yardstick=False))
        assert ctx.calc.evaluate(("T",), np.zeros((1, 0))).feasible[0]
        case = (kmh, length, before_stop, coast_s)
        solver = drive_solver(ctx)
        assert all(solver.solve(p) is not None for p in (1e-4, 1e-2, 1.0)), case
        assert run_strategy(ctx, "energy-saving").summary["feasible"], case


def test_optimize_on_time_with_a_neutral_section_before_the_stop():
    """The issue's case: a 50 m neutral section ending 150 m before the stop (10 s margins), T0 = 300 s."""
    ctx = make_context(_near_stop(60, 50, 150, 10.0), load_train("HXD1-C64-seed000"), RunSettings(time_s=300.0))
    run = run_strategy(ctx, "proposed")
    assert run.summary["feasible"] and schedule_verdict(ctx, run) is None


def test_stall_boundary_below_a_cap_too_fast_to_hold():
    """The stall boundary (the lowest speed at a node from which full traction goes on) is a bisection below the
    node's cap; where the cap itself cannot be held under the next node's (no brake in the cell), slower speeds
    still can, and the boundary is among them, not 'none' (inf)."""
    from locoplan.optimize import dp_kernel

    ctx = make_context(_near_stop(60, 50, 150, 10.0), load_train("HXD1-C64-seed000"), RunSettings(time_s=300.0,
                                                                                                  yardstick=False))
    from locoplan.strategy.strategies import drive_solver

    solver = drive_solver(ctx)
    cells, fo = solver._cells, solver.calc.forces
    n = len(cells.h)
    k = int(np.flatnonzero(cells.allowed == 0)[5])  # a cell inside the span: no traction, no brake
    e_next = cells.e_cap[k + 1]
    raised = cells.e_cap.copy()
    raised[k] = 4.0 * e_next  # twice the speed: coasting one cell cannot come down to the next cap
    low = dp_kernel._lowest_energy.py_func(k, n, cells._replace(e_cap=raised), fo, solver._low[k + 1])
    assert math.isfinite(low) and solver._low[k + 1] <= low <= e_next * 1.01



@pytest.mark.parametrize("options, consist", [(ModelOptions(), "HXD1-C80x50"), (ModelOptions(air_brake=False), "HXD1-C80x50"),
                                              (ModelOptions(point_mass=True), "HXD1-C80x30")],
                         ids=["default", "no-air-brake", "point-mass"])  # (as a point mass 50 wagons stall at 596 m, +24 per mille)
def test_a_climb_asked_for_just_more_than_its_fastest_run(root, options, consist):
    """CN_Songjiazhuang_Yizhuang's stop 11 - stop 12, a 2.1 km climb driven in traction to the stop, at 1.02 x
    its fastest run: the priced drives nearest that time all become the fastest run's sequence (T-B), with
    nothing to place. The proposed plan then holds a lower speed with partial traction: on time, with less
    traction energy than the fastest run (each model fails without the hold)."""
    from locoplan.io.load import load_journey
    from locoplan.runs.journey import legs_of

    journey, line = load_journey(root / "routes/journeys/CN_Songjiazhuang_Yizhuang-journey.yaml")
    train = load_train(root / f"configs/consists/{consist}.yaml")
    route = legs_of(journey, line, train, options)[10].route
    calc = TractionCalculator(route, train, options)
    fastest = calc.evaluate(("T",), np.zeros((1, 0)))
    ctx = make_context(route, train, RunSettings(options, time_s=1.02 * calc.fastest_time_s))
    run = run_strategy(ctx, "proposed")
    assert not schedule_verdict(ctx, run), run.summary
    assert run.summary["traction_energy_kwh"] < float(fastest.traction_energy_kwh[0])
