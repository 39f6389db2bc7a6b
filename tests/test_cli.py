"""The command line as a user meets it (typer's CliRunner)."""

import csv
import io
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app

runner = CliRunner()


@pytest.fixture(autouse=True)
def _in_repo(root, monkeypatch):
    monkeypatch.chdir(root)


def test_simulate_json_is_one_object_with_the_spec_keys():
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--strategy", "time-saving", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)  # nothing but JSON on stdout
    for key in ("route", "consist", "strategy", "algorithm", "seed", "feasible", "running_time_s",
                "traction_energy_kwh", "punctuality_error_s", "fitness", "solve_time_s", "sequence"):
        assert key in data
    assert data["feasible"] is True and data["strategy"] == "time-saving"
    assert data["punctuality_error_s"] == pytest.approx(abs(data["running_time_s"] - 1500), abs=0.01)
    seq = data["sequence"]
    assert seq[0]["condition"] == "T" and seq[0]["from_m"] == 0 and seq[-1]["condition"] == "B"
    assert "|T-T0|" not in res.stdout
    assert seq[-1]["to_m"] == 20000
    assert all(a["to_m"] == b["from_m"] for a, b in zip(seq, seq[1:]))  # contiguous
    assert all(a["condition"] != b["condition"] for a, b in zip(seq, seq[1:]))  # merged runs


def test_time_saving_sequence_follows_the_limits():
    """The fastest run reaches 55 km/h before 2000 m and cruises at it; braking begins before each drop."""
    data = json.loads(runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--json"]).stdout)
    runs = data["sequence"]
    assert [r["condition"] for r in runs[:2]] == ["T", "K"]
    assert 800 < runs[0]["to_m"] < 1000
    brake_ends = [r["to_m"] for r in runs if r["condition"] == "B"]
    for drop in (8000, 14000, 17500, 19000, 20000):  # every limit drop and the stop has a braking run into it
        assert drop in brake_ends


def test_out_csv_profile_agrees_with_summary(tmp_path):
    out = tmp_path / "p.csv"
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:2200,C:17540,B",
                              "--out", str(out), "--json"])
    assert res.exit_code == 0
    summary = json.loads(res.stdout)
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert list(rows[0]) == ["s_m", "t_s", "v_kmh", "limit_kmh", "gradient_permille", "condition", "traction_kn", "brake_kn",
                             "coupler_tension_kn", "coupler_compression_kn", "air_brake", "air_event", "limit_file_kmh",
                             "gradient_file_permille", "km_post", "station"]
    # the air brake in each cell: applied where the plan follows a braking curve, an event where it begins / ends
    assert {r["air_brake"] for r in rows} == {"applied", "released", ""}
    events = [r["air_event"] for r in rows if r["air_event"]]
    assert events and set(events) <= {"apply", "release"} and events[0] == "apply"
    assert sum(e == "apply" for e in events) == summary["air_applications"]
    tension = [float(r["coupler_tension_kn"]) for r in rows]
    assert max(tension) == pytest.approx(summary["max_coupler_tension_kn"], abs=0.05)
    assert max(float(r["coupler_compression_kn"]) for r in rows) == pytest.approx(summary["max_coupler_compression_kn"],
                                                                                  abs=0.05)
    s = np.array([float(r["s_m"]) for r in rows])
    f = np.array([float(r["traction_kn"]) for r in rows])
    assert s[0] == 0 and s[-1] == 20000
    assert float(rows[-1]["t_s"]) == pytest.approx(summary["running_time_s"], abs=0.01)
    assert np.sum(f[:-1] * np.diff(s)) / 3600 == pytest.approx(summary["traction_energy_kwh"], rel=1e-4)
    assert all(float(r["v_kmh"]) <= float(r["limit_kmh"]) + 1e-6 for r in rows)


def test_out_json_and_plots(tmp_path):
    res = runner.invoke(app, ["simulate", "routes/seed000-flat.yaml", "--consist", "HXD1-C64-seed000",
                              "--out", str(tmp_path / "r.json"), "--plot", str(tmp_path / "p.png")])
    assert res.exit_code == 0, res.output
    data = json.loads((tmp_path / "r.json").read_text())
    assert data["running_time_s"] == pytest.approx(141.51, abs=0.05)
    assert len(data["profile"]["s_m"]) == len(data["profile"]["v_kmh"]) > 10
    assert (tmp_path / "p.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--plot", str(tmp_path / "p.svg")])
    assert res.exit_code == 0 and "<svg" in (tmp_path / "p.svg").read_text()[:500]
    assert "running time" in res.stdout and "condition sequence" in res.stdout


def test_infeasible_plan_exits_1_and_says_why():
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:2200,C:9000,B:19600", "--json"])
    assert res.exit_code == 1
    data = json.loads(res.stdout)
    assert data["feasible"] is False and data["reason"].startswith("stalled at")
    assert data["running_time_s"] is None  # it never arrives


def test_validate_summaries():
    res = runner.invoke(app, ["validate", "routes/freight-20km.yaml", "configs/consists/HXD1-C80x50.yaml",
                              "configs/rolling_stock/HXD1.yaml"])
    assert res.exit_code == 0, res.output
    text = " ".join(res.stdout.split())
    assert "20 km, 9 speed-limit sections, 12 gradient sections, 3 curves, 1 tunnel," in text
    assert "51 vehicles, 5200 t, train length 635.2 m, max 100 km/h" in text
    assert "locomotive 'HXD1': 200 t, 35.2 m, max 120 km/h" in text


def test_default_consist_works_from_any_directory(tmp_path, root, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["simulate", str(root / "routes/freight-20km.yaml"), "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["consist"] == "HXD1 + 50 x C80 (5200 t)"


def test_model_options_from_the_command_line():
    """The default train keeps low limits until its tail clears them (slower than the seeds' point mass)
    and brakes with its wagons too (faster than the electric brake alone)."""
    run = lambda *a: json.loads(runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--json", *a]).stdout)["running_time_s"]
    base, point_air, electric = run(), run("--point-mass", "--air-brake"), run("--no-air-brake")
    assert point_air < base < electric
    # --point-mass alone is the seeds' model (electric brake only): slower than with the air brakes
    assert run("--point-mass") > point_air


def test_version_and_help():
    assert runner.invoke(app, ["--version"]).stdout.startswith("locoplan ")
    res = runner.invoke(app, ["--help"])
    assert "simulate" in res.stdout and "validate" in res.stdout


def test_seed000_sequence_is_accelerate_cruise_brake():
    """The fastest run on the seed 000 line: traction to the limit in about 33 m, cruise, and braking
    over the last ~37 m (the closed-form phases), reported at their exact positions."""
    data = json.loads(runner.invoke(app, ["simulate", "routes/seed000-flat.yaml", "--consist", "HXD1-C64-seed000",
                                          "--json"]).stdout)
    runs = data["sequence"]
    assert [r["condition"] for r in runs] == ["T", "K", "B"]
    assert runs[0]["to_m"] == pytest.approx(33.3, abs=0.3) and runs[2]["from_m"] == pytest.approx(1500 - 37.4, abs=0.3)
