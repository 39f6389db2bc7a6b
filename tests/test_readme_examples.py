"""Every `$ locoplan ...` example of README.md and docs/*.md runs, and prints what the page shows.

The convention the pages follow (write new examples this way):

- An example is a fenced block (```` ```console ````, ```` ```text ```` or a bare ```` ``` ````) holding
  lines that start with ``$ locoplan``. Each ``$`` line is a command, run by ``bash`` from a copy of the
  repository root (``routes/``, ``configs/``, ``tests/`` and ``docs/`` as in the checkout) with
  ``COLUMNS=80`` and its output piped (what a script or ``| less`` sees); a ``COLUMNS=N`` before
  ``locoplan`` says the page shows a wider terminal. The commands of one block run in order, so a
  later one may read what an earlier one wrote. ```` ```bash ```` blocks are scripts, not examples.
- The lines after a command, up to the next ``$`` line, are what it prints (stdout and stderr, as a
  terminal shows them). Each shown line must be a line the command printed, in the printed order; the
  page may leave lines out, and a line ``...`` says so. Every number counts: a shown table row that no
  longer matches fails the test.
- Wall-clock times differ from run to run and are masked, in shown and printed text alike, by
  ``mask_timings``: the number of "solved in 1.30 s", of "on 2
  process workers in 6.6 s (2.43 runs/s)", of "1.63/s, ETA 1 s", of a "solve time" row and of a table
  column headed "solve". A running time ("371.73 kWh in 726.5 s") is not a wall-clock time and is
  never masked.
- The exit code is 0 unless the block shows another right after the command with ``$ echo $?`` and the
  code on the next line (an example meant to fail says so).
- A command ending in the comment ``# slow`` (more than ~10 s on a fresh checkout) makes its block
  slow: it runs with ``python -m pytest --run-slow`` (marker ``slow``), not in the default run. Any
  other trailing ``# comment`` is ignored by the shell.
- Every output: no ``…`` (nothing cut), and no line wider than the terminal unless it carries one
  whole unbreakable token, a plan string or a path. ``--json`` output must parse as JSON.
- ``$ mkdir -p /tmp/...`` lines are run; other lines that are not ``$ locoplan`` commands (``$ cat``,
  ``$ python``) are shown for the reader and not run, their output not compared.
- Paths under ``/tmp/`` are real and printed as shown (the same length, so wrapped as shown). Each
  file or folder a block names right under ``/tmp/`` must be called ``locoplan-...`` (the test deletes
  it); the block holds it alone while it runs (a lock, ``/tmp/.locoplan-example-NAME.lock``, also
  against other test sessions on the machine) and finds it cleared when it starts, so a block never
  reads what another block wrote: commands that share a store or a folder are one block. An absolute
  path into the checkout is printed as ``.../`` (it differs from machine to machine). Commands that read
  ``../shared/data/external`` (the public TTOBench and railtoolkit sources, beside the checkout) are
  skipped where it is not there.

Each command has a hang guard of 900 s. Each block has a fresh cache of optima (``LOCOPLAN_CACHE_DIR``),
so a command prints what it prints on a new machine; a later command of the block finds what an
earlier one cached, as a user's does in ``~/.cache/locoplan``.
"""

from __future__ import annotations

import fcntl
import json
import os
import pickle
import re
import shlex
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
WIDTH = 80
PLAN = re.compile(r"^[TKCB](:[-0-9.e+]+)?(,[TKCB](:[-0-9.e+]+)?)+$")
EXAMPLE_FENCES = {"", "console", "text"}
TIME = "<time>"

# ------------------------------------------------------------------------------------------ timings
_NUM = r"\d[\d,]*(?:\.\d+)?"
_PHRASES = [
    # (pattern, replacement): each pattern's one or two numbers are wall-clock times or rates; the spaces
    # around them may be line breaks (a wrapped line), kept as they are
    (re.compile(rf"(solved\s+in\s+){_NUM}(\s+s\b)"), rf"\g<1>{TIME}\g<2>"),
    (re.compile(rf"(workers?\s+in\s+){_NUM}(\s+s\b)"), rf"\g<1>{TIME}\g<2>"),
    (re.compile(rf"\({_NUM}(\s+runs/s\))"), rf"({TIME}\g<1>"),
    (re.compile(rf"(done,\s+){_NUM}(/s,\s+ETA\s+){_NUM}(\s+s\b)"), rf"\g<1>{TIME}\g<2>{TIME}\g<3>"),
]
_SOLVE_ROW = re.compile(r"^([│|]?\s*solve time\s*[│|]\s*)(.*)$")
_SOLVE_HEAD = re.compile(r"\bsolve(?: time)?(?: \[s\])?(?=\s|$|[┃│|])")
_CELL_NUM = re.compile(r"\s*\d+(?:\.\d+)?")


