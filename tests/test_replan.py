"""On-board re-planning (``locoplan replan``, ``--stream``) and the closed loop (``locoplan drive``).

Oracles: the traction calculator (the re-plan's sequence simulated from rest), E* (``ocp.bound``, the least energy
in a running time), the route's limits, distance over the top speed for the fastest remainder, and the re-plan's
own drive (a re-plan from a state on it gives back its remainder).
"""

from __future__ import annotations

import json
from functools import lru_cache

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan import api
from locoplan.cli import app
from locoplan.io.load import load_route, load_train
from locoplan.model.disturbance import Disturbance
from locoplan.optimize.replan import Replanner, TrainState
from locoplan.sim.calculator import ModelOptions, TractionCalculator, limit_kmh_at
from locoplan.settings import RunSettings

runner = CliRunner()
MODELS = {"default": ModelOptions(), "point-mass": ModelOptions(point_mass=True, air_brake=False),
          "no-air-brake": ModelOptions(air_brake=False)}
FLAGS = {"default": [], "point-mass": ["--point-mass"], "no-air-brake": ["--no-air-brake"]}


@pytest.fixture(autouse=True)
def _in_repo(root, monkeypatch):
    monkeypatch.chdir(root)


@lru_cache(maxsize=None)
def _setup(route: str, model: str):
    r = load_route(route)
    train = load_train("configs/consists/HXD1-C80x50.yaml")
    opts = MODELS[model]
    if r.schedule is not None:
        t0, tol = float(r.schedule.run_time_s), float(r.schedule.tolerance_s)
    else:
        t0 = round(1.15 * TractionCalculator(r, train, opts).fastest_time_s)
        tol = api.punctuality_tolerance(r, t0, None)
    return r, train, opts, t0, tol, Replanner(r, train, opts, planned_s=t0, tolerance_s=tol, cycle=False)


@pytest.mark.parametrize("model", ["default", "point-mass"])
def test_replans_along_the_plan_give_back_its_remainder(model):
    """20 states on the departure plan's own drive, each with the plan's arrival: the remainder's time within 0.5 s
    and its energy within 0.5 % (of the remainder; 0.01 kWh where nothing is left to spend)."""
    *_, rp = _setup("routes/freight-20km.yaml", model)
    plan = rp.replan(TrainState(0.0, 0.0, 0.0))
    assert plan.on_time
    idx = np.linspace(1, len(plan.s_m) - 2, 20).round().astype(int)
    for i in idx:
        s, v, t = float(plan.s_m[i]), float(plan.v_kmh[i]), float(plan.t_s[i])
        q = rp.replan(TrainState(s, v, t, plan.condition_at(s)), plan.arrival_s)
        rest_e = plan.remaining_energy_kwh - plan.energy_kwh[i]
        assert q.arrival_s == pytest.approx(plan.arrival_s, abs=0.5), s
        assert q.remaining_energy_kwh == pytest.approx(rest_e, rel=0.005, abs=0.01), s


@pytest.mark.parametrize("model", ["default", "no-air-brake"])
def test_the_departure_plan_against_the_calculator_and_estar(model):
    """The re-plan from rest is a plan: its sequence, run by the traction calculator, arrives within 1 % of the DP's
    time and spends within 2 % of its energy; the DP's energy lies within 1.5 % of E* at its own running time; no
    node is over the limit."""
    from locoplan.ocp.bound import energy_bound

    r, train, opts, t0, tol, rp = _setup("routes/freight-20km.yaml", model)
    plan = rp.replan(TrainState(0.0, 0.0, 0.0))
    sim = api.simulate(r, train, RunSettings(opts, time_s=t0), sequence=plan.plan).summary
    assert sim["feasible"]
    assert sim["running_time_s"] == pytest.approx(plan.arrival_s, rel=0.01)
    assert sim["traction_energy_kwh"] == pytest.approx(plan.remaining_energy_kwh, rel=0.02)
    estar = energy_bound(r, train, opts, plan.arrival_s).energy_kwh
    assert plan.remaining_energy_kwh == pytest.approx(estar, rel=0.015)
    assert plan.remaining_optimum_kwh <= plan.remaining_energy_kwh + 1e-9
    lim = np.minimum(limit_kmh_at(r, plan.s_m, train.length_m if opts.strip else None), train.max_speed_kmh)
    assert np.all(plan.v_kmh <= lim + 0.5)
    assert abs(plan.arrival_s - t0) <= tol


