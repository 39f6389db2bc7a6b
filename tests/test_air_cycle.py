"""The wagons' direct-release air brake as a cycle (``sim.kernel.run_plans``, ``Train.air_cycle``): an
application builds up over TB/T 1407's brake idle time, stays on until a full release, and may not be made
again before the brake has recharged; on a descent the electric brake cannot hold, the train brakes in
cycles, and a plan that would apply again too early is refused. Numbers worked by hand in each docstring.

HXD1 + 50 x C80 (5,200 t, 635.2 m, 51 vehicles) on 10 km at 60 km/h, level but -15 per mille from 2,000 m to
9,000 m. Once the whole train is on the grade: gravity 5200 x 9.81 x 0.015 = 765.18 kN; resistance at
60 km/h R60 = 86.64 kN (test_honest_physics); the HXD1's electric brake 461 kN up to 74.97 km/h; so under the
full electric brake the train gains a_up(60) = (765.18 - 86.64 - 461) / 5200 = 0.041835 m/s^2. The 50 C80s'
air brake at beta_c = 0.5: 50 x 0.20 x 100 t x 9.81 x phi_h(v) x 0.5 kN, phi_h(60) = 0.322 x 210 / 270:
1,228.4 kN, a_air(60) = 0.23623 m/s^2.

Build-up (t_k, TB/T 1407): (3.6 + 0.00176 x 50 kPa x 51) x (1 - 0.032 x (-15)) = 8.088 x 1.48 = 11.970 s.
Recharge: 30 s + 0.6 s x 50 wagons = 60 s. Least hold: the build-up time.
"""

import math

import numpy as np
import pytest

from locoplan.errors import InputError
from locoplan.io.load import load_train
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from locoplan.sim.result import AIR_APPLIED, AIR_RELEASED
from routes import hand_made_route

G = 9.81
GRAVITY_KN = 5200 * G * 0.015
T_BUILD_S = (3.6 + 0.00176 * 50 * 51) * (1 + 0.032 * 15)
RECHARGE_S = 30.0 + 0.6 * 50


def resistance_kn(v):
    """HXD1 (200 t) + 50 loaded C80 (5,000 t): their Davis formulas [N/kN] x weight [kN] / 1000."""
    return 200 * G / 1000 * (1.40 + 0.0038 * v + 0.0003 * v * v) + 5000 * G / 1000 * (0.92 + 0.0048 * v + 0.000125 * v * v)


def air_kn(v):
    return 50 * 0.20 * 100 * G * 0.322 * (v + 150) / (2 * v + 150) * 0.5


def a_up(v):
    """m/s^2 under the full electric brake (461 kN below 74.97 km/h) once the whole train is on -15."""
    return (GRAVITY_KN - resistance_kn(v) - 461.0) / 5200


def drop_margin(drop_kmh, recharge_s):
    """The release margin that puts the release ``drop_kmh`` below the apply speed under the 60 km/h limit: the
    drop is margin x 3.6 a_up(60) x recharge (``kernel.cycle_speeds``); 2 km/h in 60 s: 0.2213."""
    return drop_kmh / (3.6 * a_up(60) * recharge_s)


def descent_line():
    return hand_made_route([(10000, 60.0)], [(2000, 0.0), (9000, -15.0), (10000, 0.0)], 10000)


@pytest.fixture(scope="module")
def c80x50():
    return load_train("HXD1-C80x50")


@pytest.mark.slow
def test_hand_worked_numbers(c80x50):
    assert GRAVITY_KN == pytest.approx(765.18, abs=0.01) and resistance_kn(60) == pytest.approx(86.64, abs=0.01)
    assert a_up(60) == pytest.approx(0.041835, abs=1e-6) and air_kn(60) / 5200 == pytest.approx(0.23623, abs=1e-5)
    assert T_BUILD_S == pytest.approx(11.970, abs=1e-3)
    cyc = c80x50.air_cycle
    assert cyc.recharge_s == RECHARGE_S == 60.0 and cyc.min_hold_s is None and cyc.n_vehicles == 51
    # the build-up along the grade, level and on the descent; the 10,400 t train: 102 vehicles, 90 s
    assert cyc.build_up_s([0.0, -15.0]) == pytest.approx([8.088, T_BUILD_S], abs=1e-9)
    big = load_train("HXD1x2-C80x100").air_cycle
    assert big.recharge_s == 90.0 and big.build_up_s([0.0, -12.0]) == pytest.approx([12.576, 12.576 * 1.384], abs=1e-9)
    calc = TractionCalculator(descent_line(), c80x50)
    on = (calc.s_m[:-1] >= 2000 + c80x50.length_m) & (calc.s_m[1:] <= 9000)
    np.testing.assert_allclose(calc.t_build_s[on], T_BUILD_S, rtol=1e-12)


