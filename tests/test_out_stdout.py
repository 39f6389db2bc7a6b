"""``--out -``: a command's output file on stdout (CSV where the command writes CSV; the tables go to stderr),
the same bytes the file would hold; refused with ``--json``, which writes its object on stdout too."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from locoplan.cli import app

ROOT = Path(__file__).resolve().parents[1]
ROUTE = str(ROOT / "routes/freight-20km.yaml")
runner = CliRunner()


def _rows(text: str) -> list[dict]:
    return list(csv.DictReader(io.StringIO(text)))


def test_a_profile_on_stdout_is_the_file_it_would_write(tmp_path):
    args = ["simulate", ROUTE, "--strategy", "time-saving"]
    to_file = runner.invoke(app, [*args, "--out", str(tmp_path / "plan.csv")])
    assert to_file.exit_code == 0, to_file.output
    written = (tmp_path / "plan.csv").read_text(encoding="utf-8")
    res = runner.invoke(app, [*args, "--out", "-"])
    assert res.exit_code == 0, res.output
    assert res.stdout == written  # stdout holds the CSV alone, as the file has it: the table went to stderr
    rows = _rows(res.stdout)
    assert len(rows) > 100 and rows[0]["s_m"] == "0.0" and float(rows[-1]["s_m"]) == pytest.approx(20000)
    assert "time-saving" in res.stderr  # the summary table, on stderr
    assert [p.name for p in tmp_path.iterdir()] == ["plan.csv"]  # --out - made no file


def test_several_runs_on_stdout_one_row_each(tmp_path):
    args = ["compare", ROUTE, "--strategies", "time-saving,energy-saving", "--no-gap"]
    res = runner.invoke(app, [*args, "--out", "-"])
    assert res.exit_code == 0, res.output
    rows = _rows(res.stdout)
    assert [r["strategy"] for r in rows] == ["time-saving", "energy-saving"]
    to_file = runner.invoke(app, [*args, "--out", str(tmp_path / "runs.csv")])
    assert to_file.exit_code == 0, to_file.output
    in_file = _rows((tmp_path / "runs.csv").read_text(encoding="utf-8"))
    timed = {"solve_time_s"}  # how long each run took: the one column two runs need not share
    assert [{k: v for k, v in r.items() if k not in timed} for r in rows] == \
        [{k: v for k, v in r.items() if k not in timed} for r in in_file]
    assert list(rows[0]) == list(in_file[0])


def test_out_dash_with_json_is_refused_naming_both_options():
    res = runner.invoke(app, ["simulate", ROUTE, "--strategy", "time-saving", "--out", "-"])
    assert res.exit_code == 0
    res = runner.invoke(app, ["simulate", ROUTE, "--strategy", "time-saving", "--out", "-", "--json"])
    assert res.exit_code == 2
    doc = json.loads(res.stdout)  # stdout holds --json's object (the refusal), no CSV
    assert doc["exit_code"] == 2 and "--out" in doc["reason"] and "--json" in doc["reason"]
    assert "--out" in res.stderr and "--json" in res.stderr
