"""Journeys in batch studies: a study's ``journeys:`` run as journey runs into the store (their records the
journey's totals, keyed by content, resumed without a run twice), ``results`` beside route runs, ``pareto``
over a journey's total running time, and a bad ``journeys`` entry named at its line."""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.runs import RunSpec, Store, run_many
from locoplan.runs.spec import load_inputs, spec_key
from locoplan.runs.study import load_study
from locoplan.settings import RunSettings

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests/data/journeys"
TWIN, HILL = DATA / "twin-journey.yaml", DATA / "hill-journey.yaml"
CONSIST = "HXD1-C80x30"
cli = CliRunner()

STUDY = f"""schema: locoplan/study@1
routes: [{DATA / 'twin.yaml'}]
journeys: [{DATA}/*-journey.yaml]
consists: [{CONSIST}]
times: [1.2x]
strategies: [four-stage]
"""


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    """The study run by ``locoplan batch`` on 2 worker processes, with a cache of optima of its own (every E*
    solved afresh, apart from the test process): (study file, store, the batch's --json report)."""
    folder = tmp_path_factory.mktemp("journey-batch")
    study, store = folder / "study.yaml", folder / "runs.sqlite"
    study.write_text(STUDY)
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "LOCOPLAN_CACHE_DIR": str(folder / "cache")}
    res = subprocess.run([sys.executable, "-m", "locoplan", "batch", str(study), "--store", str(store), "--workers", "2",
                          "--json"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    return study, store, json.loads(res.stdout)


def _records(store: Path) -> list:
    with Store(store, create=False) as s:
        return s.records()


def _journey_record(store: Path, name: str):
    return next(r for r in _records(store) if r.summary.get("journey") == name)


@pytest.mark.slow
def test_the_study_expands_journeys_by_their_fastest_total(batch):
    study, _, report = batch
    specs = load_study(study).specs
    assert [s.kind for s in specs] == ["route", "journey", "journey"]
    assert {Path(s.journey).name for s in specs if s.journey} == {"hill-journey.yaml", "twin-journey.yaml"}
    assert report["runs"] == 3 and report["ran"] == 3 and report["from_store"] == 0


@pytest.mark.slow
def test_a_journey_record_holds_what_the_journey_command_gives_at_the_same_time(batch):
    """The batch's record of the twin journey at 1.2x against ``locoplan journey --time 1.2x --json`` (this
    process, its own E* solves): the same total, the same allocation, the journey's E* within its stated
    accuracy, the same plans."""
    _, store, _ = batch
    rec = _journey_record(store, "Twin legs")
    res = cli.invoke(app, ["journey", str(TWIN), "--consist", CONSIST, "--time", "1.2x", "--strategies", "four-stage",
                           "--json"])
    assert res.exit_code == 0, res.stderr
    d = json.loads(res.stdout)
    s = rec.summary
    assert s["kind"] == "journey" and rec.row()["kind"] == "journey" and rec.spec["journey"] == str(TWIN)
    assert s["planned_time_s"] == d["running_time_s"]
    assert [leg["allocated_time_s"] for leg in s["legs_table"]] == pytest.approx(
        [leg["allocated_time_s"] for leg in d["legs_table"]], abs=0.05)
    tol = d["optimum_kwh"] * d["optimum_accuracy_percent"] / 100 + 1e-3
    assert abs(s["optimum_kwh"] - d["optimum_kwh"]) <= tol
    plan = d["plans"]["four-stage"]
    assert s["traction_energy_kwh"] == pytest.approx(plan["traction_energy_kwh"], rel=1e-3)
    assert s["running_time_s"] == pytest.approx(plan["running_time_s"], abs=0.2)
    # two identical legs: the least-energy allocation is the equal one, and no allocation beats the optimum
    assert s["equal_supplements_kwh"] >= s["optimum_kwh"] - tol
    assert s["legs_table"][0]["allocated_time_s"] == pytest.approx(s["legs_table"][1]["allocated_time_s"], abs=0.2)


def test_a_journey_records_totals_are_its_legs_and_its_windows_are_checked(batch):
    """The hill journey: the record's totals are the sums of its legs' plans; every station's clock in the plan
    is against its window as the window says, and the misses are the record's and its verdict's."""
    _, store, _ = batch
    rec = _journey_record(store, "Flat and hill")
    s = rec.summary
    plans = [leg["plan"] for leg in s["legs_table"]]
    assert s["feasible"] and all(p["feasible"] for p in plans)
    assert s["running_time_s"] == pytest.approx(sum(p["running_time_s"] for p in plans), abs=0.2)
    assert s["traction_energy_kwh"] == pytest.approx(sum(p["traction_energy_kwh"] for p in plans), abs=0.01)
    assert all(p["gap_to_optimum_kwh"] >= -0.01 * p["traction_energy_kwh"] for p in plans)  # no leg's plan beats its E*
    assert s["windows"] == 2 and s["timing_points"] == 1
    missed = []
    for st in s["stations"]:
        lo, hi = st["window_s"]
        if lo is None and hi is None:
            assert st["in_window"] is None
            continue
        inside = (lo is None or st["plan_s"] >= lo - 0.05) and (hi is None or st["plan_s"] <= hi + 0.05)
        assert st["in_window"] is inside, st
        missed += [] if inside else [st["station"]]
    assert [m.split(" at ")[0] for m in s["windows_missed"]] == missed
    # the stations' clocks, recomputed from the legs' plans and the dwells
    clock, stops = 0.0, [st for st in s["stations"] if st["stop"]]
    for leg, st in zip(plans, stops[1:]):
        clock += leg["running_time_s"]
        assert st["plan_s"] == pytest.approx(clock, abs=0.1)
        clock += st["dwell_s"]
    # punctual: the total within its tolerance and every window kept; four-stage keeps time, so anything else
    # fails the run (its verdict), as it is exit 1 of ``locoplan journey``
    on_time = abs(s["running_time_s"] - s["planned_time_s"]) <= s["tolerance_s"] + 0.05
    assert s["punctual"] is (on_time and not missed)
    assert (rec.verdict is None) == (not s["failures"]) == s["punctual"]
    assert all(f in rec.verdict for f in s["failures"])
    assert all(any(f"{m.split(' at ')[0]} at" in f for f in s["failures"]) for m in s["windows_missed"])


def test_resume_runs_nothing_again_and_the_key_is_the_journeys_content(batch, tmp_path):
    study, store, _ = batch
    res = cli.invoke(app, ["batch", str(study), "--store", str(store), "--workers", "1", "--json"])
    assert res.exit_code == 0, res.stderr
    again = json.loads(res.stdout)
    assert again["ran"] == 0 and again["from_store"] == 3 and len(_records(store)) == 3
    # the same journey and line under other names: the same key, taken from the store
    (tmp_path / "line.yaml").write_text((DATA / "twin.yaml").read_text())
    (tmp_path / "copy.yaml").write_text(TWIN.read_text().replace("route: twin.yaml", "route: line.yaml"))
    other = tmp_path / "copy-study.yaml"
    other.write_text(f"journeys: [copy.yaml]\nconsists: [{CONSIST}]\ntimes: [1.2x]\nstrategies: [four-stage]\n")
    res = cli.invoke(app, ["batch", str(other), "--store", str(store), "--workers", "1", "--json"])
    assert res.exit_code == 0, res.stderr
    assert json.loads(res.stdout)["from_store"] == 1 and len(_records(store)) == 3
    # a journey changed (another dwell) or another total time is another run
    (tmp_path / "dwell.yaml").write_text(TWIN.read_text().replace("dwell_s: 60", "dwell_s: 90").replace(
        "route: twin.yaml", "route: line.yaml"))
    base = load_study(other).specs[0]
    specs = [base, RunSpec(journey=str(tmp_path / "dwell.yaml"), consist=CONSIST, strategy="four-stage",
                           settings=RunSettings(time_s=base.time_s)),
             RunSpec(journey=base.journey, consist=CONSIST, strategy="four-stage",
                     settings=RunSettings(time_s=base.time_s + 1))]
    inputs = load_inputs(specs)
    assert len({spec_key(s, inputs) for s in specs}) == 3
    # a journey run's key is not a route run's of its line, nor does a journey spec name both
    with pytest.raises(InputError, match="one of the two"):
        load_inputs([RunSpec(str(DATA / "twin.yaml"), CONSIST, journey=str(TWIN))])


def test_a_journey_below_its_fastest_run_is_a_result_not_an_error(tmp_path):
    study = tmp_path / "fast.yaml"
    study.write_text(f"journeys: [{TWIN}]\nconsists: [{CONSIST}]\ntimes: [100]\nstrategies: [four-stage]\n")
    res = cli.invoke(app, ["batch", str(study), "--store", str(tmp_path / "s.sqlite"), "--workers", "1", "--json"])
    assert res.exit_code == 0, res.stderr
    assert json.loads(res.stdout)["fail_their_job"] == 1
    (rec,) = _records(tmp_path / "s.sqlite")
    assert rec.summary["feasible"] is False and "below its fastest run" in rec.summary["reason"]
    assert rec.summary["planned_time_s"] == 100 and "below its fastest run" in rec.verdict


def test_results_tell_journey_runs_from_route_runs(batch, tmp_path):
    _, store, _ = batch
    res = cli.invoke(app, ["results", str(store), "--json", "--plot", str(tmp_path / "et.png")])
    assert res.exit_code == 0, res.stderr
    summary = json.loads(res.stdout)["summary"]
    by_kind = {(g["kind"], g["journey"]): g for g in summary}
    assert set(by_kind) == {("route", None), ("journey", "Twin legs"), ("journey", "Flat and hill")}
    twin = _journey_record(store, "Twin legs").summary
    g = by_kind[("journey", "Twin legs")]
    assert g["runs"] == 1 and g["energy_best_kwh"] == pytest.approx(twin["traction_energy_kwh"])
    assert g["gap_mean_percent"] == pytest.approx(twin["gap_to_optimum_percent"])
    hill = _journey_record(store, "Flat and hill").summary
    assert by_kind[("journey", "Flat and hill")]["punctual_runs"] == int(bool(hill["punctual"]))
    assert (tmp_path / "et.png").stat().st_size > 10_000
    res = cli.invoke(app, ["results", str(store), "--format", "csv", "--where", "kind=journey"])
    assert res.exit_code == 0, res.stderr
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    assert sorted(r["journey"] for r in rows) == ["Flat and hill", "Twin legs"]
    assert all(r["kind"] == "journey" and r["journey_file"].endswith("-journey.yaml") for r in rows)
    assert all(float(r["optimum_kwh"]) > 0 for r in rows)
    res = cli.invoke(app, ["results", str(store), "--format", "json", "--where", "kind=route"])
    (route,) = json.loads(res.stdout)["results"]
    assert route["kind"] == "route" and "journey" not in route and route["route_file"] == str(DATA / "twin.yaml")
    res = cli.invoke(app, ["results", str(store), "--json", "--by", "kind"])
    assert {g["kind"]: g["runs"] for g in json.loads(res.stdout)["summary"]} == {"journey": 2, "route": 1}


@pytest.mark.slow
def test_pareto_on_a_journey_is_the_front_over_its_total_time(tmp_path):
    png = tmp_path / "front.png"
    res = cli.invoke(app, ["pareto", str(TWIN), "--consist", CONSIST, "--times", "1.1x,1.3x", "--strategies", "four-stage",
                           "--workers", "1", "--json", "--plot", str(png)])
    assert res.exit_code == 0, res.stderr
    front = json.loads(res.stdout)
    assert front["journey"] == "Twin legs" and "journey's least-energy allocation" in front["front_kind"]
    grid = front["grid"]
    assert [g["factor"] for g in grid] == pytest.approx([1.1, 1.3], abs=1e-3)
    assert grid[0]["planned_time_s"] == pytest.approx(1.1 * front["fastest_time_s"], abs=0.11)
    # more time, less energy: the plans and the journey's E* alike; no plan below E* at its own time
    assert grid[1]["best_energy_kwh"] < grid[0]["best_energy_kwh"] and grid[1]["optimum_kwh"] < grid[0]["optimum_kwh"]
    assert all(g["best_energy_kwh"] >= 0.999 * g["optimum_kwh"] for g in grid)
    f = front["front"]
    assert len(f) >= 3 and all(a["running_time_s"] < b["running_time_s"] and a["traction_energy_kwh"] > b["traction_energy_kwh"]
                               for a, b in zip(f, f[1:]))
    assert f[0]["strategy"] == "time-saving" and f[0]["running_time_s"] == pytest.approx(front["fastest_time_s"], abs=0.5)
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize("entry,extra,where", [
    ("[nothing/*.yaml]", "", "study.yaml:1: journeys[0]: 'nothing/*.yaml' matches no journey file"),
    ("[nope.yaml]", "", "study.yaml:1: journeys[0]: no such journey file"),
    ("[{data}/twin.yaml]", "", "study.yaml:1: journeys[0]: '{data}/twin.yaml' is a locoplan/route@1 file, not a journey: "
                               "list it under routes"),
    ("[{data}/twin-journey.yaml]\nroutes: [{data}/twin-journey.yaml]", "",
     "study.yaml:2: routes[0]: '{data}/twin-journey.yaml' is a locoplan/journey@1 file, not a route: list it under journeys"),
    ("\n  - {data}/hill-journey.yaml\n  - {data}/tw*n.yaml", "", "study.yaml:3: journeys[1]: '{data}/tw*n.yaml' matches no "
                                                              "journey file"),
    ("[{data}/twin-journey.yaml]", "times: [1.1x]\ntolerance_s: 150\n", "study.yaml:3: tolerance_s: a punctuality window of "
                                                                      "+-150 s is not below the fastest run of a leg"),
    ("[{data}/twin-journey.yaml]", "times: [0.9x]\n", "study.yaml:2: times[0]: a factor of the fastest run must be >= 1"),
    ("[{data}/twin-journey.yaml]", "", "study.yaml:1: journeys[0]: {data}/twin-journey.yaml gives no running time"),
    ("5", "", "study.yaml:1: journeys: Input should be a valid list"),
])
def test_bad_journeys_entries_exit_2_naming_line_and_field(tmp_path, entry, extra, where):
    path = tmp_path / "study.yaml"
    path.write_text(f"journeys: {entry.format(data=DATA)}\n{extra}consists: [{CONSIST}]\n")
    res = cli.invoke(app, ["batch", str(path), "--store", str(tmp_path / "s.sqlite"), "--workers", "1"])
    assert res.exit_code == 2, res.output
    assert f"{tmp_path}/{where.format(data=DATA)}" in res.stderr, res.stderr
    assert not (tmp_path / "s.sqlite").exists() or not Store(tmp_path / "s.sqlite").keys()


def test_a_study_needs_routes_or_journeys(tmp_path):
    path = tmp_path / "study.yaml"
    path.write_text(f"consists: [{CONSIST}]\n")
    res = cli.invoke(app, ["batch", str(path), "--store", str(tmp_path / "s.sqlite")])
    assert res.exit_code == 2 and f"{path}:1: routes: name the routes or the journeys" in res.stderr, res.stderr


def test_a_library_journey_run_without_a_running_time_names_the_journey():
    with pytest.raises(InputError) as exc:
        run_many([RunSpec(journey=str(TWIN), consist=CONSIST, strategy="four-stage")])
    assert exc.value.problems[0].file == str(TWIN) and exc.value.problems[0].field == "run_time_s"


def test_the_documented_journey_study_expands_as_docs_journeys_md_says():
    from locoplan.io.load import load_journey, load_train
    from locoplan.runs.journey import journey_fastest_s
    from locoplan.sim.calculator import ModelOptions

    specs = load_study(ROOT / "docs/journey_study.yaml").specs
    journeys = [s for s in specs if s.kind == "journey"]
    assert len(specs) == 8 and len(journeys) == 4
    j, line = load_journey(journeys[0].journey)
    fastest = journey_fastest_s(j, line, load_train(CONSIST), ModelOptions())
    assert sorted({s.time_s for s in journeys}) == [pytest.approx(1.1 * fastest, abs=0.1), pytest.approx(1.2 * fastest, abs=0.1)]
