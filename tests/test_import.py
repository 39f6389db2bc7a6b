"""locoplan import: the shipped real lines and railtoolkit files are what the importers make of the public
sources; conversions keep the source's limits, gradients, curvature and resistance exactly; every
broken input is exit 2 naming file, field and why, with nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.importer import run_import
from locoplan.io.load import load_route, load_train, load_vehicle
from locoplan.io.readers import ImportOptions
from locoplan.io.readers.railtoolkit import davis_coefficients
from locoplan.io.readers.ttobench import mean_abs_curvature
from locoplan.physics.resistance import basic_resistance_n_per_kn, train_resistance_kn
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions

ROOT = Path(__file__).resolve().parents[1]
EXTERNAL = ROOT.parent / "shared" / "data" / "external"
TRACKS = EXTERNAL / "ttobench" / "tracks"
RAILTOOLKIT = EXTERNAL / "railtoolkit"
needs_sources = pytest.mark.skipif(not TRACKS.is_dir() or not RAILTOOLKIT.is_dir(),
                                   reason="the public sources (../shared/data/external) are not beside this checkout")
SHIPPED_TRACKS = ["00_var_speed_limit_100", "CH_Fribourg_Bern", "CH_StGallen_Wil", "CH_Stadelhofen_Altstetten",
                  "CN_Songjiazhuang_Yizhuang", "SE_Vasteras_Kolback"]
runner = CliRunner()


def _step_value(entries, s):
    """Value of a [position, value] step list at position s (the last entry at or before s)."""
    pos = np.array([e[0] for e in entries], float)
    return entries[int(np.searchsorted(pos, s, side="right")) - 1][1]


def _at(sections, key, s):
    return next(getattr(x, key) for x in sections if x.from_m <= s < x.to_m)


def _body(text: str) -> str:
    """A file without its 'Converted by' line (which names the output folder)."""
    return "\n".join(ln for ln in text.splitlines() if not ln.startswith("# Converted by"))


# ------------------------------------------------------------------------------------------ shipped files
@needs_sources
@pytest.mark.parametrize("track", SHIPPED_TRACKS)
def test_shipped_real_lines_are_the_importers_output(track, tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)  # the header records the source path as given, relative to the repository
    source = Path("../shared/data/external/ttobench/tracks") / f"{track}.json"
    report = run_import("ttobench", [source], tmp_path, ImportOptions(cap_kmh=80))
    n_legs = len(json.loads(source.read_text())["stops"]["values"]) - 1
    assert len(report.written) == n_legs
    for path, kind, _ in report.written:
        shipped = ROOT / "routes" / "real" / path.name
        assert kind == "route" and shipped.exists(), path.name
        assert _body(path.read_text()) == _body(shipped.read_text()), f"routes/real/{path.name} is stale: re-import it"
        load_route(path)
    assert (tmp_path / "LICENSE-ttobench.txt").read_text().startswith("BSD 2-Clause License")


@needs_sources
def test_shipped_railtoolkit_files_are_the_importers_output(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    paths = sorted(Path("../shared/data/external/railtoolkit/paths").glob("*.yaml"))
    run_import("railtoolkit", paths, tmp_path, ImportOptions())
    for p in paths:
        assert _body((tmp_path / p.name).read_text()) == _body((ROOT / "routes/railtoolkit" / p.name).read_text())
    train_dir = tmp_path / "train"
    train_dir.mkdir()
    run_import("railtoolkit", [Path("../shared/data/external/railtoolkit/trains/freight.yaml")], train_dir, ImportOptions())
    for rel in ("rolling_stock/DB_V90.yaml", "rolling_stock/Facs124.yaml", "consists/Fr100.yaml"):
        assert _body((train_dir / rel).read_text()) == _body((ROOT / "locoplan/catalogue" / rel).read_text()), rel


def test_every_shipped_route_validates_and_its_fastest_run_is_feasible_with_both_freight_trains():
    routes = sorted((ROOT / "routes" / "real").glob("*.yaml")) + sorted((ROOT / "routes" / "railtoolkit").glob("*.yaml"))
    assert len(routes) == 1 + 1 + 1 + 3 + 13 + 1 + 4  # every leg of the six tracks, four railtoolkit paths
    trains = [load_train(ROOT / "configs/consists" / f"{c}.yaml") for c in ("HXD1-C80x30", "HXD1-C80x50")]
    assert [round(t.mass_t) for t in trains] == [3200, 5200]
    for path in routes:
        route = load_route(path)
        if path.parent.name == "real":
            assert max(x.kmh for x in route.speed_limits) <= 80
        for train in trains:
            ctx = make_context(route, train, RunSettings(ModelOptions(), need_time=False))
            run = run_strategy(ctx, "time-saving", with_fitness=False)
            assert run.result.feasible[0], (path.name, train.name, run.result.reason(0))


# ------------------------------------------------------------------------------------------ round trips
@needs_sources
@pytest.mark.parametrize("track", SHIPPED_TRACKS)
def test_ttobench_round_trip_limits_gradients_curves(track, tmp_path):
    source = TRACKS / f"{track}.json"
    data = json.loads(source.read_text())
    cap = 80.0
    run_import("ttobench", [source], tmp_path, ImportOptions(cap_kmh=cap))
    stops = data["stops"]["values"]
    rng = np.random.default_rng(8)
    for leg in range(1, len(stops)):
        name = f"{track}.yaml" if len(stops) == 2 else f"{track}-leg{leg}.yaml"
        route = load_route(tmp_path / name)
        a, b = stops[leg - 1], stops[leg]
        assert route.length_m == pytest.approx(b - a, abs=1e-3)
        assert route.speed_limits[-1].to_m == route.gradients[-1].to_m == route.length_m
        for s in rng.uniform(0, b - a, 200):
            if any(abs(s + a - e[0]) < 1e-2 for e in data["speed limits"]["values"] + data.get("gradients", {"values": []})["values"]):
                continue  # a boundary itself: both sides are right
            assert _at(route.speed_limits, "kmh", s) == min(cap, _step_value(data["speed limits"]["values"], s + a))
            if "gradients" in data:
                assert _at(route.gradients, "permille", s) == _step_value(data["gradients"]["values"], s + a)
        if "curvatures" in data:
            rows = data["curvatures"]["values"]
            for i, (p0, r0, r1) in enumerate(rows):
                p1 = rows[i + 1][0] if i + 1 < len(rows) else stops[-1]
                if r0 != r1 or r0 == "infinity" or not (a <= p0 and p1 <= b):
                    continue
                mid = 0.5 * (p0 + p1) - a
                assert _at(route.curves, "radius_m", mid) == pytest.approx(abs(r0), abs=0.05)


@needs_sources
def test_clothoid_becomes_its_mean_curvature(tmp_path):
    """CH_StGallen_Wil's second entry, [49.6, 502, 3570] to 125.6 m: curvature 1/502 -> 1/3570 linearly."""
    run_import("ttobench", [TRACKS / "CH_StGallen_Wil.json"], tmp_path, ImportOptions())
    route = load_route(tmp_path / "CH_StGallen_Wil.yaml")
    expected = 1.0 / (0.5 * (1 / 502 + 1 / 3570))  # 880.2 m, worked by hand
    assert _at(route.curves, "radius_m", 80.0) == pytest.approx(expected, abs=0.05)
    assert _at(route.curves, "radius_m", 20.0) == 502  # constant section
    assert all(c.radius_m >= 100 for c in route.curves)


