"""Seed 001: the multi-phase minimum-energy optimal control (MPOC), its plans, strategies and yardstick.

Checked against an independent trapezoidal collocation on a fine grid (tests/energy_oracle.py), the
traction calculator (every plan is re-simulated), quadrature facts of the LGR rule, and the physics
functions evaluated on numpy arrays and on CasADi symbols.
"""

import json
import math

import casadi as ca
import numpy as np
import pytest
from typer.testing import CliRunner

from energy_oracle import trapezoid_min_energy
from locoplan.cli import app
from locoplan.io.load import load_route, load_train
from locoplan.ocp import nodes
from locoplan.ocp.bound import energy_bound
from locoplan.ocp.energy import MAX_MESH_ITERATIONS
from locoplan.ocp.mesh import Interval
from locoplan.ocp.mpoc import run_mpoc
from locoplan.ocp.train_energy import EnergyOptions, energy_options
from locoplan.physics.backend import hinge_coefficients
from locoplan.physics.energy import EnergyModel, energy_rate_kn
from locoplan.physics.resistance import train_resistance_kn
from locoplan.physics.traction import gradient_force_kn, max_force_kn
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from routes import hand_made_route

runner = CliRunner()
SMALL = "tests/data/routes/mpoc-small.yaml"
T_SMALL = 364.0  # 1.18 x the fastest run of HXD1 + 30 C80 on it (307.6 s; 303.0 s with a continuous air brake)


@pytest.fixture(scope="module")
def small(root):
    return load_route(root / SMALL), load_train(root / "configs/consists/HXD1-C80x30.yaml")


@pytest.fixture(scope="module")
def small_run(small):
    route, train = small
    return run_mpoc(route, train, ModelOptions(), T_SMALL)


# ---- one formula for numpy and CasADi -------------------------------------------------------------


def _on_symbols(fn):
    """``fn`` traced on a CasADi symbol and evaluated numerically."""
    x = ca.SX.sym("x")
    return ca.Function("f", [x], [fn(x)])


def test_physics_is_the_same_on_numpy_and_casadi(freight):
    _, train = freight
    speeds = np.concatenate([np.linspace(-5.0, 130.0, 541), train.traction_speed_kmh, train.brake_speed_kmh])
    for curve in ((train.traction_speed_kmh, train.traction_kn), train.brake_curve(True), train.brake_curve(False)):
        f = _on_symbols(lambda v: max_force_kn(v, *curve))
        sym = np.array([float(f(v)) for v in speeds])
        np.testing.assert_allclose(sym, np.interp(speeds, *curve), rtol=1e-12, atol=1e-9)
    f = _on_symbols(lambda v: train_resistance_kn(v, train.resistance_kn))
    np.testing.assert_allclose([float(f(v)) for v in speeds], train_resistance_kn(speeds, train.resistance_kn), rtol=1e-14)
    f = _on_symbols(lambda g: gradient_force_kn(g, train.mass_t))
    assert float(f(7.5)) == pytest.approx(float(gradient_force_kn(7.5, train.mass_t)), rel=1e-15)
    model = EnergyModel(((0.0, 0.7), (40.0, 0.85), (100.0, 0.9)), 0.6)
    x = ca.SX.sym("x", 3)
    g = ca.Function("g", [x], [energy_rate_kn(x[0], x[1], x[2], model)])
    for force, brake, v in ((500.0, 0.0, 20.0), (0.0, 300.0, 55.0), (120.0, 40.0, 130.0)):
        assert float(g([force, brake, v])) == pytest.approx(float(energy_rate_kn(force, brake, v, model)), rel=1e-14)
    # the hinge sum: the first change of slope is the first slope, and the sum is flat beyond the end
    y0, knots, dslope = hinge_coefficients([0.0, 10.0, 20.0], [5.0, 7.0, 4.0])
    assert y0 == 5.0 and list(knots) == [0.0, 10.0, 20.0] and dslope == pytest.approx([0.2, -0.5, 0.3])


# ---- LGR facts and interval mappings -------------------------------------------------------------


