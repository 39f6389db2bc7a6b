"""Coupler forces (``physics.couplers``) against hand-worked numbers, and the consist's limits.

The three-vehicle train of these tests, head first:
  A: locomotive, 100 t, 20 m, w0 = 2 N/kN, traction 300 kN and electric brake 200 kN at every speed;
  B, C: wagons of 20 t tare + 30 t load = 50 t, 10 m, w0 = 1 N/kN, air brake 40 kN at full cylinder
  pressure (20 kN at the service coefficient 0.5).
Resistances: R_A = 2 x 100 x 9.81 / 1000 = 1.962 kN, R_B = R_C = 1 x 50 x 9.81 / 1000 = 0.4905 kN.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.io.load import load_train
from locoplan.physics.couplers import VehicleLine, coupler_forces_kn, force_rate_kn_per_s, vehicle_gravity_kn
from locoplan.sim.calculator import TractionCalculator
from locoplan.sim.result import COUPLER_LIMIT, FORCE_RATE
from routes import hand_made_route

LOCO = """schema: locoplan/vehicle@1
name: A
kind: locomotive
mass_t: 100
length_m: 20
max_speed_kmh: 100
resistance_n_per_kn: {a: 2.0, b: 0.0, c: 0.0}
traction_kn: [[0, 300], [100, 300]]
brake_kn: [[0, 200], [100, 200]]
"""
WAGON = """schema: locoplan/vehicle@1
name: W
kind: wagon
mass_t: 20
max_load_t: 40
length_m: 10
max_speed_kmh: 100
resistance_n_per_kn: {a: 1.0, b: 0.0, c: 0.0}
air_brake: {force_kn: [[0, 40], [100, 40]]}
"""


def _train(tmp_path: Path, extra: str = "", order: str = "A1W2"):
    (tmp_path / "A.yaml").write_text(LOCO)
    (tmp_path / "W.yaml").write_text(WAGON)
    entries = {"A1W2": "  - {type: A, count: 1}\n  - {type: W, count: 2, load_t: 30}\n",
               "W1A1W1": "  - {type: W, count: 1, load_t: 30}\n  - {type: A, count: 1}\n  - {type: W, count: 1, load_t: 30}\n"}
    f = tmp_path / "three.yaml"
    f.write_text(f"schema: locoplan/consist@1\nname: three\nvehicles:\n{entries[order]}{extra}")
    return load_train(f, tmp_path)


R_A, R_W = 1.962, 0.4905


def _forces(train, traction, brake, gravity=None):
    line = VehicleLine.from_layout(train.layout)
    g = np.zeros((1, 3)) if gravity is None else gravity
    return coupler_forces_kn(line, [traction], [brake], [40.0], g)[0]


def test_traction_on_the_level(tmp_path):
    """a = (300 - 1.962 - 2 x 0.4905) / 200 = 1.485285 m/s^2; behind A: 300 - 1.962 - 100 a = 149.5095 kN;
    behind B: 149.5095 - 0.4905 - 50 a = 74.75475 kN (tension)."""
    c = _forces(_train(tmp_path), 300.0, 0.0)
    a = (300 - R_A - 2 * R_W) / 200
    assert a == pytest.approx(1.485285, abs=1e-9)
    assert c == pytest.approx([149.5095, 74.75475], abs=1e-9)


def test_electric_braking_compresses(tmp_path):
    """200 kN of braking is all electric, at the head: a = -(200 + 2.943) / 200; behind A
    -200 - 1.962 + 100 x 1.014715 = -100.4905 kN, behind B -50.24525 kN (compression)."""
    c = _forces(_train(tmp_path), 0.0, 200.0)
    assert c == pytest.approx([-100.4905, -50.24525], abs=1e-9)


def test_blended_braking_puts_the_air_brake_on_the_wagons(tmp_path):
    """240 kN: the electric brake's 200 kN first (at the head), the 40 kN left on the two wagons' air
    brakes, 20 kN each: a = -242.943 / 200 = -1.214715; behind A -201.962 + 121.4715 = -80.4905 kN,
    behind B -80.4905 - 20.4905 + 60.73575 = -40.24525 kN."""
    c = _forces(_train(tmp_path), 0.0, 240.0)
    assert c == pytest.approx([-80.4905, -40.24525], abs=1e-9)


def test_a_grade_under_the_head_alone(tmp_path):
    """Coasting with the locomotive on +20 per mille and the wagons on the level (the grade begins 20 m
    behind the head): G_A = 100 x 9.81 x 0.02 = 19.62 kN; a = -(19.62 + 2.943) / 200 = -0.112815;
    behind A -21.582 + 11.2815 = -10.3005 kN (the wagons push the climbing locomotive), behind B -5.15025 kN."""
    train = _train(tmp_path)
    route = hand_made_route([(3000.0, 80.0)], [(1000.0, 0.0), (3000.0, 20.0)])
    line = VehicleLine.from_layout(train.layout)
    g = vehicle_gravity_kn(route, line, [1020.0])
    assert g[0] == pytest.approx([19.62, 0.0, 0.0], abs=1e-9)
    c = coupler_forces_kn(line, [0.0], [0.0], [40.0], g)[0]
    assert c == pytest.approx([-10.3005, -5.15025], abs=1e-9)
    # half of wagon B on the grade too: its mean gradient over its 10 m is 10 per mille
    g = vehicle_gravity_kn(route, line, [1025.0])
    assert g[0] == pytest.approx([19.62, 4.905, 0.0], abs=1e-9)


def test_a_whole_train_on_a_uniform_grade_feels_only_the_resistances(tmp_path):
    """Gravity is proportional to mass like inertia: on one gradient it adds nothing to the couplers."""
    train = _train(tmp_path)
    line = VehicleLine.from_layout(train.layout)
    route = hand_made_route([(3000.0, 80.0)], [(3000.0, -12.0)])
    g = vehicle_gravity_kn(route, line, [2000.0])
    level = coupler_forces_kn(line, [300.0], [0.0], [40.0], np.zeros((1, 3)))
    assert coupler_forces_kn(line, [300.0], [0.0], [40.0], g) == pytest.approx(level, abs=1e-9)


def test_a_locomotive_mid_train_pushes_the_wagon_ahead(tmp_path):
    """W, A, W in traction: the locomotive pushes the first wagon (compression ahead of it) and pulls the
    last (tension behind it): a = 297.057 / 200; ahead of A: -0.4905 - 50 a = -74.75475 kN; behind A:
    -74.75475 + 300 - 1.962 - 100 a = 74.75475 kN."""
    train = _train(tmp_path, order="W1A1W1")
    c = _forces(train, 300.0, 0.0)
    assert c == pytest.approx([-74.75475, 74.75475], abs=1e-9)


def test_force_rate_is_the_jump_over_the_time_between_cell_middles():
    """Cells of 2 s and 4 s: middles 1 s and 4 s apart by 3 s; a jump of 300 kN is 100 kN/s."""
    assert force_rate_kn_per_s([0.0, 2.0, 6.0], [300.0, 0.0]) == pytest.approx([100.0])


def test_calculator_refuses_a_plan_over_the_coupler_limit(tmp_path):
    """Starting at full traction puts 149.5 kN in the first coupler: a limit of 120 kN refuses the plan,
    with the force, the side and where; 160 kN lets it run, and the profile carries the largest forces."""
    route = hand_made_route([(3000.0, 60.0)], [(3000.0, 0.0)])
    plan = (("T", "C", "B"), np.array([[1500.0, np.nan]]))
    strict = TractionCalculator(route, _train(tmp_path, "coupler_limit_kn: 120\n"))
    res = strict.evaluate(*plan)
    assert not res.feasible[0] and res.reason_code[0] == COUPLER_LIMIT
    assert res.profile is None and np.isfinite(res.running_time_s[0])  # it runs to the end, and is refused
    assert res.failure_force[0] == pytest.approx(149.5095, abs=1e-9)  # at the start (v = 0: a = 2 N/kN, flat)
    # (at the end of the first cell: the departure's cells are short, the first 1 m long)
    assert "coupler force 150 kN in tension over the consist's limit 120 kN at 1 m" in res.reason(0)
    ok = TractionCalculator(route, _train(tmp_path, "coupler_limit_kn: 160\n")).evaluate(*plan, profile=True)
    assert ok.feasible[0]
    prof = ok.profile
    assert np.nanmax(prof.coupler_tension_kn) == pytest.approx(149.5095, abs=1e-9)
    # braking at the stop: at most the electric brake's 200 kN at the head and the wagons' air brake
    assert 0 < np.nanmax(prof.coupler_compression_kn) < 200.0


def test_calculator_refuses_a_jump_faster_than_the_rate_limit(tmp_path):
    """The fastest run accelerates at 300 kN (a = 1.485 m/s^2) and then holds 60 km/h with 2.943 kN (its
    resistance), from 16.67^2 / (2 x 1.485) = 93.5 m on: the force falls by 297 kN across the cells around
    there (one of them blends the two), in less than the limit's 297 / 50 = 5.9 s. The rate reported is the
    largest change of the cells' forces over the time between their middles, worked here from the profile."""
    route = hand_made_route([(3000.0, 60.0)], [(3000.0, 0.0)])
    calc = TractionCalculator(route, _train(tmp_path, "force_rate_limit_kn_per_s: 50\n"))
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    assert res.reason_code[0] == FORCE_RATE
    assert "kN/s, over the consist's limit 50 kN/s" in res.reason(0)
    prof = res.profile
    f = prof.traction_kn[0] - prof.brake_kn[0]
    mid_t = 0.5 * (prof.t_s[0, 1:] + prof.t_s[0, :-1])
    rates = [abs(f[k + 1] - f[k]) / (mid_t[k + 1] - mid_t[k]) for k in range(len(f) - 1)]
    k = next(i for i, r in enumerate(rates) if r > 50.0)
    assert res.failure_force[0] == pytest.approx(rates[k])
    assert prof.s_m[k] < 93.5 < prof.s_m[k + 2] and f[k] == pytest.approx(300.0) and f[k + 2] == pytest.approx(2.943)
    assert force_rate_kn_per_s(prof.t_s[0], f)[k] == pytest.approx(rates[k])


