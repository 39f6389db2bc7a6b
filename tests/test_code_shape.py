"""No function in locoplan/ is longer than MAX_LINES (issue 36, "named steps"): a long routine is split
into named functions, each one step of the method, the way OSRD builds an envelope from named parts."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "locoplan"
MAX_LINES = 120

ALLOWED = {
    # The calculator's compiled loop (numba), ~180 lines: its steps are named njit functions (the cycle's
    # speeds, release, application, level, caps after a release; the cruise caps, the capped end, time and
    # work, the profile), but the per-cell state the cycle carries (on, released, its times) is still threaded
    # through one loop; splitting further must keep every result bit-identical (tests/test_kernel.py).
    ("sim/kernel.py", "run_plans"),
}
"""(file, function) pairs allowed over MAX_LINES: compiled kernels not split yet. Remove an entry once
its function is split; the test fails on an entry that no longer needs to be here."""


def _lengths() -> dict[tuple[str, str], int]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                key = (rel, node.name)
                out[key] = max(out.get(key, 0), node.end_lineno - node.lineno + 1)
    return out


def test_no_function_is_longer_than_the_limit():
    long = {key: n for key, n in _lengths().items() if n > MAX_LINES and key not in ALLOWED}
    assert not long, f"functions over {MAX_LINES} lines (split them into named steps): {long}"


def test_the_allow_list_holds_only_long_functions():
    lengths = _lengths()
    stale = [key for key in ALLOWED if lengths.get(key, 0) <= MAX_LINES]
    assert not stale, f"no longer over {MAX_LINES} lines, remove from ALLOWED: {stale}"