def test_an_application_builds_up_over_its_idle_time(c80x50):
    """A plan braking (B) from 1,500 m on the level, at about 55 km/h: the air brake's force grows linearly
    over t_k = 8.088 s (level) from the application, so in each cell the brake force is the electric brake's
    461 kN plus air_kn(v) x (t - t_applied) / 8.088 s at the cell's middle (within 3 % of the air brake's
    force: the cell's middle time is estimated from its extrapolated middle speed), and the whole of it
    after 8.088 s."""
    calc = TractionCalculator(descent_line(), c80x50)
    res = calc.evaluate(("T", "C", "B"), np.array([[1000.0, 1500.0]]), profile=True)
    p = res.profile
    k0 = int(np.searchsorted(p.s_m, 1500.0))
    assert p.air[0, k0] == AIR_APPLIED and 50 < p.v_kmh[0, k0] < 60
    t_app = p.t_s[0, k0]
    seen_partial = seen_full = False
    for k in range(k0, k0 + 12):
        if not p.v_kmh[0, k + 1] > 30.0:  # (near rest the cell's middle speed is a poor estimate of its force)
            break
        t_mid = 0.5 * (p.t_s[0, k] + p.t_s[0, k + 1])
        v_mid = 0.5 * (p.v_kmh[0, k] + p.v_kmh[0, k + 1])
        level = min(max((t_mid - t_app) / 8.088, 0.0), 1.0)
        assert p.brake_kn[0, k] == pytest.approx(461.0 + level * air_kn(v_mid), abs=0.03 * air_kn(v_mid))
        seen_partial |= 0.2 < level < 0.8
        if t_mid - t_app > 8.088 + (p.t_s[0, k + 1] - p.t_s[0, k]):
            seen_full = True
            assert p.brake_kn[0, k] == pytest.approx(461.0 + air_kn(v_mid), rel=0.005)
    assert seen_partial and seen_full


