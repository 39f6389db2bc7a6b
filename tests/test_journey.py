"""Journeys: the running time shared out among the legs (equal marginal energy, windows held), the
journey's E* below any other allocation, the journey file's errors, and the command's outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.io.load import load_journey, load_train
from locoplan.runs.journey import allocate, allocation_energy, legs_of, running_windows
from locoplan.sim.calculator import ModelOptions

runner = CliRunner()
DATA = "tests/data/journeys"


@pytest.fixture(scope="module")
def train():
    return load_train("HXD1-C80x30")


def test_two_identical_legs_share_the_time_equally(root, train):
    j, route = load_journey(root / DATA / "twin-journey.yaml")
    legs = legs_of(j, route, train, ModelOptions())
    total = 1.2 * sum(leg.fastest_s for leg in legs)
    times, at = allocate(j, legs, train, ModelOptions(), total)
    assert times.sum() == pytest.approx(total, abs=1e-3)
    assert times[0] == pytest.approx(times[1], abs=0.05 * total / 100)  # within 0.05 % of the total
    e, bounds = allocation_energy(j, legs, train, ModelOptions(), times)
    assert bounds[0].energy_kwh == pytest.approx(bounds[1].energy_kwh, rel=1e-3)


@pytest.mark.parametrize("options", [ModelOptions(), ModelOptions(point_mass=True)], ids=["default", "point-mass"])
def test_without_windows_the_marginal_energy_is_equal_and_no_other_allocation_does_better(root, train, options):
    """The flat leg and the hill leg: the optimum's marginal energies agree, and the E* sum of the
    equal-percentage allocation and of shifts of +-5 s either way is not lower."""
    j, route = load_journey(root / DATA / "hill-journey.yaml")
    j = j.model_copy(update={"stations": [s.model_copy(update={"earliest_s": None, "latest_s": None}) for s in j.stations]})
    legs = legs_of(j, route, train, options)
    total = 1.14 * sum(leg.fastest_s for leg in legs)
    times, _ = allocate(j, legs, train, options, total)
    e_opt, b = allocation_energy(j, legs, train, options, times)
    assert b[0].slope_kwh_per_s == pytest.approx(b[1].slope_kwh_per_s, rel=0.02)
    fast = np.array([leg.fastest_s for leg in legs])
    others = [fast * total / fast.sum(), times + np.array([5.0, -5.0]), times + np.array([-5.0, 5.0])]
    for other in others:
        e_other, _ = allocation_energy(j, legs, train, options, other)
        assert e_opt <= e_other * (1 + 4e-5)


def test_a_stop_held_at_its_window_and_a_timing_point_window_met(root, train):
    """Without windows B would be reached at 176.5 s: its latest, 175 s, holds it there; the summit's
    window (335 .. 360 s, clock) is met, at its earliest."""
    j, route = load_journey(root / DATA / "hill-journey.yaml")
    legs = legs_of(j, route, train, ModelOptions())
    times, at = allocate(j, legs, train, ModelOptions(), 400.0)
    b, summit = j.stations[1], j.stations[2]
    assert at[1] == pytest.approx(b.latest_s, abs=0.05)
    clock_summit = at[2] + b.dwell_s
    assert summit.earliest_s - 0.05 <= clock_summit <= summit.latest_s + 0.05
    assert running_windows(j) == [(1, 150.0, 175.0), (2, 305.0, 330.0)]


def test_the_command_reports_allocation_windows_and_comparisons(root, tmp_path, monkeypatch):
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path / "cache"))
    out, png = tmp_path / "run.csv", tmp_path / "run.png"
    r = runner.invoke(app, ["journey", str(root / DATA / "hill-journey.yaml"), "--consist", "HXD1-C80x30",
                            "--strategies", "four-stage", "--json", "--out", str(out), "--plot", str(png)])
    d = json.loads(r.stdout)
    assert d["legs"] == 2 and d["timing_points"] == 1 and d["running_time_s"] == 400.0
    names = [a["allocation"] for a in d["allocations"]]
    assert names == ["optimal (equal marginal energy)", "equal supplements", "timetable's leg times"]
    assert all(a["optimum_kwh"] >= d["optimum_kwh"] - 1e-6 for a in d["allocations"])
    assert d["stations"][1]["optimum_s"] <= 175.05 and d["stations"][2]["optimum_s"] >= 334.95
    assert d["allocations"][2]["leg_times_s"] == [172.0, 228.0]  # the timetable's: 172, then 430 - 172 - 30
    assert sum(d["allocations"][0]["leg_times_s"]) == pytest.approx(400.0, abs=0.2)
    assert r.exit_code == (1 if d["errors"] else 0)
    header = out.read_text().splitlines()[0]
    assert header == "leg,s_m,clock_s,v_kmh,condition,traction_kn,brake_kn" and png.stat().st_size > 10_000


def test_time_forms_and_a_journey_without_a_running_time(root, tmp_path, monkeypatch):
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path / "cache"))
    r = runner.invoke(app, ["journey", str(root / DATA / "twin-journey.yaml"), "--consist", "HXD1-C80x30"])
    assert r.exit_code == 2 and "run_time_s" in r.output and "1.15x" in r.output
    r = runner.invoke(app, ["journey", str(root / DATA / "twin-journey.yaml"), "--consist", "HXD1-C80x30", "--time", "50"])
    assert r.exit_code == 1 and "below its fastest run" in r.output


BAD = {
    "unsorted": ("  - {name: A, at_m: 0}\n  - {name: B, at_m: 2000}\n  - {name: C, at_m: 1500}\n", 7, "stations[2].at_m", "running order"),
    "late_start": ("  - {name: A, at_m: 10}\n  - {name: C, at_m: 3000}\n", 5, "stations[0].at_m", "must be at 0"),
    "short_end": ("  - {name: A, at_m: 0}\n  - {name: C, at_m: 2900}\n", 6, "stations[1].at_m", "end of the line"),
    "beyond": ("  - {name: A, at_m: 0}\n  - {name: C, at_m: 3100}\n", 6, "stations[1].at_m", "beyond the end"),
    "empty_window": ("  - {name: A, at_m: 0}\n  - {name: B, at_m: 1500, earliest_s: 200, latest_s: 100}\n"
                     "  - {name: C, at_m: 3000}\n", 6, "stations[1].latest_s", "window is empty"),
    "dwell_passing": ("  - {name: A, at_m: 0}\n  - {name: B, at_m: 1500, stop: false, dwell_s: 30}\n"
                      "  - {name: C, at_m: 3000}\n", 6, "stations[1].dwell_s", "no dwell"),
    "same_name": ("  - {name: A, at_m: 0}\n  - {name: A, at_m: 3000}\n", 6, "stations[1].name", "must differ"),
    "unknown_key": ("  - {name: A, at_m: 0, dwel_s: 3}\n  - {name: C, at_m: 3000}\n", 5, "stations[0].dwel_s", "dwell_s"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_journey_files_are_named_by_file_line_and_field(root, tmp_path, case):
    stations, line, field, words = BAD[case]
    (tmp_path / "twin.yaml").write_text((root / DATA / "twin.yaml").read_text())
    f = tmp_path / f"{case}.yaml"
    f.write_text("schema: locoplan/journey@1\nname: bad\nroute: twin.yaml\nstations:\n" + stations)
    with pytest.raises(InputError) as exc:
        load_journey(f)
    p = exc.value.problems[0]
    assert (p.file, p.line, p.field) == (str(f), line, field) and words in p.message
    r = runner.invoke(app, ["validate", str(f)])
    assert r.exit_code == 2 and f"{f}:{line}: {field}" in r.output


def test_a_missing_route_file_and_a_stop_in_a_neutral_section(root, tmp_path):
    f = tmp_path / "j.yaml"
    f.write_text("schema: locoplan/journey@1\nname: j\nroute: nowhere.yaml\nstations:\n  - {name: A, at_m: 0}\n"
                 "  - {name: C, at_m: 3000}\n")
    with pytest.raises(InputError) as exc:
        load_journey(f)
    assert exc.value.problems[0].line == 3 and "nowhere.yaml" in exc.value.problems[0].message
    (tmp_path / "ns.yaml").write_text((root / DATA / "twin.yaml").read_text()
                                      + "neutral_sections:\n  - {from_m: 1450, to_m: 1550}\n")
    f.write_text("schema: locoplan/journey@1\nname: j\nroute: ns.yaml\nstations:\n  - {name: A, at_m: 0}\n"
                 "  - {name: B, at_m: 1500}\n  - {name: C, at_m: 3000}\n")
    with pytest.raises(InputError) as exc:
        load_journey(f)
    assert exc.value.problems[0].field == "stations[1].at_m" and "neutral section" in exc.value.problems[0].message


def _random_track(rng: np.random.Generator, n_stops: int) -> dict:
    """A TTOBench track drawn at random (not one of the repository's): stops 1.5-3.5 km apart, limits of
    60-120 km/h changing every 0.5-2 km, gradients of -6..+6 per mille every 300-1200 m."""
    stops = np.concatenate([[0.0], np.cumsum(rng.uniform(1500.0, 3500.0, n_stops - 1))]).round(1)
    end = float(stops[-1])

    def steps(lo, hi):
        out = [0.0]
        while out[-1] + hi < end:
            out.append(round(out[-1] + float(rng.uniform(lo, hi)), 1))
        return out
    limits = [[x, int(rng.choice([60, 80, 100, 120]))] for x in steps(500.0, 2000.0)]
    grades = [[x, round(float(rng.uniform(-6.0, 6.0)), 1)] for x in steps(300.0, 1200.0)]
    return {"metadata": {"id": "Random_Line", "library version": "TTOBench v1.1"},
            "stops": {"unit": "m", "values": stops.tolist()},
            "speed limits": {"units": {"position": "m", "velocity": "km/h"}, "values": limits},
            "gradients": {"units": {"position": "m", "slope": "permil"}, "values": grades}}


@pytest.mark.parametrize("seed", [11, 12])
def test_a_journey_imported_from_a_track_not_in_the_repository(tmp_path, monkeypatch, seed):
    """`import ttobench --journey` on a random track, then `journey --time 1.15x`: every leg planned and on
    time, the allocation adds up to the total, and no other allocation's E* sum is lower."""
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path / "cache"))
    rng = np.random.default_rng(seed)
    src = tmp_path / "track.json"
    src.write_text(json.dumps(_random_track(rng, 4)))
    out = tmp_path / "out"
    r = runner.invoke(app, ["import", "ttobench", str(src), "--out", str(out), "--journey", "--cap-kmh", "80"])
    assert r.exit_code == 0, r.output
    jfile = out / "Random_Line-journey.yaml"
    r = runner.invoke(app, ["journey", str(jfile), "--consist", "HXD1-C80x30", "--time", "1.15x", "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["legs"] == 3 and d["stops"] == 4 and not d["errors"]
    assert d["running_time_s"] == pytest.approx(1.15 * d["fastest_running_time_s"], abs=0.15)
    times = d["allocations"][0]["leg_times_s"]
    assert sum(times) == pytest.approx(d["running_time_s"], abs=0.2)
    assert all(t >= row["fastest_s"] - 0.05 for t, row in zip(times, d["legs_table"]))
    assert all(a["optimum_kwh"] >= d["optimum_kwh"] * (1 - 1e-4) for a in d["allocations"])
    plans = [row["plans"]["proposed"] for row in d["legs_table"]]
    assert all(p["feasible"] for p in plans)
    tol = [max(1.0, 0.01 * t) for t in times]  # each leg's punctuality window (+-1 % of its time, >= 1 s)
    assert all(abs(p["running_time_s"] - t) <= w + 0.05 for p, t, w in zip(plans, times, tol))
    assert d["plans"]["proposed"]["traction_energy_kwh"] == pytest.approx(sum(p["traction_energy_kwh"] for p in plans), abs=0.01)
