"""The conventions every command keeps: time forms, exit codes, JSON on failure, CSV that a spreadsheet reads,
readable output at 80 columns, output folders, and commands that work as documented."""

import json
import re

import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.sim.calculator import ModelOptions, TractionCalculator

runner = CliRunner()
SMALL = ["--params", "tests/data/optimizers/issa.yaml", "--e-min", "580", "--no-gap"]


@pytest.fixture(autouse=True)
def _in_repo(root, monkeypatch):
    monkeypatch.chdir(root)


@pytest.fixture()
def unscheduled(tmp_path, root):
    """freight-20km without its schedule (as the real lines in routes/real/ are)."""
    text = (root / "routes/freight-20km.yaml").read_text()
    text = re.sub(r"^schedule:.*\n", "", text, flags=re.M)
    assert "\nschedule" not in text
    path = tmp_path / "line.yaml"
    path.write_text(text)
    return path


def _fastest(freight):
    return TractionCalculator(*freight, ModelOptions()).fastest_time_s


# ------------------------------------------------------------------------------------ --time forms
@pytest.mark.parametrize("form, factor", [("1.1x", 1.1), ("+10%", 1.1), ("1.25X", 1.25), ("+5 %", 1.05)])
@pytest.mark.slow
def test_time_takes_a_factor_or_a_supplement_of_the_fastest_run(form, factor, freight):
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--strategy", "four-stage", "--time", form, "--json"])
    assert res.exit_code == 0, res.output
    import math
    expected = math.ceil(factor * _fastest(freight) * 10 - 1e-9) / 10
    assert json.loads(res.stdout)["planned_time_s"] == pytest.approx(expected)


def test_time_in_seconds_still_works():
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--time", "1500s", "--json"])
    assert json.loads(res.stdout)["planned_time_s"] == 1500


@pytest.mark.parametrize("form, why", [("abc", "expected seconds (1500, 1500s), minutes (25min), hours and minutes (1h05) or h:mm:ss (0:25:00), a factor of the fastest run (1.1x)"),
                                       ("0.9x", "not a factor of the fastest run in 1 .. 10"),
                                       ("-10%", "expected seconds"), ("0", "must be in")])
def test_bad_time_forms_are_input_errors(form, why):
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--time", form])
    assert res.exit_code == 2 and "--time" in res.stderr and why in res.stderr
    assert "Traceback" not in res.output


@pytest.mark.parametrize("cmd", [["optimize", *SMALL], ["sweep", "--weight-grid", "0.5", *SMALL],
                                 ["compare", "--strategies", "four-stage", "--no-gap"], ["bound"]])
@pytest.mark.slow
def test_every_command_with_time_takes_the_forms(cmd, unscheduled):
    """A route without a schedule says which forms to give; every command that takes --time takes them."""
    res = runner.invoke(app, [cmd[0], str(unscheduled), *cmd[1:], "--json"])
    assert res.exit_code == 2
    assert "has no schedule" in res.stderr and "1.1x" in res.stderr and "+10%" in res.stderr
    if cmd[0] == "bound":
        return  # a solve of seconds: the parsing is the same helper as the others'
    res = runner.invoke(app, [cmd[0], str(unscheduled), *cmd[1:], "--time", "+15%", "--json"])
    assert res.exit_code in (0, 1), res.output
    data = json.loads(res.stdout)
    row = data["results"][0] if "results" in data else data
    assert row["planned_time_s"] > 1000


def test_help_of_time_names_the_forms():
    for cmd in ("simulate", "optimize", "compare", "sweep", "study", "bound", "advise", "ocp"):
        text = " ".join(runner.invoke(app, [cmd, "--help"], env={"COLUMNS": "200"}).stdout.split())
        assert "1.1x" in text and "+10%" in text, cmd


@pytest.mark.slow
def test_times_lists_take_every_form(unscheduled):
    """sweep's --times on a route without a schedule: seconds, factors and supplements mixed in one list."""
    res = runner.invoke(app, ["sweep", str(unscheduled), "--times", "1.1x,1450,+20%", *SMALL, "--json"])
    assert res.exit_code in (0, 1), res.output
    fastest = 1227.1  # freight-20km's fastest run with the default train (the 1.1x note below says so)
    times = [r["planned_time_s"] for r in json.loads(res.stdout)["results"]]
    assert times == pytest.approx([1349.8, 1450, 1472.6], abs=0.05)
    note = runner.invoke(app, ["sweep", str(unscheduled), "--times", "1.1x", *SMALL])
    assert f"the fastest run is {fastest:.1f} s" in note.stderr and "T0 = 1349.8 s" in note.stderr


def test_planned_times_from_python(freight):
    import math

    from locoplan import api, bounds

    asked = bounds.times_request("1400, 1.1x, +25%")
    assert asked == [("s", 1400.0), ("x", 1.1), ("x", 1.25)]
    got = api.planned_times(asked, *freight).times_s
    fastest = _fastest(freight)
    assert got == pytest.approx([1400.0, math.ceil(11 * fastest - 1e-9) / 10, math.ceil(12.5 * fastest - 1e-9) / 10])
    assert bounds.times_request("1400:1600:100") == [("s", 1400.0), ("s", 1500.0), ("s", 1600.0)]
    assert api.planned_times([("s", 1500.0)]).note is None  # seconds alone: no calculator, no note