def test_cycles_on_a_constant_descent(c80x50):
    """Full traction down 7 km at -15 per mille under 60 km/h. The electric brake alone cannot hold it
    (a_up = 0.041835 m/s^2), so the train cycles: apply at 60 - max(1, 1.25 x 3.6 x a_up^2 t_k / (2 a_air))
    = 60 - max(1, 0.1995) = 59.0 km/h; release no earlier than t_k = 11.97 s after, at or below
    59.0 - 1.25 x 3.6 x a_up x 60 s = 47.70 km/h (the rule: the train, under the full electric brake, then
    takes >= 1.25 x the recharge to regain the apply speed), checked at each cell's start (one 50 m cell at
    the deceleration after build-up, about (0.236 - 0.042) m/s^2 x 3.7 s, is 2.6 km/h); in between, the full
    electric brake. Its period, integrated by hand from the forces from the observed apply and release
    speeds (linear build-up, then the full air brake down to the release speed, then a_up back up), within
    2 %; every recharge margin is that climb's time less 60 s."""
    calc = TractionCalculator(descent_line(), c80x50)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    assert res.feasible[0], res.reason(0)
    p = res.profile
    on = (p.s_m[:-1] >= 2000 + c80x50.length_m) & (p.s_m[1:] <= 9000)
    apply = np.flatnonzero(on & (p.air[0] == AIR_APPLIED))
    release = np.flatnonzero(on & (p.air[0] == AIR_RELEASED))
    assert len(apply) >= 3 and len(release) >= 3
    for k in apply:
        assert 59.0 <= p.v_kmh[0, k] <= 59.5
    every = np.flatnonzero(p.air[0] == AIR_APPLIED)
    for k in release:
        assert 47.70 - 2.8 <= p.v_kmh[0, k] <= 47.7047
        assert p.t_s[0, k] - p.t_s[0, every[every < k][-1]] >= T_BUILD_S
    # the full electric brake (and nothing else) between a release and the next application
    release = release[release > apply[0]]  # (the first may end the application made entering the grade)
    band = np.arange(release[0] + 1, apply[apply > release[0]][0])
    np.testing.assert_allclose(p.brake_kn[0, band], 461.0, rtol=1e-9)
    assert np.all(p.traction_kn[0, band] == 0)

    def period(v_app, v_rel, v_next):
        """Hand integration (dt = 5 ms) of one cycle from an application at ``v_app`` to the next at ``v_next``
        [s], and its climb from the release at ``v_rel`` [s]."""
        dt, v, t = 0.005, v_app / 3.6, 0.0
        while True:
            level = min(t / T_BUILD_S, 1.0)
            v += dt * (a_up(v * 3.6) - level * air_kn(v * 3.6) / 5200)
            t += dt
            if t >= T_BUILD_S and v * 3.6 <= v_rel:
                break
        climb = 0.0
        while v * 3.6 < v_next:
            v += dt * a_up(v * 3.6)
            climb += dt
        return t + climb, climb

    for a, r, b in zip(apply[:-1], release, apply[1:]):
        whole, climb = period(p.v_kmh[0, a], p.v_kmh[0, r], p.v_kmh[0, b])
        assert p.t_s[0, b] - p.t_s[0, a] == pytest.approx(whole, rel=0.02)
        assert p.t_s[0, b] - p.t_s[0, r] == pytest.approx(climb, rel=0.02)
    assert res.air_margin_s[0] > 0
    # the least recharge margin: over every application after a release, the stop's braking curve's at about
    # 9.6 km included (the last release, near the descent's foot, comes where the grade ends before the train
    # could reach the apply speed, and leaves the recharge before the stop's curve)
    waits = [p.t_s[0, every[every > r][0]] - p.t_s[0, r] for r in np.flatnonzero(p.air[0] == AIR_RELEASED)
             if (every > r).any()]
    assert res.air_margin_s[0] == pytest.approx(min(waits) - RECHARGE_S, abs=1e-6)


def test_a_release_waits_until_the_brake_can_recharge(c80x50):
    """The same run with a release margin of 0.2213 (a release only 2 km/h below the apply speed, 59.0 km/h): the
    train would regain 59.0 km/h from 57 km/h in about 3.6 km/h / 3.6 / 0.0425 m/s^2 = 24 s, before its 60 s
    recharge, so the release waits (the application kept on, the speed held or falling under the air brake)
    until the train, under the full electric brake, cannot reach the apply speed within the recharge: the speed
    from which integral dv / a_up(v) up to 59.0 km/h takes 60 s (hand-integrated here, 49.73 km/h). Every release
    more than the distance covered at the limit in the recharge (1,000 m) above the descent's foot is at or below
    it, within a cell's fall under the air brake (about 2.6 km/h; nearer the foot the train may release higher:
    the grade ends before it could reach the apply speed); every application comes at least the recharge after
    the release before it; the run keeps every rule and is not refused. The release by
    the rule (margin 1.25, 47.70 km/h) lies below that speed: the same safe point comes first."""
    dt, v, climb = 0.001, 59.0 / 3.6, 0.0
    while climb < RECHARGE_S:  # backwards from the apply speed: where the recharge's climb begins
        v -= dt * a_up(v * 3.6)
        climb += dt
    v_safe = v * 3.6
    assert v_safe == pytest.approx(49.73, abs=0.01)
    calc = TractionCalculator(descent_line(), c80x50)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True, release_margin=drop_margin(2.0, RECHARGE_S))
    assert res.feasible[0], res.reason(0)
    p = res.profile
    on = (p.s_m[:-1] >= 2000 + c80x50.length_m) & (p.s_m[1:] <= 9000 - 60.0 / 3.6 * RECHARGE_S)
    release = np.flatnonzero(on & (p.air[0] == AIR_RELEASED))
    assert len(release) >= 3
    for k in release:
        assert v_safe - 2.8 <= p.v_kmh[0, k] <= v_safe + 0.05
    assert res.air_margin_s[0] >= 0.0
    every = np.flatnonzero(p.air[0] == AIR_APPLIED)
    for r in np.flatnonzero(p.air[0] == AIR_RELEASED):
        later = every[every > r]
        if later.size:
            assert p.t_s[0, later[0]] - p.t_s[0, r] >= RECHARGE_S - 1e-9
    assert 47.70 < v_safe  # the rule's release speed is safe: the rule's run releases at its own speed
    assert calc.evaluate(("T",), np.zeros((1, 0))).feasible[0]


