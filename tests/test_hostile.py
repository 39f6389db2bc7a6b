"""Issue 10: the generated hostile corpus (``tests/hostile.py``) gives no traceback, no hang, no memory
blow-up and no wrong success, and every message names the file (or ``<command line>``) and the field.

The corpus runs in a few capped subprocesses that import locoplan once and run many cases each (fast);
the cases whose point is the process itself (umask, FIFOs, /dev/zero, an alias bomb, all-or-none
outputs) also run alone as ``python -m locoplan``. ``benchmarks/hostile_corpus.py`` runs every case
alone and prints the counts with each case's own peak memory.
"""

from concurrent.futures import ThreadPoolExecutor

import pytest

import hostile

ALONE = ("alias_bomb.yaml", "fifo_as_file", "dev_zero", "fifo_route_simulate", "stock_dir_with_fifo", "big.yaml",
         "nested_lists.yaml", "int_5000_digits.yaml", "billion_wagons.yaml", "pop_1e8.yaml", "sweep_weights_limit",
         "runs_1000000000", "out_ok_plot_unwritable", "out_is_folder", "umask_022_new_file", "umask_022_overwrite_0644",
         "umask_077_new_file")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hostile")
    cases = hostile.build(tmp)
    hostile.warm_up(tmp)  # the session's compiled kernels are built once, before any case is timed
    return tmp, cases


def _report(outcomes) -> str:
    bad = [o for o in outcomes if o.problems]
    return "\n".join(f"{o.case.name} [{o.case.cls}] exit {o.returncode}: {'; '.join(o.problems)}\n    "
                     + o.stderr.strip()[-400:].replace("\n", "\n    ") for o in bad)


@pytest.mark.slow
def test_corpus_covers_every_class(corpus):
    _, cases = corpus
    assert len(cases) >= 100
    assert len({c.name for c in cases}) == len(cases)
    by_class = {}
    for c in cases:
        by_class.setdefault(c.cls, []).append(c)
    assert set(by_class) == {"yaml", "file", "number", "physics", "params", "option", "output", "message", "store", "study", "json",
                             "inout", "cache", "env"}
    assert all(len(v) >= 5 for v in by_class.values()), {k: len(v) for k, v in by_class.items()}
    # valid-but-infeasible requests exit 1 with the physical reason; a few valid controls exit 0
    assert sum(c.exit == 1 for c in cases) >= 4 and sum(c.exit == 0 for c in cases) >= 5
    # every failure names the texts its message must hold (but where stderr is a full device: no message gets out)
    assert all(c.expect or c.expect_out or c.exit == 0 or c.stderr_file for c in cases)


def test_every_numeric_option_of_every_command_has_a_bound():
    """A numeric option added to a command without an entry in bounds.OPTIONS fails here."""
    from locoplan import bounds

    missing = [f"{' '.join(words)} {flag}" for words, cmd in hostile.commands() for flag, _ in hostile.numeric_options(cmd)
               if flag not in bounds.OPTIONS and f"{' '.join(words)} {flag}" not in bounds.OPTIONS]
    assert not missing, missing


def test_every_text_option_holding_numbers_has_a_parser():
    """A text option that holds numbers (its metavar is not a name, a file or a plan) without a parser in
    bounds.TEXT_NUMBERS fails here: its numbers would reach the command unchecked."""
    from locoplan import bounds

    missing = [f"{' '.join(words)} {flag}" for words, cmd in hostile.commands() for flag in hostile.text_number_options(cmd)
               if flag not in bounds.TEXT_NUMBERS and f"{' '.join(words)} {flag}" not in bounds.TEXT_NUMBERS]
    assert not missing, missing
    found = {flag for _, cmd in hostile.commands() for flag in hostile.text_number_options(cmd)}
    assert {"--time", "--times", "--weights", "--factors", "--seeds", "--masses", "--efficiency"} <= found


@pytest.mark.slow
def test_corpus_no_traceback_hang_or_wrong_success(corpus):
    tmp, cases = corpus
    batched = [c for c in cases if not c.alone_only]
    chunks = [batched[i::6] for i in range(6)]
    with ThreadPoolExecutor(2) as pool:
        outcomes = [o for part in pool.map(lambda ch: hostile.run_batch(ch, tmp), chunks) for o in part]
    assert len(outcomes) == len(batched)
    assert not any(o.problems for o in outcomes), _report(outcomes)
    assert max(o.peak_rss_bytes for o in outcomes) < hostile.MEMORY_CAP_BYTES


@pytest.mark.slow
def test_process_level_cases_alone(corpus):
    """The cases about the process itself, each as its own ``python -m locoplan`` under the caps."""
    tmp, cases = corpus
    alone = [c for c in cases if (c.name in ALONE or c.alone_only) and not c.slow]  # slow ones: the benchmark's
    assert len([c for c in alone if c.name in ALONE]) == len(ALONE)
    with ThreadPoolExecutor(2) as pool:
        outcomes = list(pool.map(lambda c: hostile.run_case(c, tmp), alone))
    assert not any(o.problems for o in outcomes), _report(outcomes)
    assert all(o.peak_rss_bytes < hostile.MEMORY_CAP_BYTES for o in outcomes)