def test_limits_are_validated_with_their_line(tmp_path):
    with pytest.raises(InputError) as exc:
        _train(tmp_path, "coupler_limit_kn: 20\n")
    p = exc.value.problems[0]
    assert p.field == "coupler_limit_kn" and p.line == 6 and "implausible" in p.message


def test_the_cheap_bound_is_a_bound():
    """The calculator computes the coupler forces only where ``CouplerBound`` reaches the limit: on the
    distributed-power consist over the heavy-haul line, at random forces and speeds in every cell, no
    coupler force is above it (and it is not loose by orders of magnitude)."""
    from locoplan.io.load import load_route

    calc = TractionCalculator(load_route("routes/heavy-haul-60km.yaml"), load_train("HXD1x2-C80x100"))
    rng = np.random.default_rng(7)
    n = len(calc.h_m)
    bound = calc.coupler_bound
    worst = 0.0
    for _ in range(5):
        v = rng.uniform(0.0, 100.0, n)
        f = rng.uniform(0.0, 1.0, n) * np.interp(v, calc.train.traction_speed_kmh, calc.train.traction_kn)
        b = rng.uniform(0.0, 1.0, n) * np.interp(v, calc.train.brake_speed_kmh, calc.train.brake_kn)
        f = np.where(rng.uniform(size=n) < 0.5, f, 0.0)
        b = np.where(f > 0, 0.0, b)
        c = coupler_forces_kn(calc.vehicle_line, f, b, v, calc.vehicle_gravity_kn, calc.traction_allowed)
        e = np.minimum(b, np.interp(v, calc.electric_brake_speed_kmh, calc.electric_brake_kn) * calc.traction_allowed)
        lim = bound.kn(f, e, b - e)
        assert np.all(np.abs(c).max(axis=1) <= lim + 1e-9)
        worst = max(worst, float(np.max(np.abs(c).max(axis=1) / lim)))
    assert worst > 0.3


