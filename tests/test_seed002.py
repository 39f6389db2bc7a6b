"""Seed 002 end to end: classification and builder on hand-made routes, fitness eq. 10-11, the
switching-point problem, strategies, determinism, infeasible handling, and the commands."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.optimize.base import Evaluation
from locoplan.optimize.problem import SwitchingProblem, fitness_eq10
from locoplan.runner import load_optimizer_params
from locoplan.optimize.registry import get_algorithm
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from locoplan.strategy.sequence import build_sequence, classify_grades, classify_limits
from routes import hand_made_route

runner = CliRunner()
SEEDS = ModelOptions.papers()
"""Seed 002's own train model (point mass, HXD1 electric brake alone): the builder's classification and
the strategies' order are checked as the seed states them."""


def _route(limits, grades, length=None):
    return hand_made_route(limits, grades, length, schedule={"run_time_s": 900, "tolerance_s": 30})


def test_limit_types_one_of_each(freight):
    _, train = freight
    route = _route([(2000, 40), (4000, 60), (6000, 50), (8000, 70), (10000, 30)], [(10000, 0.0)])
    kinds = [s.kind for s in classify_limits(TractionCalculator(route, train, SEEDS))]
    # 0 < 40 < 60: rising; 40 < 60 > 50: convex (a hump); 60 > 50 < 70: concave (a dip);
    # 50 < 70 > 30: convex; 70 > 30 > stop: falling
    assert kinds == ["rising", "convex", "concave", "convex", "falling"]


def test_grade_types_one_of_each(freight):
    """At 80 km/h the HXD1 gives 432 kN: 8.47 N/kN of 5200 t, minus 2.16 N/kN of resistance, holds at
    most ~6.3 per mille; coasting at 80 km/h holds a down-grade only down to -2.16 per mille."""
    _, train = freight
    w = 5200 * 9.81 / 1000
    assert 432 / w - (47.8728 + 80 * (0.24290 + 0.0067198 * 80)) / w == pytest.approx(6.31, abs=0.01)
    route = _route([(12000, 80)], [(2000, 0.0), (4000, 12.0), (6000, 1.0), (8000, -6.0), (10000, -1.0), (12000, 5.0)])
    grades = classify_grades(TractionCalculator(route, train, SEEDS))
    assert [g.kind for g in grades] == ["ordinary", "long-up", "ordinary", "long-down", "ordinary", "ordinary"]
    assert grades[1].speed_change_kmh < -2 and grades[3].speed_change_kmh > 2


def test_builder_puts_traction_on_long_ups_and_coasting_on_long_downs(freight):
    _, train = freight
    route = _route([(12000, 80)], [(2000, 0.0), (4000, 12.0), (6000, 1.0), (8000, -6.0), (10000, -1.0), (12000, 0.0)])
    calc = TractionCalculator(route, train, SEEDS)
    seq = build_sequence(calc)
    starts = np.concatenate([[0.0], seq.nominal_m, [12000.0]])
    def condition_at(x):
        j = np.searchsorted(starts, x, side="right") - 1
        return seq.conditions[j]
    assert condition_at(3000) == "T" and condition_at(7000) == "C"
    assert condition_at(500) == "T"  # ordinary grades keep the fastest run's condition: accelerating
    assert seq.conditions[-1] == "B" and seq.conditions[0] == "T"
    # the switch into the long down-grade may move back before it (pre-positioning, Fig. 5a)
    j = list(seq.nominal_m).index(6000.0)
    assert seq.conditions[j + 1] == "C" and seq.lower_m[j] < 6000.0 - 500
    assert np.all(seq.lower_m <= seq.nominal_m) and np.all(seq.nominal_m <= seq.upper_m)


def test_freight_route_classification_matches_its_design(freight):
    route, train = freight
    grades = classify_grades(TractionCalculator(route, train, SEEDS))
    kinds = {g.from_m: g.kind for g in grades}
    assert [x for x, k in kinds.items() if k == "long-up"] == [4500, 11500]
    assert [x for x, k in kinds.items() if k == "long-down"] == [3000, 6500, 9500, 15500]


def test_fitness_eq10_by_hand():
    # w1 |1530-1500|/1500 + w2 |600-500|/500 = 0.5*0.02 + 0.5*0.2
    assert fitness_eq10(1530.0, 600.0, 1500.0, 500.0, 0.5, 0.5) == pytest.approx(0.11)
    assert fitness_eq10(np.array([1470.0]), np.array([450.0]), 1500.0, 500.0, 0.3, 0.7)[0] == pytest.approx(0.3 * 0.02 + 0.7 * 0.1)


def _problem(freight, strict=False):
    route, train = freight
    calc = TractionCalculator(route, train, ModelOptions.papers(step_m=100, strict_limits=strict))
    seq = build_sequence(calc)
    return SwitchingProblem(calc, seq.conditions, seq.lower_m, seq.upper_m, t0_s=1500, e_min_kwh=580)