def _consist(tmp_path, cycle: str):
    f = tmp_path / "c.yaml"
    f.write_text("schema: locoplan/consist@1\nname: c\nvehicles:\n  - {type: HXD1, count: 1}\n"
                 f"  - {{type: C80, count: 50, load_t: 80}}\n{cycle}")
    return f


def test_the_cycle_is_set_in_the_consist(tmp_path):
    """A consist's own recharge, build-up and hold: 10 s recharge (the shallow release above then comes at once), a fixed
    5 s build-up, a 20 s hold (each release at least 20 s after its application)."""
    train = load_train(_consist(tmp_path, "air_brake_cycle: {recharge_s: 10, recharge_s_per_wagon: 0, build_up_s: 5,"
                                          " min_hold_s: 20}\n"))
    cyc = train.air_cycle
    assert cyc.recharge_s == 10.0 and cyc.min_hold_s == 20.0
    assert cyc.build_up_s([0.0, -15.0]) == pytest.approx([5.0, 5.0])
    calc = TractionCalculator(descent_line(), train)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True, release_margin=drop_margin(2.0, 10.0))
    assert res.feasible[0], res.reason(0)
    p = res.profile
    apply = np.flatnonzero(p.air[0] == AIR_APPLIED)
    for k in np.flatnonzero(p.air[0] == AIR_RELEASED):
        before = apply[apply < k]
        assert p.t_s[0, k] - p.t_s[0, before[-1]] >= 20.0 - 1e-9
    assert res.air_margin_s[0] >= 0 and res.recharge_s == 10.0


def test_cycle_fields_are_validated_with_their_line(tmp_path):
    with pytest.raises(InputError) as exc:
        load_train(_consist(tmp_path, "air_brake_cycle:\n  reduction_kpa: 20\n"))
    p = exc.value.problems[0]
    assert "reduction_kpa" in p.field and p.line == 7 and "50" in p.message


def test_models_without_the_cycle_are_unchanged(c80x50):
    """The electric brake alone (--no-air-brake, the seeds' model) has no cycle; and a descent the electric
    brake holds needs no application: freight-20km's fastest run is the same with or without the cycle."""
    route = descent_line()
    for opts in (ModelOptions(air_brake=False), ModelOptions.papers()):
        res = TractionCalculator(route, c80x50, opts).evaluate(("T",), np.zeros((1, 0)), profile=True)
        assert res.air_applications is None and res.profile.air is None
    from locoplan.io.load import load_route

    f20 = load_route("routes/freight-20km.yaml")
    a = TractionCalculator(f20, c80x50).evaluate(("T",), np.zeros((1, 0)), profile=True)
    b = TractionCalculator(f20, c80x50, ModelOptions(air_cycle=False)).evaluate(("T",), np.zeros((1, 0)), profile=True)
    # (the same run up to the last release, 19,050 m: see the next test)
    same = a.profile.s_m <= 19050.0
    np.testing.assert_allclose(a.profile.v_kmh[0, same], b.profile.v_kmh[0, same], rtol=1e-12)
    assert a.air_applications[0] >= 4 and a.air_margin_s[0] >= 0.0  # braking curves only, each on a recharged brake


