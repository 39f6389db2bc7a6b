"""The optimum with the air brake's cycle (``strategy.cycle_start.cycle_optimum``, ``optimize.cycle_dp``): the least
energy of a drive that keeps the cycle, checked against a cycle worked by hand, against E* (the relaxation, a
lower bound), and for the rules its drive keeps, independently of the DP's own state machine.

The hand-worked line: point mass (so that the grade acts at once), 36 km at 60 km/h, level to 3 km, -12 per mille
to 33 km, level to the stop; HXD1 + 50 x C80 (5,200 t, 51 vehicles). On the descent: gravity 5200 x 9.81 x 0.012 =
612.14 kN, resistance R(v) of the HXD1 and the 50 loaded C80s (their Davis formulas below), the HXD1's electric
brake 461 kN (below 74.97 km/h): under it alone the train gains a_up(60) = (612.14 - 86.64 - 461) / 5200 = 0.01240
m/s^2, so the air brake must cycle. Its rules (docs/model.md, ``kernel.cycle_speeds``): a released brake is applied
at the apply speed, 60 - max(1, 1.25 x 3.6 x a_up^2 t_b / (2 a_air)) = 60 - max(1, 0.0164) = 59.0 km/h (t_b the build-up,
(3.6 + 0.00176 x 50 kPa x 51)(1 + 0.032 x 12) = 11.194 s; a_air(60) = 1,228.4 / 5200 m/s^2); held at least t_b; while
it recharges (30 + 0.6 x 50 = 60 s) on a descent the electric brake holds the speed (here: at full, the speed rises).

The best cycle (worked below with ``scipy.integrate.solve_ivp``): apply at 59.0 km/h, hold the least (11.194 s,
the air brake building up linearly) down to v_r = 54.72 km/h, release, and under the full electric brake regain
59.0 km/h in 91.3 s (more than the 60 s recharge: the least hold binds, not the recharge): a period of 102.5 s over
1,622 m, 56.97 km/h on average, 5.18 s behind a train held at 60 km/h, 3.19 s per kilometre. E* holds 60 km/h
(the air brake modulated at will), so on the 30 km the cycle costs dt = 95.8 s, and the cycle optimum at T is E* at
T - dt (the rest of the line is the same problem with that much less time) give or take one cycle at either end of
the descent (where it begins and ends), 5.18 s.
"""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from locoplan.errors import InfeasibleError
from locoplan.io.load import load_train
from locoplan.ocp.bound import energy_bound
from locoplan.optimize.cycle_dp import CycleDPSolver, cycle_binds, energy_at
from locoplan.optimize.cycle_kernel import EV_APPLY, EV_CHARGED, EV_CURVE, EV_RELEASE
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from locoplan.sim.result import AIR_RECHARGE
from locoplan.strategy import cycle_start
from locoplan.strategy.cycle_start import cycle_optimum, plan_from_cycle_drive
from routes import hand_made_route

G = 9.81
MASS_T = 5200.0
GRADE = -12.0
V_LIM = 60.0
DESCENT_M = 30000.0
T_BUILD_S = (3.6 + 0.00176 * 50 * 51) * (1 - 0.032 * GRADE)
RECHARGE_S = 30.0 + 0.6 * 50
GRAVITY_KN = MASS_T * G * -GRADE / 1000
POINT_MASS = ModelOptions(point_mass=True)


def resistance_kn(v):
    """HXD1 (200 t) + 50 loaded C80 (5,000 t): their Davis formulas [N/kN] x weight [kN] / 1000, v in km/h."""
    return 200 * G / 1000 * (1.40 + 0.0038 * v + 0.0003 * v * v) + 5000 * G / 1000 * (0.92 + 0.0048 * v + 0.000125 * v * v)


def air_kn(v):
    """The 50 C80s' air brake at beta_c = 0.5 (composite shoes, braking ratio 0.20), v in km/h."""
    return 50 * 0.20 * 100 * G * 0.322 * (v + 150) / (2 * v + 150) * 0.5


