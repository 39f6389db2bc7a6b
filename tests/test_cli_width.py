"""Tables at 80 columns and in a pipe (issue 10): a plan string is never cut to "…" and prints whole,
numbers are never folded or cut, narrow tables leave out whole columns and say which."""

import json
import os
import re
import subprocess
import sys
from io import StringIO

import pytest
from rich.console import Console
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.reporting.tables import Line, compare_tables, show, study_table, summary_table, sweep_table

runner = CliRunner()
LONG_PLAN = "T:0,K:930,C:3256.2,T:4746,C:6238,T:11673.8,C:12947.7,K:14100.5,C:15300.5,T:16000,C:17000.5,B"


@pytest.fixture(scope="module")
def summaries(root):
    """Real summaries (simulate --json): the fastest run, a long hand-made plan and a plan that stalls."""
    def run(*args):
        res = runner.invoke(app, ["simulate", str(root / "routes/freight-20km.yaml"), *args, "--json"])
        return json.loads(res.stdout)
    fast = run("--strategy", "time-saving")
    long = run("--sequence", LONG_PLAN)
    stall = run("--sequence", "T:0,K:2200,C:9000,B:19600")
    long["strategy"], stall["strategy"] = "proposed", "four-stage"
    return fast, long, stall


def _render(blocks, width=80) -> str:
    buf = StringIO()
    show(Console(file=buf, width=width, force_terminal=False, color_system=None), blocks)
    return buf.getvalue()


def _check_lines(text: str, width: int, whole: tuple[str, ...] = ()) -> None:
    assert "…" not in text
    for line in text.splitlines():
        if len(line) > width:  # only a line carrying a whole plan may be longer (the terminal wraps it)
            assert any(w in line for w in whole), line


def test_summary_keeps_a_long_plan_whole_under_the_table(summaries):
    _, long, _ = summaries
    text = _render(summary_table(long, 80), 80)
    _check_lines(text, 80, whole=(LONG_PLAN,))
    assert f"plan {LONG_PLAN}" in text.splitlines()  # one line, whole, copyable
    assert "(below the table)" in text
    assert f"{long['traction_energy_kwh']:.2f} kWh" in text and f"{long['running_time_s']:.1f} s" in text
    wide = _render(summary_table(long, 160), 160)
    assert "(below the table)" not in wide and LONG_PLAN in wide  # inside the table when it fits


def test_summary_of_a_stalled_plan_says_dash_not_nan(summaries):
    _, _, stall = summaries
    text = _render(summary_table(stall, 80), 80)
    assert "nan" not in text.lower() and "running time      │ -" in text
    assert "stalled at 13,000 m" in text


@pytest.mark.parametrize("width", [60, 80, 100])
def test_compare_tables_fit_without_cutting_digits(summaries, width):
    fast, long, stall = summaries
    blocks = compare_tables([fast, long, stall], "Freight test line, 20 km — HXD1 + 50 x C80 (5200 t), T0 = 1500 s", width)
    text = _render(blocks, width)
    _check_lines(text, width, whole=(LONG_PLAN,))
    for s in (fast, long):  # every shown energy and time, digit for digit
        assert f"{s['traction_energy_kwh']:.2f}" in text and f"{s['running_time_s']:.1f}" in text
    assert any(isinstance(b, Line) and b.endswith(LONG_PLAN) for b in blocks)  # the plan whole, to copy
    assert "four-stage: no feasible plan: stalled at 13,000 m" in " ".join(text.split())
    if width < 100:
        assert "left out at" in text  # a narrow table says which columns it left out
    for n in ("17000", "15300"):  # switching points of Table 8 rounded but whole
        assert n[:5] in text


def test_study_and_sweep_tables_fit_80(summaries):
    rows = [{"algorithm": a, "runs": 10, "feasible_runs": 10,
             "best": {"seed": 3, "running_time_s": 1506.2, "traction_energy_kwh": 687.22, "fitness": 0.0938},
             "worst": {"seed": 5, "running_time_s": 1501.5, "traction_energy_kwh": 697.84, "fitness": 0.10138},
             "mean_running_time_s": 1507.5, "mean_traction_energy_kwh": 690.13, "mean_fitness": 0.09674,
             "std_fitness": 0.00228, "punctual_runs": 10,
             "punctual_best": {"seed": 3, "running_time_s": 1506.2, "traction_energy_kwh": 687.22, "fitness": 0.0938},
             "mean_solve_time_s": 1.4, "mean_gap_to_optimum_percent": 1.23} for a in ("issa", "ssa", "pso")]
    text = _render(study_table(rows, "Freight test line, 20 km: 10 runs per optimiser (Tables 10-12), E_min 538.5 kWh"))
    _check_lines(text, 80)
    assert "by fitness" in text  # the best / worst columns say what ranks them
    assert "0.09380" in text and "687.22" in text and "0.10138" in text
    fast, long, _ = summaries
    for r, t in ((fast, 1470), (long, 1530)):
        r.update(planned_time_s=t, energy_reduction_percent=1.5)
    _check_lines(_render(sweep_table([fast, long], "sweep", by_weights=False)), 80)


