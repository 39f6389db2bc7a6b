"""Every `$ locoplan ...` example of README.md runs as shown, and reads whole at 80 columns in a pipe.

The convention the README follows (write new examples this way):

- An example is a fenced block opened with ```` ```console ````. Each line starting with ``$ locoplan``
  is a command, run from the repository root as ``python -m locoplan ...`` with ``COLUMNS=80`` and its
  output piped (what a script or ``| less`` sees). The lines after it, up to the next ``$`` line, are
  its output as printed.
- The exit code is 0 unless the block shows another right after the command with
  ``$ echo $?`` and the code on the next line.
- A command ending in the comment ``# slow`` is not run here (keep the test under a minute: a command
  that takes more than ~10 s on a fresh checkout is ``# slow``; note that ``--gap``, on by default,
  solves seed 001's optimum for every plan). Any other trailing ``# comment`` is ignored.
- A block opened with ```` ```console checked ```` holds real output: every plan string
  (``T:0,K:930,...``) and every number its output lines print must appear in the command's output
  (lines about solve / wall time are left out: they differ from run to run). Plain ```` ```console ````
  blocks are run and checked for their exit code and width, not for their numbers.
- Every command's output: no ``…`` (nothing cut), and no line longer than 80 characters unless it
  carries one whole unbreakable token, a plan string or a path (the terminal wraps it; nothing in
  locoplan cuts it). ``--json`` output is checked for its exit code only (it is one JSON document).

Each command has a time limit of 120 s. The optima (E*) that ``--gap`` needs are cached in pytest's
cache folder between runs (``LOCOPLAN_CACHE_DIR``), as a user's are in ``~/.cache/locoplan``.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WIDTH = 80
PLAN = re.compile(r"^[TKCB](:[-0-9.e+]+)?(,[TKCB](:[-0-9.e+]+)?)+$")
TIMING = re.compile(r"solve|wall|elapsed|runs/s|per second|\bin [0-9.]+ s\b", re.I)


@dataclass
class Example:
    line: int
    command: str
    output: list[str] = field(default_factory=list)
    exit_code: int = 0
    checked: bool = False
    slow: bool = False


def examples(text: str) -> list[Example]:
    """The README's `$ locoplan` commands with their printed output and expected exit codes."""
    found: list[Example] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^```console(.*)$", lines[i].strip())
        if not m:
            i += 1
            continue
        checked = "checked" in m.group(1).split()
        i += 1
        current: Example | None = None
        expect_code_for: Example | None = None
        while i < len(lines) and not lines[i].strip().startswith("```"):
            line = lines[i]
            if line.startswith("$ "):
                cmd = line[2:].strip()
                expect_code_for = None
                if cmd == "echo $?":
                    expect_code_for, current = found[-1] if found else None, None
                elif cmd.startswith("locoplan "):
                    slow = bool(re.search(r"#\s*slow\s*$", cmd))
                    current = Example(i + 1, cmd, checked=checked, slow=slow)
                    found.append(current)
                else:
                    current = None
            elif expect_code_for is not None and line.strip().lstrip("-").isdigit():
                expect_code_for.exit_code = int(line.strip())
                expect_code_for = None
            elif current is not None:
                current.output.append(line)
            i += 1
        i += 1
    return found


def _argv(cmd: str) -> list[str]:
    words = shlex.split(cmd, comments=True)
    assert words[0] == "locoplan"
    return [sys.executable, "-m", "locoplan", *words[1:]]


def _whole_token(line: str) -> bool:
    """A long line is allowed when it carries one unbreakable token (plan or path) and little else."""
    tokens = line.split()
    if not tokens:
        return False
    token = max(tokens, key=len)
    bare = token.strip("\"',;()[]")
    unbreakable = bool(PLAN.match(bare)) or "/" in bare or bare.endswith((".yaml", ".json", ".csv", ".png", ".svg"))
    return unbreakable and len(line) - len(token) <= 40


def _numbers(lines: list[str]) -> set[str]:
    return {n for line in lines if not TIMING.search(line) for n in re.findall(r"\d+(?:[.,]\d+)*", line)}


def _plans(lines: list[str]) -> set[str]:
    return {b for line in lines for t in line.split() if PLAN.match(b := t.strip("\"',;()[]")) and "," in b}


README = (ROOT / "README.md").read_text(encoding="utf-8")
EXAMPLES = examples(README)


def test_the_readme_has_examples():
    assert len(EXAMPLES) >= 3 and any(e.command.startswith("locoplan optimize") for e in EXAMPLES)


def test_parser_reads_the_convention():
    text = ("```console checked\n$ locoplan simulate r.yaml --sequence \"T:0,C:500,B\"   # note\nplan  T:0,C:500,B\n"
            "energy 12.5 kWh\n$ echo $?\n1\n$ locoplan compare r.yaml # slow\n```\n```console\n$ locoplan validate a.yaml\nok\n```\n")
    a, b, c = examples(text)
    assert a.exit_code == 1 and a.checked and not a.slow and a.output == ["plan  T:0,C:500,B", "energy 12.5 kWh"]
    assert _argv(a.command)[3:] == ["simulate", "r.yaml", "--sequence", "T:0,C:500,B"]
    assert b.slow and c.exit_code == 0 and not c.checked
    assert _plans(a.output) == {"T:0,C:500,B"} and {"12.5", "500"} <= _numbers(a.output)
    assert _whole_token("plan  T:0,K:930,C:3256.2,T:4746,C:6238,T:11673.8,C:12947.7,K:14100.5,C:15300.5,T:16000,B")
    assert not _whole_token("x " * 50)


def _run(example: Example, cache: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": str(WIDTH), "LOCOPLAN_CACHE_DIR": cache}
    env.pop("LINES", None)
    return subprocess.run(_argv(example.command), cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)  # a hang guard, not a speed test (a cold compare solves five E*)


@pytest.fixture(scope="module")
def ran(request):
    """Every runnable example, two at a time (each is one process)."""
    cache = str(request.config.cache.mkdir("locoplan-readme-optima"))
    todo = [e for e in EXAMPLES if not e.slow]
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda e: _run(e, cache), todo))
    return dict(zip((e.line for e in todo), results))


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda e: f"README:{e.line}:{e.command[:50]}")
def test_readme_example(example, ran):
    if example.slow:
        pytest.skip("marked # slow in the README")
    res = ran[example.line]
    assert res.returncode == example.exit_code, f"{example.command}\nexit {res.returncode}\n{res.stdout}\n{res.stderr}"
    assert "Traceback" not in res.stderr
    if "--json" in shlex.split(example.command, comments=True):
        if res.returncode == 0:
            json.loads(res.stdout)
        return
    assert "…" not in res.stdout, res.stdout
    long = [line for line in res.stdout.splitlines() if len(line) > WIDTH and not _whole_token(line)]
    assert not long, "lines wider than 80 columns:\n" + "\n".join(long)
    if example.checked:
        shown = res.stdout + res.stderr  # the README shows both streams, as a terminal does
        missing_plans = [p for p in _plans(example.output) if p not in shown]
        assert not missing_plans, f"plans the README shows that the command did not print: {missing_plans}\n{res.stdout}"
        missing = sorted(n for n in _numbers(example.output) if n not in shown)
        assert not missing, f"numbers the README shows that the command did not print: {missing}\n{res.stdout}"
