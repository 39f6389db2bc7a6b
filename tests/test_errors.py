"""Every broken input gives exit code 2, a message naming file, line and field, and no traceback;
and nothing half-written is left behind."""

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from locoplan.cli import app

BAD = Path(__file__).parent / "data" / "bad"
runner = CliRunner()

# file -> (field named in the message, why, 1-based line of the offending field or None)
EXPECTED = {
    "route_gap.yaml": ("speed_limits[1].from_m", "gap after the previous section", 6),
    "route_overlap.yaml": ("gradients[1].from_m", "overlaps the previous section", 8),
    "route_unknown_key.yaml": ("tunnel", "unknown key; did you mean 'tunnels'?", 8),
    "route_wrong_unit.yaml": ("speed_limits[0].mph", "unknown key", 5),
    "route_length_in_km.yaml": ("length_km", "did you mean 'length_m'? (units live in key names", 3),
    "route_negative_radius.yaml": ("curves[0].radius_m", "greater than or equal to 100", 9),
    "route_string_for_number.yaml": ("speed_limits[0].kmh", "valid number (got 'fast')", 5),
    "route_quoted_number.yaml": ("gradients[0].permille", "valid number (got '2.5')", 7),
    "empty.yaml": ("", "file is empty", None),
    "not_yaml.yaml": ("", "not valid YAML", 4),
    "route_short_coverage.yaml": ("gradients[0].to_m", "must end at length_m 3000", 7),
    "route_too_steep.yaml": ("gradients[0].permille", "less than or equal to 40", 7),
    "route_zero_speed.yaml": ("speed_limits[0].kmh", "greater than 0", 5),
    "route_wrong_schema.yaml": ("schema", "unknown or missing schema 'locoplan/route@2'", 1),
    "route_reversed_section.yaml": ("tunnels[0]", "from_m > to_m: section reversed", 9),
    "route_beyond_end.yaml": ("curves[0].to_m", "beyond the route's length_m 3000", 9),
    "route_is_a_list.yaml": ("", "expected a mapping", 1),
    "consist_unknown_type.yaml": ("vehicles[0].type", "unknown vehicle type 'HXD2'; did you mean 'HXD1'?", 4),
    "consist_no_locomotive.yaml": ("vehicles", "the consist has no locomotive", 3),
    "consist_no_brake.yaml": ("vehicles", "the train has no brake: no locomotive gives a brake_kn above 0 kN", 5),
    "consist_overloaded.yaml": ("vehicles[1].load_t", "95 t exceeds C80's max_load_t 80 t", 5),
    "consist_zero_count.yaml": ("vehicles[0].count", "greater than or equal to 1", 4),
    "consist_air_reduction.yaml": ("air_brake_cycle.reduction_kpa", "greater than or equal to 50 (got 20)", 7),
    "vehicle_locomotive_without_curves.yaml": ("traction_kn", "needs its max force curve", 1),
    "vehicle_curve_not_rising.yaml": ("traction_kn[2]", "speeds must increase (40 after 50)", 8),
}


def test_corpus_is_complete():
    assert sorted(p.name for p in BAD.glob("*.yaml")) == sorted(EXPECTED)
    assert len(EXPECTED) >= 15


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_validate_reports_file_line_field_and_why(name):
    field, why, line = EXPECTED[name]
    path = BAD / name
    res = runner.invoke(app, ["validate", str(path)])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    where = f"{path}:{line}" if line else f"{path}"
    expected = f"{where}: {field}: " if field else f"{where}: "
    assert expected in res.stderr, res.stderr
    assert why in res.stderr, res.stderr


def test_validate_json_lists_problems():
    res = runner.invoke(app, ["validate", "--json", str(BAD / "route_gap.yaml"), str(BAD / "empty.yaml")])
    assert res.exit_code == 2
    data = json.loads(res.stdout)
    assert [r["valid"] for r in data["results"]] == [False, False]
    p = data["results"][0]["problems"][0]  # structured: file, line, field, message
    assert p["file"].endswith("route_gap.yaml") and p["line"] == 6 and p["field"] == "speed_limits[1].from_m"
    assert "gap" in p["message"] and data["valid"] is False and len(data["problems"]) >= 2


def test_validate_json_describes_valid_files(root):
    res = runner.invoke(app, ["validate", "--json", str(root / "routes/freight-20km.yaml"),
                              str(root / "configs/consists/HXD1-C80x50.yaml")])
    assert res.exit_code == 0
    data = json.loads(res.stdout)
    route, consist = data["results"]
    assert data["valid"] is True and data["problems"] == []
    assert route["kind"] == "route" and route["description"]["length_m"] == 20000
    assert route["description"]["speed_limit_sections"] == 9 and route["description"]["schedule"]["run_time_s"] == 1500
    assert consist["description"]["mass_t"] == 5200 and consist["description"]["vehicles"] == 51


def _simulate(*args):
    return runner.invoke(app, ["simulate", *args])


@pytest.mark.parametrize("args,why", [
    (["routes/nope.yaml"], "routes/nope.yaml: no such file"),
    (["routes/seed000-flat.yaml", "--consist", "configs/consists/none.yaml"], "configs/consists/none.yaml: no such file"),
    (["routes/seed000-flat.yaml", "--sequence", "T:0,C:900,K:500,B"], "switching points out of order: 500 m after 900 m"),
    (["routes/seed000-flat.yaml", "--sequence", "T:0,X:500"], "unknown condition 'X'"),
    (["routes/seed000-flat.yaml", "--sequence", "T:0,C:abc"], "position 'abc' is not a number"),
    (["routes/seed000-flat.yaml", "--sequence", "T:100,C:500"], "the first condition must start at 0 m"),
    (["routes/seed000-flat.yaml", "--sequence", "T:0,C:1600"], "not before the end of the route (1500 m)"),
    (["routes/seed000-flat.yaml", "--strategy", "fastest"], "unknown strategy 'fastest' (one of:"),
    (["routes/seed000-flat.yaml", "--step", "0"], "--step: must be in [0.1, 1,000] m"),
    (["routes/seed000-flat.yaml", "--out", "profile.txt"], "unknown output type '.txt'"),
    (["routes/seed000-flat.yaml", "--plot", "profile.jpg"], "use a .png, .svg or .pdf file name"),
    (["routes/seed000-flat.yaml", "--out", "routes/seed000-flat.yaml/p.csv"], "routes/seed000-flat.yaml is not a folder"),
    ([str(BAD / "route_gap.yaml")], "speed_limits[1].from_m: gap"),
])
def test_simulate_bad_input_exit_2(root, monkeypatch, tmp_path, args, why):
    monkeypatch.chdir(root)
    before = set(Path(".").iterdir())
    res = _simulate(*args)
    assert res.exit_code == 2, res.output
    assert why in res.stderr, res.stderr
    assert res.stdout == ""
    assert set(Path(".").iterdir()) == before  # nothing half-written


def test_bad_plot_name_is_refused_before_anything_is_written(root, monkeypatch, tmp_path):
    """--out is fine but --plot is not: the command stops before computing, and writes nothing."""
    monkeypatch.chdir(tmp_path)
    route = str(root / "routes/seed000-flat.yaml")
    res = _simulate(route, "--consist", "HXD1-C64-seed000", "--out", "p.csv", "--plot", "p.jpg")
    assert res.exit_code == 2 and "use a .png, .svg or .pdf file name" in res.stderr
    assert list(tmp_path.iterdir()) == []