def test_a_braking_curve_within_the_recharge_waits_for_it(c80x50):
    """Level, 60 km/h to 9,060 m, 45 km/h to the stop at 10 km. The fastest run releases the air brake at 9,060 m,
    where its braking curve reaches 45 km/h; the stop's braking curve needs the air brake from 9,784 m, 724 m on,
    less than the 45 / 3.6 x 60 s = 750 m the train covers at the limit in the 60 s recharge. The electric brake
    can slow it enough to arrive later (at 0.9 x 461 kN + R(45) = 0.09 m/s^2 it would cover the 724 m in more than
    60.5 s): so it is released there, and until the recharge is over the train is capped by the speed that
    reaches 9,784 m 0.5 s after the recharge is over, slowed to it by 90 % of the electric brake: never faster
    than (0.9 x 461 + R(v)) / m_eff decelerates, held below 724 m / 60.5 s = 43.08 km/h, and the stop's
    application comes at least 60 s after the release. With the air brake as a continuous force the train holds
    45 km/h and reaches that curve 724 / 12.5 = 57.9 s after: the run is 60.5 - 57.9 = 2.58 s (up to 1 s more
    for the slowing) faster."""
    route = hand_made_route([(9060, 60.0), (10000, 45.0)], [(10000, 0.0)], 10000)
    calc = TractionCalculator(route, c80x50)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    assert res.feasible[0], res.reason(0)
    p = res.profile
    k_rel = np.flatnonzero(p.air[0] == AIR_RELEASED)[-1]
    assert p.s_m[k_rel] == pytest.approx(9060.0) and p.v_kmh[0, k_rel] == pytest.approx(45.0, abs=0.01)
    s_air = p.s_m[calc.next_air_curve[k_rel]]
    assert s_air == pytest.approx(9784.07, abs=0.01) and s_air - 9060.0 < 45.0 / 3.6 * RECHARGE_S
    v_wait = (s_air - 9060.0) / (RECHARGE_S + 0.5) * 3.6
    assert v_wait == pytest.approx(43.08, abs=0.01)
    e = p.v_kmh[0] ** 2 / 2 / 3.6 ** 2
    on = np.flatnonzero((p.s_m[:-1] >= 9060.0) & (p.s_m[1:] <= s_air))
    for k in on:
        v_mid = 0.5 * (p.v_kmh[0, k] + p.v_kmh[0, k + 1])
        slope = (e[k + 1] - e[k]) / (p.s_m[k + 1] - p.s_m[k])
        assert slope >= -(0.9 * 461.0 + resistance_kn(v_mid)) / calc.m_eff_t * 1.01
    held = (p.s_m >= s_air - 400.0) & (p.s_m < s_air)
    assert np.ptp(p.v_kmh[0, held]) < 0.01 and 42.0 < p.v_kmh[0, held][0] < v_wait
    k_app = np.flatnonzero(p.air[0] == AIR_APPLIED)[-1]
    assert p.t_s[0, k_app] - p.t_s[0, k_rel] >= RECHARGE_S and res.air_margin_s[0] >= 0.0
    cont = TractionCalculator(route, c80x50, ModelOptions(air_cycle=False)).evaluate(("T",), np.zeros((1, 0)))
    # the continuous run reaches 9,784 m at 45 km/h 724 / 12.5 = 57.9 s after 9,060 m; this one 60.5 s after
    late = (RECHARGE_S + 0.5) - (s_air - 9060.0) / (45.0 / 3.6)
    assert late == pytest.approx(2.58, abs=0.01)
    assert late - 0.1 < res.running_time_s[0] - cont.running_time_s[0] < late + 1.0