@pytest.mark.parametrize("cmd", [["sweep", "--no-gap"], ["bound"], ["pareto"]])
@pytest.mark.parametrize("value, why", [("abc,1500", "expected seconds (1500, 1500s), minutes (25min), hours and minutes (1h05) or h:mm:ss (0:25:00), a factor of the fastest run (1.1x)"),
                                        ("1500,0.5x", "not a factor of the fastest run in 1 .. 10"),
                                        ("1400:1.1x:100", "expected start:stop:step")])
def test_bad_times_lists_are_input_errors(cmd, value, why):
    res = runner.invoke(app, [cmd[0], "routes/freight-20km.yaml", *cmd[1:], "--times", value, "--json"])
    assert res.exit_code == 2, res.output
    data = json.loads(res.stdout)
    assert data["verdict"] == "invalid input" and "--times" in data["reason"] and why in data["reason"]


def test_simulate_a_timetabled_strategy_on_a_route_without_schedule(unscheduled):
    """four-stage plans to a time: without a schedule and without --time it names the forms (it used to
    run to an undefined time and exit 0)."""
    res = runner.invoke(app, ["simulate", str(unscheduled), "--strategy", "four-stage"])
    assert res.exit_code == 2
    assert "has no schedule" in res.stderr and "1.1x" in res.stderr and "+10%" in res.stderr
    measured = runner.invoke(app, ["simulate", str(unscheduled), "--strategy", "time-saving", "--json"])
    assert measured.exit_code == 0 and json.loads(measured.stdout)["running_time_s"] == pytest.approx(1227.1, abs=0.05)
    timed = runner.invoke(app, ["simulate", str(unscheduled), "--strategy", "four-stage", "--time", "+20%", "--json"])
    assert timed.exit_code == 0, timed.output
    data = json.loads(timed.stdout)
    assert data["planned_time_s"] == pytest.approx(1472.6) and data["punctual"] is True


def test_drivers_simulate_without_schedule_says_what_to_give(unscheduled, tmp_path):
    res = runner.invoke(app, ["drivers", "simulate", str(unscheduled), "--out", str(tmp_path / "logs")])
    assert res.exit_code == 2 and "has no schedule" in res.stderr and "--times 1500" in res.stderr
    assert not (tmp_path / "logs").exists()


# ------------------------------------------------------------------------------------ one exit rule
def test_simulate_sequence_reports_late_and_follows_the_one_rule():
    """A --sequence is measured, not planned to T0: exit 0, but the table says how late and that it is
    outside the window (the JSON has punctual false)."""
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:2200,C:17540,B"])
    assert res.exit_code == 0
    text = " ".join(res.stdout.replace("│", " ").split())
    assert "76.7 s early, outside the window 1470 .. 1530 s" in text
    same = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:2200,C:17540,B",
                               "--time", "1500"])
    assert same.exit_code == res.exit_code  # --time equal to the schedule: the same verdict


def test_simulate_timetabled_strategy_outside_the_window_exits_1(freight):
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--strategy", "four-stage", "--time", "1000",
                              "--json"])
    assert res.exit_code == 1
    data = json.loads(res.stdout)
    assert data["verdict"] == "failed" and "below the fastest possible run" in data["reason"]


