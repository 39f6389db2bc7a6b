"""A run as data: :class:`RunSpec` (what to run) -> :class:`RunRecord` (what came out).

A spec names its route by file (or, for a journey run, its journey file) and its consist by catalogue
name or file, plus everything that decides the result (model options, strategy, optimiser, seed, planned
time, weights, builder, punctuality window). It is small and picklable, so any executor can ship it to
any worker.

Before anything runs, :func:`prepare` loads every route and consist once (input errors surface here,
before any work starts) and gives each spec its **key**: a SHA-256 of the validated route and train
models (their content, not their file names; for a journey the journey's stations and timetable too), the
optimiser's parameters and the spec's settings. The same key means the same result; a result store is
keyed by it (resume, no run done twice).

A **journey run** (``RunSpec.journey``) plans a whole journey of several stops as ``locoplan journey``
does (:func:`locoplan.runs.journey.plan_journey`): ``time_s`` is its total running time, dwells excluded;
the strategy plans every leg at the leg's share of it; the record's summary holds the journey's totals
(:func:`locoplan.runs.journey.journey_run_summary`).

:func:`execute` runs one :class:`Task` (a spec with its loaded inputs and its group's E_min) in
whatever process it lands in; it never reads the spec's files again (the optimiser's parameters
travel inside the task), so a cluster's workers need no shared file system. The strategies' traits
(whether one needs a planned time, E_min, an optimiser) come from :mod:`locoplan.strategy.registry`,
which every process knows.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import platform
import socket
import time
from dataclasses import MISSING, asdict, dataclass, field, fields
from functools import lru_cache
from pathlib import Path
from typing import Any

from .. import bounds
from ..catalogue import DEFAULT_CONSIST
from ..errors import InfeasibleError, InputError, Problem
from ..io.load import load_journey, load_route, load_train, resolve_consist_path
from ..runner import load_optimizer_params
from ..optimize.registry import ALGORITHMS
from ..runner import make_context, planned_time, run_strategy, schedule_verdict
from ..settings import RunSettings
from ..model.train import shorter_than_train
from ..sim.calculator import ModelOptions
from ..strategy import registry
from ..strategy.strategies import ENERGY_SAVING_ALGORITHM
RESULTS_FORMAT = 1
"""Version of the record layout (the store refuses another one)."""

TIMING_FIELDS = ("solve_time_s", "wall_time_s", "cpu_time_s")
"""Fields that measure the machine, not the result: left out when records are compared."""


SETTING_NAMES = {"algorithm": "algorithm", "seed": "seed", "time_s": "time_s", "weights": "weights",
                 "tolerance_s": "tolerance_s", "window": "window", "builder": "builder", "e_min_kwh": "e_min_kwh",
                 "params": "params_path", "options": "options", "yardstick": "yardstick", "objective": "objective"}
"""A spec's names of its settings (``RunSpec.replace``, the record's spec) -> the ``RunSettings`` fields."""
SPEC_SETTINGS = tuple(SETTING_NAMES)


def _setting(name: str) -> property:
    return property(lambda self: getattr(self.settings, name), doc=f"``settings.{name}``")


@dataclass(frozen=True)
class RunSpec:
    """One run. Field names are the library's (``time_s``, ``e_min_kwh``), never a command's flags.

    route: route file; or journey: a journey file (locoplan/journey@1), one of the two. A journey run plans
    the journey whole (its legs' time shared for the least energy, each leg planned by ``strategy``), with
    ``time_s`` its total running time, dwells excluded (None: the journey's own). consist: catalogue name or
    consist file. strategy: a name of ``strategy.registry.STRATEGIES``. settings: the run's
    :class:`~locoplan.settings.RunSettings` (model options, planned time and window, builder, optimiser, seed,
    weights, E_min, yardstick, objective), read here by their names (``spec.time_s``; ``spec.params`` is the
    optimiser's parameter file, ``settings.params_path``, None: the shipped one). A given ``e_min_kwh`` is used;
    None: the energy-saving strategy's, computed once per route, consist and options and passed to every run of
    that group. fitness: report eq. 10's fitness. strict: a plan outside the window
    fails its job whatever the strategy (None: only the timetabled strategies). inputs: further
    strategy inputs as (name, value) pairs (e.g. compare's logs and patterns). tags: labels carried
    into the record but not into the key (e.g. the study file's time factor '1.1x').
    """

    route: str | None = None
    consist: str = DEFAULT_CONSIST
    strategy: str = "proposed"
    settings: RunSettings = field(default_factory=RunSettings)
    stock_dir: str | None = None
    fitness: bool = True
    strict: bool | None = None
    inputs: tuple[tuple[str, Any], ...] = ()
    tags: tuple[tuple[str, str], ...] = ()
    journey: str | None = None

    def replace(self, **changes) -> RunSpec:
        """A copy with ``changes`` made: the spec's own fields, or its settings' by their names here (``params``:
        the parameter file, ``settings.params_path``)."""
        own = {k: v for k, v in changes.items() if k not in SETTING_NAMES}
        moved = {SETTING_NAMES[k]: v for k, v in changes.items() if k in SETTING_NAMES}
        if moved:
            own["settings"] = self.settings.replace(**moved)
        return dataclasses.replace(self, **own)

    @property
    def kind(self) -> str:
        """'journey' for a journey run, else 'route'."""
        return "route" if self.journey is None else "journey"

    @property
    def source(self) -> str:
        """The file the run plans: its journey file, else its route file."""
        return self.journey if self.journey is not None else self.route

    def to_dict(self) -> dict:
        """The spec as a flat dict, its settings by their names here, in the order (and so the key) specs had
        before the settings were one value."""
        d = {"route": self.route, "consist": self.consist, "strategy": self.strategy,
             **{k: getattr(self, k) for k in SPEC_SETTINGS[:9]}, "options": asdict(self.options),
             "stock_dir": self.stock_dir, "fitness": self.fitness, "strict": self.strict, "yardstick": self.yardstick,
             "inputs": {k: _plain(v) for k, v in self.inputs}, "tags": dict(self.tags), "objective": self.objective}
        if self.journey is not None:  # a route run's dict (and so its key) as before journeys existed
            d["journey"] = self.journey
        d["weights"] = list(self.weights)
        return d

    @property
    def resolved_builder(self) -> str:
        """The builder the run uses: the general one unless the ISSA paper's is named (runner.make_context)."""
        return registry.builder_name(self.builder) or "general"


for _name, _field in SETTING_NAMES.items():  # spec.time_s, spec.params ... read its settings (SETTING_NAMES)
    setattr(RunSpec, _name, _setting(_field))


def _plain(value: Any) -> Any:
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def canonical_hash(obj: Any) -> str:
    """SHA-256 (hex, 32 characters) of a canonical JSON text of ``obj``: stable across processes and machines."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:32]


@dataclass(frozen=True)
class Inputs:
    """What :func:`prepare` loaded: routes, trains and journeys by content hash, and each spec's hashes."""

    routes: dict[str, Any]          # route hash -> Route
    trains: dict[str, Any]          # train hash -> Train
    route_of: dict[str, str]        # route file (a journey file: the route it names) -> route hash
    train_of: dict[tuple, str]      # (consist, stock_dir) -> train hash
    params_of: dict[tuple, dict]    # (algorithm, params file) -> parameters (validated), as hashed
    param_models: dict[tuple, Any] = field(default_factory=dict)  # the same as the optimiser's Params objects
    journeys: dict[str, Any] = field(default_factory=dict)    # journey hash -> Journey
    journey_of: dict[str, str] = field(default_factory=dict)  # journey file -> journey hash

    def params(self, algorithm: str, path: str | None):
        """The optimiser's parameters of a params file (None: no file, the algorithm's defaults)."""
        return None if path is None else self.param_models[(algorithm, path)]

    def route_hash(self, spec: "RunSpec") -> str:
        return self.route_of[spec.source]

    def train_hash(self, spec: "RunSpec") -> str:
        return self.train_of[(spec.consist, spec.stock_dir)]


def _check_values(spec: RunSpec) -> None:
    """A spec's numbers inside the bounds a command line's would be held to (``bounds``), so that a bad one
    (a seed past 2**63 - 1 as seed + run, a NaN weight) stops the batch before any run, not at its turn."""
    bounds.seed(spec.seed, "seed")
    bounds.objective(spec.objective, "objective")
    if spec.time_s is not None:
        bounds.planned_time(spec.time_s, "time_s")
    if spec.tolerance_s is not None:
        bounds.finite(spec.tolerance_s, "tolerance_s", 0.0, bounds.LIMITS["time_s"][1], "s", "the punctuality window +-")
    if spec.e_min_kwh is not None:
        bounds.finite(spec.e_min_kwh, "e_min_kwh", *bounds.LIMITS["e_min_kwh"], "kWh", "the least traction energy whatever the time")
    w = tuple(spec.weights)
    if len(w) != 2 or not all(isinstance(x, (int, float)) and math.isfinite(x) and x >= 0 for x in w) \
            or abs(sum(w) - 1) > 1e-9:
        raise InputError(Problem("", "weights", f"expected two finite non-negative weights summing to 1, got {list(w)}"))


def load_inputs(specs: list[RunSpec]) -> Inputs:
    """Load every distinct route, journey, consist and optimiser parameter file of ``specs`` once.

    Raises :class:`InputError` for a bad file (naming file, line and field) or an unknown strategy,
    algorithm or builder (naming the spec field), before any run starts."""
    problems: list[Problem] = []
    inputs = Inputs({}, {}, {}, {}, {}, {})
    routes, trains, route_of, train_of = inputs.routes, inputs.trains, inputs.route_of, inputs.train_of
    checked_journeys: set[tuple] = set()
    for spec in specs:
        if (spec.route is None) == (spec.journey is None):
            problems.append(Problem("", "route", "give a route file (route) or a journey file (journey): one of the two"))
        if registry.lookup(spec.strategy) is None:
            problems.append(Problem("", "strategy", registry.unknown_message(spec.strategy)))
        if spec.algorithm not in ALGORITHMS:
            problems.append(Problem("", "algorithm", f"unknown optimiser {spec.algorithm!r} (one of: {', '.join(ALGORITHMS)})"))
        if spec.resolved_builder not in registry.BUILDERS:
            problems.append(Problem("", "builder", registry.builder_message(spec.builder)))
        if problems:
            raise InputError(problems[:1])
        _check_values(spec)  # every run's numbers, before the first run starts
        if spec.source not in route_of:
            if spec.journey is not None:
                j, r = load_journey(spec.journey)
                jh = canonical_hash(_journey_identity(j))
                inputs.journeys[jh], inputs.journey_of[spec.journey] = j, jh
            else:
                r = load_route(spec.route)
            h = canonical_hash(r.model_dump(mode="json"))
            routes[h], route_of[spec.source] = r, h
        if spec.journey is None and needs_time(spec):
            planned_time(routes[route_of[spec.route]], spec.time_s)  # no schedule and no time: say so now
        ck = (spec.consist, spec.stock_dir)
        if ck not in train_of:
            t = load_train(spec.consist, spec.stock_dir)
            h = canonical_hash(_train_identity(t))
            trains[h], train_of[ck] = t, h
        route, train = routes[route_of[spec.source]], trains[train_of[ck]]
        if spec.journey is not None:
            jk = (spec.journey, train_of[ck], spec.options, spec.time_s, spec.tolerance_s, spec.e_min_kwh)
            if jk not in checked_journeys:
                _check_journey(spec, inputs.journeys[inputs.journey_of[spec.journey]], route, train)
                checked_journeys.add(jk)
        elif train.length_m >= route.length_m:
            raise InputError(shorter_than_train(route, train, spec.route, str(resolve_consist_path(spec.consist))))
        for pk in ((spec.algorithm, spec.params), (ENERGY_SAVING_ALGORITHM, _e_min_params(spec))):
            if pk not in inputs.params_of:
                inputs.param_models[pk] = load_optimizer_params(*pk)
                inputs.params_of[pk] = inputs.param_models[pk].model_dump()
    return inputs


def _journey_identity(journey) -> dict:
    """A journey's content as hashed: its stations and timetable, not the path of the route file it names (the
    route's content is hashed on its own)."""
    d = journey.model_dump(mode="json", by_alias=True)
    d.pop("route")
    return d


def _check_journey(spec: RunSpec, journey, route, train) -> None:
    """What a journey run would otherwise find only when it runs, said before the batch starts: a total running
    time to plan for, a leg no longer than the train, a punctuality window +- (the total's, and the widest a leg's
    plan is asked to keep) as long as a leg's fastest run,
    an E_min given (each leg has its own), an objective other than traction energy."""
    from .journey import legs_of, total_running_time

    if spec.e_min_kwh is not None:
        raise InputError(Problem(spec.journey, "e_min_kwh", "a journey's legs each have their own E_min (the energy-saving "
                                 "strategy's, found per leg): give none"))
    if spec.objective != "traction":
        raise InputError(Problem(spec.journey, "objective", "a journey is planned and priced by its traction energy "
                                 f"(its summary shows the recovered and net energy too): not '{spec.objective}'"))
    total_running_time(journey, spec.time_s, spec.journey)  # none given and none in the journey: say so now
    try:
        legs = legs_of(journey, route, train, spec.options)
    except InfeasibleError:  # a leg the train cannot run: the run's result (no feasible plan), not an input error
        return
    shortest = min(legs, key=lambda leg: leg.fastest_s)
    if spec.tolerance_s is not None and spec.tolerance_s >= shortest.fastest_s:
        raise InputError(Problem(spec.journey, "tolerance_s", f"a punctuality window of +-{spec.tolerance_s:g} s is not "
                                 f"below the fastest run of the leg {shortest.route.name!r} ({shortest.fastest_s:.1f} s): "
                                 "a leg's plan may be asked to keep it, and its window would open at or before departure"))


def _train_identity(train) -> dict:
    """The resolved train's numbers (what the physics sees), arrays as lists: its content hash does not
    depend on which files or catalogue names it was built from. A field at its declared default is left
    out (``regen_efficiency`` 0: no regeneration), so that a field added to ``Train`` later keeps the keys
    a store holds the runs of trains without it under."""
    out = {}
    for f in fields(train):
        v = getattr(train, f.name)
        if f.default is not MISSING and not hasattr(v, "tolist") and v == f.default:
            continue
        out[f.name] = v.tolist() if hasattr(v, "tolist") else v
    return out


def _e_min_params(spec: RunSpec) -> str | None:
    """The parameter file E_min's ISSA search reads: the spec's own only when its algorithm is ISSA
    (strategies._optimise), so that a batch gives what the same run alone gives."""
    return spec.params if spec.algorithm == ENERGY_SAVING_ALGORITHM else None


def _options_dict(options: ModelOptions) -> dict:
    return asdict(options)


def group_key(spec: RunSpec, inputs: Inputs) -> str:
    """Key of the spec's E_min group: route, train, model options, builder and E_min's optimiser
    parameters (E_min does not depend on the planned time, the seed or the algorithm studied)."""
    return canonical_hash({
        "what": "e_min", "route": inputs.route_hash(spec), "train": inputs.train_hash(spec),
        "options": _options_dict(spec.options), "builder": registry.builder_key(spec.resolved_builder),
        "params": inputs.params_of[(ENERGY_SAVING_ALGORITHM, _e_min_params(spec))], "format": RESULTS_FORMAT,
        **({} if spec.objective == "traction" else {"objective": spec.objective}),
    })


def spec_key(spec: RunSpec, inputs: Inputs) -> str:
    """The run's key: everything that decides its result, by content (see the module docstring)."""
    d = spec.to_dict()
    for k in ("route", "consist", "stock_dir", "params", "tags", "builder"):
        d.pop(k)
    if d["objective"] == "traction":  # the default: the keys of runs stored before the field existed
        d.pop("objective")
    d.update(route=inputs.route_hash(spec), train=inputs.train_hash(spec),
             params=inputs.params_of[(spec.algorithm, spec.params)], builder=registry.builder_key(spec.resolved_builder),
             e_min_group=None if spec.e_min_kwh is not None or spec.resolved_builder != "issa-paper"
             else group_key(spec, inputs), format=RESULTS_FORMAT)
    if spec.journey is not None:
        # the journey's content, not its file; its legs find their own E_min (with these parameters), and its
        # E* and gaps are always computed (``yardstick`` changes nothing)
        d.pop("yardstick")
        d.update(kind="journey", journey=inputs.journey_of[spec.journey], e_min_group=None,
                 e_min_params=inputs.params_of[(ENERGY_SAVING_ALGORITHM, _e_min_params(spec))])
    return canonical_hash(d)


@dataclass(frozen=True)
class Task:
    """What a worker gets: the spec, its key, its loaded route and train, and the E_min of its group,
    computed once for the whole batch."""

    spec: RunSpec
    key: str
    route: Any
    train: Any
    route_hash: str
    train_hash: str
    e_min_kwh: float | None = None
    keep_profile: bool = False
    params: Any = None
    """The optimiser's parameters read from ``spec.params`` (None: no file, its defaults)."""
    journey: Any = None
    """A journey run's Journey (``route`` is then the whole line it names)."""


@dataclass
class RunRecord:
    """The result of one run: ``summary`` is the SPEC's ``--json`` object; ``verdict`` why the run fails its job (None if it does it); ``spec`` the
    spec as a dict; ``wall_time_s`` the worker's wall time; ``versions`` what computed it; ``worker``
    host:pid; ``cpu_time_s`` the worker's CPU time for it (a machine shared with other work stretches
    the wall time, not this). ``profile`` and ``history`` (the reporting-grid profile and the optimiser's convergence)
    are kept only when asked for, and never stored."""

    key: str
    summary: dict
    spec: dict
    verdict: str | None
    wall_time_s: float
    versions: dict
    worker: str
    profile: Any = None
    history: Any = None
    cpu_time_s: float | None = None

    def row(self) -> dict:
        """One flat row: the summary's fields (their ``--json`` names), then the record's own: ``kind`` says
        whether it is a route run or a journey run (``journey_file``)."""
        tags = self.spec.get("tags") or {}
        journey = {"journey_file": self.spec["journey"]} if self.spec.get("journey") else {}
        return {**self.summary, "kind": self.summary.get("kind", "route"), "key": self.key,
                "route_file": self.spec.get("route"), **journey, "route_sha": self.spec.get("route_sha"),
                "consist_file": self.spec.get("consist"), "consist_sha": self.spec.get("consist_sha"),
                "time_spec": tags.get("time"),
                "verdict": self.verdict, "wall_time_s": self.wall_time_s, "cpu_time_s": self.cpu_time_s, "worker": self.worker,
                "locoplan_version": self.versions.get("locoplan")}

    def comparable(self) -> dict:
        """The summary without the fields that time the machine (for 'same result' checks)."""
        return {k: v for k, v in self.summary.items() if k not in TIMING_FIELDS}

    def to_json(self) -> dict:
        return {"key": self.key, "summary": self.summary, "spec": self.spec, "verdict": self.verdict,
                "wall_time_s": self.wall_time_s, "cpu_time_s": self.cpu_time_s, "versions": self.versions,
                "worker": self.worker}

    @classmethod
    def from_json(cls, d: dict) -> "RunRecord":
        return cls(d["key"], d["summary"], d["spec"], d.get("verdict"), d["wall_time_s"], d["versions"], d["worker"],
                   cpu_time_s=d.get("cpu_time_s"))


@lru_cache(maxsize=1)
def versions() -> dict:
    import numba
    import numpy

    from .. import __version__

    return {"locoplan": __version__, "python": platform.python_version(), "numpy": numpy.__version__,
            "numba": numba.__version__, "results_format": RESULTS_FORMAT}


# ---------------------------------------------------------------------------------------- workers
_CONTEXTS: dict[tuple, Any] = {}
_CONTEXTS_MAX = 16
"""Per process: the calculators and the priced-drive DP of a (route, train, options, builder), reused by
its runs (the DP's work arrays are rewritten by every solve, so reuse cannot change a result)."""


def _base_context(task: Task):
    spec = task.spec
    k = (task.route_hash, task.train_hash, spec.options, spec.resolved_builder)
    ctx = _CONTEXTS.get(k)
    if ctx is None:
        if len(_CONTEXTS) >= _CONTEXTS_MAX:
            _CONTEXTS.pop(next(iter(_CONTEXTS)))
        ctx = make_context(task.route, task.train, RunSettings(spec.options, need_time=False,
                                                               builder=spec.resolved_builder, yardstick=False))
        _CONTEXTS[k] = ctx
    return ctx


def context_for(task: Task):
    """The run's StrategyContext: a fresh one sharing only the calculators and the DP with earlier runs."""
    spec = task.spec
    base = _base_context(task)
    # validate the settings exactly as a single run would (same errors, same defaults)
    settings = spec.settings.replace(e_min_kwh=task.e_min_kwh, params=task.params, params_path=None,
                                     need_time=needs_time(spec), builder=spec.resolved_builder)
    ctx = make_context(task.route, task.train, settings, calculators=(base.calc, base.search))
    if base.priced_drive is not None:
        ctx.priced_drive = base.priced_drive
    ctx.inputs.update(dict(spec.inputs))
    return ctx, base


def needs_time(spec: RunSpec) -> bool:
    """A planned time is needed (given, or the route's schedule) by every strategy but those that ignore
    the timetable by definition (``StrategyEntry.needs_time``)."""
    entry = registry.lookup(spec.strategy)
    return spec.time_s is not None or entry is None or entry.needs_time


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def execute(task: Task) -> RunRecord:
    """Run one task (in any process). A run that has no feasible plan (InfeasibleError) is a result,
    recorded with ``feasible`` false and the reason; input errors propagate."""
    if task.journey is not None:
        return execute_journey(task)
    t, cpu = time.perf_counter(), time.process_time()
    spec = task.spec
    ctx, base = context_for(task)
    profile = history = None
    if spec.fitness and task.e_min_kwh is None and ctx.e_min_kwh is None and not math.isnan(ctx.t0_s):
        try:  # (the general builder's E_min, E* at the window's end, each run from E*'s cache: every run's fitness)
            ctx.e_min()
        except InfeasibleError:
            pass
    try:
        run = run_strategy(ctx, spec.strategy, with_fitness=spec.fitness)
    except InfeasibleError as exc:
        summary = infeasible_summary(ctx, spec, str(exc))
        verdict = f"{spec.strategy}: {exc}"
    else:
        if ctx.priced_drive is not None and base.priced_drive is None:
            base.priced_drive = ctx.priced_drive
        summary = dict(run.summary)
        verdict = schedule_verdict(ctx, run, strict=spec.strict)
        if task.keep_profile:
            profile, history = run.result.profile, run.outcome.history
    return RunRecord(task.key, summary, _spec_dict(task), verdict, round(time.perf_counter() - t, 4), versions(),
                     _worker_name(), profile, history, round(time.process_time() - cpu, 4))


CONTENT_DIGITS = 12
"""The digits of a content hash a record keeps."""


def _spec_dict(task: Task) -> dict:
    """The record's spec: the spec as written, with the content hashes of the route (or the journey's line) and the
    train it ran (``route_sha``, ``consist_sha``, 12 hex digits): a name or a path may cover two contents."""
    return {**task.spec.to_dict(), "route_sha": task.route_hash[:CONTENT_DIGITS],
            "consist_sha": task.train_hash[:CONTENT_DIGITS]}


def execute_journey(task: Task) -> RunRecord:
    """Run one journey task: the journey planned whole by the spec's strategy (``runs.journey.plan_journey``),
    its record's summary the journey's totals. No feasible plan (a time below the fastest run, windows no run
    keeps, a leg the train cannot run) is a result, as for a route run."""
    from .journey import infeasible_journey_summary, journey_run_summary, plan_journey

    t, cpu = time.perf_counter(), time.process_time()
    spec = task.spec
    try:
        settings = spec.settings.replace(params=task.params, params_path=None)  # (the file read by load_inputs)
        result = plan_journey(task.journey, task.route, task.train, settings, strategies=(spec.strategy,),
                              strict=spec.strict, inputs=spec.inputs, with_fitness=spec.fitness, source=spec.journey)
    except InfeasibleError as exc:
        summary = infeasible_journey_summary(task.journey, task.route, task.train, spec.strategy, spec.time_s, str(exc))
        verdict = f"{spec.strategy}: {exc}"
    else:
        summary = journey_run_summary(result, task.journey, spec.strategy)
        verdict = "; ".join(dict.fromkeys(result.failures)) or None
    return RunRecord(task.key, summary, _spec_dict(task), verdict, round(time.perf_counter() - t, 4), versions(),
                     _worker_name(), None, None, round(time.process_time() - cpu, 4))


def infeasible_summary(ctx, spec: RunSpec, reason: str) -> dict:
    """The summary of a run that produced no plan: the SPEC's fields, with nothing measured."""
    t0 = ctx.t0_s
    entry = registry.lookup(spec.strategy)
    # the optimiser asked for is named for the strategies checked against the fastest run (four-stage's
    # record says 'issa' though it searches a grid: kept so that records compare with earlier ones)
    named = entry is not None and entry.refuses_impossible_time
    return {"route": ctx.calc.route.name, "consist": ctx.calc.train.name, "strategy": spec.strategy,
            "algorithm": spec.algorithm if named else None,
            "seed": spec.seed if named else None, "feasible": False, "reason": reason,
            "running_time_s": None, "traction_energy_kwh": None, "recovered_energy_kwh": None, "net_energy_kwh": None,
            "objective": spec.objective, "planned_time_s": None if math.isnan(t0) else t0, "punctuality_error_s": None, "punctual": None,
            "window_s": None, "fitness": None, "weights": None,
            "e_min_kwh": None if ctx.e_min_kwh is None else round(float(ctx.e_min_kwh), 2),
            "e_min_source": ctx.e_min_source,
            "solve_time_s": None, "n_evaluations": 0, "plan": None, "switching_points_m": [], "sequence": []}


@dataclass(frozen=True)
class EMinTask:
    """E_min of one group (route, train, options, builder, E_min's optimiser parameters)."""

    key: str
    route: Any
    train: Any
    options: ModelOptions
    builder: str
    params: Any
    """E_min's optimiser parameters (None: its defaults)."""
    objective: str = "traction"


def execute_e_min(task: EMinTask) -> tuple[str, float | None, str | None]:
    """(group key, E_min [kWh] or None, why not). E_min is the energy-saving strategy's energy
    (StrategyContext.e_min), searched from a fixed seed, so it does not depend on where it runs."""
    ctx = make_context(task.route, task.train, RunSettings(task.options, need_time=False, builder=task.builder,
                                                           params=task.params, yardstick=False,
                                                           objective=task.objective))
    try:
        return task.key, float(ctx.e_min()), None
    except InfeasibleError as exc:
        return task.key, None, str(exc)


__all__ = ["RunSpec", "RunRecord", "Task", "EMinTask", "Inputs", "load_inputs", "spec_key", "group_key",
           "execute", "execute_e_min", "canonical_hash", "versions", "DEFAULT_CONSIST"]
