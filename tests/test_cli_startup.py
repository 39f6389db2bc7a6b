"""The command line starts without the planner: importing it, and printing ``locoplan --help`` or a command's
``--help``, loads no numerical package and none of the planner's modules (what made ``--help`` take a second);
a command imports what it runs. Checked in a fresh process by what is in ``sys.modules``, never by a clock
(``benchmarks/startup.py`` measures the time)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

HEAVY = ("numpy", "numba", "scipy", "casadi", "matplotlib", "pandas", "yaml",
         "locoplan.api", "locoplan.runner", "locoplan.bounds", "locoplan.model", "locoplan.io.load",
         "locoplan.sim.calculator", "locoplan.optimize.registry", "locoplan.reporting.writers",
         "locoplan.reporting.tables", "locoplan.io.readers.osrd")
"""What a help text must not load: the numerical packages and the planner (each of these brings some of them)."""


def _modules(code: str) -> set[str]:
    """The modules a fresh interpreter has loaded after ``code``."""
    script = textwrap.dedent(code) + "\nimport json, sys\nprint(json.dumps(sorted(sys.modules)))\n"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), COLUMNS="80")
    res = subprocess.run([sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    return set(json.loads(res.stdout.splitlines()[-1]))


def test_importing_the_command_line_loads_no_heavy_module():
    assert sorted(_modules("import locoplan.cli") & set(HEAVY)) == []


@pytest.mark.parametrize("args", [["--help"], ["optimize", "--help"], ["import", "--help"], ["ocp", "--help"]])
def test_help_loads_no_heavy_module(args):
    loaded = _modules(f"""
        from locoplan.cli import app
        try:
            app({args!r}, prog_name="locoplan")
        except SystemExit as exc:
            assert exc.code in (0, None), exc.code
    """)
    assert sorted(loaded & set(HEAVY)) == []


def test_a_command_loads_what_it_runs():
    """The check above sees a heavy import where there is one: the command modules' ``api`` loads the planner
    on first use."""
    loaded = _modules("import locoplan.cli as cli\ncli.api.ModelRequest")
    assert {"locoplan.api", "locoplan.sim.calculator", "numpy"} <= loaded