def test_a_late_sequence_says_late_and_keeps_the_one_rule():
    """Late as well as early: the table says how late and outside which window, the JSON has punctual false,
    and the exit code is the same whether the time is the schedule's or --time's."""
    seq = ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:700,C:18000,B"]
    res = runner.invoke(app, seq, env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    text = " ".join(res.stdout.replace("│", " ").split())
    assert "41.0 s late, outside the window 1470 .. 1530 s" in text
    data = json.loads(runner.invoke(app, [*seq, "--json"]).stdout)
    assert data["running_time_s"] == pytest.approx(1540.96, abs=0.01)
    assert data["punctual"] is False and data["verdict"] == "ok" and data["exit_code"] == 0
    assert runner.invoke(app, [*seq, "--time", "1500"]).exit_code == 0


def test_the_exit_rule_is_in_the_help():
    top = " ".join(runner.invoke(app, ["--help"], env={"COLUMNS": "80"}).stdout.split())
    assert "Exit codes, the same for every command: 0" in top
    assert "a --sequence, time-saving and energy-saving are measured" in top and "2 invalid input" in top
    sim = " ".join(runner.invoke(app, ["simulate", "--help"], env={"COLUMNS": "80"}).stdout.split())
    assert "arrives outside T0 +- tolerance, as optimize and compare do" in sim and "early or late" in sim


@pytest.mark.parametrize("cmd", [["simulate", "--strategy", "four-stage", "--time", "1000"],
                                 ["optimize", "--time", "1000", *SMALL],
                                 ["compare", "--strategies", "four-stage", "--time", "1000", "--no-gap"],
                                 ["sweep", "--times", "1000,1500", *SMALL],
                                 ["study", "--runs", "1", "--algorithms", "issa", "--time", "1000", "--e-min", "580"],
                                 ["bound", "--time", "1000"], ["ocp", "--objective", "energy", "--time", "1000"],
                                 ["pareto", "--times", "1000", "--no-optimum"]], ids=lambda c: c[0])
def test_every_command_below_the_fastest_run_is_exit_1_with_one_json_object(cmd):
    res = runner.invoke(app, [cmd[0], "routes/freight-20km.yaml", *cmd[1:], "--json"])
    assert res.exit_code == 1, res.output
    data = json.loads(res.stdout)
    assert data["verdict"] == "failed" and data["exit_code"] == 1
    assert "1000 s is below the fastest possible run, 1227.1 s" in data["reason"]
    assert "the route's schedule" not in data["reason"]  # the time came from the command line
    assert data["errors"] and all("below the fastest possible run" in e for e in data["errors"])


# ------------------------------------------------------------------------------------ JSON on failure
def test_json_on_an_infeasible_request_is_an_object_with_verdict_reason_and_exit_code():
    res = runner.invoke(app, ["optimize", "routes/freight-20km.yaml", "--time", "1000", "--json", *SMALL])
    assert res.exit_code == 1
    data = json.loads(res.stdout)
    assert data["verdict"] == "failed" and data["exit_code"] == 1
    assert "below the fastest possible run" in data["reason"] and data["errors"] == [data["reason"]]


def test_json_on_invalid_input_names_file_field_and_why(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("schema: locoplan/route@1\nname: x\nlength_m: 1000\nspeed_limits: []\ngradients: []\n")
    res = runner.invoke(app, ["simulate", str(bad), "--json"])
    assert res.exit_code == 2
    data = json.loads(res.stdout)
    assert data["verdict"] == "invalid input" and data["exit_code"] == 2
    assert data["problems"] and all(p["file"] == str(bad) for p in data["problems"])
    assert {"file", "line", "field", "message"} <= set(data["problems"][0])
    assert "Traceback" not in res.output


def test_json_of_a_result_has_verdict_version_and_inputs():
    from locoplan import __version__

    ok = json.loads(runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--json"]).stdout)
    assert ok["verdict"] == "ok" and ok["exit_code"] == 0 and ok["errors"] == []
    assert ok["locoplan_version"] == __version__
    assert ok["inputs"] == {"route": "routes/freight-20km.yaml", "consist": "configs/consists/HXD1-C80x50.yaml"}
    bad = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:1000,C:4000,B", "--json"])
    data = json.loads(bad.stdout)
    assert bad.exit_code == data["exit_code"] == 1 and data["verdict"] == "failed"
    assert data["feasible"] is False and data["errors"][0].startswith("sequence: no feasible plan (stalled")


def _sha256(path) -> str:
    import hashlib

    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def test_json_and_out_files_name_every_file_read_with_its_hash(tmp_path, root):
    """stdout's object and the --out .json file carry the version, the inputs as given and every file read
    with its SHA-256; a changed file changes its hash."""
    from locoplan import __version__

    route = tmp_path / "line.yaml"
    route.write_text((root / "routes/freight-20km.yaml").read_text())
    out = tmp_path / "plan.json"
    res = runner.invoke(app, ["simulate", str(route), "--json", "--out", str(out)])
    assert res.exit_code == 0, res.output
    data, saved = json.loads(res.stdout), json.loads(out.read_text())
    files = {f["path"]: f for f in data["input_files"]}
    assert files[str(route)]["sha256"] == _sha256(route) and files[str(route)]["bytes"] == route.stat().st_size
    consist = files["configs/consists/HXD1-C80x50.yaml"]
    assert consist["sha256"] == _sha256(root / "configs/consists/HXD1-C80x50.yaml")
    assert {"configs/rolling_stock/HXD1.yaml", "configs/rolling_stock/C80.yaml"} <= set(files)  # the consist's types
    for key in ("locoplan_version", "inputs", "input_files"):
        assert saved[key] == data[key]
    assert saved["locoplan_version"] == __version__ and saved["inputs"]["route"] == str(route)
    assert "verdict" not in saved and "profile" in saved
    route.write_text(route.read_text() + "# a comment\n")
    again = json.loads(runner.invoke(app, ["simulate", str(route), "--json"]).stdout)
    assert {f["path"]: f["sha256"] for f in again["input_files"]}[str(route)] != files[str(route)]["sha256"]


@pytest.mark.parametrize("argv, out_name", [
    (["compare", "routes/freight-20km.yaml", "--strategies", "time-saving", "--no-gap"], "c.json"),
    (["sweep", "routes/freight-20km.yaml", "--times", "1500", *SMALL], "s.json"),
    (["ocp", "routes/seed000-grade30.yaml"], "o.json")], ids=lambda a: a[0] if isinstance(a, list) else a)
@pytest.mark.slow
def test_out_json_of_every_command_carries_the_provenance(tmp_path, argv, out_name):
    out = tmp_path / out_name
    res = runner.invoke(app, [*argv, "--out", str(out)])
    assert res.exit_code == 0, res.output
    saved = json.loads(out.read_text())
    assert saved["inputs"]["route"] == argv[1]
    assert {f["path"]: f["sha256"] for f in saved["input_files"]}[argv[1]] == _sha256(argv[1])


def test_a_failure_names_the_files_it_read_too(tmp_path):
    res = runner.invoke(app, ["simulate", str(tmp_path / "none.yaml"), "--json"])
    data = json.loads(res.stdout)
    assert res.exit_code == 2 and data["inputs"]["route"] == str(tmp_path / "none.yaml")
    assert str(tmp_path / "none.yaml") not in [f["path"] for f in data["input_files"]]  # never read: no hash


def test_validate_json_has_the_verdict_too(tmp_path):
    res = runner.invoke(app, ["validate", "routes/freight-20km.yaml", "--json"])
    data = json.loads(res.stdout)
    assert res.exit_code == 0 and data["valid"] and data["verdict"] == "ok"
    assert data["inputs"] == {"files": ["routes/freight-20km.yaml"]}


def test_library_errors_name_the_argument_not_the_command_line(freight):
    from locoplan.errors import InputError
    from locoplan.runner import make_context
    from locoplan.settings import RunSettings

    with pytest.raises(InputError) as exc:
        make_context(*freight, RunSettings(time_s=-5))
    assert str(exc.value).startswith("time_s: must be in") and "<command line>" not in str(exc.value)


# ------------------------------------------------------------------------------------ compare, fairly
@pytest.fixture(scope="module")
def compared(tmp_path_factory, root):
    import os
    out = tmp_path_factory.mktemp("cmp") / "c.csv"
    old = os.getcwd()
    os.chdir(root)
    try:
        res = runner.invoke(app, ["compare", "routes/freight-20km.yaml", "--strategies", "time-saving,four-stage",
                                  "--json", "--out", str(out)])
        table = runner.invoke(app, ["compare", "routes/freight-20km.yaml", "--strategies", "time-saving,four-stage"],
                              env={"COLUMNS": "80"})
    finally:
        os.chdir(old)
    return res, table, out


@pytest.mark.slow
def test_compare_json_has_the_fields_its_table_shows(compared):
    res, _, _ = compared
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    rows = {r["strategy"]: r for r in data["results"]}
    fast, four = rows["time-saving"], rows["four-stage"]
    assert (fast["switches"], fast["coasts"]) == (0, 0)
    conds = [c.split(":")[0] for c in four["plan"].split(",")]
    assert four["switches"] == len(conds) - 1 and four["coasts"] == conds.count("C")
    assert fast["energy_reduction_percent"] == 0
    assert four["energy_reduction_percent"] == pytest.approx(
        100 * (1 - four["traction_energy_kwh"] / fast["traction_energy_kwh"]), abs=0.01)


@pytest.mark.slow
def test_compare_gives_every_punctual_energy_at_the_planned_time(compared):
    res, table, out = compared
    data = json.loads(res.stdout)
    rows = {r["strategy"]: r for r in data["results"]}
    four = rows["four-stage"]
    assert four["punctual"] and four["energy_at_t0_kwh"] == pytest.approx(
        data["optimum_at_t0_kwh"] + four["gap_to_optimum_kwh"], abs=0.011)
    assert rows["time-saving"]["energy_at_t0_kwh"] is None  # 270 s early: its gap says nothing about T0
    text = table.stdout
    assert "at T0" in text and f"{four['energy_at_t0_kwh']:.2f}" in text
    assert max(len(line) for line in text.splitlines()) <= 80
    import csv
    csv_rows = list(csv.DictReader(out.open()))
    assert {"switches", "coasts", "energy_reduction_percent", "energy_at_t0_kwh"} <= set(csv_rows[0])


# ------------------------------------------------------------------------------------ help, version, completion
HELP_COMMANDS = [["validate"], ["simulate"], ["optimize"], ["compare"], ["sweep"], ["study"], ["ocp"], ["ocp-study"],
                 ["learn"], ["advise"], ["import", "ttobench"], ["import", "railtoolkit"], ["bound"], ["batch"],
                 ["results"], ["pareto"], ["drivers", "simulate"], ["journey"]]


def test_top_help_lists_every_command_whole_at_80_columns():
    res = runner.invoke(app, ["--help"], env={"COLUMNS": "80"})
    assert res.exit_code == 0
    commands = res.stdout.split("Commands:")[1]
    assert "..." not in commands and "…" not in commands
    assert max(len(x) for x in res.stdout.splitlines()) <= 80
    for name in ("validate", "simulate", "optimize", "compare", "sweep", "study", "ocp", "ocp-study", "learn",
                 "advise", "import", "bound", "batch", "results", "pareto", "drivers"):
        assert re.search(rf"^  {re.escape(name)} +\S", commands, re.M), name


@pytest.mark.parametrize("path", HELP_COMMANDS, ids=" ".join)
def test_help_names_methods_not_paper_sections(path):
    """No 'Seed 002', 'eq. 10', 'Fig. 15' in help: methods by what they do, the paper cited once."""
    text = " ".join(runner.invoke(app, [*path, "--help"], env={"COLUMNS": "200"}).stdout.split())
    assert not re.search(r"\bseed 00\d|\bseed's\b|\bseeds'|\beq\. ?\d|\bfigs?\. ?\d", text, re.I), text
    assert len(re.findall(r"Method(s)?:", text)) <= 1


def test_short_version_flag_and_shell_completion():
    from locoplan import __version__

    assert runner.invoke(app, ["-V"]).stdout.strip() == f"locoplan {__version__}"
    text = runner.invoke(app, ["--help"]).stdout
    assert "--install-completion" in text and "--show-completion" in text


FIGURE_MAGIC = {".pdf": b"%PDF-", ".svg": b"<svg", ".png": b"\x89PNG"}


@pytest.mark.parametrize("suffix", [".pdf", ".svg", ".PDF"])
@pytest.mark.parametrize("argv", [["optimize", "routes/freight-20km.yaml", *SMALL],
                                  ["compare", "routes/freight-20km.yaml", "--strategies", "time-saving,four-stage",
                                   "--no-gap"],
                                  ["sweep", "routes/freight-20km.yaml", "--times", "1500", *SMALL],
                                  ["bound", "routes/freight-20km.yaml", "--times", "1500,1600"],
                                  ["ocp", "routes/seed000-grade30.yaml"]], ids=lambda a: a[0])
@pytest.mark.slow
def test_every_plot_takes_pdf_and_svg(tmp_path, argv, suffix):
    """Wherever --plot takes a PNG it takes a PDF and an SVG (by the name's suffix, in any case)."""
    if suffix == ".PDF" and argv[0] != "optimize":
        pytest.skip("the case of the suffix once is enough")
    plot = tmp_path / f"figure{suffix}"
    res = runner.invoke(app, [*argv, "--plot", str(plot)])
    assert res.exit_code == 0, res.output
    head = plot.read_bytes()[:400]
    assert FIGURE_MAGIC[suffix.lower()] in head, head[:40]


@pytest.mark.slow
def test_pareto_plot_as_pdf(tmp_path):
    plot = tmp_path / "front.pdf"
    res = runner.invoke(app, ["pareto", "routes/freight-20km.yaml", "--factors", "1.2", "--strategies", "four-stage",
                              "--no-optimum", "--plot", str(plot)])
    assert res.exit_code == 0, res.output
    assert plot.read_bytes()[:5] == b"%PDF-"


@pytest.mark.parametrize("argv", [["simulate", "routes/freight-20km.yaml"], ["pareto", "routes/freight-20km.yaml"],
                                  ["ocp", "routes/seed000-grade30.yaml"]], ids=lambda a: a[0])
def test_a_figure_type_matplotlib_cannot_pick_is_refused_naming_the_three(tmp_path, argv):
    res = runner.invoke(app, [*argv, "--plot", str(tmp_path / "x.jpg")])
    assert res.exit_code == 2 and ".png" in res.stderr and ".svg" in res.stderr and ".pdf" in res.stderr
    assert not (tmp_path / "x.jpg").exists()


def test_plots_as_pdf(tmp_path):
    out = tmp_path / "p.pdf"
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--plot", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:5] == b"%PDF-"


# ------------------------------------------------------------------------------------ plots and profiles
def test_profile_csv_has_the_files_limit_and_gradient_beside_the_trains(tmp_path, freight):
    import csv

    from locoplan.reporting.writers import section_values

    out = tmp_path / "p.csv"
    assert runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--out", str(out)]).exit_code == 0
    rows = list(csv.DictReader(out.open()))
    route, _ = freight
    s = [float(r["s_m"]) for r in rows]
    file_limit = [float(r["limit_file_kmh"]) for r in rows]
    train_limit = [float(r["limit_kmh"]) for r in rows]
    assert file_limit[:-1] == list(section_values(route.speed_limits, "kmh", s[:-1]))
    assert all(t <= f + 1e-9 for t, f in zip(train_limit, file_limit))
    # a rise in the file's limit reaches the train only once its tail (635.2 m) has cleared the lower one
    rise = next(x for x in route.speed_limits[1:] if x.kmh > section_values(route.speed_limits, "kmh", [x.from_m - 1])[0])
    at = s.index(rise.from_m)
    assert file_limit[at] == rise.kmh and train_limit[at] < rise.kmh
    assert [float(r["gradient_file_permille"]) for r in rows][:-1] == list(section_values(route.gradients, "permille", s[:-1]))


def test_plot_marks_the_line_and_labels_both_limits(root):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from locoplan.io.load import load_route, load_train
    from locoplan.reporting.plot import draw_profiles

    route = load_route(root / "routes/freight-20km-ns.yaml")
    calc = TractionCalculator(route, load_train(root / "configs/consists/HXD1-C80x50.yaml"), ModelOptions())
    prof = calc.evaluate(("T",), np.zeros((1, 0)), profile=True).profile
    fig, (ax, axg) = plt.subplots(2, 1)
    draw_profiles(ax, axg, [("time-saving", prof)], "t", route)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    for want in ("neutral section", "tunnel", "curve", "station (stop)", "speed limit (route file)",
                 "speed limit for the train (held until its tail clears)"):
        assert want in labels, labels
    assert [t.get_text() for t in axg.get_legend().get_texts()] == ["equivalent gradient over the train",
                                                                   "gradient (route file)"]
    # the legend sits beside the axes, not over the limit line
    fig.canvas.draw()
    box, axes = ax.get_legend().get_window_extent(), ax.get_window_extent()
    assert box.x0 >= axes.x1
    bands = [p for p in ax.patches if p.get_label() == "neutral section"]
    assert len(route.neutral_sections) >= 1 and bands
    plt.close(fig)


def test_one_colour_per_strategy_in_a_figure():
    from locoplan.reporting.plot import _colour

    profiles = [("time-saving", None), ("four-stage", None), ("proposed", None)]
    assert _colour("proposed", profiles) == _colour("proposed", profiles)
    assert len({_colour(n, profiles) for n, _ in profiles}) == 3


# ------------------------------------------------------------------------------------ CSV a spreadsheet reads
def _python_spellings(text: str) -> list[str]:
    """Cells written as Python writes values (True, None, nan, a tuple) instead of CSV's typed spellings."""
    import csv
    import io

    bad = []
    for row in csv.reader(io.StringIO(text)):
        bad += [c for c in row if c in ("True", "False", "None", "nan", "inf", "-inf") or c.startswith("(")]
    return bad


@pytest.mark.slow
def test_every_csv_writes_booleans_as_true_false_and_no_value_empty(tmp_path):
    """bound's curve (converged: a boolean; a failed time: empty cells) and drivers.csv read as typed values."""
    import csv

    out = tmp_path / "curve.csv"
    res = runner.invoke(app, ["bound", "routes/freight-20km.yaml", "--times", "1500,1000", "--out", str(out)])
    assert res.exit_code == 1, res.output  # 1000 s is below the fastest run: its row says why
    text = out.read_text()
    assert _python_spellings(text) == []
    ok, failed = list(csv.DictReader(text.splitlines()))
    assert ok["converged"] == "true" and float(ok["energy_kwh"]) == pytest.approx(675.83, abs=0.05)
    assert failed["converged"] == "false" and failed["energy_kwh"] == "" and failed["cells"] == ""
    logs = tmp_path / "logs"
    assert runner.invoke(app, ["drivers", "simulate", "routes/freight-20km.yaml", "--drivers", "2", "--runs", "1",
                               "--out", str(logs)]).exit_code == 0
    drivers = (logs / "drivers.csv").read_text()
    assert _python_spellings(drivers) == []
    rows = list(csv.DictReader(drivers.splitlines()))
    assert [r["driver_id"] for r in rows] == ["D01", "D02"] and all(float(r["skill"]) > 0 for r in rows)


def test_profile_csv_is_numbers_and_conditions(tmp_path):
    import csv

    out = tmp_path / "p.csv"
    assert runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--out", str(out)]).exit_code == 0
    rows = list(csv.DictReader(out.open()))
    assert _python_spellings(out.read_text()) == []
    for r in rows:
        assert r["condition"] in ("T", "K", "C", "B", "")  # the last node (the stop) has none
        assert r["air_brake"] in ("applied", "released", "") and r["air_event"] in ("apply", "release", "")
        [float(v) for k, v in r.items() if k not in ("condition", "air_brake", "air_event") and v != ""]
    assert float(rows[-1]["t_s"]) == pytest.approx(1227.1, abs=0.05)


# ------------------------------------------------------------------------------------ small habits
@pytest.mark.slow
def test_output_folders_are_created(tmp_path):
    out, plot = tmp_path / "new" / "deep" / "p.csv", tmp_path / "figs" / "p.svg"
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--out", str(out), "--plot", str(plot)])
    assert res.exit_code == 0, res.output
    assert out.is_file() and plot.is_file()
    logs = tmp_path / "logs" / "freight"
    res = runner.invoke(app, ["drivers", "simulate", "routes/freight-20km.yaml", "--out", str(logs), "--drivers", "1",
                              "--runs", "1"])
    assert res.exit_code == 0, res.output
    assert logs.is_dir() and any(logs.rglob("*.csv"))


@pytest.mark.slow
def test_one_rule_for_output_folders_on_every_command(tmp_path, root):
    """Every output's missing folder is created with its parents: drivers' logs, learn's patterns and plot,
    compare's runs, a new store and results' exports, import's folder."""
    logs = tmp_path / "a" / "b" / "logs"
    res = runner.invoke(app, ["drivers", "simulate", "routes/freight-20km.yaml", "--drivers", "4", "--runs", "2",
                              "--out", str(logs)])
    assert res.exit_code == 0, res.output
    patterns, fit = tmp_path / "c" / "d" / "p.json", tmp_path / "e" / "fit.svg"
    res = runner.invoke(app, ["learn", str(logs), "--out", str(patterns), "--plot", str(fit)])
    assert res.exit_code == 0, res.output
    assert json.loads(patterns.read_text())["input_files"] and b"<svg" in fit.read_bytes()[:400]
    runs = tmp_path / "f" / "g" / "runs.csv"
    assert runner.invoke(app, ["compare", "routes/freight-20km.yaml", "--strategies", "time-saving", "--no-gap",
                               "--out", str(runs)]).exit_code == 0 and runs.is_file()
    study = tmp_path / "study.yaml"
    study.write_text(f"schema: locoplan/study@1\nroutes: [{root / 'routes/freight-20km.yaml'}]\n"
                     "consists: [HXD1-C80x30]\nstrategies: [time-saving]\n")
    store = tmp_path / "h" / "i" / "runs.sqlite"
    res = runner.invoke(app, ["batch", str(study), "--store", str(store)])
    assert res.exit_code == 0, res.output
    export, summary = tmp_path / "j" / "k" / "runs.csv", tmp_path / "l" / "summary.json"
    assert runner.invoke(app, ["results", str(store), "--format", "csv", "--out", str(export)]).exit_code == 0
    assert runner.invoke(app, ["results", str(store), "--out", str(summary)]).exit_code == 0
    assert "time-saving" in export.read_text() and summary.is_file()


def test_import_creates_its_output_folder(tmp_path):
    from test_import import _track

    src = tmp_path / "track.json"
    src.write_text(_track())
    out = tmp_path / "m" / "n" / "routes"
    res = runner.invoke(app, ["import", "ttobench", str(src), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert any(out.glob("*.yaml"))
    blocked = tmp_path / "file"
    blocked.write_text("")
    res = runner.invoke(app, ["import", "ttobench", str(src), "--out", str(blocked / "routes")])
    assert res.exit_code == 2 and "is not a folder" in res.stderr


def test_readme_names_the_commands_that_exist():
    from locoplan.cli import app as the_app
    import typer.main

    group = typer.main.get_command(the_app)
    text = open("README.md").read()
    for first, second in re.findall(r"`locoplan ([a-z-]+) ([a-z-]+)", text):
        assert first in group.commands, first
        sub = group.commands[first]
        if hasattr(sub, "commands"):
            assert second in sub.commands, f"locoplan {first} {second}"
    assert "drivers learn" not in text


def test_a_failed_command_creates_no_output_folder(tmp_path):
    out = tmp_path / "never" / "p.csv"
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--out", str(out), "--sequence", "T:0,C:nan"])
    assert res.exit_code == 2 and not (tmp_path / "never").exists()


def test_validate_warns_about_a_route_written_in_km(tmp_path):
    km = tmp_path / "km.yaml"
    km.write_text("schema: locoplan/route@1\nname: km line\nlength_m: 12\nspeed_limits:\n"
                  "  - {from_m: 0, to_m: 1, kmh: 55}\n  - {from_m: 1, to_m: 12, kmh: 80}\n"
                  "gradients:\n  - {from_m: 0, to_m: 12, permille: 0}\n")
    res = runner.invoke(app, ["validate", str(km)])
    assert res.exit_code == 0
    text = " ".join(res.stderr.split())
    assert f"warning: {km}:3: length_m: 12 m is shorter than any freight train" in text and "in km?" in text
    assert "speed_limits[0]: 1 of 2 sections are shorter than 10 m" in text
    data = json.loads(runner.invoke(app, ["validate", str(km), "--json"]).stdout)
    assert [w["field"] for w in data["warnings"]] == ["length_m", "speed_limits[0]"]
    plain = runner.invoke(app, ["validate", "routes/freight-20km.yaml"])
    assert "warning" not in plain.stderr


@pytest.mark.parametrize("key, meant, how", [("mps: 20", "kmh", "km/h: m/s x 3.6"), ("kph: 70", "kmh", "km/h")])
def test_unit_keys_get_a_hint_at_the_unit_the_format_wants(tmp_path, key, meant, how):
    f = tmp_path / "r.yaml"
    f.write_text(f"schema: locoplan/route@1\nname: x\nlength_m: 2000\nspeed_limits:\n  - {{from_m: 0, to_m: 2000, {key}}}\n"
                 "gradients:\n  - {from_m: 0, to_km: 2, percent: 0.5}\n")
    res = runner.invoke(app, ["validate", str(f)])
    assert res.exit_code == 2
    text = " ".join(res.stderr.split())
    units = "(units live in key names: _m, _kmh, _s, _t, _kn, _permille)"
    assert f"speed_limits[0].{key.split(':')[0]}: unknown key; did you mean '{meant}'? {units}; the format wants {how}" in text
    assert f"gradients[0].percent: unknown key; did you mean 'permille'? {units}; the format wants per mille: % x 10" in text
    assert f"gradients[0].to_km: unknown key; did you mean 'to_m'? {units}; the format wants metres: km x 1000" in text


def test_a_tight_schedule_names_its_file_and_line_and_is_said_once(tmp_path, root):
    tight = tmp_path / "tight.yaml"
    text = (root / "routes/freight-20km.yaml").read_text()
    text = re.sub(r"^schedule:.*$", "schedule: {run_time_s: 1100, tolerance_s: 30}", text, flags=re.M)
    tight.write_text(text)
    line = text.splitlines().index("schedule: {run_time_s: 1100, tolerance_s: 30}") + 1
    where = f"planned running time 1100 s (the route's schedule, {tight}:{line}: schedule.run_time_s) is below"
    res = runner.invoke(app, ["compare", str(tight), "--strategies", "time-saving,four-stage,proposed", "--no-gap",
                              "--e-min", "580"], env={"COLUMNS": "80"})
    assert res.exit_code == 1
    out, errs = " ".join(res.stdout.split()), " ".join(res.stderr.split())
    assert out.count("below the fastest possible run") == 1 and errs.count("below the fastest possible run") == 1
    # (a long temporary path may be wrapped anywhere in the 80-column table: compared without white space)
    assert ("four-stage, proposed: no feasible plan: " + where).replace(" ", "") in out.replace(" ", "")
    assert ("error: four-stage, proposed: " + where).replace(" ", "") in errs.replace(" ", "")
    one = runner.invoke(app, ["optimize", str(tight), "--json", *SMALL])
    assert one.exit_code == 1 and where in json.loads(one.stdout)["reason"]
    asked = runner.invoke(app, ["optimize", str(tight), "--time", "1100", "--json", *SMALL])
    assert "route's schedule" not in asked.stdout  # a --time is the user's, not the file's


def test_unknown_consist_lists_the_catalogue():
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--consist", "HXD1-C80x40"])
    assert res.exit_code == 2
    assert "HXD1-C80x40: consist: no such file, nor a consist of that name; the catalogue has: " in res.stderr
    assert "HXD1-C80x50" in res.stderr and "HXD1-C80x30" in res.stderr


def test_box_plot_axis_reads_plain_per_cents():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from locoplan.reporting.plot_runs import _plain_ticks

    fig, ax = plt.subplots()
    ax.boxplot([[0.1, 0.5, 3.0, 40.0]])
    ax.set_yscale("symlog", linthresh=2.0)
    _plain_ticks(ax, 40.0)
    fig.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels()]
    assert labels[:6] == ["0", "1", "2", "5", "10", "20"] and not any("^" in x or "10^" in x for x in labels)
    plt.close(fig)


def test_convergence_curve_ends_at_the_reported_value(tmp_path):
    import numpy as np

    import matplotlib

    matplotlib.use("Agg")
    from locoplan.io.load import load_route, load_train
    from locoplan.reporting.plot import plot_profiles
    from locoplan.sim.calculator import ModelOptions, TractionCalculator

    route = load_route("routes/freight-20km.yaml")
    prof = TractionCalculator(route, load_train("configs/consists/HXD1-C80x50.yaml"), ModelOptions()).evaluate(
        ("T",), np.zeros((1, 0)), profile=True).profile
    captured = {}
    import matplotlib.figure

    original = matplotlib.figure.Figure.savefig

    def keep(self, *a, **k):
        captured["fig"] = self
        return original(self, *a, **k)

    matplotlib.figure.Figure.savefig = keep
    try:
        plot_profiles(tmp_path / "p.png", [("proposed", prof)], "t", histories=[("issa", np.array([0.2, 0.1280]), None, 0.12814)])
    finally:
        matplotlib.figure.Figure.savefig = original
    axc = captured["fig"].axes[-1]
    labels = [t.get_text() for t in axc.get_legend().get_texts()]
    assert "issa: 0.12814 reported (reporting grid)" in labels
    end = [line for line in axc.lines if line.get_label().startswith("issa: ")][0]
    assert list(end.get_ydata()) == [0.12814] and list(end.get_xdata()) == [2]


@pytest.mark.parametrize("argv, field", [(["simulate", "routes/freight-20km.yaml", "--seed", "abc"], "--seed"),
                                         (["drivers", "simulate", "routes/freight-20km.yaml", "--drivers", "x"], "--drivers")])
def test_json_when_the_command_line_itself_is_refused(argv, field):
    res = runner.invoke(app, [*argv, "--json"])
    assert res.exit_code == 2
    data = json.loads(res.stdout)
    assert data["verdict"] == "invalid input" and data["exit_code"] == 2 and data["problems"][0]["field"] == field


@pytest.mark.parametrize("args", [["optimize", "routes/freight-20km.yaml", "--out", ""],
                                  ["optimize", "routes/freight-20km.yaml", "--plot="],
                                  ["batch", "docs/small_study.yaml", "--store", ""],
                                  ["simulate", "routes/freight-20km.yaml", "--consist", ""]])
def test_an_empty_path_option_is_empty_not_the_current_folder(args):
    """A path option given '' arrives as the folder '.': it is refused as empty, before any work."""
    r = runner.invoke(app, args, catch_exceptions=False)
    assert r.exit_code == 2 and "is empty ('')" in r.output and "is a folder" not in r.output


def test_a_library_that_does_not_load_is_named_with_the_likely_cause():
    """Under an address-space limit numba's llvmlite fails to load with an OSError that names no file: the message
    says a compiled library did not load and why that most often happens, not 'cannot read or write a file'."""
    from locoplan.cli_common import _os_problem

    exc = OSError("Could not find/load shared object file 'libllvmlite.so' from resource location: "
                  "'llvmlite.binding'. This could mean that the library literally cannot be found")
    err = _os_problem(exc)
    assert err.exit_code == 2
    assert "could not load a compiled library" in str(err) and "ulimit -v" in str(err)
    assert "cannot read or write" not in str(err)
