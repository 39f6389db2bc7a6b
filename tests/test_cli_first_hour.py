"""What a railway engineer meets in the first hour: time forms, exit codes, JSON on failure, CSV that
a spreadsheet reads, readable output at 80 columns, and commands that work as documented."""

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
def test_time_takes_a_factor_or_a_supplement_of_the_fastest_run(form, factor, freight):
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--strategy", "four-stage", "--time", form, "--json"])
    assert res.exit_code == 0, res.output
    import math
    expected = math.ceil(factor * _fastest(freight) * 10 - 1e-9) / 10
    assert json.loads(res.stdout)["planned_time_s"] == pytest.approx(expected)


def test_time_in_seconds_still_works():
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--time", "1500s", "--json"])
    assert json.loads(res.stdout)["planned_time_s"] == 1500


@pytest.mark.parametrize("form, why", [("abc", "expected seconds (1500), a factor of the fastest run (1.1x)"),
                                       ("0.9x", "not a factor of the fastest run in 1 .. 10"),
                                       ("-10%", "expected seconds"), ("0", "must be in")])
def test_bad_time_forms_are_input_errors(form, why):
    res = runner.invoke(app, ["simulate", "routes/freight-20km.yaml", "--time", form])
    assert res.exit_code == 2 and "--time" in res.stderr and why in res.stderr
    assert "Traceback" not in res.output


@pytest.mark.parametrize("cmd", [["optimize", *SMALL], ["sweep", "--weight-grid", "0.5", *SMALL],
                                 ["compare", "--strategies", "four-stage", "--no-gap"], ["bound"]])
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
    assert data["verdict"] == "infeasible" and "below the fastest possible run" in data["reason"]