def hand_worked_cycle() -> dict:
    """The best cycle on the descent, by ``solve_ivp`` on the forces above: apply speed, release speed [km/h], the
    climb back's time, the period [s], its distance [m] and its time behind a train held at the limit [s]."""
    a_up = (GRAVITY_KN - resistance_kn(V_LIM) - 461.0) / MASS_T
    over = a_up * a_up * T_BUILD_S / (2 * air_kn(V_LIM) / MASS_T)
    v_app = V_LIM - max(1.0, 1.25 * 3.6 * over)

    def hold(t, y):  # the air brake building up linearly over t_b, with the full electric brake
        v = y[0] * 3.6
        return [(GRAVITY_KN - resistance_kn(v) - 461.0 - min(t / T_BUILD_S, 1.0) * air_kn(v)) / MASS_T, y[0]]

    def climb(t, y):  # released: the full electric brake alone
        return [(GRAVITY_KN - resistance_kn(y[0] * 3.6) - 461.0) / MASS_T, y[0]]

    back = lambda t, y: y[0] * 3.6 - v_app  # noqa: E731
    back.terminal, back.direction = True, 1
    h = solve_ivp(hold, (0.0, T_BUILD_S), [v_app / 3.6, 0.0], rtol=1e-11, atol=1e-12)
    v_rel = h.y[0, -1] * 3.6
    c = solve_ivp(climb, (0.0, 1e4), [v_rel / 3.6, 0.0], events=back, rtol=1e-11, atol=1e-12)
    t_climb, d = float(c.t_events[0][0]), float(h.y[1, -1] + c.y_events[0][0][1])
    period = T_BUILD_S + t_climb
    return {"v_app": v_app, "v_rel": v_rel, "t_climb": t_climb, "period": period, "distance": d,
            "behind": period - d / (V_LIM / 3.6)}


def descent_line():
    return hand_made_route([(36000, V_LIM)], [(3000, 0.0), (3000 + DESCENT_M, GRADE), (36000, 0.0)], 36000)


@pytest.fixture(scope="module")
def c80x50():
    return load_train("HXD1-C80x50")


@pytest.fixture(scope="module")
def descent(c80x50):
    """The hand-worked line, its calculator, a running time of 1.1 x its fastest run and the cycle optimum there."""
    route = descent_line()
    calc = TractionCalculator(route, c80x50, POINT_MASS)
    t = 1.1 * calc.fastest_time_s
    return route, calc, t, cycle_optimum(route, c80x50, POINT_MASS, t, calc=calc)


def test_hand_worked_numbers():
    cyc = hand_worked_cycle()
    assert GRAVITY_KN == pytest.approx(612.144, abs=1e-3) and T_BUILD_S == pytest.approx(11.1938, abs=1e-4)
    assert cyc["v_app"] == pytest.approx(59.0, abs=1e-9)
    assert cyc["v_rel"] == pytest.approx(54.72, abs=0.01) and cyc["t_climb"] == pytest.approx(91.3, abs=0.1)
    assert cyc["t_climb"] > RECHARGE_S  # the least hold binds, not the recharge
    assert cyc["period"] == pytest.approx(102.5, abs=0.1) and cyc["distance"] == pytest.approx(1622, abs=1)
    assert cyc["behind"] == pytest.approx(5.18, abs=0.01)


