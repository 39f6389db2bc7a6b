"""``locoplan replay``: logged runs against E* at their own running times, the excess split by section.

The logs are made here from plans run on the traction calculator: a plan read off E*'s own solution (near the
optimum), and the same plan with a needless braking and the traction to win the speed back on one section, the
known loss. The oracles are independent of the replay's code: the calculator's energy and time of each plan, its
braking work, the cell solver's E* solved again at the log's time, and Pontryagin's condition on the price of
kinetic energy.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan import api
from locoplan.cli import app
from locoplan.io.load import load_route, load_train
from locoplan.io.logs import load_logs
from locoplan.learn.replay import replay_run
from locoplan.learn.segments import segment_route
from locoplan.model.logs import LogData
from locoplan.ocp.bound import E_STAR_TOL, optimum_run, optimum_solution, relaxed
from locoplan.ocp.cells import solve_estar
from locoplan.physics.units import kmh, kwh
from locoplan.reporting.logs import manifest_text
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from locoplan.strategy.general_builder import sequence_from_optimum

ROOT = Path(__file__).resolve().parents[1]
CONSIST = ROOT / "configs/consists/HXD1-C80x50.yaml"
runner = CliRunner()

BRAKE_M = 80.0
"""The needless braking: full braking over this many metres, then full traction back to the plan's speed."""


# ------------------------------------------------------------------------------------------ logs from plans
def plan_near_optimum(calc: TractionCalculator, time_s: float) -> tuple[tuple[str, ...], np.ndarray]:
    """The condition sequence and switching points read off E*'s solution at ``time_s`` (the final B bare)."""
    grid, sol = optimum_solution(calc.route, calc.train, calc.options, time_s)
    seq = sequence_from_optimum(calc, grid, sol)
    return seq.conditions, np.append(seq.nominal_m, np.nan)


def run_plan(calc: TractionCalculator, conds, sw):
    res = calc.evaluate(conds, np.atleast_2d(sw), profile=True)
    assert res.feasible[0], res.reason(0)
    return res


def log_of(res) -> LogData:
    """The calculator's run as a recorder logs it: a row per node, the cell's force held to the next row (its
    traction where it has any, else its braking)."""
    p = res.profile
    f = np.where(p.traction_kn[0] > 0, p.traction_kn[0], -p.brake_kn[0])
    return LogData(p.t_s[0], p.s_m, p.v_kmh[0], np.append(f, 0.0))


def csv_text(d: LogData) -> str:
    rows = ["time_s,position_m,speed_kmh,force_kn"]
    rows += [f"{t:.6f},{s:.6f},{v:.6f},{f:.6f}" for t, s, v, f in zip(d.time_s, d.position_m, d.speed_kmh, d.force_kn)]
    return "\n".join(rows) + "\n"


def write_log_set(folder: Path, route_file: Path, train, logs: dict[str, LogData], planned_s: float) -> Path:
    (folder / "logs").mkdir(parents=True)
    runs = []
    for name, d in logs.items():
        (folder / "logs" / f"{name}.csv").write_text(csv_text(d))
        runs.append({"log": f"logs/{name}.csv", "driver_id": name, "mass_t": float(train.mass_t),
                     "scheduled_time_s": float(planned_s), "actual_time_s": round(float(d.running_time_s), 3),
                     "date": dt.date(2025, 1, 1)})
    (folder / "manifest.yaml").write_text(manifest_text({"schema": "locoplan/driver-logs@1", "route": str(route_file),
                                                         "consist": str(CONSIST), "synthetic": True, "runs": runs}))
    return folder