@pytest.mark.parametrize("n", [3, 5, 8])
def test_lgr_rule_and_radau_differentiation(n):
    x, w = nodes.legendre_gauss_radau(n)
    assert x[0] == -1.0 and w.sum() == pytest.approx(2.0, abs=1e-14)
    for k in range(2 * n - 1):  # exact up to degree 2n - 2
        assert w @ x ** k == pytest.approx((1 - (-1) ** (k + 1)) / (k + 1), abs=1e-13)
    k = 2 * n - 1  # not for degree 2n - 1
    assert abs(w @ x ** k - (1 - (-1) ** (k + 1)) / (k + 1)) > 1e-6
    support = nodes.radau_support_points(n)
    D = nodes.radau_differentiation_matrix(n)
    p = np.polynomial.Polynomial(np.arange(1.0, n + 2.0))  # degree n
    np.testing.assert_allclose(D @ p(support), p.deriv()(x), atol=1e-10)
    # the integration matrix of the error estimate: inv(D[:, 1:]) integrates from -1
    integ = np.linalg.solve(D[:, 1:], p.deriv()(x))
    np.testing.assert_allclose(integ, p(support[1:]) - p(-1.0), atol=1e-10)


@pytest.mark.parametrize("mapping", ["linear", "start", "end"])
def test_interval_mappings(mapping):
    iv = Interval(0, 100.0, 400.0, 5, mapping)
    tau = np.linspace(-1, 1, 41)
    s = iv.s_of(tau)
    assert s[0] == pytest.approx(100.0) and s[-1] == pytest.approx(400.0) and np.all(np.diff(s) > 0)
    np.testing.assert_allclose(iv.tau_of(s), tau, atol=1e-12)
    fd = (iv.s_of(tau + 1e-6) - iv.s_of(tau - 1e-6)) / 2e-6
    np.testing.assert_allclose(iv.ds_dtau(tau), fd, rtol=1e-6, atol=1e-6)
    if mapping == "start":  # the point of it: sqrt(s - s_a) is linear in tau, as the speed leaving rest
        r = np.sqrt(s - 100.0)
        np.testing.assert_allclose(np.diff(r, 2), 0.0, atol=1e-9)


# ---- the optimum against an independent check --------------------------------------------------------


@pytest.mark.slow
def test_optimum_agrees_with_a_fine_trapezoidal_collocation(small, small_run):
    route, train = small
    s = small_run.summary
    oracle = trapezoid_min_energy(route, train, T_SMALL, step_m=5.0)
    assert oracle["success"] and s["mesh"]["converged"]
    assert s["objective"] == pytest.approx(oracle["energy_kwh"], rel=1e-3)
    # checked, not claimed: the plan runs on time, within the limits, and within 0.5 % of the objective
    assert s["feasible"] and s["running_time_s"] == pytest.approx(T_SMALL, abs=1.0)
    assert s["traction_energy_kwh"] == pytest.approx(s["objective"], rel=5e-3)
    assert s["max_limit_violation_kmh"] < 0.1 and s["mesh_history"][-1]["max_error"] <= 1e-5


@pytest.mark.slow
def test_neutral_section_is_coasted_and_ignoring_it_is_a_lower_bound(small, small_run):
    route, train = small
    sol = small_run.solution.solution
    (a, b), = small_run.tep.spans_m
    # from coast_before_s before the head enters until coast_after_s after the 395 m train has left
    assert a == pytest.approx(1500 - 5 * 70 / 3.6) and b == pytest.approx(1600 + train.length_m + 5 * 70 / 3.6)
    inside = (sol.grid.s_col > a) & (sol.grid.s_col < b)
    # no traction there (bounded to 0); the air brake is allowed (the electric brake is cut with the
    # power), and this optimum coasts: its braking is zero to the solver's tolerance
    assert inside.sum() >= 3 and np.all(sol.U[0, inside] == 0.0)
    assert np.all(np.abs(sol.U[1:, inside]) < 1e-3 * np.max(np.abs(sol.U[1:])))
    before, after = small_run.summary["neutral_margins_s"][0]
    assert before >= 5.0 and after >= 5.0  # re-simulated: at least the asked margins
    free = run_mpoc(route, train, ModelOptions(), T_SMALL, energy=EnergyOptions(ignore_neutral=True))
    # (here the optimum coasts through the span anyway: equal within the discretisation, 1e-4)
    assert free.summary["objective"] <= small_run.summary["objective"] * (1 + 1e-4)


@pytest.mark.slow
def test_energy_options_scale_and_credit(small, small_run):
    route, train = small
    half = run_mpoc(route, train, ModelOptions(), T_SMALL, energy=energy_options("0.8"))
    assert half.summary["objective"] == pytest.approx(small_run.summary["objective"] / 0.8, rel=2e-4)
    regen = run_mpoc(route, train, ModelOptions(), T_SMALL, energy=energy_options(None, regen=0.5))
    assert regen.summary["objective"] < small_run.summary["objective"] - 1.0  # braking before the stop pays back
    assert regen.tep.model.controls == ("F", "B_e", "B_a")  # only the electric brake earns the credit