def test_mean_abs_curvature_through_zero_is_two_triangles():
    assert mean_abs_curvature(1 / 500, 1 / 1000) == pytest.approx(0.5 * (1 / 500 + 1 / 1000))
    assert mean_abs_curvature(1 / 500, -1 / 500) == pytest.approx(1 / 1000)  # |k| falls to 0 and rises: mean = half the peak
    assert mean_abs_curvature(1 / 300, -1 / 600) == pytest.approx((1 / 300 * 200 / 2 + 1 / 600 * 100 / 2) / 300)  # zero at 1/3 of the way
    assert mean_abs_curvature(1 / 500, 0.0) == pytest.approx(1 / 1000)


@needs_sources
def test_railtoolkit_round_trip_limits_and_path_resistance(tmp_path):
    source = RAILTOOLKIT / "paths" / "realworld.yaml"
    rows = yaml.safe_load(source.read_text())["paths"][0]["characteristic_sections"]
    run_import("railtoolkit", [source], tmp_path, ImportOptions(cap_kmh=100))
    route = load_route(tmp_path / "realworld.yaml")
    assert route.length_m == rows[-1][0] - rows[0][0] and not route.curves
    for s in np.random.default_rng(3).uniform(0, route.length_m, 500):
        if any(abs(s - r[0]) < 1e-2 for r in rows):
            continue
        i = max(j for j, r in enumerate(rows[:-1]) if r[0] <= s)
        assert _at(route.speed_limits, "kmh", s) == min(100, rows[i][1])
        assert _at(route.gradients, "permille", s) == rows[i][2]


