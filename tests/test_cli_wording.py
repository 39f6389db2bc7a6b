"""Outputs that read well at 80 columns: no paper named by its section number ("seed 001", "eq. 10", "Table 2"
of "Seed 000"), no table that spends lines on a repeated name or breaks a sequence early, no legend over lines or
title over the station marks, no progress line without a count or an ETA."""

import ast
import re
import sys
from io import StringIO
from pathlib import Path
from types import SimpleNamespace

import pytest
from rich.console import Console
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.reporting.tables import fit, show

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[1]
PAPER_SECTION = re.compile(r"\bseed 00\d|\bseed's\b|\bseeds'|\beq\. ?[0-9IV]|\bfigs?\. ?\d|\bclaims? \d", re.I)
"""How the papers' sections were cited in output: "seed 001" (also read as a random seed), "eq. 10", "Fig. 2",
"claim 3". The commands name a method by what it does and cite its paper once, in their help."""


def _render(blocks, width=80) -> str:
    buf = StringIO()
    show(Console(file=buf, width=width, force_terminal=False, color_system=None), blocks)
    return buf.getvalue()


def _docstrings(tree) -> set[int]:
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            found.add(id(node.value))  # module, class, function and attribute docstrings: for readers of the code
    return found


# the strategy registry's source keys ("the ISSA paper") select strategies and are never printed; the ISSA
# parameters' descriptions document a parameter file by the paper's equations
ALLOWED = {"locoplan/strategy/registry.py", "locoplan/optimize/issa.py"}