@pytest.mark.slow
def test_orderings_of_seed001_strategies(freight):
    """Seed 001 Tables 3-4 on a freight line with two neutral sections: ignoring them is a lower
    bound (MPOC-N's optimum), honouring them in the model beats coasting through them afterwards
    (MPOC-C) and the four-stage method (SFS); every plan is the calculator's re-simulation."""
    _, train = freight
    route = load_route("routes/freight-20km-ns.yaml")
    ctx = make_context(route, train, RunSettings(ModelOptions(), yardstick=False))
    e = {n: run_strategy(ctx, n).summary for n in ("mpoc", "mpoc-c", "sfs")}
    assert all(s["feasible"] and s["punctual"] for s in e.values())
    assert e["mpoc"]["traction_energy_kwh"] < e["mpoc-c"]["traction_energy_kwh"] < e["sfs"]["traction_energy_kwh"]
    n_opt = run_mpoc(route, train, ModelOptions(), 1500.0, energy=EnergyOptions(ignore_neutral=True)).summary["objective"]
    assert n_opt < energy_bound(route, train, ModelOptions(), 1500.0).energy_kwh


# ---- the refinement meets its tolerance ---------------------------------------------------------------


@pytest.mark.parametrize("options", [ModelOptions(point_mass=True, air_brake=False), ModelOptions()],
                         ids=["point-mass", "default"])
@pytest.mark.slow
def test_refinement_meets_its_tolerance_on_freight_20km(freight, options, monkeypatch, tmp_path):
    """The hp refinement reaches 1e-5 on freight-20km at 1500 s (the command's models: --point-mass brakes
    with the locomotive alone) in fewer solves than its cap, and its optimum is E* (the cell method,
    ocp/cells.py, an independent transcription) within 0.02 %."""
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path))
    route, train = freight
    run = run_mpoc(route, train, options, 1500.0)
    es, mesh = run.solution, run.summary["mesh"]
    assert es.converged and mesh["converged"] and mesh["max_error"] <= 1e-5
    assert len(es.history) < MAX_MESH_ITERATIONS and es.history[-1].max_error <= 1e-5
    b = energy_bound(route, train, options, 1500.0)
    assert b.converged and b.accuracy < 2e-5
    assert es.objective_kwh == pytest.approx(b.energy_kwh, rel=2e-4)
    assert run.feasible and run.summary["running_time_s"] == pytest.approx(1500.0, abs=1.0)


def test_a_train_on_its_limit_shows_no_arc_to_hold():
    """A point where the train is on its speed limit holds the limit (the control is the state
    constraint's), so it is no evidence of a control arc next to a moving point: the interval keeps its
    controls free; without the state constraint the same point makes the arc 'lower' (a coast)."""
    from locoplan.ocp.mesh import Mesh, RefineSettings, refine

    # two intervals of 3 points; the switch (a jump of the first control) lies between points 1 and 2
    ivs = (Interval(0, 0.0, 300.0, 3), Interval(0, 300.0, 600.0, 3))
    s_col = np.array([0.0, 100.0, 250.0, 300.0, 400.0, 550.0])
    u = np.array([[1.0, 1.0, 0.0, 0.3, 0.3, 0.3], [0.0] * 6])
    lower = np.array([[False, False, True, False, False, False], [True] * 6])
    upper = np.array([[True, True, False, False, False, False], [False] * 6])
    errors = np.array([1e-3, 1e-9])
    new, _ = refine(Mesh(ivs), errors, s_col, u, np.array([0, 3, 6]), RefineSettings(), lower, upper)
    held = {iv.s_a: iv.regime for iv in new.intervals}
    right = next(iv for iv in new.intervals if iv.free_start is not None)
    assert held[right.s_a] == ("lower", "lower")  # the coasting point 250 m: a coast arc after the switch
    on_limit = np.array([False, False, True, False, False, False])
    new, _ = refine(Mesh(ivs), errors, s_col, u, np.array([0, 3, 6]), RefineSettings(), lower, upper, on_limit)
    right = next(iv for iv in new.intervals if iv.free_start is not None)
    assert right.regime in (None, (None, "lower"))  # on the limit: the traction there is free