def test_constant_descent_cycles_as_worked_by_hand(descent, c80x50):
    """The DP's drive cycles as the hand-worked best cycle: on the descent (its first and last application left
    out: where the descent begins and ends) each application at 59.0 km/h, held its build-up time, released at
    54.72 km/h and made again 91.3 s later (within the DP's one step per cell of 25 .. 50 m: 0.05 km/h, 0.5 s;
    the last two climbs may end sooner, the drive fitting its cycles to the descent's foot); and the
    cycle optimum is E* at T less the cycle's cost on the descent, 30 km x 3.19 s/km, within one cycle's 5.18 s at
    either end (E*'s slope x 2 x 5.18 s) plus the optimum's stated accuracy."""
    route, calc, t, co = descent
    cyc = hand_worked_cycle()
    assert co.cycles and co.energy_kwh is not None and co.accuracy is not None
    d = co.drive
    on = (d.event_m > 3000.0) & (d.event_m < 3000.0 + DESCENT_M)
    apply = np.flatnonzero(on & (d.event_kind == EV_APPLY))
    assert len(apply) >= 0.8 * DESCENT_M / cyc["distance"]
    inner = apply[1:-1]
    assert len(inner) >= 10
    np.testing.assert_allclose(d.event_kmh[inner], cyc["v_app"], atol=0.01)
    assert np.all(d.event_kind[inner + 1] == EV_RELEASE)
    np.testing.assert_allclose(d.event_s[inner + 1] - d.event_s[inner], T_BUILD_S, atol=1e-6)
    np.testing.assert_allclose(d.event_kmh[inner + 1], cyc["v_rel"], atol=0.05)
    climbs = d.event_s[apply[1:]] - d.event_s[apply[:-1] + 1]
    np.testing.assert_allclose(climbs[:-2], cyc["t_climb"], atol=0.5)
    assert np.all(climbs[-2:] <= cyc["t_climb"] + 0.5)  # (near the foot it may apply sooner: the descent ends)
    # the cycle's cost on the descent, as time: the optimum is E* with that much less time elsewhere
    cost_s = DESCENT_M / cyc["distance"] * cyc["behind"]
    assert cost_s == pytest.approx(95.8, abs=0.1)
    b = energy_bound(route, c80x50, POINT_MASS, t - cost_s)
    tol = 2 * cyc["behind"] * abs(b.slope_kwh_per_s) + co.accuracy * co.energy_kwh
    assert co.energy_kwh == pytest.approx(b.energy_kwh, abs=tol)
    # and it lies above the relaxed E* at T by about the same
    e_star = energy_bound(route, c80x50, POINT_MASS, t).energy_kwh
    assert co.energy_kwh - e_star > 0.5 * (b.energy_kwh - e_star) and co.estar_kwh == pytest.approx(e_star)


LINES = [("freight-20km", "routes/freight-20km.yaml", "HXD1-C80x50", 1500.0),
         ("heavy-haul-60km", "routes/heavy-haul-60km.yaml", "HXD1x2-C80x100", 3300.0)]


@pytest.fixture(scope="module")
def optima(root, descent, c80x50):
    """(route, calc, time, cycle optimum) on the hand-worked line and the shipped lines of ``LINES``."""
    from locoplan.io.load import load_route

    out = {"descent": descent}
    for name, path, consist, t in LINES:
        route, train = load_route(root / path), load_train(consist)
        calc = TractionCalculator(route, train)
        out[name] = (route, calc, t, cycle_optimum(route, train, ModelOptions(), t, calc=calc))
    return out


@pytest.mark.parametrize("name", ["descent", "freight-20km", "heavy-haul-60km"])
def test_cycle_optimum_lies_above_the_relaxed_estar(optima, name):
    """E* relaxes the air brake: every drive that keeps the cycle is one of its runs, so the cycle optimum lies at or
    above it, within the cycle optimum's stated accuracy (a drive on the DP's grid). On these lines the cycle binds
    (freight-20km: the drops at 17.5 and 19 km and the stop lie closer than the recharge's distance)."""
    route, calc, t, co = optima[name]
    assert co.cycles and cycle_binds(calc)
    e_star = energy_bound(route, calc.train, calc.options, t).energy_kwh
    assert co.energy_kwh >= e_star - co.accuracy * co.energy_kwh
    assert 0.0 < co.accuracy < 0.05
    # the accuracy counts the DP's own excess over E* on its finer grid, without the cycle
    assert co.relaxed_dp_kwh is not None and co.relaxed_dp_kwh >= e_star - co.accuracy * e_star