def test_a_drop_just_before_the_stop_is_braked_electrically():
    """The MPOC test line's fastest run, HXD1 + 30 x C80 (48 s recharge): the limit drops from 70 to 50 km/h at
    3,500 m and the stop's braking curve needs the air brake about 400 m further on, nearer than the 667 m
    covered at 50 km/h in the recharge, and 90 % of the electric brake (about 0.1 m/s^2) cannot slow the train
    enough to arrive after it. So that drop is braked on the electric brake's own curve, with no air: the only
    application of the run is the stop's, on a charged brake, and on the way down to 50 km/h the train never
    decelerates faster than (0.9 x 461 kN + R(v) + grade) / m_eff. (Applying the air brake for the drop, it
    would have to keep it on, braking, until slow enough.) Against the air brake as a continuous force the run
    loses at most what the electric curve's extra length costs: braked at about 0.1 m/s^2 instead of full
    braking, the curve from 70 to 50 km/h is at most (19.44^2 - 13.89^2) / (2 x 0.1) = 925 m long, covered in
    at most 925 / 13.89 - 925 / 19.44 = 19 s more than at 70 km/h."""
    from locoplan.io.load import load_route

    train = load_train("HXD1-C80x30")
    calc = TractionCalculator(load_route("tests/data/routes/mpoc-small.yaml"), train)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    assert res.feasible[0], res.reason(0)
    assert train.air_cycle.recharge_s == pytest.approx(48.0) and 50.0 / 3.6 * 48.0 == pytest.approx(666.7, abs=0.1)
    p = res.profile
    app = np.flatnonzero(p.air[0] == AIR_APPLIED)
    assert len(app) == 1 and p.s_m[app[0]] > 3700.0 and res.air_applications[0] == 1
    assert not (p.air[0] == AIR_RELEASED).any()
    e = p.v_kmh[0] ** 2 / 2 / 3.6 ** 2
    mass_t = 200 + 30 * 100  # HXD1 + 30 loaded C80
    down = np.flatnonzero((p.s_m[:-1] > 3000.0) & (p.s_m[1:] <= 3500.0) & (np.diff(e) < 0))
    assert down.size >= 5
    for k in down:
        v_mid = 0.5 * (p.v_kmh[0, k] + p.v_kmh[0, k + 1])
        r_kn = 200 * G / 1000 * (1.40 + 0.0038 * v_mid + 0.0003 * v_mid ** 2) + 3000 * G / 1000 * (
            0.92 + 0.0048 * v_mid + 0.000125 * v_mid ** 2)
        grade_kn = mass_t * G * calc.gradient_permille[k] / 1000
        slope = (e[k + 1] - e[k]) / (p.s_m[k + 1] - p.s_m[k])
        assert slope >= -(0.9 * 461.0 + r_kn + grade_kn) / calc.m_eff_t * 1.01
    cont = TractionCalculator(calc.route, train, ModelOptions(air_cycle=False)).evaluate(("T",), np.zeros((1, 0)))
    bound = 925.0 / (50 / 3.6) - 925.0 / (70 / 3.6)
    assert bound == pytest.approx(19.0, abs=0.1)
    assert 0.0 < res.running_time_s[0] - cont.running_time_s[0] < bound


@pytest.mark.slow
def test_heavy_haul_optimize_respects_the_recharge_and_the_couplers(heavy_haul):
    """`optimize` on the heavy-haul line (30.5 km at -12 per mille, which the two HXD1s cannot hold): on time,
    its cycles each at least the 90 s recharge apart, its couplers within 2,250 kN, and E* (the air brake
    relaxed to a continuous force) below it."""
    from locoplan.runner import make_context, run_strategy
    from locoplan.settings import RunSettings

    route, train = heavy_haul
    ctx = make_context(route, train, RunSettings(ModelOptions(), yardstick=True))
    out = run_strategy(ctx, "proposed")
    s = out.summary
    assert s["feasible"] and s["punctual"], s["reason"]
    assert s["air_applications"] >= 6 and s["recharge_s"] == 90.0
    assert s["min_recharge_margin_s"] >= 0.0
    assert s["max_coupler_tension_kn"] <= 2250.0 and s["max_coupler_compression_kn"] <= 2250.0
    assert s["gap_to_optimum_kwh"] > 0
    p = out.result.profile
    t_app = p.t_s[0, :-1][p.air[0] == AIR_APPLIED]
    t_rel = p.t_s[0, :-1][p.air[0] == AIR_RELEASED]
    for t in t_app:
        before = t_rel[t_rel < t]
        assert not before.size or t - before[-1] >= 90.0 - 1e-6 or math.isclose(t, before[-1])
    # the plan releases as soon as the brake can recharge (the least margin, 0.25) on both descents where the air
    # brake cycles (the -12 and the -11 per mille one), and carries that: re-run, it gives the same run
    regions = ctx.calc.cycle_regions_m
    assert len(regions) == 2
    placed = s["release_margins"]
    assert [r["from_m"] for r in placed] == regions[:, 0].round(1).tolist() and all(r["margin"] == 0.25 for r in placed)
    plan = out.outcome.plan
    again = ctx.calc.evaluate(plan.conditions, plan.switches_m, **plan.cycle_kwargs())
    assert again.running_time_s[0] == pytest.approx(s["running_time_s"], abs=0.01)
    # the rule's margin 1.25 given as a plan's reproduces the rule exactly; deeper cycles lose time on the descents
    # (the time the plan spends elsewhere for less traction): the earliest release is the fastest
    rule = ctx.calc.evaluate(plan.conditions, plan.switches_m)
    same = ctx.calc.evaluate(plan.conditions, plan.switches_m, release_margin=[[1.25, 1.25]], margin_regions_m=regions)
    deep = ctx.calc.evaluate(plan.conditions, plan.switches_m, release_margin=[[3.0, 3.0]], margin_regions_m=regions)
    assert same.running_time_s[0] == rule.running_time_s[0]
    assert same.traction_energy_kwh[0] == rule.traction_energy_kwh[0]
    assert again.running_time_s[0] + 5.0 < rule.running_time_s[0] and again.air_applications[0] > rule.air_applications[0]
    assert deep.feasible[0] and deep.running_time_s[0] > rule.running_time_s[0] + 10.0