@pytest.mark.slow
def test_mpoc_on_a_descent_where_the_air_brake_cycles(monkeypatch, tmp_path):
    """HXD1 + 50 x C80 on 10 km at 60 km/h with 7 km at -15 per mille (tests/test_air_cycle.py's line): the
    electric brake cannot hold 60 km/h there, so the calculator's air brake cycles (applied at 59.0 km/h,
    released at about 45.5 km/h, 60 s to recharge), where the optimum's continuous air brake holds the
    limit. The cycle's mean speed, (59.0 + 45.5) / 2 km/h over the 6.7 km where it cycles, costs about
    6700 / (52.25 / 3.6) - 6700 / (60 / 3.6) = 59.6 s: the optimum is solved for that much less, and its
    plan, which cycles, runs in T. Both stay above E*(T), the relaxation's optimum."""
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path))
    route = hand_made_route([(10000, 60.0)], [(2000, 0.0), (9000, -15.0), (10000, 0.0)], 10000)
    train = load_train("HXD1-C80x50")
    calc = TractionCalculator(route, train, ModelOptions())
    (a, b), = calc.cycle_regions_m
    loss = (b - a) / ((59.0 + 45.5) / 2 / 3.6) - (b - a) / (60.0 / 3.6)
    assert loss == pytest.approx(59.6, abs=0.5)
    T = round(1.25 * calc.fastest_time_s)
    run = run_mpoc(route, train, ModelOptions(), T, calc=calc)
    s = run.summary
    assert s["feasible"], s["reason"]
    assert s["running_time_s"] == pytest.approx(T, abs=1.0) and run.check.result.air_applications[0] >= 2
    assert 0.7 * loss <= T - s["optimum_time_s"] <= 1.5 * loss  # the time the cycle costs, given back
    assert "cycles" in s["cycle_note"] and f"solved for {s['optimum_time_s']:.1f} s" in s["cycle_note"]
    e_star = energy_bound(route, train, ModelOptions(), T).energy_kwh
    assert s["traction_energy_kwh"] >= e_star and s["objective"] >= e_star * (1 - 2e-4)
    # at 1.2 x the plan's running time jumps by about 10 s where the time solved for moves an application
    # (861.1 s solved: 930.5 s; 862.0 s: 941.0 s, for 938 s asked): where no plan is timed, the reason says so
    other = run_mpoc(route, train, ModelOptions(), round(1.2 * calc.fastest_time_s), calc=calc)
    assert other.feasible or ("air brake cycles" in other.summary["reason"]
                              and "no optimum's plan with the cycle runs in" in other.summary["reason"])
    # near the fastest run no optimum's plan keeps the cycle in the time: the reason names the cycle and what
    # its plans did (a recharge cut short, or a running time the cycle's applications make jump past T)
    near = run_mpoc(route, train, ModelOptions(), round(1.05 * calc.fastest_time_s), calc=calc)
    why = near.summary["reason"] or ""
    assert not near.feasible and "air brake cycles" in why
    assert ("before its recharge of 60 s was over" in why or "no optimum's plan with the cycle runs in" in why)


# ---- commands ------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_ocp_energy_command(root, monkeypatch, tmp_path, small_run):
    monkeypatch.chdir(root)
    out = tmp_path / "p.csv"
    res = runner.invoke(app, ["ocp", SMALL, "--objective", "energy", "--time", str(T_SMALL), "--consist", "HXD1-C80x30",
                              "--json", "--out", str(out), "--plot", str(tmp_path / "p.png")])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["strategy"] == "mpoc" and d["algorithm"] == "radau" and d["feasible"]
    assert d["objective"] == pytest.approx(small_run.summary["objective"], rel=1e-9)
    assert d["mesh_history"] and d["mesh"]["max_error"] <= 1e-5 and d["sequence"][0]["condition"] == "T"
    rows = out.read_text().splitlines()
    assert rows[0].startswith("s_m,t_s,v_kmh") and len(rows) > 50
    assert (tmp_path / "p.png").stat().st_size > 20000
    res = runner.invoke(app, ["ocp", SMALL, "--objective", "energy", "--time", str(T_SMALL), "--consist", "HXD1-C80x30"])
    assert res.exit_code == 0 and "mesh refinement" in res.stdout and "confirmed" in res.stdout


@pytest.mark.slow
def test_bound_command_and_gap_column(root, monkeypatch, small_run):
    monkeypatch.chdir(root)
    res = runner.invoke(app, ["bound", SMALL, "--times", "340,380", "--consist", "HXD1-C80x30", "--json"])
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)["results"]
    assert [r["time_s"] for r in rows] == [340, 380] and rows[0]["energy_kwh"] > rows[1]["energy_kwh"]
    res = runner.invoke(app, ["bound", SMALL, "--time", str(T_SMALL), "--consist", "HXD1-C80x30"])
    assert res.exit_code == 0 and res.stdout.startswith("E* = ")
    e_star = float(res.stdout.split()[2])  # the same optimum, warm-started from the 380 s one: equal within the mesh
    assert e_star == pytest.approx(small_run.summary["objective"], rel=2e-4)
    res = runner.invoke(app, ["compare", SMALL, "--time", str(T_SMALL), "--consist", "HXD1-C80x30", "--e-min", "100",
                              "--strategies", "sfs,mpoc", "--json"])
    assert res.exit_code == 0, res.output
    sfs, mpoc = json.loads(res.stdout)["results"]
    # the optimum's own plan is within the calculator's discretisation of E*; no plan is materially below it
    # (on this short line SFS's traction / coasting is close to optimal too)
    assert abs(mpoc["gap_to_optimum_percent"]) < 0.5 and sfs["gap_to_optimum_percent"] > -0.2