def test_problem_repair_keeps_order_spacing_and_windows(freight):
    prob = _problem(freight)
    X = prob.repair(np.random.default_rng(3).uniform(0, 20000, (40, prob.n_var)))
    assert np.all(np.diff(X, axis=1) >= prob.min_gap_m - 1e-9)
    assert np.all(X >= prob.lower - 1e-9) and np.all(X <= prob.upper + 1e-9)


def test_repair_lets_an_electric_brake_run_be_shorter(freight):
    """Each run keeps the least spacing, but a run of the electric brake alone (E) only ``E_MIN_RUN_M``: a touch of
    the electric brake before a lower limit."""
    from locoplan.optimize.problem import E_MIN_RUN_M

    route, train = freight
    calc = TractionCalculator(route, train, ModelOptions(step_m=100))
    conds = ("T", "C", "E", "C", "K", "B")
    prob = SwitchingProblem(calc, conds, np.full(4, 0.0), np.full(4, 20000.0), t0_s=1500, e_min_kwh=580, min_gap_m=100.0)
    X = prob.repair(np.array([[5000.0, 5010.0, 5020.0, 5030.0]]))
    runs = np.diff(X[0])  # the runs of C, E and C between the switching points
    assert runs[1] == pytest.approx(E_MIN_RUN_M) and runs[0] >= 100.0 - 1e-9 and runs[2] >= 100.0 - 1e-9
    assert E_MIN_RUN_M < 100.0


def test_infeasible_plans_get_infinite_fitness_and_are_replaced(freight):
    """With --strict-limits most random plans break a limit; the optimiser replaces them (seed 002
    section 3.2 step 5) and returns a feasible best."""
    prob = _problem(freight, strict=True)
    ev = prob.evaluate(prob.sample(200, np.random.default_rng(0)))
    assert isinstance(ev, Evaluation) and 0 < ev.feasible.mean() < 0.5
    assert np.all(np.isinf(ev.fitness[~ev.feasible])) and np.all(np.isfinite(ev.fitness[ev.feasible]))
    opt = get_algorithm("issa")()
    params = load_optimizer_params("issa").model_dump() | {"pop_size": 12, "max_iter": 10}
    opt.setup(prob, np.random.default_rng(5), **params)
    res = opt.run()
    assert res.n_infeasible_replaced > 0 and np.isfinite(res.best_fitness)
    assert prob.simulate(res.best_x).feasible[0]


@pytest.fixture(scope="module")
def small_ctx(freight, root):
    route, train = freight
    base = RunSettings(SEEDS, builder="issa-paper", yardstick=False, e_min_kwh=580.0,
                       params_path=str(root / "tests/data/optimizers/issa.yaml"))
    return lambda **kw: make_context(route, train, base.replace(**kw))


def test_same_seed_same_result_different_seed_differs(small_ctx):
    a = run_strategy(small_ctx(seed=4), "proposed").summary
    b = run_strategy(small_ctx(seed=4), "proposed").summary
    c = run_strategy(small_ctx(seed=5), "proposed").summary
    assert a["switching_points_m"] == b["switching_points_m"] and a["traction_energy_kwh"] == b["traction_energy_kwh"]
    assert a["switching_points_m"] != c["switching_points_m"]


def test_strategies_physics_order(small_ctx):
    """Time-saving is fastest and costliest; four-stage is on time; even a small-budget proposed run
    beats four-stage and time-saving on energy while staying inside the +-30 s window."""
    ctx = small_ctx(seed=1)
    ts = run_strategy(ctx, "time-saving").summary
    fs = run_strategy(ctx, "four-stage").summary
    pr = run_strategy(ctx, "proposed").summary
    assert ts["running_time_s"] == pytest.approx(ctx.calc.fastest_time_s, abs=0.01)
    assert ts["running_time_s"] < fs["running_time_s"] and ts["traction_energy_kwh"] > fs["traction_energy_kwh"]
    assert fs["punctuality_error_s"] <= 1.5 and fs["cruise_kmh"] > 0
    assert pr["feasible"] and pr["punctuality_error_s"] <= 30
    assert pr["traction_energy_kwh"] < fs["traction_energy_kwh"] < ts["traction_energy_kwh"]
    # reported numbers are re-simulated on the 50 m reporting grid
    res = ctx.calc.evaluate(tuple(pr["plan"].replace(":", ",").split(",")[::2][:-1]) + ("B",),
                            np.array([pr["switching_points_m"] + [np.nan]]))
    assert res.traction_energy_kwh[0] == pytest.approx(pr["traction_energy_kwh"], abs=0.01)


def test_time_below_fastest_is_exit_1_with_the_fastest_time(root, monkeypatch, freight):
    monkeypatch.chdir(root)
    fastest = TractionCalculator(*freight).fastest_time_s  # the default model, as the command uses
    res = runner.invoke(app, ["optimize", "routes/freight-20km.yaml", "--time", f"{fastest - 1:.1f}", "--e-min", "580", "--no-gap"])
    assert res.exit_code == 1
    assert f"below the fastest possible run, {fastest:.1f} s" in res.stderr