def needless_brake(calc: TractionCalculator, conds, sw, base, sections):
    """The plan with a needless braking where it runs under traction at the limit, and full traction after it, at
    the first such place of a section from which the speed is won back inside the section (from there on the two
    runs drive alike): (the braked run, its plan, the section's index)."""
    p = base.profile
    mid = 0.5 * (p.s_m[1:] + p.s_m[:-1])
    starts = np.concatenate([[0.0], np.nan_to_num(sw, nan=np.inf)])
    planned = np.array([conds[int(np.searchsorted(starts, x, side="right")) - 1] for x in mid])
    at_limit = (planned == "T") & (p.v_kmh[0][1:] >= p.limit_kmh - 0.5) & (p.v_kmh[0][:-1] >= p.limit_kmh - 0.5)
    for sec in sorted(sections, key=lambda s: -s.length_m):
        places = np.flatnonzero(at_limit & (mid > sec.from_m + 100.0) & (mid < sec.to_m - 600.0))
        for i in places[::10]:
            a = float(mid[i])
            k = int(np.searchsorted(starts, a, side="right")) - 1  # the T the braking interrupts
            c2 = conds[:k + 1] + ("B", "T") + conds[k + 1:]
            s2 = np.concatenate([sw[:k], [a, a + BRAKE_M], sw[k:]])
            res = calc.evaluate(c2, np.atleast_2d(s2), profile=True)
            if not res.feasible[0]:
                continue
            apart = np.flatnonzero(np.abs(res.profile.v_kmh[0] - p.v_kmh[0][:]) > 0.3)
            if apart.size and p.s_m[apart[-1]] < sec.to_m - 200.0:
                return res, (c2, s2), sec.index
    raise AssertionError("no place under traction at the limit to brake on and win the speed back in one section")


def build_case(tmp: Path, route_file: Path, time_s: float | None = None):
    """A log set of two runs of one route: ``base`` (near the optimum) and ``braked`` (with the needless braking)."""
    route, train = load_route(route_file), load_train(CONSIST)
    calc = TractionCalculator(route, train, ModelOptions(step_m=10.0))
    time_s = time_s or 1.15 * calc.fastest_time_s
    conds, sw = plan_near_optimum(calc, time_s)
    base = run_plan(calc, conds, sw)
    sections = segment_route(route, train)
    braked, _, k = needless_brake(calc, conds, sw, base, sections)
    folder = write_log_set(tmp, route_file, train, {"base": log_of(base), "braked": log_of(braked)}, time_s)
    return {"folder": folder, "route": route, "train": train, "calc": calc, "base": base, "braked": braked,
            "section": k, "sections": sections}


@pytest.fixture(scope="module")
def freight(tmp_path_factory):
    return build_case(tmp_path_factory.mktemp("freight") / "logs", ROOT / "routes/freight-20km.yaml", 1500.0)


