"""Net energy (traction less what the electric brake recovers) and the ``net`` objective.

The hand-worked case: the shipped HXD1 + 50 x C80 (5200 t, HXD1 regen_efficiency 0.85) holding 60 km/h
over 10 km of -5 per mille, against the same run on the level. Its Davis coefficients: HXD1 200 t
(w = 1.962 kN per N/kN): 2.7468 + 0.0074556 v + 0.0005886 v^2; 50 C80 of 100 t (w = 49.05): 45.126 +
0.23544 v + 0.00613125 v^2; at 60 km/h R = 47.8728 + 14.573736 + 24.19146 = 86.637996 kN. On -5 per mille
gravity pulls with 5200 x 9.81 x 0.005 = 255.06 kN, so holding 60 km/h takes B = 168.422004 kN of braking,
all electric (461 kN available): over 10,000 m the electric brake recovers 0.85 x 168.422004 x 10,000 / 3600
= 397.6630 kWh, and the traction that holds the speed on the level (R x 10,000 / 3600 = 240.6611 kWh) is
not needed.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.io.load import load_train
from locoplan.ocp.bound import check_bound, energy_bound
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from routes import hand_made_route

R_60 = 86.637996
B_HOLD = 5200 * 9.81 * 0.005 - R_60
L = 10_000.0


def _runs():
    train = load_train("HXD1-C80x50")
    assert train.regen_efficiency == 0.85
    opts = ModelOptions(point_mass=True)  # the gradient changes under the head, at one node
    out = {}
    for name, grade in (("descent", -5.0), ("level", 0.0)):
        route = hand_made_route([(16000.0, 60.0)], [(3000.0, 0.0), (13000.0, grade), (16000.0, 0.0)])
        res = TractionCalculator(route, train, opts).evaluate(("T",), np.zeros((1, 0)), profile=True)
        assert res.feasible[0]
        out[name] = res
    return out


def test_a_descent_held_by_the_electric_brake_recovers_eta_times_its_work():
    runs = _runs()
    d, lv = runs["descent"], runs["level"]
    assert B_HOLD == pytest.approx(168.422004, abs=1e-6)
    recovered = float(d.recovered_energy_kwh[0] - lv.recovered_energy_kwh[0])
    assert recovered == pytest.approx(0.85 * B_HOLD * L / 3600, rel=1e-6)  # 397.6630 kWh
    saved = float(lv.traction_energy_kwh[0] - d.traction_energy_kwh[0])
    assert saved == pytest.approx(R_60 * L / 3600, rel=1e-6)  # 240.6611 kWh
    net = float(d.net_energy_kwh[0] - lv.net_energy_kwh[0])
    assert net == pytest.approx(-(397.6630 + 240.6611), abs=2e-3)
    # on the descent the train brakes, and only electrically: no traction there
    prof = d.profile
    mid = 0.5 * (prof.s_m[1:] + prof.s_m[:-1])
    on = (mid > 3000) & (mid < 13000)
    assert np.all(prof.traction_kn[0, on] == 0.0)
    assert prof.brake_kn[0, on] == pytest.approx(B_HOLD, rel=1e-9)


@pytest.mark.slow
def test_net_estar_is_a_lower_bound_and_agrees_with_the_radau_check():
    """E* of the net objective on a short line: below every plan's net energy at its time, below the
    traction E* less nothing (crediting can only lower the optimum: the traction optimum's own net energy
    is a candidate), and the second, independent method (Radau collocation with the same credit) agrees."""
    train = load_train("HXD1-C80x50")
    route = hand_made_route([(6000.0, 70.0)], [(2000.0, 0.0), (4500.0, -6.0), (6000.0, 0.0)])
    opts = ModelOptions()
    calc = TractionCalculator(route, train, opts)
    fastest = calc.evaluate(("T",), np.zeros((1, 0)), recovered=True)
    t = 1.15 * float(fastest.running_time_s[0])
    net = energy_bound(route, train, opts, t, objective="net")
    trac = energy_bound(route, train, opts, t)
    assert net.objective == "net" and trac.objective == "traction"
    assert net.energy_kwh == pytest.approx(net.traction_kwh - net.recovered_kwh, abs=1e-6)
    assert trac.energy_kwh == pytest.approx(trac.traction_kwh, abs=1e-6)
    assert net.energy_kwh <= trac.traction_kwh - trac.recovered_kwh + 1e-3
    assert net.recovered_kwh > trac.recovered_kwh  # the net optimum brakes more with the electric brake
    # plans at their own times never beat it
    plans = calc.evaluate(("T", "C", "B"), np.column_stack([np.linspace(1000, 5000, 9), np.full(9, np.nan)]),
                          recovered=True)
    for i in np.flatnonzero(plans.feasible):
        e = energy_bound(route, train, opts, float(plans.running_time_s[i]), objective="net").energy_kwh
        assert float(plans.net_energy_kwh[i]) >= e - 1e-3
    check = check_bound(route, train, opts, t, mesh_tol=1e-5, max_degree=10, objective="net")
    assert check.energy_kwh == pytest.approx(net.energy_kwh, rel=2e-4)


def test_a_train_that_regenerates_nothing_has_one_estar():
    train = dataclasses.replace(load_train("HXD1-C80x50"), regen_efficiency=0.0)
    route = hand_made_route([(5000.0, 70.0)], [(5000.0, 0.0)])
    t = 1.2 * TractionCalculator(route, train).fastest_time_s
    assert energy_bound(route, train, None, t, objective="net").energy_kwh == energy_bound(route, train, None, t).energy_kwh


@pytest.mark.slow
def test_optimize_with_the_net_objective():
    """--objective net: the summary says so, its fitness counts the net energy, the gap is against the net
    E*, and the net plan's net energy is no worse than the traction plan's (each is searched for its own)."""
    args = ["optimize", "routes/freight-20km.yaml", "--json"]
    out = {}
    for objective in ("traction", "net"):
        res = CliRunner().invoke(app, [*args, "--objective", objective])
        assert res.exit_code == 0, res.output
        out[objective] = json.loads(res.output)
    n, tr = out["net"], out["traction"]
    assert n["objective"] == "net" and tr["objective"] == "traction"
    assert n["net_energy_kwh"] == pytest.approx(n["traction_energy_kwh"] - n["recovered_energy_kwh"], abs=0.011)
    assert n["gap_to_optimum_kwh"] == pytest.approx(n["net_energy_kwh"] - n["optimum_kwh"], abs=0.011)
    assert tr["gap_to_optimum_kwh"] == pytest.approx(tr["traction_energy_kwh"] - tr["optimum_kwh"], abs=0.011)
    assert n["optimum_kwh"] < tr["optimum_kwh"]
    assert n["net_energy_kwh"] <= tr["net_energy_kwh"] + 0.5
    res = CliRunner().invoke(app, [*args, "--objective", "power"])
    assert res.exit_code == 2 and "--objective" in res.output


@pytest.mark.slow
def test_a_batch_with_the_net_objective(tmp_path):
    """A study file's ``objective: net`` reaches every run (its records say so and count the net energy in
    their fitness), keys the runs apart from the traction ones, and leaves the traction runs' keys as they
    were before the field existed; ``batch --objective`` overrides the file."""
    from locoplan.runs import RunSpec, run_many
    from locoplan.runs.spec import load_inputs, spec_key
    from locoplan.runs.study import load_study

    study = tmp_path / "s.yaml"
    route = str(Path("routes/freight-20km.yaml").resolve())
    study.write_text(f"routes: [{route}]\nstrategies: [four-stage]\nobjective: net\n")
    specs = load_study(study).specs
    assert [s.objective for s in specs] == ["net"]
    traction = specs[0].replace(objective="traction")
    inputs = load_inputs([specs[0], traction])
    assert spec_key(specs[0], inputs) != spec_key(traction, inputs)
    assert spec_key(traction, inputs) == spec_key(RunSpec(route, strategy="four-stage"), inputs)
    rec = run_many(specs).records[0]
    assert rec.summary["objective"] == "net" and rec.summary["feasible"]
    assert rec.summary["net_energy_kwh"] < rec.summary["traction_energy_kwh"]
    out = CliRunner().invoke(app, ["batch", str(study), "--store", str(tmp_path / "s.sqlite"), "--workers", "1",
                                   "--objective", "traction", "--json"])
    assert out.exit_code == 0, out.output