def _run_cli(args, env_extra=None, timeout=120):
    env = {**os.environ, "COLUMNS": "80", **(env_extra or {})}
    return subprocess.run([sys.executable, "-m", "locoplan", *args], capture_output=True, text=True, env=env,
                          timeout=timeout)


def test_piped_at_80_columns(root):
    res = subprocess.run([sys.executable, "-m", "locoplan", "simulate", "routes/freight-20km.yaml", "--sequence", LONG_PLAN],
                         capture_output=True, text=True, cwd=root, env={**os.environ, "COLUMNS": "80"}, timeout=120)
    assert res.returncode == 0, res.stderr
    _check_lines(res.stdout, 80, whole=(LONG_PLAN,))
    assert f"plan {LONG_PLAN}" in res.stdout.splitlines()


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
def test_in_a_pseudo_terminal_of_80_columns(root):
    """As a user sees it: a terminal 80 columns wide (no COLUMNS), colours and all."""
    code, raw = _in_pty(["simulate", "routes/freight-20km.yaml", "--sequence", LONG_PLAN], root)
    text = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", raw).replace("\r", "")
    assert code == 0, text
    _check_lines(text, 80, whole=(LONG_PLAN,))
    assert LONG_PLAN in text


def _in_pty(args, root, timeout=120) -> tuple[int, str]:
    """Run the command with stdout and stderr on an 80-column pseudo-terminal; (exit code, all it wrote)."""
    import fcntl
    import pty
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 50, 80, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen([sys.executable, "-m", "locoplan", *args], stdout=slave, stderr=slave, stdin=slave, cwd=root,
                            env=env, close_fds=True)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:
            break
        if not data:
            break
        chunks.append(data)
    proc.wait(timeout=timeout)
    os.close(master)
    return proc.returncode, b"".join(chunks).decode("utf-8", "replace")


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
@pytest.mark.slow
def test_progress_bar_on_a_terminal_only_and_never_with_json(root):
    args = ["compare", "routes/freight-20km.yaml", "--strategies", "time-saving,four-stage", "--no-gap"]
    code, text = _in_pty(args, root)
    assert code == 0 and "compare runs" in text
    # at 80 columns the bar reads: short label, count, bar, ETA, no line wider than the terminal
    frames = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", "\n").splitlines()
    bars = [f for f in frames if "compare runs" in f]
    assert any(re.search(r"compare runs +[0-2]/2 .*━.* ETA", f) for f in bars), bars
    assert max(len(f.rstrip()) for f in frames) <= 80
    code, text = _in_pty(args + ["--json"], root)
    assert code == 0 and "compare runs" not in text
    json.loads(re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", ""))  # nothing but the JSON
    res = subprocess.run([sys.executable, "-m", "locoplan", *args], capture_output=True, text=True, cwd=root, timeout=120)
    assert res.returncode == 0 and "compare runs" not in res.stderr  # piped: no bar


def test_plot_of_a_stalled_plan_ends_where_it_stalls(root, tmp_path):
    """The line stops at the stall (13 km), the title names the reason, never "nan s"."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from locoplan.io.load import load_route, load_train
    from locoplan.reporting.plot import ENERGY, FITNESS, draw_profiles, plot_profiles, run_title
    from locoplan.sim.calculator import ModelOptions, TractionCalculator

    route, train = load_route(root / "routes/freight-20km.yaml"), load_train(root / "configs/consists/HXD1-C80x50.yaml")
    calc = TractionCalculator(route, train, ModelOptions())
    res = calc.evaluate(("T", "K", "C", "B"), np.array([[2200.0, 9000.0, 19600.0]]), profile=True)
    assert not res.feasible[0]
    prof = res.profile
    fig, (ax, axg) = plt.subplots(2, 1)
    draw_profiles(ax, axg, [("stalls", prof), ("again", prof)], "t")
    for line in ax.lines[1:]:  # [0] is the limit
        x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
        drawn = x[np.isfinite(y)]
        assert drawn.max() <= 13.0 + 1e-9 and np.nanmin(y[x > 12.0]) >= 0
    plt.close(fig)
    title = run_title("Freight", "HXD1", "sequence", {"feasible": False, "running_time_s": None,
                                                      "traction_energy_kwh": 584.5, "reason": "stalled at 13,000 m"})
    assert "nan" not in title and "stalled at 13,000 m" in title
    out = tmp_path / "p.png"
    plot_profiles(out, [("stalls", prof)], title, histories=[("issa", np.array([0.3, 0.2])),
                                                             ("energy-saving", np.array([600.0, 580.0]), ENERGY)])
    assert out.stat().st_size > 1000 and FITNESS != ENERGY


def test_fit_leaves_out_columns_rather_than_split_a_number():
    """A table wider than the terminal even after its listed columns are left out (ocp-study's at 80
    columns): more whole columns go, the last first, and every number stays on one line."""
    from rich.table import Table

    from locoplan.reporting.tables import fit

    t = Table(title="wide")
    numbers = [f"{-13.123456 * (k + 1):.6f}" for k in range(12)]
    for k in range(12):
        t.add_column(f"column {k}", justify="right")
    t.add_row(*numbers)
    text = _render(fit(t, 80, drop=(11,)), 80)
    assert max(len(x) for x in text.splitlines()) <= 80
    shown = [n for n in numbers if n in text]
    assert shown and numbers[0] in text
    assert "left out at 80 columns" in text
    for n in numbers:  # a number is whole or absent, never split over lines
        assert n in text or n[:4] not in text.replace(n, "")


@pytest.mark.parametrize("label,field,text", [
    ("compare runs", None, ""), ("sweep runs", None, ""), ("study runs", None, ""),
    ("batch runs", "{task.fields[now]}", "12,345 stored, 0 failed"),
    ("bound solves", "{task.fields[now]}", "E* at 1500 s, second method"),
    ("ocp-study solves", "{task.fields[now]}", "table 3: two-stage hp 17, and a step text far longer than the line"),
    ("issa iterations", "best {task.fields[now]}", "0.12345")])
def test_every_progress_bar_reads_at_80_columns(monkeypatch, label, field, text):
    """Label, count, bar and ETA keep their room at 80 columns whatever the command's own field says;
    a field too long for the line is cut with "…", never the count or the ETA."""
    import locoplan.cli_common as cc

    buf = StringIO()
    monkeypatch.setattr(cc, "err", Console(file=buf, width=80, force_terminal=True, color_system=None))
    extra = (cc.field_column(field),) if field else ()
    bar = cc.progress_bar(*extra, bar_width=cc.BAR_WIDTH // 2 if "solves" in label else cc.BAR_WIDTH)
    task = bar.add_task(label, total=12000, now=text)
    bar.update(task, completed=3700)
    cc.err.print(bar.get_renderable())
    line, = [x for x in buf.getvalue().splitlines() if x.strip()]
    assert len(line) <= 80, line
    assert re.match(rf"{label} +3700/12000 ━+ +ETA [-:0-9]+", line), line
    if len(text) > 40:
        assert line.endswith("…") and text[:20] in line
    elif text:
        assert line.endswith(text)


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
@pytest.mark.slow
def test_bound_times_progress_at_80_columns(root):
    """bound --times on an 80-column terminal: "bound solves", the count, the bar, the ETA and the time
    being solved; nothing of it with --json."""
    args = ["bound", "routes/freight-20km.yaml", "--times", "1500,1600"]
    code, text = _in_pty(args, root, timeout=300)
    frames = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", "\n").splitlines()
    assert code == 0, text
    bars = [f for f in frames if "bound solves" in f]
    assert any(re.search(r"bound solves +[01]/2 ━.* ETA .*E\* at 1[56]00 s", f) for f in bars), bars
    assert max(len(f.rstrip()) for f in frames) <= 80
    code, text = _in_pty(args + ["--json"], root, timeout=300)
    assert code == 0 and "bound solves" not in text
    assert json.loads(re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", ""))["results"][1]["time_s"] == 1600


@pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")
@pytest.mark.slow
def test_batch_progress_at_80_columns_and_never_with_json(root, tmp_path):
    study = tmp_path / "s.yaml"
    study.write_text(f"schema: locoplan/study@1\nroutes: [{root / 'routes/freight-20km.yaml'}]\ntimes: [1500]\n"
                     "algorithms: [issa]\nseeds: [1, 2]\n")
    code, text = _in_pty(["batch", str(study), "--store", str(tmp_path / "a.db"), "--workers", "1"], root, timeout=300)
    frames = re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", "\n").splitlines()
    assert code == 0, text
    assert any(re.search(r"batch runs +2/2 ━+ +ETA [-:0-9]+ 0 stored, 0 failed", f) for f in frames), frames
    assert max(len(f.rstrip()) for f in frames) <= 80
    code, text = _in_pty(["batch", str(study), "--store", str(tmp_path / "b.db"), "--workers", "1", "--json"], root,
                         timeout=300)
    assert code == 0 and "batch runs" not in text and "ETA" not in text
    assert json.loads(re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text).replace("\r", ""))["verdict"]