def _mask_columns(lines: list[str]) -> list[str]:
    """The number in a table column headed "solve" (a solve time [s]): the cell that ends under the
    header's span. Applies from the header line to the table's end (a blank line or a box's bottom)."""
    out: list[str] = []
    spans: list[tuple[int, int]] = []
    for line in lines:
        heads = [(m.start(), m.end()) for m in _SOLVE_HEAD.finditer(line)]
        if heads:
            spans = heads
            out.append(line)
            continue
        if not line.strip() or line.lstrip().startswith("└"):
            spans = []
        for a, b in reversed(spans):
            for m in _CELL_NUM.finditer(line):
                if a - 2 < m.end() <= b + 2:  # right- or left-aligned under the header
                    line = line[:m.start()] + " " + TIME + line[m.end():]
                    break
        out.append(line)
    return out


def mask_timings(text: str) -> str:
    """``text`` with each wall-clock time replaced by ``<time>`` (see the module docstring); every
    other character, every other number included, as it was."""
    for pattern, repl in _PHRASES:
        text = pattern.sub(repl, text)
    lines = []
    for line in text.splitlines():
        m = _SOLVE_ROW.match(line)
        if m:
            line = m.group(1) + re.sub(rf"{_NUM}(\s+s\b)", rf"{TIME}\g<1>", m.group(2))
        lines.append(line)
    return "\n".join(_mask_columns(lines))


# ------------------------------------------------------------------------------------------ parsing
@dataclass
class Example:
    page: str
    line: int
    command: str
    output: list[str] = field(default_factory=list)
    exit_code: int = 0
    slow: bool = False
    block: int = 0
    mkdirs: list[str] = field(default_factory=list)


def examples(text: str, page: str = "README.md") -> list[Example]:
    """The page's `$ locoplan` commands with their shown output and expected exit codes."""
    found: list[Example] = []
    lines = text.splitlines()
    i, block = 0, 0
    while i < len(lines):
        m = re.match(r"^(`{3,})\s*([\w-]*)(.*)$", lines[i].strip())
        if not m:
            i += 1
            continue
        fence, lang = m.group(1), m.group(2)
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        body = lines[i + 1:j]
        if lang in EXAMPLE_FENCES and any(_is_locoplan(b[2:]) for b in body if b.startswith("$ ")):
            block += 1
            current: Example | None = None
            expect_code_for: Example | None = None
            mine: list[Example] = []
            mkdirs: list[str] = []
            for k, line in enumerate(body):
                if line.startswith("$ "):
                    cmd = line[2:].strip()
                    expect_code_for = None
                    made = re.match(r"^mkdir -p ((/tmp/[\w./-]+\s*)+)$", cmd)
                    if made:
                        mkdirs += [d[len("/tmp/"):] for d in made.group(1).split()]
                        current = None
                    elif cmd == "echo $?":
                        expect_code_for, current = (mine[-1] if mine else None), None
                    elif _is_locoplan(cmd):
                        current = Example(page, i + 2 + k, cmd, slow=bool(re.search(r"#\s*slow\b", cmd)), block=block,
                                          mkdirs=mkdirs)
                        mkdirs = []
                        mine.append(current)
                    else:
                        current = None
                elif expect_code_for is not None and line.strip().lstrip("-").isdigit():
                    expect_code_for.exit_code = int(line.strip())
                    expect_code_for = None
                elif current is not None:
                    current.output.append(line)
            if any(e.slow for e in mine):  # later commands of a block may read what a slow one wrote
                for e in mine:
                    e.slow = True
            found += mine
        i = j + 1
    return found


def _is_locoplan(cmd: str) -> bool:
    return bool(re.match(r"^(COLUMNS=\d+\s+)?locoplan\s", cmd))


def _width(cmd: str) -> int:
    m = re.match(r"^COLUMNS=(\d+)\s", cmd)
    return int(m.group(1)) if m else WIDTH


def _whole_token(line: str) -> bool:
    """A long line is allowed when it carries one unbreakable token (plan or path) and little else."""
    tokens = line.split()
    if not tokens:
        return False
    token = max(tokens, key=len)
    bare = token.strip("\"',;()[]")
    unbreakable = bool(PLAN.match(bare)) or "/" in bare or bare.endswith((".yaml", ".json", ".csv", ".png", ".svg"))
    return unbreakable and len(line) - len(token) <= 40