def test_no_output_text_cites_a_paper_by_section():
    """Every string the package can print (not docstrings or comments) is free of the papers' section
    numbers: a table row says "fitness", not "fitness (eq. 10)"; the gap to E* does not say "(seed 001)"."""
    hits = []
    for path in sorted((ROOT / "locoplan").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel in ALLOWED:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _docstrings(tree)
        hits += [f"{rel}:{node.lineno}: {node.value!r}" for node in ast.walk(tree)
                 if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip
                 and PAPER_SECTION.search(node.value)]
    assert not hits, "\n".join(hits)


@pytest.fixture(scope="module")
def four_stage(root):
    res = runner.invoke(app, ["simulate", str(root / "routes/freight-20km.yaml"), "--strategy", "four-stage", "--json"])
    assert res.exit_code == 0, res.output
    import json
    return json.loads(res.stdout)


@pytest.mark.parametrize("gap", ["percent", "kwh"])
def test_summary_names_fitness_and_gap_plainly(four_stage, gap):
    from locoplan.reporting.tables import summary_table

    s = {**four_stage, "algorithm": "issa", "seed": 1, "fitness": 0.12814, "weights": [0.5, 0.5], "e_min_kwh": 538.5,
         "optimum_kwh": 897.8, "gap_to_optimum_kwh": 0.6,
         "gap_to_optimum_percent": 0.07 if gap == "percent" else None,
         "optimum_accuracy_percent": 0.0011 if gap == "percent" else 0.02}
    text = " ".join(_render(summary_table(s, 200), 200).split())  # wide: each row on one line
    assert "fitness │ 0.12814 (weights 0.5/0.5, E_min 538.5 kWh)" in text
    assert "the least energy in this running time" in text and "(issa, seed 1)" in text  # the random seed stays
    assert not PAPER_SECTION.search(text), text


def test_ocp_study_tables_cite_the_paper_not_a_seed():
    from locoplan.reporting.ocp_tables import ratio_table, study_tables

    row = {"table": 2, "gradient_permille": 0.0, "label": "two-stage hp", "algorithm": "two-stage", "control_nodes": 17,
           "state_nodes": 34, "final_control_nodes": 3, "final_state_nodes": 34, "segments": 3, "objective": 141.507,
           "resimulated_running_time_s": 141.507, "gap_to_exact_s": 0.0, "solve_time_s": 0.33, "feasible": True,
           "seed_objective_s": 141.59, "seed_solve_time_s": 1.2}
    study = SimpleNamespace(rows=[row], exact={2: 141.5073}, repeats=1, ratios=[
        {"two_stage": "hp", "versus": "cvp", "per_test": [{"table": 2, "test": 1, "percent": -1.2, "seed_percent": 88.5}],
         "mean_percent": -1.2, "seed_tables_mean_percent": 91.0, "seed_claim_percent": 91.93}])
    text = _render(fit(study_tables(study)[0], 200) + fit(ratio_table(study), 200), 200)
    assert "Table 2 of the paper (level, exact minimum 141.5073 s)" in text
    assert "paper obj." in text and "paper solve" in text and "paper mean" in text and "paper claim" in text
    assert "141.59" in text and "91.93" in text
    assert not re.search(r"\bseed\b", text, re.I), text


def _fit_report(routes: list[str]) -> dict:
    groups = [{"route": r, "mean_mass_t": 4200.0, "scheduled_time_s": 1450.0, "runs": 4, "drivers": 4, "good_drivers": 2,
               "good_runs": 2, "mean_energy_kwh": 762.1, "good_mean_energy_kwh": 701.9, "best_energy_kwh": 684.2}
              for r in routes]
    return {"data": {"good_runs": 2 * len(routes), "runs": 4 * len(routes), "synthetic_runs": 4 * len(routes), "drivers": 4,
                     "groups": groups},
            "upper": {"cv": {}, "form": "pace", "order": 1}, "lower": {"cv": [], "order": 1}, "heldout": {}, "fit": {}}


def test_learn_names_a_single_route_once_not_on_every_row():
    """One route: it is in the title, and each group is one line at 80 columns (the name used to wrap
    over four lines of every row); two routes: a route column."""
    from locoplan.reporting.learn_tables import fit_tables

    one = _render(fit(fit_tables(_fit_report(["Freight test line, 20 km"] * 2))[0], 80, wrap=(0,)))
    assert "good drivers: 4 good runs of 8 (8 synthetic), 4 drivers; route Freight test line, 20 km" in " ".join(one.split())
    rows = [line for line in one.splitlines() if "762.1" in line]
    assert len(rows) == 2 and all("4200" in r and "684.2" in r for r in rows)
    assert not any("Freight" in line and "│" in line for line in one.splitlines())
    assert "claim" not in one
    two = _render(fit(fit_tables(_fit_report(["Line A", "Line B"]))[0], 80, wrap=(0,)))
    assert "route" in two and "Line A" in two and "Line B" in two


def test_a_sequence_fills_its_room_before_it_breaks():
    """compare's sequence column: a sequence as long as the room is one line; a longer one breaks after a '-'."""
    from locoplan.reporting.tables import _wrap_sequence

    assert _wrap_sequence(list("TCKCKCKCB")) == "T-C-K-C-K-C-K-C-B"  # 17 characters in a room of 17
    assert _wrap_sequence(list("TCKCKCKCBT")) == "T-C-K-C-K-C-K-C-\nB-T"
    assert all(len(line) <= 17 for line in _wrap_sequence(list("TKCTCTCBTKCTCB")).splitlines())


@pytest.fixture()
def saved_figures(monkeypatch):
    """The figures a command saves, kept open for inspection."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.figure

    kept = []
    original = matplotlib.figure.Figure.savefig

    def keep(self, *a, **k):
        kept.append(self)
        return original(self, *a, **k)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return kept


def _renderer(fig):
    """A drawn renderer of a saved (and so closed) figure."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


def test_ocp_plot_legends_stand_beside_the_axes(tmp_path, saved_figures, root):
    """The force bounds and the speed limit run the whole width of their panels: a legend inside would
    cover them, so every legend stands right of its axes."""
    res = runner.invoke(app, ["ocp", str(root / "routes/seed000-grade30.yaml"), "--plot", str(tmp_path / "o.png")])
    assert res.exit_code == 0, res.output
    fig, = saved_figures
    renderer = _renderer(fig)
    with_legend = [ax for ax in fig.axes if ax.get_legend() is not None]
    assert len(with_legend) == 3
    for ax in with_legend:
        assert ax.get_legend().get_window_extent(renderer).x0 >= ax.get_window_extent(renderer).x1


def test_the_title_stands_clear_of_the_station_marks(tmp_path, saved_figures, freight):
    """A long title (advise's) spans the stations at both ends: it stands above their ▼ marks."""
    import numpy as np

    from locoplan.reporting.plot import plot_profiles
    from locoplan.sim.calculator import ModelOptions, TractionCalculator

    route, train = freight
    prof = TractionCalculator(route, train, ModelOptions()).evaluate(("T",), np.zeros((1, 0)), profile=True).profile
    title = f"{route.name} — {train.name}: advice from patterns.json, 1506.6 s, 711.6 kWh, and a few more words"
    plot_profiles(tmp_path / "p.png", [("advice", prof)], title, route=route)
    fig = saved_figures[-1]
    renderer = _renderer(fig)
    ax = fig.axes[0]
    marks = [t for t in ax.texts if t.get_text() == "▼"]
    assert len(marks) == 2
    top_of_marks = max(t.get_window_extent(renderer).y1 for t in marks)
    assert ax.title.get_window_extent(renderer).y0 >= top_of_marks


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
@pytest.mark.slow
def test_drivers_simulate_shows_count_bar_and_eta_at_80_columns(tmp_path, root):
    from test_cli_width import _in_pty

    code, text = _in_pty(["drivers", "simulate", "routes/seed000-flat.yaml", "--drivers", "2", "--runs", "1", "--times", "250",
                          "--masses", "4200,5200", "--out", str(tmp_path / "logs")], root)  # 1.5 km: a few seconds
    frames = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", "\n").splitlines()
    assert code == 0, text
    bars = [f for f in frames if "mass batches" in f]
    assert any(re.search(r"mass batches [01]/2 ━+ ETA [-:0-9]+ (4200|5200) t, 2 runs", f) for f in bars), bars
    assert max(len(f.rstrip()) for f in frames) <= 80


def test_a_grouping_key_of_numbers_is_aligned_as_numbers():
    """results --by route,planned_time_s: the planned times stand right-aligned like every number, the route left."""
    from locoplan.reporting.tables import store_summary_table

    base = {"runs": 2, "feasible_runs": 2, "punctual_runs": 2, "energy_mean_kwh": 33.56, "energy_best_kwh": 33.5,
            "energy_sd_kwh": 0.01, "time_mean_s": 154.9, "time_sd_s": 0.1, "gap_mean_percent": None, "gap_best_percent": None}
    rows = [{**base, "route": "A", "planned_time_s": 154.8}, {**base, "route": "A line", "planned_time_s": 1830.0}]
    text = _render(store_summary_table(rows, ["route", "planned_time_s"], "store", 200), 200)
    lines = [line for line in text.splitlines() if "33.56" in line]
    assert re.search(r"│ A +│ +154\.8 │", lines[0]) and re.search(r"│ A line +│ +1830\.0 │", lines[1]), lines