@pytest.mark.parametrize("route, args, code, words", [
    # a neutral section longer than the route is a file error
    ("neutral_long", [], 2, ["neutral_sections[0].to_m", "beyond the route's length_m"]),
    ("neutral_start", [], 1, ["cannot run", "traction is cut there by a neutral section"]),
    ("steep", [], 1, ["cannot run", "steepest equivalent grade there", "per mille", "traction curve gives at most 760 kN"]),
    # (ocp plans runs of the calculator, whose fastest run cycles the air brake: 307.6 s; bound's E* is the
    # relaxation with the air brake as a continuous force, whose fastest run is 303.0 s)
    (SMALL, ["--time", "250", "--consist", "HXD1-C80x30"], 1,
     {"ocp": ["below the fastest possible run, 307.6 s"], "bound": ["below the fastest possible run, 303.0 s"]}),
])
def test_bad_input_is_a_clear_message(root, monkeypatch, tmp_path, route, args, code, words):
    monkeypatch.chdir(root)
    base = (root / SMALL).read_text()
    files = {
        "neutral_long": base.replace("{from_m: 1500, to_m: 1600,", "{from_m: 0, to_m: 5000,"),
        "neutral_start": base.replace("{from_m: 1500, to_m: 1600,", "{from_m: 10, to_m: 60,"),
        "steep": base.replace("permille: 6.0}", "permille: 30.0}"),
    }
    if route in files:
        path = tmp_path / f"{route}.yaml"
        path.write_text(files[route])
        route = str(path)
        args = ["--time", "400"]
    for cmd in (["ocp", route, "--objective", "energy"], ["bound", route]):
        res = runner.invoke(app, [*cmd, *args])
        assert res.exit_code == code, res.output
        assert "Traceback" not in res.output and res.stdout == ""
        for w in (words[cmd[0]] if isinstance(words, dict) else words):
            assert w in res.stderr, (w, res.stderr)


def test_energy_options_are_validated():
    with pytest.raises(Exception) as err:
        energy_options("0:0.8,0:0.9", regen=1.5, comfort_ms2=-1)
    text = str(err.value)
    assert "--efficiency" in text and "--regen" in text and "--comfort" in text
    opts = energy_options("0:0.8,60:0.9", 0.3, 0.5)
    assert opts.energy.efficiency == ((0.0, 0.8), (60.0, 0.9)) and opts.comfort_ms2 == 0.5 and not math.isnan(opts.energy.regen_credit)


def test_the_force_axis_is_not_squashed_by_the_braking_bound(small_run, tmp_path):
    """The energy plot's force axis spans the traction bound and the braking used, down to at most the
    traction bound below zero; the consist's braking bound (about 1,700 kN with the air brakes against
    760 kN of traction) and a full-braking stop are cut there and named."""
    from locoplan.reporting.plot_ocp import force_axis_kn, plot_energy_run

    lo, hi, note = force_axis_kn(np.array([0.0, 500.0]), np.array([0.0, 120.0]), np.array([760.0, 600.0]),
                                 np.array([1700.0, 1600.0]))
    assert hi == pytest.approx(760 * 1.12) and lo == pytest.approx(-0.25 * 760 * 1.12)  # 120 kN used < 190
    assert note == "-B max(v) reaches -1,700 kN, below the axis"
    lo, _, note = force_axis_kn(np.array([700.0]), np.array([600.0]), np.array([760.0]), np.array([650.0]))
    assert lo == pytest.approx(-600 * 1.12) and note == ""  # the braking used sets it, the bound fits
    lo, _, note = force_axis_kn(np.array([700.0]), np.array([1900.0]), np.array([760.0]), np.array([1950.0]))
    assert lo == pytest.approx(-760 * 1.12) and note == "braking reaches -1,900 kN, below the axis"
    plot_energy_run(tmp_path / "e.png", small_run)
    assert (tmp_path / "e.png").stat().st_size > 20000