def replay_json(*args) -> dict:
    res = runner.invoke(app, ["replay", *map(str, args), "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


# ------------------------------------------------------------------------------------------ the attribution
def check_needless_braking(case, doc):
    runs = {r["driver_id"]: r for r in doc["runs"]}
    base, braked = runs["base"], runs["braked"]
    k = case["section"]
    for name, r in (("base", base), ("braked", braked)):
        res = case[name]
        # the run's energy and time, recomputed independently: the calculator's, not the log's sum
        assert r["traction_energy_kwh"] == pytest.approx(float(res.traction_energy_kwh[0]), rel=1e-6, abs=2e-3)
        assert r["running_time_s"] == pytest.approx(float(res.running_time_s[0]), abs=0.01)
        # the sections add up to the run's excess (each section rounded to 0.001 kWh in the document)
        assert sum(s["excess_kwh"] for s in r["sections"]) == pytest.approx(r["excess_kwh"], abs=1e-3 * len(r["sections"]))
        assert r["excess_kwh"] == pytest.approx(r["traction_energy_kwh"] - r["optimum_kwh"], abs=2e-3)
    diff = np.array([b["excess_kwh"] - a["excess_kwh"] for a, b in zip(base["sections"], braked["sections"])])
    # the known loss: the kinetic energy braked away (won back by traction) and the time lost, at E*'s price
    p_b, p_m = case["base"].profile, case["braked"].profile
    braking_kwh = kwh(float(np.sum((p_m.brake_kn[0] - p_b.brake_kn[0]) * np.diff(p_b.s_m))))
    lost_s = float(case["braked"].running_time_s[0] - case["base"].running_time_s[0])
    price = (base["optimum_kwh"] - braked["optimum_kwh"]) / lost_s  # E*'s chord between the two times
    loss = braking_kwh + price * lost_s
    assert braking_kwh > 5.0 and lost_s > 0.3
    assert int(np.argmax(diff)) == k
    assert diff[k] == pytest.approx(loss, rel=0.1)
    others = np.delete(diff, k)
    assert np.sum(np.abs(others)) <= 0.1 * diff[k], (diff, k)
    # no run of the calculator's uses less than E* at its own time (E* relaxes the air brake's cycle)
    assert base["excess_kwh"] >= -2e-3 and braked["excess_kwh"] >= -2e-3
    return diff


def test_a_needless_braking_is_charged_to_its_section(freight):
    doc = replay_json(freight["folder"])
    check_needless_braking(freight, doc)
    s = doc["summary"]
    assert s["runs"] == s["compared"] == 2
    assert s["excess_kwh"] == pytest.approx(sum(r["excess_kwh"] for r in doc["runs"]), abs=2e-3)
    assert s["excess_percent"] == pytest.approx(100 * s["excess_kwh"] / s["traction_energy_kwh"], abs=0.01)
    (line,) = s["lines"]
    assert line["runs"] == 2 and sum(x["excess_kwh"] for x in line["sections"]) == pytest.approx(s["excess_kwh"], abs=0.02)


def test_a_needless_braking_on_an_imported_line(tmp_path):
    case = build_case(tmp_path / "logs", ROOT / "routes/real/CH_Fribourg_Bern.yaml")
    check_needless_braking(case, replay_json(case["folder"]))


def test_the_sections_add_up_exactly_in_the_library(freight):
    for run in load_logs(freight["folder"]):
        r = replay_run(run, ModelOptions())
        total = sum(s.excess_kwh for s in r.sections)
        assert total == pytest.approx(r.excess_kwh, abs=1e-9 * r.traction_energy_kwh)
        assert sum(s.time_kwh for s in r.sections) == pytest.approx(0.0, abs=1e-9 * r.traction_energy_kwh)
        assert sum(s.speed_kwh for s in r.sections) == pytest.approx(0.0, abs=1e-9 * r.traction_energy_kwh)
        assert sum(s.run_s for s in r.sections) == pytest.approx(r.running_time_s, abs=1e-9)


def test_the_optimum_replayed_has_no_excess_anywhere(tmp_path):
    """E*'s own run, logged, is its own optimum: every section's excess is zero (to the log's interpolation)."""
    route_file = ROOT / "tests/data/learn/line-6km.yaml"
    route, train = load_route(route_file), load_train(CONSIST)
    opt = optimum_run(route, train, ModelOptions(), 560.0)
    t = np.concatenate([[0.0], np.cumsum(opt.cell_times_s())])
    d = LogData(t, opt.s_m, kmh(opt.v_ms), np.append(opt.traction_kn, 0.0))
    write_log_set(tmp_path, route_file, train, {"optimum": d}, 560.0)
    (run,) = load_logs(tmp_path)
    r = replay_run(run, ModelOptions())
    assert r.traction_energy_kwh == pytest.approx(opt.bound.energy_kwh, rel=1e-6)
    assert len(r.sections) >= 3
    for s in r.sections:
        assert abs(s.excess_kwh) <= 1e-3 * opt.bound.energy_kwh / len(r.sections), s


def test_a_run_slow_at_a_boundary_and_optimal_either_side_is_charged_second_order_only(tmp_path):
    """The least-energy run that must pass 1000 m 6 km/h slower than the optimum (the cell solver with that node's
    speed pinned) drives each side optimally from its state: it saves about mu dK of traction before the boundary
    and spends it after. The speed term moves that to where it belongs: both sections' excesses are second order
    (a tenth of mu dK at most), where the energy terms alone would credit one and charge the other with all of it."""
    from locoplan.ocp.cells import CellIPM, IPMSettings, cell_calculator, cell_problem, initial_speeds
    from locoplan.physics.units import ms

    route_file = ROOT / "tests/data/learn/line-6km.yaml"
    route, train = load_route(route_file), load_train(CONSIST)
    T, x_b = 560.0, 1000.0
    opt = optimum_run(route, train, ModelOptions(), T)
    v_star = float(np.interp(x_b, opt.s_m, opt.v_ms))
    calc = cell_calculator(route, train, relaxed(ModelOptions()), 5.0)
    prob = cell_problem(calc, T)
    i = int(np.argmin(np.abs(calc.s_m - x_b)))
    assert calc.s_m[i] == pytest.approx(x_b)
    v_b = v_star - ms(6.0)
    prob.lb[3 * i] = prob.ub[3 * i] = v_b / prob.v_ref
    x0 = prob.start_from_profile(np.minimum(initial_speeds(calc, T), prob.ub[0::3] * prob.v_ref))
    res = CellIPM(prob, IPMSettings(mu_strategy="monotone", max_iter=300)).solve(x0)
    assert res.converged
    v, F = prob.speeds_ms(res.x), (res.x * prob.ref)[1::3]
    t = np.concatenate([[0.0], np.cumsum(2 * calc.h_m / np.maximum(v[:-1] + v[1:], 1e-12))])
    write_log_set(tmp_path, route_file, train, {"pinned": LogData(t, calc.s_m, kmh(v), np.append(F, 0.0))}, T)
    (run,) = load_logs(tmp_path)
    r = replay_run(run, ModelOptions())
    k = next(j for j, sec in enumerate(r.sections) if sec.to_m == pytest.approx(x_b))
    mu = float(np.interp(x_b, 0.5 * (opt.s_m[1:] + opt.s_m[:-1]), opt.kinetic_price))
    carried = mu * kwh(0.5 * opt.mass_t * (v_b ** 2 - v_star ** 2))  # < 0: the run carries less over the boundary
    assert carried < -10.0
    before, after = r.sections[k], r.sections[k + 1]
    assert before.energy_kwh == pytest.approx(carried, rel=0.05) and after.energy_kwh == pytest.approx(-carried, rel=0.1)
    assert before.speed_kwh == pytest.approx(-carried, rel=0.02)
    assert 0.0 <= r.excess_kwh <= 0.1 * abs(carried)
    for sec in r.sections:
        assert abs(sec.excess_kwh) <= 0.1 * abs(carried), sec


def test_the_price_of_kinetic_energy_meets_pontryagin():
    """Where the optimum applies part of its traction, one kWh more of kinetic energy saves one kWh of traction
    (price 1); where it brakes with part of its brake, none (price 0); under full traction more than 1."""
    from locoplan.physics.traction import max_force_kn

    route, train = load_route(ROOT / "routes/freight-20km.yaml"), load_train(CONSIST)
    opt = optimum_run(route, train, ModelOptions(), 1500.0)
    v = opt.v_ms
    vm = kmh(np.sqrt(0.5 * (v[1:] ** 2 + v[:-1] ** 2)))
    f_max = max_force_kn(vm, train.traction_speed_kmh, train.traction_kn)
    F, mu = opt.traction_kn, opt.kinetic_price
    partial = (F > 0.05 * f_max) & (F < 0.9 * f_max)
    full = F > 0.999 * f_max
    assert partial.sum() > 10 and full.sum() > 10
    assert np.allclose(mu[partial], 1.0, atol=2e-3)
    assert np.all(mu[full] > 1.0 - 1e-3)


def test_the_model_options_set_the_optimum(freight):
    """E* at the log's time in each model, solved again here on the cells from a cold start, is the replay's."""
    found = {}
    for flag, opts in (("", api.ModelRequest().options()), ("--point-mass", api.ModelRequest(point_mass=True).options()),
                       ("--no-air-brake", api.ModelRequest(air_brake=False).options())):
        doc = replay_json(freight["folder"], *([flag] if flag else []))
        r = next(x for x in doc["runs"] if x["driver_id"] == "base")
        es = solve_estar(freight["route"], freight["train"], relaxed(opts), r["running_time_s"], tol=E_STAR_TOL)
        assert r["optimum_kwh"] == pytest.approx(es.energy_kwh, rel=5 * E_STAR_TOL, abs=2e-3)
        assert sum(s["excess_kwh"] for s in r["sections"]) == pytest.approx(r["excess_kwh"], abs=0.02)
        found[flag] = r["optimum_kwh"]
    assert found["--point-mass"] != pytest.approx(found[""], rel=1e-3)
    assert found["--no-air-brake"] != pytest.approx(found[""], rel=1e-3)


def test_outputs_csv_json_and_plot(freight, tmp_path):
    csv_file, json_file, png = tmp_path / "r.csv", tmp_path / "r.json", tmp_path / "r.png"
    res = runner.invoke(app, ["replay", str(freight["folder"]), "--out", str(csv_file), "--plot", str(png)])
    assert res.exit_code == 0, res.output
    assert "would have saved" in res.output and "Traceback" not in res.output
    import csv

    rows = list(csv.DictReader(csv_file.open()))
    assert len(rows) == 2 * len(freight["sections"])
    assert png.stat().st_size > 10_000 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = runner.invoke(app, ["replay", str(freight["folder"]), "--out", str(json_file)])
    assert res.exit_code == 0, res.output
    doc = json.loads(json_file.read_text())
    by_run = {r["driver_id"]: r for r in doc["runs"]}
    for row in rows:
        sec = by_run[row["driver_id"]]["sections"][int(row["section_index"])]
        assert float(row["section_excess_kwh"]) == sec["excess_kwh"]


def test_a_run_faster_than_the_train_can_run_fails_with_its_reason(freight, tmp_path):
    """A log that says the train ran the line faster than the model's train can (another train, a clock in other
    units) has no E*: exit 1 with the reason, the other runs still replayed."""
    base = read_back(freight["folder"] / "logs/base.csv")
    fast = LogData(base.time_s * 0.5, base.position_m, base.speed_kmh, base.force_kn)
    folder = write_log_set(tmp_path / "logs", ROOT / "routes/freight-20km.yaml", freight["train"],
                           {"base": base, "fast": fast}, 1500.0)
    res = runner.invoke(app, ["replay", str(folder), "--json"])
    assert res.exit_code == 1, res.output
    doc = json.loads(res.stdout)
    fast_run = next(r for r in doc["runs"] if r["driver_id"] == "fast")
    assert fast_run["optimum_kwh"] is None and "below the fastest possible run" in fast_run["reason"]
    assert doc["summary"]["compared"] == 1 and any("fast.csv" in e for e in doc["errors"])


def read_back(path: Path) -> LogData:
    from locoplan.io.logs import read_log_csv

    return read_log_csv(path)


# ------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("case", ["missing_log", "wrong_columns", "short_log"])
def test_bad_logs_exit_2_naming_file_line_and_why(case, freight, tmp_path):
    folder = tmp_path / "logs"
    base = read_back(freight["folder"] / "logs/base.csv")
    write_log_set(folder, ROOT / "routes/freight-20km.yaml", freight["train"], {"base": base}, 1500.0)
    log = folder / "logs/base.csv"
    if case == "missing_log":
        log.unlink()
        where, why = f"{folder / 'manifest.yaml'}:", "no such log file: logs/base.csv"
    elif case == "wrong_columns":
        log.write_text(log.read_text().replace("speed_kmh", "speed_mph", 1))
        where, why = f"{log}:1: column 3 (speed_mph)", "units in mph are not accepted"
    else:  # the log of a shorter line: it ends 2 km before the route's end
        keep = base.position_m <= 18_000.0
        short = LogData(base.time_s[keep], base.position_m[keep], base.speed_kmh[keep], base.force_kn[keep])
        log.write_text(csv_text(short))
        where, why = f"{log}:{int(keep.sum()) + 1}: column 2 (position_m)", "the route 'Freight test line, 20 km' is 20,000 m long"
    out_file, plot = tmp_path / "r.json", tmp_path / "r.png"
    res = runner.invoke(app, ["replay", str(folder), "--out", str(out_file), "--plot", str(plot)])
    text = res.output.replace("\n", "")
    assert res.exit_code == 2, res.output
    assert where in text and why in text, res.output
    assert "Traceback" not in res.output
    assert not out_file.exists() and not plot.exists()
    res = runner.invoke(app, ["replay", str(folder), "--json"])
    assert res.exit_code == 2 and json.loads(res.stdout)["exit_code"] == 2


def test_api_replay_returns_the_document_and_verdict(freight):
    result = api.replay(load_logs(freight["folder"]), ModelOptions())
    assert result.verdict.exit_code == 0
    assert [r["driver_id"] for r in result.document["runs"]] == ["base", "braked"]
    assert all(math.isfinite(r.excess_kwh) for r in result.replays)