def test_no_cycle_no_solve(freight, root):
    """Without the cycle (the seeds' point mass without an air brake, the electric brake alone, the air brake
    relaxed) or on a line where it cannot bind (one place needs the air brake: the stop), the cycle optimum is E*
    itself: nothing is solved and nothing is reported."""
    route, train = freight
    for opts in (ModelOptions.seeds(), ModelOptions(air_brake=False), ModelOptions(air_cycle=False)):
        co = cycle_optimum(route, train, opts, 1500.0)
        assert not co.cycles and co.energy_kwh is None and co.drive is None
    gentle = hand_made_route([(10000, 60.0)], [(10000, 0.0)], 10000)
    calc = TractionCalculator(gentle, train)
    assert not len(calc.cycle_regions_m) and not cycle_binds(calc)
    co = cycle_optimum(gentle, train, ModelOptions(), 1.2 * calc.fastest_time_s, calc=calc)
    assert not co.cycles and co.energy_kwh is None
    from locoplan.api import cycle_optimum_row
    assert cycle_optimum_row(gentle, train, ModelOptions(), 1.2 * calc.fastest_time_s) == {}


def _check_rules(calc, d):
    """The rules, from the drive's record alone: applications and releases alternate (the stop's application may
    stay on); an application of its own is held at least its build-up time (the least hold, ``AirCycle.build_up_s``
    of the grade where it is made, from the route), every application comes at least the recharge time after the
    release before it (and the recharge is over no sooner); each event lies in time between its cell's two nodes,
    and a cell without one takes the time of its two node speeds (dt = 2 h / (v0 + v1))."""
    cyc = calc.air_cycle
    kinds, times, where = d.event_kind, d.event_s, d.event_m
    applied = False
    t_app = t_rel = None
    hold = 0.0
    for k, t, x in zip(kinds, times, where):
        if k == EV_CHARGED:  # (the recharge over: exactly where a path ends it, at a node a cell later at most)
            assert not applied and t_rel is not None and t - t_rel >= cyc.recharge_s - 1e-6
            continue
        if k in (EV_APPLY, EV_CURVE):
            assert not applied, f"applied again at {x:.0f} m without a release"
            if t_rel is not None:
                assert t - t_rel >= cyc.recharge_s - 1e-6, f"applied {t - t_rel:.2f} s after the release at {x:.0f} m"
            applied, t_app = True, t
            k_calc = int(np.clip(np.searchsorted(calc.s_m, x, side="right") - 1, 0, len(calc.h_m) - 1))
            g = float(calc.gradient_permille[k_calc])  # (the calculator's cell where it is made)
            hold = float(cyc.build_up_s(g)) if k == EV_APPLY else 0.0
        else:
            assert applied, f"released at {x:.0f} m without an application"
            assert t - t_app >= hold - 1e-6, f"held {t - t_app:.2f} s < {hold:.2f} s at {x:.0f} m"
            applied, t_rel = False, t
    s, v, tn = d.s_m, d.speed_kmh, d.t_s
    cell = np.clip(np.searchsorted(s, where, side="right") - 1, 0, len(s) - 2)
    assert np.all(times >= tn[cell] - 1e-6) and np.all(times <= tn[cell + 1] + 1e-6)
    quiet = np.ones(len(s) - 1, dtype=bool)
    quiet[cell] = False
    quiet[np.clip(cell - 1, 0, None)] = False
    dt = 2 * np.diff(s) / ((v[1:] + v[:-1]) / 3.6)
    np.testing.assert_allclose(np.diff(tn)[quiet], dt[quiet], rtol=1e-9)


@pytest.mark.parametrize("name", ["descent", "freight-20km", "heavy-haul-60km"])
def test_the_drive_keeps_the_rules(optima, name):
    route, calc, t, co = optima[name]
    d = co.drive
    assert len(d.event_kind) > 0
    _check_rules(calc, d)
    assert d.time_s == pytest.approx(d.t_s[-1]) and d.speed_kmh[-1] == 0.0