@pytest.mark.slow
def test_the_shipped_heavy_haul_train_and_line():
    """HXD1 x 2 (head and mid-train) + 100 x C80: 10,400 t, 1,270.4 m, found by its catalogue name; on the
    heavy-haul line (48 km of descent, 30.5 km of it at -12 per mille) the optimised plan is on time and its
    couplers stay within the consist's 2,250 kN; the mid-train locomotive carries half the traction, so the
    largest tension at the start is the head's share less its own resistance and what its own mass takes:
    760 - 2.7468 - 200 x (1520 - A) / 10400 kN (A = the train's resistance at rest, 95.7456 kN; the HXD1's
    own 1.40 N/kN x 200 t x 9.81 / 1000 = 2.7468 kN) = 729.86 kN."""
    from locoplan.io.load import load_route

    train = load_train("HXD1x2-C80x100")
    assert train.mass_t == 10400.0 and train.length_m == pytest.approx(1270.4)
    assert [g.kind for g in train.layout] == ["locomotive", "wagon", "locomotive", "wagon"]
    assert train.coupler_limit_kn == 2250.0
    route = load_route("routes/heavy-haul-60km.yaml")
    steep = sum(g.to_m - g.from_m for g in route.gradients if g.permille <= -12.0)
    descent = sum(g.to_m - g.from_m for g in route.gradients if g.permille < 0)
    assert steep == 30500.0 and descent == 48000.0
    res = CliRunner().invoke(app, ["optimize", "routes/heavy-haul-60km.yaml", "--consist", "HXD1x2-C80x100", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    assert d["feasible"] and d["punctual"]
    assert d["coupler_limit_kn"] == 2250.0
    assert train.resistance_kn[0] == pytest.approx(95.7456, abs=1e-9)
    assert d["max_coupler_tension_kn"] == pytest.approx(760.0 - 2.7468 - 200.0 * (1520.0 - 95.7456) / 10400.0, abs=0.05)
    assert 0 < d["max_coupler_compression_kn"] < 2250.0
