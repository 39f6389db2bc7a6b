"""The result store after it is opened: damaged records named and run again, a store that cannot be
written, commits in the file itself after a kill (WAL checkpointed), one writer at a time. The corpus
(tests/hostile.py, class ``store``) covers the command-line side: devices, folders, a full disk, a dropped
table, a garbled file."""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import hostile
from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.runs.spec import RunRecord
from locoplan.runs.store import Store

ROOT = Path(__file__).resolve().parents[1]
cli = CliRunner()


def _record(key: str, store: Store) -> RunRecord:
    return RunRecord(key, {"route": "r", "consist": "c", "strategy": "time-saving", "algorithm": None, "feasible": True,
                           "running_time_s": 99.0, "traction_energy_kwh": 15.0, "planned_time_s": 200.0},
                     {"route": "r.yaml", "consist": "c"}, None, 0.1, {"locoplan": store.meta["locoplan"]}, "host:1")


@pytest.fixture()
def study(tmp_path):
    route = tmp_path / "r.yaml"
    route.write_text(hostile.route())
    path = tmp_path / "s.yaml"
    path.write_text(f"schema: locoplan/study@1\nroutes: [{route}]\nconsists: [{hostile.SMALL}]\ntimes: [200, 210]\n"
                    "strategies: [time-saving, four-stage]\n")
    return path


def test_damaged_records_are_named_and_batch_runs_them_again(study, tmp_path):
    store = tmp_path / "runs.sqlite"
    res = cli.invoke(app, ["batch", str(study), "--store", str(store), "--workers", "1", "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    with sqlite3.connect(store) as conn:
        keys = [k for (k,) in conn.execute("SELECT key FROM runs ORDER BY rowid")]
        conn.execute("UPDATE runs SET record = '{bad' WHERE key = ?", (keys[0],))
        conn.execute("UPDATE runs SET record = '{}' WHERE key = ?", (keys[1],))
    res = cli.invoke(app, ["results", str(store), "--json"])
    assert res.exit_code == 1, res.output  # the result lacks the damaged runs: said, never a silent success
    assert "the store is damaged (2 damaged records" in res.stderr
    assert keys[0] in res.stderr and "not valid JSON" in res.stderr and keys[1] in res.stderr and "lacks" in res.stderr
    assert '"runs": 2' in res.stdout  # the two readable ones
    res = cli.invoke(app, ["batch", str(study), "--store", str(store), "--workers", "1", "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    assert "written over" in res.stderr and keys[0] in res.stderr
    with Store(store, create=False) as s:
        assert len(s.records()) == 4 and not s.damaged


def test_a_store_that_cannot_be_written_says_so_and_keeps_its_runs(tmp_path):
    path = tmp_path / "ro.sqlite"
    with Store(path) as s:
        s.put(_record("k1", s))
    s = Store(path)
    s.conn.execute("PRAGMA query_only = 1")  # writes fail as on a read-only file (root ignores chmod)
    with pytest.raises(InputError) as err:
        s.put(_record("k2", s))
    s.close()
    text = str(err.value)
    assert str(path) in text and "read-only" in text and "runs committed so far are kept" in text
    with Store(path, create=False) as s:
        assert [r.key for r in s.records()] == ["k1"]


def test_commits_are_in_the_store_file_itself_after_a_kill(tmp_path):
    """Killed with no clean-up (os._exit), the .sqlite file alone (copied without its -wal) holds every run."""
    path = tmp_path / "runs.sqlite"
    code = (f"import os, sys; sys.path.insert(0, {str(ROOT)!r}); sys.path.insert(0, {str(ROOT / 'tests')!r})\n"
            "from test_store_errors import _record\nfrom locoplan.runs.store import Store\n"
            f"s = Store({str(path)!r})\nfor i in range(8):\n    s.put(_record(f'k{{i}}', s))\nos._exit(0)\n")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)
    alone = tmp_path / "copy.sqlite"
    shutil.copyfile(path, alone)
    with sqlite3.connect(alone) as conn:
        assert conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0] == 8


def test_a_second_writer_is_refused_and_the_lock_dies_with_its_holder(tmp_path):
    path = tmp_path / "runs.sqlite"
    first = Store(path)
    first.check_writer()
    second = Store(path)
    with pytest.raises(InputError, match="another locoplan batch"):
        second.check_writer()
    first.close()
    second.check_writer()  # free once the first has gone
    second.close()
    os.unlink(path)


@pytest.mark.slow
def test_store_cases_of_the_corpus(tmp_path):
    """The corpus's result-store cases (tests/hostile.py, class ``store``) alone: each exits as it says, with
    the words it names, no traceback (the full corpus runs them with every other class)."""
    files = tmp_path / "files"
    files.mkdir()

    def write(name, content):
        p = files / name
        p.write_text(content) if isinstance(content, str) else p.write_bytes(content)
        return str(p)

    cases: list = []
    hostile._store_cases(cases, write, write("good_route.yaml", hostile.route()), tmp_path)
    assert len({c.name for c in cases}) == len(cases)
    assert {"results_typed_records", "results_typed_records_json", "results_typed_records_format_json", "batch_wal_is_folder", "results_shm_is_folder",
            "batch_disk_full", "batch_new_store_disk_full", "results_disk_full_runs_in_wal", "results_malformed_one_page", "batch_malformed_one_page", "batch_second_writer", "results_malformed", "batch_dropped_runs"} <= {c.name for c in cases}
    hostile.warm_up(tmp_path)  # kernels and caches built first: a case under a file-size limit cannot write them
    together = [c for c in cases if not c.alone_only]
    outcomes = hostile.run_batch(together, tmp_path) + [hostile.run_case(c, tmp_path) for c in cases if c.alone_only]
    bad = [f"{o.case.name}: exit {o.returncode}: {'; '.join(o.problems)}\n{o.stderr[-400:]}" for o in outcomes if o.problems]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("how", ["removed", "replaced"])
def test_a_store_removed_or_replaced_while_a_batch_writes_is_refused(tmp_path, how):
    """SQLite would go on writing into the removed file: every run since would be lost without a word."""
    path = tmp_path / "runs.sqlite"
    s = Store(path)
    s.put(_record("k1", s))
    for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
        p.unlink(missing_ok=True)
    if how == "replaced":
        with Store(path) as other:
            other.put(_record("k0", other))
    with pytest.raises(InputError) as err:
        s.put(_record("k2", s))
    s.close()
    text = str(err.value)
    assert str(path) in text and "was removed or replaced" in text and "run the same command again" in text
    if how == "replaced":
        with Store(path, create=False) as again:
            assert [r.key for r in again.records()] == ["k0"]  # the file now there is whole