@pytest.mark.parametrize("name", ["descent", "freight-20km", "heavy-haul-60km"])
def test_the_plan_from_the_drive_runs(optima, name):
    """The plan read off the drive (its sequence and per-descent release margins) runs on the calculator to the stop,
    no application refused for its recharge, and within 10 % of the drive's time and energy: the plan is a start for
    the proposed strategy's search, not the optimum (the DP's cells are coarser than the calculator's, and its drive
    mixes traction, holding and coasting cell by cell where the plan has one condition: over freight-20km's crest at
    13.5 km the plan crawls 5 km/h slower and arrives 5 % later)."""
    route, calc, t, co = optima[name]
    plan = plan_from_cycle_drive(calc, co.drive)
    res = calc.evaluate(plan.conditions, plan.switches_m, **plan.cycle_kwargs())
    assert res.feasible[0], res.reason(0)
    assert res.reason_code[0] != AIR_RECHARGE
    assert float(res.running_time_s[0]) == pytest.approx(co.drive.time_s, rel=0.1)
    assert float(res.traction_energy_kwh[0]) == pytest.approx(co.drive.energy_kwh, rel=0.1)
    for a, b, m in plan.release_margins:
        assert 0.25 <= m <= 4.0 and any(a == x and b == y for x, y in calc.cycle_regions_m)


def test_cache_and_round_trip(descent, c80x50):
    """A second call comes from the process's cache (no solve time), the disk's form gives back the same optimum."""
    route, calc, t, co = descent
    again = cycle_optimum(route, c80x50, POINT_MASS, t, calc=calc)
    assert again.solve_time_s == 0.0 and again.energy_kwh == co.energy_kwh
    back = cycle_start._from_json(cycle_start._to_json(co))
    assert back.energy_kwh == co.energy_kwh and back.grids == co.grids
    np.testing.assert_array_equal(back.drive.event_s, co.drive.event_s)
    np.testing.assert_array_equal(back.drive.controls, co.drive.controls)


def test_energy_at_the_time_and_beyond(descent):
    """The energy at T lies on the chord between the drives that bracket it; a time faster than every drive has no
    cycle optimum."""
    route, calc, t, co = descent
    solver = CycleDPSolver(calc, 100.0, 0.5)
    slow, fast = solver.bracket(t, co.price_kwh_per_s)
    assert slow.time_s > t >= fast.time_s
    e = energy_at(solver.drives, t)
    w = (slow.time_s - t) / (slow.time_s - fast.time_s)
    assert e <= slow.energy_kwh + w * (fast.energy_kwh - slow.energy_kwh) + 1e-9
    assert min(slow.energy_kwh, fast.energy_kwh) <= e <= max(slow.energy_kwh, fast.energy_kwh)
    with pytest.raises(InfeasibleError):
        energy_at([d for d in solver.drives if d.time_s > t], t)


def test_summary_gives_the_bracket(descent, c80x50):
    """A plan's summary puts it in the bracket: E* <= the cycle optimum, both at its own running time, and its gap
    to the latter (None without the cycle: the same plan with the air brake a continuous force)."""
    from locoplan.runner import make_context, run_sequence

    route, calc, t, co = descent
    plan = plan_from_cycle_drive(calc, co.drive)
    ctx = make_context(route, c80x50, POINT_MASS, time_s=t, yardstick=True)
    s = run_sequence(ctx, plan.text()).summary
    assert s["feasible"] and s["optimum_with_cycle_kwh"] is not None
    assert s["optimum_with_cycle_kwh"] >= s["optimum_kwh"]
    e, e_cyc = s["traction_energy_kwh"], s["optimum_with_cycle_kwh"]
    assert s["gap_to_cycle_optimum_percent"] == pytest.approx(100 * (e - e_cyc) / e_cyc, abs=0.01)
    assert s["optimum_with_cycle_accuracy_percent"] > 0
    ctx = make_context(route, c80x50, ModelOptions(point_mass=True, air_cycle=False), time_s=t, yardstick=True)
    s = run_sequence(ctx, plan.text()).summary
    assert s["feasible"] and s["optimum_kwh"] is not None
    assert s["optimum_with_cycle_kwh"] is None and s["gap_to_cycle_optimum_percent"] is None