def _shown(lines: list[str]) -> list[str]:
    """The shown lines to find in the output: masked, trailing spaces dropped; ``...`` and blanks skipped."""
    return [s for s in mask_timings("\n".join(lines)).splitlines() if s.strip() and s.strip() != "..."]


def missing_lines(shown: list[str], stdout: str, stderr: str) -> list[str]:
    """The shown lines that are not printed lines, in order (each stream's order kept; a terminal
    interleaves the two)."""
    streams = [[s.rstrip() for s in mask_timings(t).splitlines()] for t in (stdout, stderr)]
    at = [0, 0]
    missing = []
    for want in _shown(shown):
        want = want.rstrip()
        for k, lines in enumerate(streams):
            try:
                at[k] = lines.index(want, at[k]) + 1
                break
            except ValueError:
                continue
        else:
            missing.append(want)
    return missing


EXAMPLES = [e for page in PAGES for e in examples(page.read_text(encoding="utf-8"), page.relative_to(ROOT).as_posix())]


# ------------------------------------------------------------------------------------------ the parser's own tests
def test_the_pages_have_examples():
    pages = {e.page for e in EXAMPLES}
    assert {"README.md", "docs/batch.md", "docs/ocp-energy.md", "docs/journeys.md", "docs/learn.md"} <= pages, pages
    assert any(e.command.startswith("locoplan optimize") for e in EXAMPLES)


def test_parser_reads_the_convention():
    text = ("```console\n$ locoplan simulate r.yaml --sequence \"T:0,C:500,B\"   # note\nplan  T:0,C:500,B\n"
            "energy 12.5 kWh\n$ echo $?\n1\n$ locoplan compare r.yaml # slow\n```\n```\n$ locoplan validate a.yaml\nok\n```\n"
            "```bash\n$ locoplan not-an-example\n```\n```text\n$ COLUMNS=200 locoplan results s.sqlite\nwide\n```\n")
    a, b, c, d = examples(text)
    assert a.exit_code == 1 and a.slow and a.output == ["plan  T:0,C:500,B", "energy 12.5 kWh"]
    assert b.slow and c.exit_code == 0 and not c.slow and c.output == ["ok"] and c.block != a.block
    assert a.line == 2 and c.line == 10
    assert _width(d.command) == 200 and d.output == ["wide"]
    assert _whole_token("plan  T:0,K:930,C:3256.2,T:4746,C:6238,T:11673.8,C:12947.7,K:14100.5,C:15300.5,T:16000,B")
    assert not _whole_token("x " * 50)


@pytest.mark.parametrize("line", [
    "│ proposed          │ 371.73 kWh in 726.5 s (inside 719.8 +- 2.4 s); +0.28 %   │",
    "E* = 675.83 kWh  (Freight test line, 20 km, HXD1 + 50 x C80 (5200 t), 1500 s;",
    "16 runs: 0 from the store, 16 run now in 2 steps",
    "│   1470 │   1470.1 │    686.12 │       0.1 │  0.0076 │    +0.03 │         0.0 │",
])
def test_masking_leaves_every_other_number(line):
    assert mask_timings(line) == line


def test_masking_hides_only_the_time():
    assert mask_timings("1,184 cells, solved in 0.28 s; within 0.00075 %)") == "1,184 cells, solved in <time> s; within 0.00075 %)"
    assert mask_timings("16 run now on 2 process workers in 6.6 s (2.43\nruns/s); 0 fail") == \
        "16 run now on 2 process workers in <time> s (<time>\nruns/s); 0 fail"  # wrapped, as rich wraps it
    assert mask_timings("16 run now on 2 process workers in 6.6 s (2.43 runs/s); 0 fail") == \
        "16 run now on 2 process workers in <time> s (<time> runs/s); 0 fail"
    assert mask_timings("e_min: 1/2 done, 1.63/s, ETA 1 s") == "e_min: 1/2 done, <time>/s, ETA <time> s"
    assert mask_timings("│ solve time      │ 0.734 s                │") == "│ solve time      │ <time> s                │"
    table = ["  method   objective   solve    ok", "  CVP        142.044   0.734   yes", "  GPM        141.567   0.488    no"]
    masked = mask_timings("\n".join(table)).splitlines()
    assert masked[1].split() == ["CVP", "142.044", TIME, "yes"] and masked[2].split() == ["GPM", "141.567", TIME, "no"]
    box = ["┃ T [s] ┃ E* [kWh] ┃ solve [s] ┃", "│  1500 │   675.83 │      0.28 │", "│  1600 │   650.10 │     12.50 │"]
    masked = mask_timings("\n".join(box)).splitlines()
    assert masked[1].split() == ["│", "1500", "│", "675.83", "│", TIME, "│"] and "650.10" in masked[2] and "12.50" not in masked[2]