def two_descents():
    """Two 7 km descents at -15 per mille under 60 km/h, 9 km of level between them (more than the 1 km the train
    covers at 60 km/h in the 60 s recharge): two cycle regions."""
    return hand_made_route([(27000, 60.0)], [(2000, 0.0), (9000, -15.0), (18000, 0.0), (25000, -15.0), (27000, 0.0)],
                           27000)


def test_each_descent_releases_where_its_margin_says(c80x50):
    """The release margin of one descent moves that descent's releases only. Margin 3 on the second descent: the
    release speed lies 3 x 3.6 x a_up(60) x 60 s = 27.1 km/h below the apply speed (59.0 km/h): about 31.9 km/h
    (below it, as releases are made at a cell's start); the first descent keeps the rule's 1.25 (release above
    45 km/h), exactly as with no margins given."""
    calc = TractionCalculator(two_descents(), c80x50)
    regions = calc.cycle_regions_m
    assert len(regions) == 2
    assert 2000 <= regions[0, 0] < 3000 and 9000 <= regions[0, 1] < 9700  # (the train's 635 m on the grade)
    assert 18000 <= regions[1, 0] < 19000 and 25000 <= regions[1, 1] < 25700
    rule = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True, release_margin=[[0.0, 3.0]],
                        margin_regions_m=regions)
    assert res.feasible[0] and rule.feasible[0], res.reason(0)
    p, q = res.profile, rule.profile
    first = p.s_m[:-1] < 12000
    np.testing.assert_array_equal(p.air[0, first], q.air[0, first])
    np.testing.assert_allclose(p.v_kmh[0, :-1][first], q.v_kmh[0, :-1][first], rtol=1e-12)
    rel = np.flatnonzero(p.air[0] == AIR_RELEASED)
    v_first, v_second = p.v_kmh[0, rel[p.s_m[rel] < 12000]], p.v_kmh[0, rel[(p.s_m[rel] > 18000) & (p.s_m[rel] < 25000)]]
    drop = 3.0 * 3.6 * a_up(60) * RECHARGE_S
    assert drop == pytest.approx(27.11, abs=0.01)
    assert v_first.size >= 2 and (v_first > 45.0).all()
    assert v_second.size >= 1 and (v_second <= 59.0 - drop + 0.05).all() and (v_second > 59.0 - drop - 3.0).all()


@pytest.mark.parametrize("strategy", ["time-saving", "energy-saving", "four-stage", "proposed"])
@pytest.mark.slow
def test_every_strategy_plans_drivable_cycles(c80x50, strategy):
    """Every strategy's plan down the 7 km at -15 per mille is accepted by the calculator, so its air brake keeps
    the recharge (each application at least 60 s after the release before it) and the limit."""
    from locoplan.runner import make_context, run_strategy
    from locoplan.settings import RunSettings

    route = hand_made_route([(10000, 60.0)], [(2000, 0.0), (9000, -15.0), (10000, 0.0)], 10000,
                            schedule={"run_time_s": 900, "tolerance_s": 30})
    ctx = make_context(route, c80x50, RunSettings(ModelOptions(), yardstick=False))
    out = run_strategy(ctx, strategy)
    s = out.summary
    assert s["feasible"], s["reason"]
    assert s["air_applications"] >= 3 and s["min_recharge_margin_s"] >= 0.0
    p = out.result.profile
    assert np.nanmax(p.v_kmh[0]) <= 60.0 + 1e-9
    t_app = p.t_s[0, :-1][(p.air[0] == AIR_APPLIED) & (p.s_m[:-1] < 9000)]
    t_rel = p.t_s[0, :-1][p.air[0] == AIR_RELEASED]
    for t in t_app:
        before = t_rel[t_rel < t]
        assert not before.size or t - before[-1] >= RECHARGE_S - 1e-6
