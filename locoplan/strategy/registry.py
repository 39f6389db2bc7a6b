"""The strategies as data: one :class:`StrategyEntry` per strategy, with the traits the runs need.

Every process knows every built-in strategy from this table alone: an entry names the function that
plans (``module:function``), imported on first use, so a spawned or Dask worker that has imported
nothing but :mod:`locoplan.runs` runs ``drivers`` as well as ``proposed``, and ``import locoplan`` does
not load the optimal-control or learning code. The traits are what the rest of the code asks about a
strategy by name (whether it must keep the timetable, needs a planned time, E_min or an optimiser's
seed); they live here and nowhere else.

Adding a strategy: write its function ``(StrategyContext) -> StrategyOutcome`` in a module of its own
and add its entry to :data:`BUILT_IN`. A library user may add one at run time with :func:`register`
(that process only: a worker knows the built-in entries).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Union

from ..errors import InputError, Problem

if TYPE_CHECKING:  # the context module loads the calculator; the table itself needs nothing
    from .strategies import StrategyContext, StrategyOutcome

StrategyFn = Callable[["StrategyContext"], "StrategyOutcome"]


@dataclass(frozen=True)
class StrategyEntry:
    """One strategy and its traits.

    name: what ``--strategy`` and ``RunSpec.strategy`` call it. plan: the function, as
    ``"module:function"`` (imported on first use) or a callable. source: the paper it comes from.
    timetabled: its job is to meet the planned running time (a miss fails the run, exit 1); the others
    ignore the timetable by definition or report what drivers did. needs_time: it needs a planned
    time (given, or the route's schedule). needs_e_min: its plan is ranked by eq. 10-11, so E_min
    (the energy-saving run) is computed first. seeded: its result depends on the optimiser and its
    seed (a study repeats it per algorithm and seed; the others run once). refuses_impossible_time: a
    planned time below the fastest run is refused before it plans (its search would find nothing).
    inputs: what it needs beyond route and train, as (name, ``"module:reader"``) pairs: the runner reads
    ``StrategyContext.inputs[name]`` (what was given: ``compare --logs``, ``--patterns``) with the reader
    into ``StrategyContext.loaded[name]``, so that the strategy itself never opens a file."""

    name: str
    plan: Union[str, StrategyFn] = field(repr=False)
    source: str = ""
    timetabled: bool = False
    needs_time: bool = True
    needs_e_min: bool = False
    seeded: bool = False
    refuses_impossible_time: bool = False
    inputs: tuple[tuple[str, str], ...] = ()

    def function(self) -> StrategyFn:
        """The strategy's function (its module imported now if it was not)."""
        return _resolve(self.plan)

    def read_inputs(self, given: dict, loaded: dict) -> dict:
        """The inputs named in ``given`` and not yet in ``loaded``, read by their readers."""
        return {name: _resolve(reader)(given[name]) for name, reader in self.inputs
                if given.get(name) and name not in loaded}


def _resolve(target):
    if callable(target):
        return target
    module, _, attr = target.partition(":")
    return getattr(importlib.import_module(module), attr)


ISSA_PAPER, MPOC_PAPER, PATTERN_PATENT = "the ISSA paper", "the MPOC paper", "the pattern-curve patent"

BUILT_IN: tuple[StrategyEntry, ...] = (
    # the ISSA paper (Tables 8-9): the fastest run, the least energy, four-stage and the proposed method
    StrategyEntry("time-saving", "locoplan.strategy.strategies:time_saving", ISSA_PAPER, needs_time=False),
    StrategyEntry("energy-saving", "locoplan.strategy.strategies:energy_saving", ISSA_PAPER, needs_time=False),
    StrategyEntry("four-stage", "locoplan.strategy.strategies:four_stage", ISSA_PAPER, timetabled=True,
                  refuses_impossible_time=True),
    StrategyEntry("proposed", "locoplan.strategy.strategies:proposed", ISSA_PAPER, timetabled=True, needs_e_min=True,
                  seeded=True, refuses_impossible_time=True),
    # the MPOC paper (Tables 3-5): the multi-phase optimum three ways, and standard four-stage with neutral sections
    StrategyEntry("mpoc", "locoplan.strategy.optimal:mpoc", MPOC_PAPER, timetabled=True),
    StrategyEntry("mpoc-n", "locoplan.strategy.optimal:mpoc_n", MPOC_PAPER, timetabled=True),
    StrategyEntry("mpoc-c", "locoplan.strategy.optimal:mpoc_c", MPOC_PAPER, timetabled=True),
    StrategyEntry("sfs", "locoplan.strategy.optimal:sfs", MPOC_PAPER, timetabled=True),
    # the pattern-curve patent: what the drivers' logs say, and the learned patterns' advice
    StrategyEntry("drivers", "locoplan.learn.strategies:drivers", PATTERN_PATENT, inputs=(("logs", "locoplan.io.logs:load_logs"),)),
    StrategyEntry("advice", "locoplan.learn.strategies:advice", PATTERN_PATENT, timetabled=True,
                  inputs=(("patterns", "locoplan.io.patterns:read_patterns_file"),)),
)

STRATEGIES: dict[str, StrategyEntry] = {e.name: e for e in BUILT_IN}
"""Every known strategy by name, in the order the help and the error messages list them."""

BUILDERS = ("general", "issa-paper")
"""The condition-sequence builders (``StrategyContext.builder``; strategy/strategies.py)."""

BUILDER_ALIASES = {"seed002": "issa-paper"}
"""Other names a builder is accepted by (``--builder``, a study file's ``builder``): its first name."""


def builder_name(builder: str | None) -> str | None:
    """The builder's own name for ``builder`` (an alias resolved; None and unknown names unchanged)."""
    return BUILDER_ALIASES.get(builder, builder)


def builder_key(builder: str) -> str:
    """The name a store's keys give ``builder``: its first one, so that runs stored before a rename are found."""
    return {v: k for k, v in BUILDER_ALIASES.items()}.get(builder, builder)


def register(entry: StrategyEntry) -> StrategyEntry:
    """Add (or replace) a strategy in this process. A process-pool or Dask worker knows only the
    built-in entries: give a new strategy its line in :data:`BUILT_IN` to run it there."""
    STRATEGIES[entry.name] = entry
    return entry


def names(**traits) -> tuple[str, ...]:
    """The strategies' names, those with the given trait values only (``names(timetabled=True)``)."""
    return tuple(n for n, e in STRATEGIES.items() if all(getattr(e, k) == v for k, v in traits.items()))


def lookup(name: str) -> StrategyEntry | None:
    """The entry of ``name``, or None (a ``--sequence`` run or a name not registered)."""
    return STRATEGIES.get(name)


def unknown_message(name: str) -> str:
    return f"unknown strategy {name!r} (one of: {', '.join(STRATEGIES)})"


def get(name: str, file: str = "", field: str = "strategy") -> StrategyEntry:
    """The entry of ``name``; an :class:`InputError` naming ``field`` and the known names otherwise."""
    entry = STRATEGIES.get(name)
    if entry is None:
        raise InputError(Problem(file, field, unknown_message(name)))
    return entry


def check_builder(builder: str, field: str = "builder") -> None:
    if builder_name(builder) not in BUILDERS:
        raise InputError(Problem("", field, builder_message(builder)))


def builder_message(builder) -> str:
    return f"unknown sequence builder {builder!r} (one of: {', '.join(BUILDERS)})"


def is_timetabled(name: str) -> bool:
    """Whether the strategy's job is to meet the planned time (False for a name not registered)."""
    entry = STRATEGIES.get(name)
    return entry is not None and entry.timetabled


__all__ = ["StrategyEntry", "BUILT_IN", "STRATEGIES", "BUILDERS", "register", "names", "lookup", "get",
           "is_timetabled", "unknown_message", "check_builder", "builder_message", "BUILDER_ALIASES", "builder_name",
           "builder_key"]
