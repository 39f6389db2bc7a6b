"""locoplan: driving-strategy planner for heavy freight trains.

Everything the command line does is a few lines of Python (docs/batch.md)::

    from locoplan import RunSpec, run_many, make_executor, Store, load_study

    batch = run_many(load_study("study.yaml").specs, make_executor(workers=2), store=Store("runs.sqlite"))

The names below are imported on first use, so that ``import locoplan`` (and ``locoplan --help``)
stays fast.
"""

from __future__ import annotations

import importlib

__version__ = "0.5.0"
"""The one place the version is written (pyproject.toml reads it): it moves whenever results change (CHANGELOG.md),
so that ``locoplan_version`` in every JSON output and a store's version check mean something."""

_API = {
    # files and models
    "load_route": "locoplan.io.load", "load_train": "locoplan.io.load", "ModelOptions": "locoplan.sim.calculator",
    "TractionCalculator": "locoplan.sim.calculator",
    # one run
    "RunSettings": "locoplan.settings", "make_context": "locoplan.runner", "run_strategy": "locoplan.runner",
    "run_sequence": "locoplan.runner",
    "summarize": "locoplan.runner", "STRATEGIES": "locoplan.strategy.registry",
    # many runs
    "RunSpec": "locoplan.runs.spec", "RunRecord": "locoplan.runs.spec", "run_many": "locoplan.runs.many",
    "make_executor": "locoplan.runs.executors", "SerialExecutor": "locoplan.runs.executors",
    "ProcessExecutor": "locoplan.runs.executors", "DaskExecutor": "locoplan.runs.executors",
    "Store": "locoplan.runs.store", "load_study": "locoplan.runs.study",
    "compare_specs": "locoplan.runs.plans", "weight_specs": "locoplan.runs.plans", "time_specs": "locoplan.runs.plans",
    "study_specs": "locoplan.runs.plans", "study_table": "locoplan.runner",
    "pareto": "locoplan.runs.pareto", "register_optimum": "locoplan.runs.optimum",
    "summarize_rows": "locoplan.runs.results", "export": "locoplan.runs.results",
    # errors
    "InputError": "locoplan.errors", "InfeasibleError": "locoplan.errors", "LocoplanError": "locoplan.errors",
}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'locoplan' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