def test_at_the_stop_there_is_nothing_to_do():
    r, *_, rp = _setup("routes/freight-20km.yaml", "default")
    q = rp.replan(TrainState(r.length_m, 0.0, 1495.0))
    assert q.next_condition is None and q.plan == "" and q.remaining_energy_kwh == 0.0
    assert q.arrival_s == 1495.0 and q.on_time


def test_a_state_that_cannot_keep_the_time_gets_the_fastest_remainder():
    """10 km left with 100 s to go: late. The remainder is no slower than the full fastest run from rest (an upper
    bound of any remainder's fastest time) and no faster than the distance at the top speed; exit 1, saying how
    late."""
    r, train, opts, t0, tol, rp = _setup("routes/freight-20km.yaml", "default")
    t = t0 - 100.0
    q = rp.replan(TrainState(10_000.0, 50.0, t))
    assert not q.on_time and q.late_s > tol
    fastest = TractionCalculator(r, train, opts).fastest_time_s
    top = float(np.max(limit_kmh_at(r, np.linspace(10_000, r.length_m, 200)))) / 3.6
    assert (r.length_m - 10_000) / top <= q.arrival_s - t <= fastest
    res = runner.invoke(app, ["replan", "routes/freight-20km.yaml", "--at-m", "10000", "--speed-kmh", "50",
                              "--elapsed-s", str(t), "--json"])
    assert res.exit_code == 1
    d = json.loads(res.stdout)
    # (the command tracks the air brake's cycle on this line: the cycle DP's fastest remainder, within the same bounds)
    qc = Replanner(r, train, opts, planned_s=t0, tolerance_s=tol).replan(TrainState(10_000.0, 50.0, t))
    assert (r.length_m - 10_000) / top <= qc.arrival_s - t <= fastest
    assert d["late_s"] == pytest.approx(qc.late_s, abs=0.01) and "late" in d["errors"][0]


@pytest.mark.parametrize("state, why", [(["--at-m", "1000", "--speed-kmh", "80"], "over the speed limit"),
                                        (["--at-m", "19950", "--speed-kmh", "40"], "beyond the braking curve")])
def test_an_impossible_state_is_refused_with_the_reason(state, why):
    res = runner.invoke(app, ["replan", "routes/freight-20km.yaml", *state, "--elapsed-s", "100"])
    assert res.exit_code == 2
    assert why in res.stderr and "Traceback" not in res.output


