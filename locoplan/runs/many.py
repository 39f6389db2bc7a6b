"""``run_many(specs, executor)``: the one loop behind study, sweep, compare, batch and the benchmarks.

1. :func:`~locoplan.runs.spec.load_inputs` loads every route, consist and parameter file once (bad
   input stops everything here, before any work) and keys every spec.
2. With a store, the keys it already holds are taken from it and not run again.
3. E_min (the energy-saving strategy's energy, the ISSA paper's eq. 11) is computed once per group (route,
   train, options, builder) on the executor, kept in the store, and handed to every run of the group.
   A run's result therefore depends on its spec alone, not on the executor, the number of workers or
   which other runs share the batch (a journey run's legs find their own E_min, from the same fixed seed) (the optional gap to the MPOC paper's optimum, ``RunSpec.yardstick``,
   excepted in its last digits: the bound warm-starts from its process's previous solve).
4. The runs go to the executor, longest route first (a scheduling choice only); each finished run is
   committed to the store as it arrives.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable

from ..strategy import registry
from ..strategy.strategies import ENERGY_SAVING_ALGORITHM
from .executors import Executor, SerialExecutor
from .spec import (EMinTask, RunRecord, RunSpec, Task, _e_min_params, execute, execute_e_min, group_key, load_inputs,
                   spec_key)


@dataclass(frozen=True)
class ProgressEvent:
    """Passed to ``progress`` after each finished task. phase: 'e_min' or 'runs'; done / total: tasks
    of that phase finished / to do in this call; reused: runs found in the store; failed: runs so far
    that fail their job (no feasible plan, or outside the window for a timetabled strategy)."""

    phase: str
    done: int
    total: int
    reused: int = 0
    failed: int = 0
    record: RunRecord | None = None


@dataclass
class Batch:
    """What :func:`run_many` returns: ``records`` in the order of the specs (one per spec), ``ran`` the
    keys run by this call (in the order they finished), ``reused`` how many came from the store,
    ``e_min_kwh`` group key -> E_min."""

    records: list[RunRecord]
    ran: list[str] = field(default_factory=list)
    reused: int = 0
    e_min_kwh: dict = field(default_factory=dict)

    @property
    def failures(self) -> list[str]:
        return [r.verdict for r in self.records if r.verdict]


def needs_e_min(spec: RunSpec) -> bool:
    """The run needs its group's E_min, computed once for the group before the runs: a strategy ranked by eq.
    10-11 is built on it (``StrategyEntry.needs_e_min``), and any fitness reports it. Only the ISSA paper's builder
    shares one (its energy-saving run's, whatever the time); with the general builder E_min is E* at the run's
    own window's end, which each run finds (from E*'s cache); a journey run's legs find their own."""
    entry = registry.lookup(spec.strategy)
    return (spec.journey is None and spec.e_min_kwh is None and spec.resolved_builder == "issa-paper"
            and (spec.fitness or (entry is not None and entry.needs_e_min)))


def run_many(specs: Iterable[RunSpec], executor: Executor | None = None, *, store=None,
             progress: Callable[[ProgressEvent], None] | None = None, keep_profiles: bool = False) -> Batch:
    """Run ``specs`` on ``executor`` (default: this process), resuming from ``store`` if given.

    Returns a :class:`Batch`. Raises :class:`~locoplan.errors.InputError` for bad inputs before any
    run; a run with no feasible plan is a record (``feasible`` false, ``verdict`` says why), not an
    error. ``keep_profiles``: records carry the reporting-grid profile and convergence history (for
    plots; runs taken from a store have none)."""
    specs = list(specs)
    executor = executor or SerialExecutor()
    inputs = load_inputs(specs)
    keys = [spec_key(s, inputs) for s in specs]
    if store is not None:
        store.check_writer()
        done = store.get(sorted(set(keys)))
    else:
        done = {}
    batch = Batch([], reused=len({k for k in keys if k in done}))

    # E_min once per group (from the store when it has it)
    groups: dict[str, EMinTask] = {}
    for s, k in zip(specs, keys):
        if k in done or not needs_e_min(s):
            continue
        g = group_key(s, inputs)
        if g not in groups:
            groups[g] = EMinTask(g, inputs.routes[inputs.route_hash(s)], inputs.trains[inputs.train_hash(s)], s.options,
                                 s.resolved_builder, inputs.params(ENERGY_SAVING_ALGORITHM, _e_min_params(s)), s.objective)
    known = store.refs("e_min") if store is not None else {}
    e_min = {g: known[g][0] for g in groups if g in known}
    todo = [t for g, t in groups.items() if g not in known]
    for n, (_, (g, value, note)) in enumerate(executor.imap_unordered(execute_e_min, todo), 1):
        e_min[g] = value
        if store is not None:
            store.put_ref(g, "e_min", value, note)
        if progress:
            progress(ProgressEvent("e_min", n, len(todo)))
    batch.e_min_kwh = e_min

    # the runs not yet in the store, each key once
    tasks: list[Task] = []
    seen: set[str] = set()
    for s, k in zip(specs, keys):
        if k in done or k in seen:
            continue
        seen.add(k)
        rh, th = inputs.route_hash(s), inputs.train_hash(s)
        e = s.e_min_kwh if s.e_min_kwh is not None else (e_min.get(group_key(s, inputs)) if needs_e_min(s) else None)
        journey = None if s.journey is None else inputs.journeys[inputs.journey_of[s.journey]]
        tasks.append(Task(s, k, inputs.routes[rh], inputs.trains[th], rh, th, e, keep_profiles,
                          inputs.params(s.algorithm, s.params), journey))
    tasks.sort(key=lambda t: -t.route.length_m)
    failed = sum(1 for k in set(keys) if k in done and done[k].verdict)
    for n, (_, record) in enumerate(executor.imap_unordered(execute, tasks), 1):
        if store is not None:
            store.put(record)
        done[record.key] = record
        batch.ran.append(record.key)
        failed += record.verdict is not None
        if progress:
            progress(ProgressEvent("runs", n, len(tasks), batch.reused, failed, record))
    batch.records = [done[k] for k in keys]
    return batch