def test_a_drifted_number_is_caught():
    """The comparison fails on one changed digit anywhere on a shown line, and passes on the same text."""
    printed = "E* = 675.83 kWh (1,184 cells, solved in 0.28 s)\nits run: traction 675.83 kWh\n"
    assert missing_lines(["E* = 675.83 kWh (1,184 cells, solved in 9.99 s)", "its run: traction 675.83 kWh"], printed, "") == []
    assert missing_lines(["E* = 675.84 kWh (1,184 cells, solved in 0.28 s)"], printed, "") != []
    assert missing_lines(["its run: traction 675.83 kWh", "E* = 675.83 kWh (1,184 cells, solved in 0.28 s)"], printed, "") != []
    assert missing_lines(["│ proposed │ 371.73 kWh in 726.5 s │"], "│ proposed │ 371.33 kWh in 726.5 s │", "") != []


def test_tmp_names_are_the_tests_own():
    """The test deletes what a block names under /tmp/: only locoplan-... names, never a user's file."""
    blocks: dict[tuple[str, int], list[Example]] = {}
    for e in EXAMPLES:
        blocks.setdefault((e.page, e.block), []).append(e)
    bad = {f"{page}: /tmp/{name}" for (page, _), block in blocks.items() for name in tmp_names(block)
           if not name.startswith("locoplan-")}
    assert not bad, sorted(bad)
    assert tmp_names(examples("```\n$ mkdir -p /tmp/locoplan-a/b\n$ locoplan x --out /tmp/locoplan-c.db\n```\n")) == \
        ["locoplan-a", "locoplan-c.db"]


# ------------------------------------------------------------------------------------------ running them
EXTERNAL = ROOT.parent / "shared" / "data" / "external"
"""The public TTOBench and railtoolkit sources the import examples read (not part of this repository)."""


def _sandbox(tmp: Path) -> Path:
    """A working folder that looks like the checkout: inputs linked, docs/ copied (examples write plots
    there) and ``../shared`` beside it as beside the checkout."""
    repo = tmp / "repo"
    repo.mkdir()
    for name in ("routes", "configs", "tests", "benchmarks", "locoplan", "pyproject.toml", "README.md"):
        if (ROOT / name).exists():
            (repo / name).symlink_to(ROOT / name)
    shutil.copytree(ROOT / "docs", repo / "docs")
    if (ROOT.parent / "shared").exists():
        (tmp / "shared").symlink_to(ROOT.parent / "shared")
    return repo


TMP = Path("/tmp")
_TMP_NAME = re.compile(r"(?<![\w.])/tmp/([^\s/'\"]+)")


def tmp_names(block: list[Example]) -> list[str]:
    """The files and folders right under /tmp/ that the block's commands name (sorted: the order their
    locks are taken in)."""
    names = {m.group(1) for e in block for m in _TMP_NAME.finditer(e.command)}
    return sorted(names | {d.split("/")[0] for e in block for d in e.mkdirs})


def _clear(path: Path) -> None:
    """``path`` gone, with a store's SQLite journal beside it (``-wal``, ``-shm``, ``-journal``)."""
    for p in (path, *(path.with_name(path.name + tail) for tail in ("-wal", "-shm", "-journal"))):
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        elif p.exists() or p.is_symlink():
            p.unlink()