SMALL = ["--params", "tests/data/optimizers/issa.yaml", "--point-mass", "--builder", "issa-paper", "--no-gap"]


def test_optimize_json(root, monkeypatch):
    monkeypatch.chdir(root)
    res = runner.invoke(app, ["optimize", "routes/freight-20km.yaml", "--json", "--seed", "2", *SMALL])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["strategy"] == "proposed" and d["algorithm"] == "issa" and d["seed"] == 2
    assert d["e_min_kwh"] > 0 and d["fitness"] == pytest.approx(
        fitness_eq10(d["running_time_s"], d["traction_energy_kwh"], 1500, d["e_min_kwh"], 0.5, 0.5), abs=2e-5)
    assert len(d["switching_points_m"]) == d["plan"].count(":") - 1


def test_builder_alias_gives_the_same_plan(root, monkeypatch):
    """``--builder seed002`` is the ISSA paper's builder under its earlier name: the same plan, the same numbers."""
    monkeypatch.chdir(root)
    out = {}
    for name in ("issa-paper", "seed002"):
        res = runner.invoke(app, ["optimize", "routes/freight-20km.yaml", "--json", "--seed", "2", "--e-min", "580",
                                  "--params", "tests/data/optimizers/issa.yaml", "--point-mass", "--builder", name, "--no-gap"])
        assert res.exit_code == 0, res.output
        d = json.loads(res.stdout)
        out[name] = (d["plan"], d["switching_points_m"], d["running_time_s"], d["traction_energy_kwh"], d["fitness"])
    assert out["seed002"] == out["issa-paper"]
    res = runner.invoke(app, ["optimize", "routes/freight-20km.yaml", "--builder", "seed003"])
    assert res.exit_code == 2 and "unknown sequence builder 'seed003' (one of: general, issa-paper)" in res.stderr


@pytest.mark.slow
def test_compare_explain_and_json(root, monkeypatch, tmp_path):
    monkeypatch.chdir(root)
    res = runner.invoke(app, ["compare", "routes/freight-20km.yaml", "--explain", "--e-min", "580", *SMALL,
                              "--plot", str(tmp_path / "c.png")], env={"COLUMNS": "160"})
    assert res.exit_code == 0, res.output
    for word in ("concave", "convex", "rising", "falling", "long-up", "long-down", "ordinary", "four-stage"):
        assert word in res.stdout
    assert (tmp_path / "c.png").stat().st_size > 10000
    res = runner.invoke(app, ["compare", "routes/freight-20km.yaml", "--json", "--strategies", "time-saving,four-stage",
                              "--e-min", "580", "--point-mass", "--builder", "issa-paper", "--no-gap"])
    d = json.loads(res.stdout)
    assert [r["strategy"] for r in d["results"]] == ["time-saving", "four-stage"]


def test_sweep_and_study(root, monkeypatch):
    monkeypatch.chdir(root)
    res = runner.invoke(app, ["sweep", "routes/freight-20km.yaml", "--times", "1470,1530", "--json", "--e-min", "580", *SMALL])
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)["results"]
    assert [r["planned_time_s"] for r in rows] == [1470, 1530] and rows[0]["energy_reduction_percent"] == 0
    res = runner.invoke(app, ["study", "routes/freight-20km.yaml", "--algorithms", "issa,pso", "--runs", "2", "--json",
                              "--e-min", "580", "--params-dir", "tests/data/optimizers", "--point-mass", "--builder", "issa-paper", "--no-gap"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert [r["algorithm"] for r in d["table"]] == ["issa", "pso"] and len(d["results"]) == 4
    assert {r["seed"] for r in d["results"]} == {1, 2}


@pytest.mark.parametrize("args,why", [
    (["optimize", "routes/freight-20km.yaml", "--weights", "0.7,0.7"], "--weights: expected two non-negative weights summing to 1"),
    (["optimize", "routes/freight-20km.yaml", "--algorithm", "ga"], "unknown"),
    (["optimize", "routes/freight-20km.yaml", "--e-min", "-5"], "--e-min: must be in [1e-06, 10,000,000] kWh (got -5)"),
    (["optimize", "routes/freight-20km.yaml", "--out", "x.txt"], "unknown output type '.txt'"),
    (["compare", "routes/freight-20km.yaml", "--strategies", "fast"], "unknown strategy 'fast'"),
    (["sweep", "routes/freight-20km.yaml"], "give exactly one of --weight-grid or --times"),
    (["sweep", "routes/freight-20km.yaml", "--weight-grid", "0.9:0.1:0.1"], "needs start <= stop"),
    (["study", "routes/freight-20km.yaml", "--runs", "0", "--e-min", "580"], "--runs: must be 1 .. 1,000 (got 0)"),
    (["optimize", "routes/seed000-flat.yaml", "--consist", "HXD1-C64-seed000"], "--time: route"),
])
def test_seed002_bad_input_exit_2(root, monkeypatch, args, why):
    monkeypatch.chdir(root)
    res = runner.invoke(app, args)
    assert res.exit_code == 2, res.output
    assert why in res.stderr