# ------------------------------------------------------------------------------------------ railtoolkit train
def test_resistance_conversion_against_hand_worked_values():
    # DB V90 (traction unit, 80 t all on driving axles): 2.2 + 10 ((60 + 15) / 100)^2 = 2.2 + 5.625 = 7.825 N/kN
    assert basic_resistance_n_per_kn(60, *davis_coefficients("traction unit", 2.2, 0, 10, 80, 80)) == pytest.approx(7.825, rel=1e-12)
    # Facs 124 (freight, Strahl): 1.4 + 3.9 (60 / 100)^2 = 2.804
    assert basic_resistance_n_per_kn(60, *davis_coefficients("freight", 1.4, 0, 3.9)) == pytest.approx(2.804, rel=1e-12)
    # passenger car (Sauthoff) at 100 km/h: 3 + 1.4 * 1 + 3.9 * 1.15^2 = 9.55775
    assert basic_resistance_n_per_kn(100, *davis_coefficients("passenger", 3, 1.4, 3.9)) == pytest.approx(9.55775, rel=1e-12)
    # multiple unit with carrying axles (DB 642: 68 t, 45.333 t driving) at standstill:
    # (3 * 45.333 + 1.4 * 22.667) / 68 + 3.9 * 0.15^2 = 2.46666 + 0.08775
    a, b, c = davis_coefficients("multiple unit", 3, 1.4, 3.9, 68, 45.333)
    assert a == pytest.approx((3 * 45.333 + 1.4 * 22.667) / 68 + 0.08775, rel=1e-12)


def test_imported_train_resistance_equals_trainruns_formula():
    """Whole train (catalogue Fr100 = the import of railtoolkit's freight.yaml), fully loaded: locoplan's
    A + B v + C v^2 [kN] equals TrainRuns.jl's traction-unit + freight-wagon resistance at every speed."""
    train = load_train("Fr100")
    g = 9.81  # locoplan's g (TrainRuns.jl uses 9.80665: the conversion itself is g-free, per mille of weight)
    assert train.mass_t == 80 + 10 * (25 + 59)
    for v in (0.0, 17.0, 45.5, 80.0):
        loco_n = 2.2 / 1000 * 80e3 * g + 10 / 1000 * 80e3 * g * ((v + 15) / 100) ** 2
        wagons_n = 840e3 * g * (1.4 / 1000 + 3.9 / 1000 * (v / 100) ** 2)
        assert float(train_resistance_kn(v, train.resistance_kn)) == pytest.approx((loco_n + wagons_n) / 1000, rel=1e-12)
    assert train.inertial_mass_t == pytest.approx(80 * 1.09 + 840 * 1.03)
    assert train.traction_kn[0] == pytest.approx(186.94) and train.traction_kn[-1] == pytest.approx(26.98)


def test_imported_locomotive_brakes_by_the_consists_constant_deceleration():
    loco = load_vehicle(ROOT / "locoplan/catalogue/rolling_stock/DB_V90.yaml")
    assert loco.brake_kn == [[0, 0], [80, 0]] and loco.rotating_mass_factor == 1.09
    train = load_train("Fr100")
    speeds, force = train.brake_curve(air=True)
    assert np.allclose(force, train.inertial_mass_t * 0.225)  # kN = t * m/s^2


# TrainRuns.jl's own running times for this train (test/highlevel_test.jl, default settings: mass point,
# 20 m distance steps; its test tolerance is rtol = 1 %).
TRAINRUNS_S = {"const": 746.6594691660882, "slope": 842.3797947097586, "speed": 751.9727357301351,
               "realworld": 8789.299477891092}


