"""Help that reads well (issue 10): every command's options name their values with units, boolean
options come as --x / --no-x pairs, defaults are shown, markup never eats "[m]", and one option name
means one thing across commands."""

import re

import pytest
import typer
import typer.main
from typer.core import TyperGroup
from typer.testing import CliRunner

from locoplan.cli import app

runner = CliRunner()


def _commands() -> list[list[str]]:
    group = typer.main.get_command(app)
    ctx = typer.Context(group)
    found = []

    def walk(cmd, path):
        if isinstance(cmd, TyperGroup):
            for name in cmd.list_commands(ctx):
                walk(cmd.get_command(ctx, name), path + [name])
        else:
            found.append(path)
    walk(group, [])
    return found


COMMANDS = _commands()


def _help(path: list[str]) -> str:
    res = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    return res.output


def _options(text: str) -> dict[str, str]:
    """'--flag' -> its whole entry (the flag line and its wrapped help) in the Options section."""
    body = text.split("\nOptions:\n", 1)[1]
    entries, current = {}, None
    for line in body.splitlines():
        m = re.match(r"^  (--[a-z0-9-]+)", line)
        if m:
            current = m.group(1)
            entries[current] = line
        elif current:
            entries[current] += " " + line.strip()
    return entries


def test_every_command_is_listed_and_covered():
    names = {" ".join(p) for p in COMMANDS}
    for name in ("validate", "simulate", "optimize", "compare", "sweep", "study", "ocp", "ocp-study", "bound", "batch",
                 "results", "pareto", "import", "learn", "advise", "drivers simulate", "journey"):
        assert name in names


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p))
def test_help_names_values_not_types(path):
    text = _help(path)
    # typer's own type tags and braces would read "<float>", "<str>", "{route}", "<bool>"
    assert not re.search(r"<(str|int|float|bool|path|list\[[A-Za-z]+\])>", text), text
    assert not re.search(r"\{[a-z_]+\}", text), text
    usage = text.splitlines()[0]
    assert "{" not in usage
    for flag, entry in _options(text).items():
        head = entry.split("  ")[1] if entry.startswith("  --") else entry
        if " / --no-" in entry or flag in ("--help", "--json", "--quiet", "--explain", "--all-legs", "--journey", "--thermal", "--version"):
            continue
        # an option taking a value shows a capitalised metavar right after the flag, or its choices
        assert re.match(rf"^  {flag} [A-Z]", entry) or re.match(rf"^  {flag} (csv|time|traction|km)\|", entry), (path, entry, head)


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p))
def test_numeric_options_show_a_default_or_say_what_none_means(path):
    """Every option with a number (N, S, M, KWH...) says its default, in [default: ...] or in words."""
    numeric = re.compile(r"^  --[a-z0-9-]+ (N|S|M|KWH|KMH|T|SHARE|GAMMA|REL|PERMILLE|M/S2)\b")
    for entry in _options(_help(path)).values():
        if numeric.match(entry):
            assert "default" in entry or "required" in entry, (path, entry)


def test_model_switches_are_pairs_with_their_default():
    text = _help(["optimize"])
    opts = _options(text)
    for flag in ("--point-mass", "--air-brake", "--strict-limits", "--window", "--gap"):
        assert f"{flag} / --no-{flag[2:]}" in opts[flag], opts[flag]
    assert "[default: no-point-mass]" in opts["--point-mass"]
    assert "[default: window]" in opts["--window"]


def test_units_in_brackets_survive_and_defaults_show():
    opts = _options(_help(["optimize"]))
    assert "[s]" in opts["--time"] and "25min" in opts["--time"] and opts["--time"].startswith("  --time TIME ")
    assert opts["--depart"].startswith("  --depart HH:MM ") and opts["--arrive"].startswith("  --arrive HH:MM ")
    assert "[kWh]" in opts["--e-min"] and opts["--e-min"].startswith("  --e-min KWH ")
    assert "[m]" in opts["--step"] and "[default: 50.0]" in opts["--step"]
    assert "[default: 1]" in opts["--seed"]
    assert "[default: 0.5,0.5]" in opts["--weights"]


def test_weights_mean_one_thing():
    """--weights is the pair w_time,w_energy wherever it appears; sweep's grid is --weight-grid."""
    for path in (["optimize"], ["compare"], ["study"]):
        assert _options(_help(path))["--weights"].startswith("  --weights W_TIME,W_ENERGY ")
    sweep = _options(_help(["sweep"]))
    assert "--weights" not in sweep and sweep["--weight-grid"].startswith("  --weight-grid A:B:STEP|W,... ")


def test_old_sweep_weights_still_parses_as_the_grid(root, monkeypatch):
    monkeypatch.chdir(root)
    res = runner.invoke(app, ["sweep", "routes/freight-20km.yaml", "--weights", "0:1:0.0000001"])
    assert res.exit_code == 2
    assert "--weight-grid" in res.stderr and "10,000,001 values" in res.stderr


def test_pinned_typer_is_the_tested_one(root):
    """pyproject pins the typer range these tests ran with (help layout and metavars are typer's)."""
    import importlib.metadata as md

    text = (root / "pyproject.toml").read_text()
    pin = re.search(r'"typer>=([0-9.]+),<([0-9.]+)"', text)
    assert pin, "typer is pinned to a tested range"
    from packaging.version import Version

    assert Version(pin.group(1)) <= Version(md.version("typer")) < Version(pin.group(2))


def test_bound_help_describes_the_methods_it_runs():
    """bound solves E* on the calculator's cells (ocp.bound.METHOD) and --check by the Radau method
    (ocp.bound.CHECK_METHOD): the help says so, and names no method the command does not run."""
    from locoplan.ocp import bound

    assert (bound.METHOD, bound.CHECK_METHOD) == ("cells", "radau")
    text = " ".join(_help(["bound"]).split())
    summary, options = text.split("Options:", 1)
    assert "calculator's cells" in summary and "Radau" not in summary
    check = options.split("--check / --no-check", 1)[1].split("[default", 1)[0]
    assert "Radau" in check and "trapezoidal" not in text and "10 and 5 m" not in text
    assert "(--check)" in options.split("--mesh-tol", 1)[1].split("--max-phase-degree", 1)[0]