def _run_block(block: list[Example], cache: str, cwd: Path) -> dict[int, subprocess.CompletedProcess]:
    env = {**os.environ, "COLUMNS": str(WIDTH), "LOCOPLAN_CACHE_DIR": cache,
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    env.pop("LINES", None)
    done = {}
    names = tmp_names(block)
    locks = []
    try:
        for name in names:  # the block's own /tmp/ names: held alone (blocks run side by side), found cleared
            lock = open(TMP / f".locoplan-example-{name}.lock", "w")
            locks.append(lock)
            fcntl.flock(lock, fcntl.LOCK_EX)
            _clear(TMP / name)
        for e in block:
            for folder in e.mkdirs:
                (TMP / folder).mkdir(parents=True, exist_ok=True)
            script = re.sub(r"^(COLUMNS=\d+\s+)?locoplan\s",
                            lambda m: f"{m.group(1) or ''}{shlex.quote(sys.executable)} -m locoplan ", e.command)
            res = subprocess.run(["bash", "-c", script], cwd=cwd, env=env, capture_output=True, text=True,
                                 timeout=900)  # a hang guard, not a speed test
            res.stdout, res.stderr = (t.replace(f"{cwd}/", ".../").replace(f"{ROOT}/", ".../")
                                      for t in (res.stdout, res.stderr))
            done[e.line] = res
    finally:
        for name in names[:len(locks)]:
            _clear(TMP / name)
        for lock in locks:
            lock.close()  # releases the lock
    return done


def _key(e: Example) -> str:
    return f"{e.page}:{e.line}"


def _run_chosen(request, tmp_path_factory) -> dict[str, subprocess.CompletedProcess]:
    """Every example that runs in this session, block by block, two blocks at a time (each command one process)."""
    slow = request.config.getoption("--run-slow")
    chosen = {(x.callspec.params["example"].page, x.callspec.params["example"].block) for x in request.session.items
              if getattr(x, "callspec", None) is not None and "example" in x.callspec.params}
    blocks: dict[tuple[str, int], list[Example]] = {}
    for e in EXAMPLES:  # the whole block of every selected example (a command may read what an earlier one wrote)
        if (slow or not e.slow) and (e.page, e.block) in chosen:
            blocks.setdefault((e.page, e.block), []).append(e)

    def one(item):
        (page, _), block = item
        cwd = _sandbox(tmp_path_factory.mktemp("example"))
        cache = cwd / ".cache"  # a fresh cache of optima per block: E* is solved as on a new machine, every time
        return {f"{page}:{line}": res for line, res in _run_block(block, str(cache), cwd).items()}

    results: dict[str, subprocess.CompletedProcess] = {}
    with ThreadPoolExecutor(max_workers=2) as pool:
        for part in pool.map(one, blocks.items()):
            results.update(part)
    return results


@pytest.fixture(scope="session")
def ran(request, tmp_path_factory):
    """The examples' results, run once per test session: under pytest-xdist the first worker to need them runs them
    and leaves them in the run's shared temporary folder, the others wait for that and read them (each worker
    running them all cost a worker the whole run of the examples again)."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return _run_chosen(request, tmp_path_factory)
    shared = tmp_path_factory.getbasetemp().parent  # this run's, shared by its workers
    done = shared / "examples-ran.pickle"
    with open(shared / "examples-ran.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if done.exists():
            return pickle.loads(done.read_bytes())
        results = _run_chosen(request, tmp_path_factory)
        part = done.with_suffix(".part")
        part.write_bytes(pickle.dumps(results))
        os.replace(part, done)
        return results


@pytest.mark.parametrize("example", [pytest.param(e, marks=pytest.mark.slow) if e.slow else e for e in EXAMPLES],
                         ids=lambda e: f"{e.page}:{e.line}:{e.command[:50]}")
def test_example(example, ran, request):
    if example.slow and not request.config.getoption("--run-slow"):
        pytest.skip("a slow example (# slow): python -m pytest --run-slow runs it")
    if "../shared/data/external" in example.command and not EXTERNAL.exists():
        pytest.skip(f"needs the public sources in {EXTERNAL}")
    res = ran[_key(example)]
    where = f"{example.page}:{example.line}: {example.command}"
    assert res.returncode == example.exit_code, f"{where}\nexit {res.returncode}\n{res.stdout}\n{res.stderr}"
    assert "Traceback" not in res.stderr, f"{where}\n{res.stderr}"
    if "--json" in shlex.split(example.command, comments=True):
        if res.returncode == 0 and "|" not in example.command:
            json.loads(res.stdout)
    else:
        assert "…" not in res.stdout, res.stdout
        width = _width(example.command)
        long = [line for line in res.stdout.splitlines() if len(line) > width and not _whole_token(line)]
        assert not long, f"{where}\nlines wider than {width} columns:\n" + "\n".join(long)
    missing = missing_lines(example.output, res.stdout, res.stderr)
    assert not missing, (f"{where}\nshown lines the command did not print (in this order):\n" + "\n".join(missing)
                         + f"\n--- it printed (stdout):\n{res.stdout}\n--- (stderr):\n{res.stderr}")