@pytest.mark.slow
def test_workers_end_with_their_parent(tmp_path):
    """kill -9 of a batch parent: its worker processes end too (they would live on, reparented)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    route = tmp_path / "r.yaml"
    route.write_text(hostile.route())
    study = tmp_path / "s.yaml"
    study.write_text(f"schema: locoplan/study@1\nroutes: [{route}]\nconsists: [{hostile.SMALL}]\n"
                     "times: [200, 205, 210, 215, 220, 225]\nstrategies: [proposed]\nseeds: [1, 2, 3]\n")
    env = dict(os.environ, PYTHONPATH=str(hostile.ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "locoplan", "batch", str(study), "--store", str(tmp_path / "s.sqlite"),
                             "--workers", "2", "--quiet"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def children() -> list[int]:
        out = subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout
        return [int(x) for x in out.split()]

    deadline = time.monotonic() + 60
    kids: list[int] = []
    while time.monotonic() < deadline and proc.poll() is None:
        kids = children()
        if len(kids) >= 2:  # the resource tracker and at least one worker
            break
        time.sleep(0.2)
    assert proc.poll() is None and len(kids) >= 2, "the batch ended before it started its workers"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 10
    alive = kids
    while alive and time.monotonic() < deadline:
        time.sleep(0.2)
        alive = [k for k in alive if _running(k)]
    assert not alive, f"workers alive after their parent was killed: {alive}"


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended
    except OSError:
        return False


def test_drivers_killed_leave_a_named_folder_that_the_next_run_removes(tmp_path):
    """kill -9 of ``drivers simulate`` while it writes: what is left is ``NAME.incomplete-PID`` beside NAME (not a
    hidden folder), saying what it is; the next run into NAME removes it, says so, and writes NAME whole."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from typer.testing import CliRunner

    from locoplan.cli import app

    route = tmp_path / "r.yaml"
    route.write_text(hostile.route())
    out = tmp_path / "logs"
    env = dict(os.environ, PYTHONPATH=str(hostile.ROOT))
    proc = subprocess.Popen([sys.executable, "-m", "locoplan", "drivers", "simulate", str(route), "--out", str(out),
                             "--drivers", "40", "--runs", "20"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    partial = tmp_path / f"logs.incomplete-{proc.pid}"
    deadline = time.monotonic() + 60
    while not (partial / "route.yaml").is_file() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, "drivers simulate ended before it was killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs.incomplete-" + str(proc.pid), "r.yaml"]
    assert "is being written by 'locoplan drivers simulate" in (partial / "INCOMPLETE.txt").read_text()
    res = CliRunner().invoke(app, ["drivers", "simulate", str(route), "--out", str(out), "--drivers", "2", "--runs", "1"])
    assert res.exit_code == 0, res.output
    assert f"note: removed {partial}" in res.stderr.replace("\n", "")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs", "r.yaml"]
    assert (out / "manifest.yaml").is_file() and not (out / "INCOMPLETE.txt").exists()


def test_an_error_without_a_file_name_is_not_blamed_on_stdout():
    """An OSError that names no file (a library's write under a file-size limit) is said as such; only stdout's
    own errors (named <stdout> while a command runs) are stdout's."""
    from locoplan.cli_common import _os_problem, _Stdout

    said = str(_os_problem(OSError(27, "File too large")))
    assert "<unnamed file>" in said and "File too large" in said and "<stdout>" not in said

    class Full:
        def write(self, text):
            raise OSError(28, "No space left on device")

    try:
        _Stdout(Full()).write("x")
    except OSError as exc:
        assert exc.filename == "<stdout>" and exc.errno == 28
    else:
        raise AssertionError("the write did not fail")


def test_outputs_move_into_place_together_or_not_at_all(tmp_path, monkeypatch):
    """When a later output cannot be moved into place (a full disk, a folder made read-only), the outputs moved before
    it are undone: the file an output replaced is back byte for byte, a new one is gone, no temporary file is left."""
    import os

    from locoplan.errors import InputError
    from locoplan.reporting import files

    kept, new, last = tmp_path / "kept.json", tmp_path / "new.csv", tmp_path / "last.png"
    kept.write_bytes(b"the user's old file\n")
    real = os.replace

    def replace(src, dst):
        if os.fspath(dst) == os.fspath(last):
            raise OSError(28, "No space left on device")
        return real(src, dst)
    monkeypatch.setattr(files.os, "replace", replace)
    with pytest.raises(InputError, match="no output of this command was written"):
        with files.all_or_none():
            files.atomic_write_text(kept, "new content\n")
            files.atomic_write_text(new, "a,b\n")
            files.atomic_write_text(last, "png")
    assert kept.read_bytes() == b"the user's old file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.json"]


def test_an_output_that_is_an_input_is_refused_when_moved_into_place(tmp_path):
    """A file the command read (recorded by io.load) is never written over, whatever path names the output."""
    from locoplan.errors import InputError
    from locoplan.io.load import read_text, recording_reads
    from locoplan.reporting import files

    source = tmp_path / "line.yaml"
    source.write_text("name: x\n")
    (tmp_path / "link").symlink_to(tmp_path)
    with recording_reads():
        read_text(source)
        with pytest.raises(InputError, match="is an input this command read"):
            with files.all_or_none():
                files.atomic_write_text(tmp_path / "link" / "line.yaml", "overwritten\n")
    assert source.read_text() == "name: x\n" and sorted(p.name for p in tmp_path.iterdir()) == ["line.yaml", "link"]
