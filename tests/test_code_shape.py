"""No function in locoplan/ is longer than MAX_LINES (issue 36, "named steps"): a long routine is split
into named functions, each one step of the method, the way OSRD builds an envelope from named parts."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "locoplan"
MAX_LINES = 120

ALLOWED: set[tuple[str, str]] = set()
"""(file, function) pairs allowed over MAX_LINES, each with a comment saying why (none today: the compiled
kernels, ``run_plans`` and the cycle DP's ``_forward``, are split into named njit steps too). The test
fails on an entry that no longer needs to be here."""


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