@pytest.mark.parametrize("path", sorted(TRAINRUNS_S))
def test_running_times_agree_with_trainruns_within_its_own_tolerance(path):
    route = load_route(ROOT / "routes/railtoolkit" / f"{path}.yaml")
    ctx = make_context(route, load_train("Fr100"), RunSettings(ModelOptions(step_m=20, point_mass=True,
                                                                            air_brake=True), need_time=False))
    run = run_strategy(ctx, "time-saving", with_fitness=False)
    assert run.result.feasible[0]
    assert run.summary["running_time_s"] == pytest.approx(TRAINRUNS_S[path], rel=0.01)


# ------------------------------------------------------------------------------------------ CLI
def test_every_format_has_its_reader_and_the_help_lists_them_all():
    """FORMATS (plain data, what ``locoplan import --help`` lists) and READERS (the reader objects) name the same
    formats, in the same order, each reader under its own name."""
    from locoplan.io.readers import FORMATS, READERS

    assert list(READERS) == list(FORMATS) == ["ttobench", "railtoolkit", "osrd", "osrd-train", "railml"]
    assert all(reader.name == name for name, reader in READERS.items())
    shown = " ".join(CliRunner().invoke(app, ["import", "--help"]).output.split())  # the help's lines joined
    assert all(f"{name}: {fmt.description}" in shown for name, fmt in FORMATS.items())