def test_the_json_fields():
    res = runner.invoke(app, ["replan", "routes/freight-20km.yaml", "--at-m", "5000", "--speed-kmh", "60",
                              "--elapsed-s", "400", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    for key in ("next_condition", "next_switch_m", "target_speed_kmh", "arrival_s", "remaining_energy_kwh",
                "remaining_optimum_kwh", "late_s", "plan", "solve_time_s"):
        assert key in d
    assert d["plan"].startswith(f"{d['next_condition']}:5000.0") and d["late_s"] == 0.0


def test_a_stream_of_1000_states_gives_1000_lines_in_order():
    """States along and around the departure plan (10 % slower and faster, late), one bad line answered by an
    error line (exit 2 at the end), the rest by advice, in order."""
    *_, rp = _setup("routes/freight-20km.yaml", "default")
    plan = rp.replan(TrainState(0.0, 0.0, 0.0))
    rng = np.random.default_rng(7)
    lines = []
    for _ in range(1000):
        i = int(rng.integers(0, len(plan.s_m) - 1))
        f = float(rng.choice([0.9, 1.0, 1.1]))
        lines.append(json.dumps({"s_m": float(plan.s_m[i]), "v_kmh": float(plan.v_kmh[i]) * f,
                                 "t_s": float(plan.t_s[i]) + float(rng.choice([0.0, 20.0]))}))
    lines[500] = '{"s_m": 100, "v_kmh": "fast", "t_s": 3}'
    res = runner.invoke(app, ["replan", "routes/freight-20km.yaml", "--stream"], input="\n".join(lines) + "\n")
    assert res.exit_code == 2
    out = [json.loads(x) for x in res.stdout.splitlines()]
    assert [o["line"] for o in out] == list(range(1, 1001))
    assert out[500]["exit_code"] == 2 and "v_kmh" in out[500]["errors"][0]
    good = [o for o in out if o["exit_code"] == 0]
    assert len(good) > 500 and all("next_condition" in o for o in good)


def test_a_restriction_in_the_stream_is_kept():
    """A restriction of 30 km/h from 12 to 13 km: the advice's plan stays under it from then on."""
    lines = [{"s_m": 5000, "v_kmh": 60, "t_s": 400},
             {"s_m": 5000, "v_kmh": 60, "t_s": 400, "restriction": {"from_m": 12000, "to_m": 13000, "kmh": 30}}]
    res = runner.invoke(app, ["replan", "routes/freight-20km.yaml", "--stream"],
                        input="\n".join(json.dumps(x) for x in lines) + "\n")
    assert res.exit_code in (0, 1), res.output
    before, after = (json.loads(x) for x in res.stdout.splitlines())
    # slower through the restriction, or dearer in the same time (a restriction takes drives away, none added)
    assert after["arrival_s"] > before["arrival_s"] or after["remaining_energy_kwh"] > before["remaining_energy_kwh"]


def _disturbance(**kw) -> Disturbance:
    return Disturbance.model_validate({"schema": "locoplan/disturbance@1", **kw})


CLOSED_LOOP = [("routes/freight-20km.yaml", m) for m in MODELS] + [("routes/real/SE_Vasteras_Kolback.yaml", m)
                                                                   for m in MODELS]


def _with_a_stop_fastest_s(r, train, opts, at_m: float) -> float:
    """The fastest run with a stop at ``at_m``: its two legs' fastest runs (the calculator's)."""
    from locoplan.model.route import route_slice

    return sum(TractionCalculator(route_slice(r, a, b, "leg"), train, opts).fastest_time_s
               for a, b in ((0.0, at_m), (at_m, r.length_m)))


@pytest.mark.slow
@pytest.mark.parametrize("route, model", CLOSED_LOOP)
@pytest.mark.parametrize("what", ["mass", "hold"])
def test_the_closed_loop_arrives_on_time_near_the_optimum_in_hindsight(route, model, what):
    """Mass +5 % (at the line's planned time), or a 60 s hold at mid-line (planned 1.1 x the fastest run that stops
    there, plus the hold, so that the time can be kept): the re-planned run arrives inside the window, no later than
    the open-loop run (late after a hold). With the heavier train it spends at most 2 % more than E* of the real
    train; after an unannounced hold it is not held to that (docs/replan.md: the catch-up after a hold the planner
    could not foresee costs 0.3-25 % over E* in hindsight, which knew of it from the start)."""
    from locoplan.runs.drive import drive

    r, train, opts, t0, tol, rp = _setup(route, model)
    if what == "mass":
        d = _disturbance(mass_factor=1.05)
    else:
        at = round(r.length_m / 2)
        d = _disturbance(holds=[{"at_m": at, "s": 60}])
        t0 = round(1.1 * _with_a_stop_fastest_s(r, train, opts, at) + 60)
        tol = api.punctuality_tolerance(r, t0, None)
        rp = Replanner(r, train, opts, planned_s=t0, tolerance_s=tol, prices=rp.prices, cycle=False)
    res = drive(r, train, opts, d, planned_s=t0, tolerance_s=tol, replanner=rp).summary()
    closed, opened, best = res["closed_loop"], res["open_loop"], res["hindsight"]
    assert closed["inside_window"], res
    assert closed["arrival_s"] <= opened["arrival_s"] + 1e-6 or opened["inside_window"]
    if what == "hold":
        assert not opened["inside_window"]
    else:
        assert closed["traction_energy_kwh"] <= 1.02 * best["traction_energy_kwh"], res


def test_drive_command_and_a_bad_disturbance_file(tmp_path):
    bad = tmp_path / "d.yaml"
    bad.write_text("schema: locoplan/disturbance@1\nmass_factr: 1.05\n")
    res = runner.invoke(app, ["drive", "routes/freight-20km.yaml", "--disturb", str(bad)])
    assert res.exit_code == 2 and "mass_factr" in res.stderr and ":2:" in res.stderr
    good = tmp_path / "g.yaml"
    good.write_text("schema: locoplan/disturbance@1\nholds: [{at_m: 10000, s: 60}]\n")
    res = runner.invoke(app, ["drive", "routes/freight-20km.yaml", "--disturb", str(good), "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    for key in ("open_loop", "closed_loop", "hindsight"):
        assert "arrival_s" in d[key] and "traction_energy_kwh" in d[key]