def test_cli_import_ttobench_one_leg(tmp_path):
    track = {"metadata": {"id": "T1", "library version": "TTOBench v1.1"},
             "stops": {"unit": "m", "values": [0.0, 1000.0, 2500.0]},
             "speed limits": {"units": {"position": "m", "velocity": "km/h"}, "values": [[0.0, 100], [1200.0, 60]]},
             "gradients": {"units": {"position": "m", "slope": "permil"}, "values": [[0.0, 0.0], [1500.0, 5.0]]}}
    src = tmp_path / "t1.json"
    src.write_text(json.dumps(track))
    out = tmp_path / "out"
    out.mkdir()
    res = runner.invoke(app, ["import", "ttobench", str(src), "--out", str(out), "--leg", "2", "--cap-kmh", "80"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["T1-leg2.yaml"]
    route = load_route(out / "T1-leg2.yaml")
    assert [(x.from_m, x.to_m, x.kmh) for x in route.speed_limits] == [(0, 200, 80), (200, 1500, 60)]
    assert [(x.from_m, x.to_m, x.permille) for x in route.gradients] == [(0, 500, 0), (500, 1500, 5)]
    text = (out / "T1-leg2.yaml").read_text()
    assert f"# Converted by: locoplan import ttobench {src} --out {out} --cap-kmh 80 --leg 2" in text
    res = runner.invoke(app, ["import", "ttobench", str(src), "--out", str(out), "--json"])
    assert res.exit_code == 0 and [Path(f["path"]).name for f in json.loads(res.stdout)["files"]] == ["T1-leg1.yaml", "T1-leg2.yaml"]


# ------------------------------------------------------------------------------------------ bad inputs
GOOD_TRACK = {
    "metadata": {"id": "Bad_1", "library version": "TTOBench v1.1"},
    "stops": {"unit": "m", "values": [0.0, 800.0, 2000.0]},
    "speed limits": {"units": {"position": "m", "velocity": "km/h"}, "values": [[0.0, 90], [500.0, 70]]},
    "gradients": {"units": {"position": "m", "slope": "permil"}, "values": [[0.0, 1.0], [300.0, -2.0], [600.0, 3.0], [900.0, 0.0]]},
    "curvatures": {"units": {"position": "m", "radius at start": "m", "radius at end": "m"},
                   "values": [[0.0, "infinity", "infinity"], [100.0, 600.0, 600.0], [400.0, "infinity", "infinity"]]},
}


def _track(**changes):
    data = json.loads(json.dumps(GOOD_TRACK))
    for path, value in changes.items():
        node = data
        keys = path.split("/")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node[k]
        last = keys[-1]
        if value is DELETE:
            del node[last]
        elif isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value
    return json.dumps(data)


DELETE = object()

# name -> (file text, extra CLI args, field named, why)
TTOBENCH_BAD = {
    "malformed": ('{"metadata": {"id": "x"},\n "stops": [0, 1,]}', [], "", "not valid JSON"),
    "not_an_object": ("[1, 2, 3]", [], "", "expected a JSON object"),
    "unknown_velocity_unit": (_track(**{"speed limits/units/velocity": "mph"}), [], "speed limits.units.velocity",
                              "unknown velocity unit 'mph'"),
    "unknown_slope_unit": (_track(**{"gradients/units/slope": "degrees"}), [], "gradients.units.slope", "unknown slope unit"),
    "non_monotone": (_track(**{"gradients/values/3": [250.0, 0.0]}), [], "gradients.values[3][0]", "must increase strictly"),
    "gradients_not_at_0": (_track(**{"gradients/values/0": [10.0, 1.0]}), [], "gradients.values[0][0]", "the first position must be 0"),
    "zero_speed": (_track(**{"speed limits/values/1": [500.0, 0]}), [], "speed limits.values[1][1]", "must be > 0"),
    "text_speed": (_track(**{"speed limits/values/1": [500.0, "fast"]}), [], "speed limits.values[1][1]", "must be a number"),
    "missing_limits": (_track(**{"speed limits": DELETE}), [], "speed limits", "required field is missing"),
    "missing_id": (_track(**{"metadata/id": DELETE}), [], "metadata.id", "required field is missing"),
    "id_with_slash": (_track(**{"metadata/id": "../evil"}), [], "metadata.id", "it names the output file"),
    "leg_out_of_range": (_track(), ["--leg", "3"], "stops.values", "--leg 3 is out of range"),
    "too_steep": (_track(**{"gradients/values/2": [600.0, 45.0]}), [], "gradients.values[2][1]", "beyond the route schema's +-40"),
    "beyond_end": (_track(**{"speed limits/values/1": [2000.0, 70]}), [], "speed limits.values[1][0]", "not before the track's end"),
    "bad_radius": (_track(**{"curvatures/values/1": [100.0, "tight", 600.0]}), [], "curvatures.values[1][1]", "must be a number"),
    "short_pair": (_track(**{"speed limits/values/1": [500.0]}), [], "speed limits.values[1]", "expected [position, velocity]"),
    "stops_not_at_0": (_track(**{"stops/values": [5.0, 800.0, 2000.0]}), [], "stops.values[0]", "the first position must be 0"),
}


def _invoke(args):
    res = runner.invoke(app, args)
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res


def _import_bad(fmt: str, src: Path, text: str, extra: list[str]):
    """Import one broken source: exit 2, and nothing in the output folder (no temporary folder either)."""
    src.write_text(text)
    out = src.parent / "out"
    out.mkdir()
    res = _invoke(["import", fmt, str(src), "--out", str(out), *extra])
    assert res.exit_code == 2, res.output
    assert list(out.iterdir()) == []
    return res


@pytest.mark.parametrize("name", sorted(TTOBENCH_BAD))
def test_bad_ttobench_input_names_file_field_and_why(name, tmp_path):
    text, extra, field, why = TTOBENCH_BAD[name]
    src = tmp_path / f"{name}.json"
    res = _import_bad("ttobench", src, text, extra)
    where = f"{src}:2: " if name == "malformed" else f"{src}: "
    assert (where + (f"{field}: " if field else "")) in res.stderr, res.stderr
    assert why in res.stderr, res.stderr


GOOD_PATH = """%YAML 1.2
---
schema: https://railtoolkit.org/schema/running-path.json
schema_version: "2022.05"
paths:
  - name: "test path"
    id: p1
    characteristic_sections:
      - [    0.0, 100, 0.0 ]
      - [ 1000.0,  80, 2.5 ]
      - [ 3000.0,  80, 0.0 ]
"""
GOOD_STOCK = """schema: https://railtoolkit.org/schema/rolling-stock.json
schema_version: "2022.05"
trains:
  - name: "loco and two wagons"
    id: T1
    formation: [L1, W1, W1]
vehicles:
  - name: "wagon"
    id: W1
    vehicle_type: freight
    length: 15
    mass: 20
    load_limit: 60
    speed_limit: 100
  - name: "loco"
    id: L1
    vehicle_type: traction unit
    length: 18
    mass: 84
    speed_limit: 100
    tractive_effort: [[0, 250000], [40, 150000], [100, 60000]]
"""

# name -> (file text, extra CLI args, field named, line, why)
RAILTOOLKIT_BAD = {
    "malformed": (GOOD_PATH.replace("- [ 1000.0,  80, 2.5 ]", "- [ 1000.0,  80, 2.5 "), [], "", None, "not valid YAML"),
    "wrong_schema": (GOOD_PATH.replace("running-path.json", "timetable.json"), [], "schema", 3, "not a railtoolkit file"),
    "wrong_version": (GOOD_PATH.replace('"2022.05"', '"2019.01"'), [], "schema_version", 4, "unsupported schema version"),
    "non_monotone": (GOOD_PATH.replace("[ 3000.0,", "[ 900.0,"), [], "paths[0].characteristic_sections[2][0]", 11,
                     "must increase strictly (900 m after 1000 m)"),
    "zero_speed": (GOOD_PATH.replace("[ 1000.0,  80,", "[ 1000.0,  0,"), [], "paths[0].characteristic_sections[1][1]", 10,
                   "speed limit must be > 0"),
    "missing_sections": (GOOD_PATH.split("    characteristic_sections")[0], [], "paths[0].characteristic_sections", None,
                         "required field is missing"),
    "missing_mass": (GOOD_STOCK.replace("    mass: 20\n", ""), [], "vehicles[0].mass", None, "required field is missing"),
    "unknown_vehicle": (GOOD_STOCK.replace("[L1, W1, W1]", "[L1, W2, W1]"), [], "trains[0].formation[1]", 6,
                        "vehicle 'W2' is not among this file's vehicles"),
    "unknown_type": (GOOD_STOCK.replace("vehicle_type: freight", "vehicle_type: tank"), [], "vehicles[0].vehicle_type", 10,
                     "unknown vehicle type 'tank'"),
    "no_tractive_effort": (GOOD_STOCK.replace("    tractive_effort: [[0, 250000], [40, 150000], [100, 60000]]\n", ""), [],
                           "vehicles[1].tractive_effort", None, "required field is missing"),
    "rotation_mass_beyond_schema": (GOOD_STOCK.replace("    speed_limit: 100\n    tractive", "    speed_limit: 100\n    rotation_mass: 2.0\n    tractive"),
                                    [], "vehicles[1].rotation_mass", 21, "less than or equal to 1.5"),
    "leg_option": (GOOD_PATH, ["--leg", "1"], "--leg", None, "does not apply to railtoolkit"),
    "load_fraction": (GOOD_STOCK, ["--load-fraction", "1.5"], "--load-fraction", None, "must be in [0, 1]"),
}


@pytest.mark.parametrize("name", sorted(RAILTOOLKIT_BAD))
def test_bad_railtoolkit_input_names_file_field_and_why(name, tmp_path):
    text, extra, field, line, why = RAILTOOLKIT_BAD[name]
    src = tmp_path / f"{name}.yaml"
    res = _import_bad("railtoolkit", src, text, extra)
    if field.startswith("--"):
        assert f"<command line>: {field}: " in res.stderr, res.stderr
    else:
        where = f"{src}:{line}: " if line else f"{src}"
        assert where in res.stderr and (f": {field}: " in res.stderr if field else True), res.stderr
    assert why in res.stderr, res.stderr


def test_good_railtoolkit_fixtures_import_and_fully_load_the_wagons(tmp_path):
    (tmp_path / "p.yaml").write_text(GOOD_PATH)
    (tmp_path / "s.yaml").write_text(GOOD_STOCK)
    out = tmp_path / "out"
    out.mkdir()
    res = _invoke(["import", "railtoolkit", str(tmp_path / "s.yaml"), str(tmp_path / "p.yaml"), "--out", str(out)])
    assert res.exit_code == 0, res.output
    train = load_train(out / "consists" / "T1.yaml")
    assert train.mass_t == 84 + 2 * (20 + 60) and train.length_m == 48
    assert load_route(out / "p1.yaml").length_m == 3000
    half = tmp_path / "half"
    half.mkdir()
    res = _invoke(["import", "railtoolkit", str(tmp_path / "s.yaml"), "--out", str(half), "--load-fraction", "0.5"])
    assert res.exit_code == 0 and load_train(half / "consists" / "T1.yaml").mass_t == 84 + 2 * (20 + 30)


def test_all_or_nothing_when_a_later_source_is_bad(tmp_path):
    good, bad = tmp_path / "good.yaml", tmp_path / "bad.yaml"
    good.write_text(GOOD_PATH)
    bad.write_text(GOOD_PATH.replace("id: p1", "id: p2").replace("[ 1000.0,  80,", "[ 1000.0,  -5,"))
    out = tmp_path / "out"
    out.mkdir()
    res = _invoke(["import", "railtoolkit", str(good), str(bad), "--out", str(out)])
    assert res.exit_code == 2 and f"{bad}:10: paths[0].characteristic_sections[1][1]: " in res.stderr
    assert list(out.iterdir()) == []


def test_a_missing_out_folder_is_created(tmp_path):
    src = tmp_path / "t.json"
    src.write_text(_track())
    out = tmp_path / "new" / "out"
    res = _invoke(["import", "ttobench", str(src), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert out.is_dir() and any(out.rglob("*.yaml"))


@pytest.mark.parametrize("case", ["file", "unwritable"])
def test_out_must_be_a_writable_folder(case, tmp_path, monkeypatch):
    src = tmp_path / "t.json"
    src.write_text(_track())
    out = tmp_path / "out"
    if case == "file":
        out.write_text("")
    elif case == "unwritable":
        out.mkdir()
        # root ignores permission bits, so the check itself is made to see a read-only folder
        monkeypatch.setattr("locoplan.importer._writable", lambda folder: False)
    res = _invoke(["import", "ttobench", str(src), "--out", str(out)])
    assert res.exit_code == 2
    why = {"file": "is a file, not a folder", "unwritable": "folder is not writable"}[case]
    assert f"{out}: --out: {why}" in res.stderr, res.stderr


def test_unknown_format_lists_the_known_ones(tmp_path):
    res = _invoke(["import", "osm", str(tmp_path / "x"), "--out", str(tmp_path)])
    assert res.exit_code == 2 and "unknown format 'osm' (one of: ttobench, railtoolkit, osrd, osrd-train, railml)" in res.stderr


def test_units_are_converted_and_sharp_curves_clamped_with_a_note(tmp_path):
    track = {"metadata": {"id": "U1"},
             "stops": {"unit": "km", "values": [0.0, 2.0]},
             "speed limits": {"units": {"position": "km", "velocity": "m/s"}, "values": [[0.0, 25.0], [1.5, 12.5]]},
             "gradients": {"units": {"position": "m", "slope": "%"}, "values": [[0.0, 0.5], [1000.0, -1.2]]},
             "curvatures": {"units": {"position": "m", "radius at start": "m", "radius at end": "m"},
                            "values": [[0.0, "infinity", "infinity"], [500.0, -60.0, -60.0], [600.0, "infinity", "infinity"]]}}
    src = tmp_path / "u1.json"
    src.write_text(json.dumps(track))
    out = tmp_path / "out"
    out.mkdir()
    res = _invoke(["import", "ttobench", str(src), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "1 curve(s) sharper than 100 m set to 100 m" in res.stderr
    route = load_route(out / "U1.yaml")
    assert route.length_m == 2000
    assert [(x.from_m, x.to_m, x.kmh) for x in route.speed_limits] == [(0, 1500, 90), (1500, 2000, 45)]
    assert [(x.from_m, x.to_m, x.permille) for x in route.gradients] == [(0, 1000, 5), (1000, 2000, -12)]
    assert [(x.from_m, x.to_m, x.radius_m) for x in route.curves] == [(500, 600, 100)]


def test_leg_and_all_legs_together_is_an_error(tmp_path):
    src = tmp_path / "t.json"
    src.write_text(_track())
    res = _invoke(["import", "ttobench", str(src), "--out", str(tmp_path), "--leg", "1", "--all-legs"])
    assert res.exit_code == 2 and "<command line>: --leg: give --leg N or --all-legs, not both" in res.stderr
