"""Study files: a batch as the product of its lists (``locoplan batch STUDY.yaml``).

```yaml
schema: locoplan/study@1          # optional
routes: [routes/real/*.yaml]      # files or globs, relative to the study file's folder
journeys: [routes/journeys/*-journey.yaml]   # journey files or globs (routes, journeys or both)
consists: [HXD1-C80x30, HXD1-C80x50]   # catalogue names or files (default: HXD1-C80x50)
times: [1.1x, 1.2x, 1500]         # planned running times: seconds (1500, 25min, 1h05), or factors of each route's fastest
                                  # run with each consist (default: each route's schedule); for a journey
                                  # its total running time, dwells excluded, the factors of its fastest
                                  # total (default: the journey's own)
strategies: [proposed]            # default: proposed
algorithms: [issa, ssa, pso]      # default: issa
seeds: [1, 2, 3, 4, 5]            # default: 1
```
Optional settings shared by every run: ``weights`` ([w_time, w_energy]), ``tolerance_s``, ``window``,
``builder``, ``stock_dir``, ``gap`` (true: each record's ``gap_to_optimum_percent``, the MPOC paper's bound at
the plan's own running time, seconds per run), ``objective`` (``traction``, the default, or ``net``: what
the energy terms count, as ``--objective``), and ``model`` (``step_m``, ``point_mass``, ``air_brake``,
``rotating_mass``, ``strict_limits``: the options every model-running command has).

The batch is (routes + journeys) x consists x times x strategies x algorithms x seeds, except that
algorithms and seeds multiply only the strategies whose result depends on the optimiser and its seed
(``StrategyEntry.seeded`` in :mod:`locoplan.strategy.registry`); the others run once per route, consist
and time. A journey run plans the whole journey (``RunSpec.journey``). A glob takes the files of its
kind (a route glob passes over journey files and the other way round). Every problem is reported as
``file:line: field: message`` (exit 2): an unknown key, strategy or algorithm, a glob that matches nothing,
a journey file under routes (or a route under journeys), a time factor below 1.
"""

from __future__ import annotations

import fnmatch
import glob as _glob
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Optional

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .. import bounds
from ..catalogue import DEFAULT_CONSIST
from ..errors import InfeasibleError, InputError, Problem
from ..io.load import SCHEMAS, _line_for, file_schema, load_journey, load_route, load_train, read_yaml, validate_model
from ..model.journey import JOURNEY_SCHEMA
from ..optimize.registry import ALGORITHMS
from ..physics.energy import OBJECTIVES
from ..settings import RunSettings
from ..sim.calculator import DEFAULT_STEP_M, ModelOptions, TractionCalculator
from ..strategy import registry
from .spec import RunSpec

STUDY_SCHEMA = "locoplan/study@1"


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)

    step_m: float = Field(DEFAULT_STEP_M, gt=0, le=1000)
    point_mass: bool = False
    air_brake: Optional[bool] = None
    rotating_mass: Optional[float] = Field(None, ge=0, lt=1)
    strict_limits: bool = False


class StudyFile(BaseModel):
    """The study file's keys (unknown keys are errors, with a 'did you mean'). Strict types, as in every
    locoplan file: ``true`` is no seed, weight or tolerance, a quoted '10' no number (``times`` takes text:
    factors such as '1.1x')."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)

    schema_: Optional[str] = Field(None, alias="schema")
    routes: list[str] = Field(default_factory=list)
    journeys: list[str] = Field(default_factory=list)
    consists: list[str] = Field(default_factory=lambda: [DEFAULT_CONSIST], min_length=1)
    times: Optional[list[Any]] = Field(None, min_length=1)  # checked by _time_value (a bool is no time)
    strategies: list[str] = Field(default_factory=lambda: ["proposed"], min_length=1)
    algorithms: list[str] = Field(default_factory=lambda: ["issa"], min_length=1)
    seeds: list[int] = Field(default_factory=lambda: [1], min_length=1)
    weights: list[float] = Field(default_factory=lambda: [0.5, 0.5], min_length=2, max_length=2)
    tolerance_s: Optional[float] = Field(None, ge=0)
    window: bool = True
    builder: Optional[str] = None
    stock_dir: Optional[str] = None
    gap: bool = False
    objective: str = "traction"
    model: _Model = Field(default_factory=_Model)


@dataclass(frozen=True)
class Study:
    """A loaded study: its file, the settings, and the specs (the product, in a stable order)."""

    path: Path
    settings: StudyFile
    specs: list[RunSpec]


def _time_value(value, where: str) -> tuple[str, float]:
    """('s', seconds) or ('x', factor) from a study file's ``times`` entry; ValueError says why not."""
    if isinstance(value, bool) or value is None or isinstance(value, (list, dict)):
        raise ValueError(f"expected seconds or a factor such as '1.1x', got {short(value)}")
    if isinstance(value, (int, float)):
        lo, hi = bounds.LIMITS["time_s"]
        if not math.isfinite(value):
            raise ValueError(f"a running time must be a finite number of seconds (got {value})")
        if not lo <= value <= hi:
            raise ValueError(f"a running time must be in [{lo:g}, {hi:,.0f}] s (got {value:g}): no stop-to-stop run "
                             "is planned shorter than a second or longer than a week")
        return "s", float(value)
    text = str(value).strip().lower().replace(" ", "")
    if text.startswith("+") and text.endswith("%"):  # a running-time supplement on the fastest run: +10% is 1.1x
        try:
            text = f"{1 + float(text[1:-1]) / 100!r}x"
        except ValueError:
            raise ValueError(f"expected a supplement such as '+10%', got {value!r}") from None
    if text.endswith("x"):
        try:
            f = float(text[:-1])
        except ValueError:
            raise ValueError(f"expected a factor such as '1.1x', got {value!r}") from None
        if not (math.isfinite(f) and f >= 1):
            raise ValueError(f"a factor of the fastest run must be >= 1 (got {value!r}: no train runs faster than its fastest run)")
        if f > 10:
            raise ValueError(f"a factor of the fastest run must be at most 10, as on the command line (got {value!r}): "
                             "give seconds instead")
        return "x", f
    seconds = bounds.duration_s(text)  # 1500, 1500s, 25min, 1h05, 0:25:00: as --time reads them
    if seconds is None:
        try:
            seconds = float(text)
        except ValueError:
            raise ValueError(f"expected seconds (1500, 25min, 1h05, 0:25:00) or a factor such as '1.1x', got "
                             f"{short(value)}") from None
    return _time_value(seconds, where)


MAX_GLOB_ENTRIES = 100_000
"""A route glob looks at no more files and folders than this (a '**' over a whole disk is a mistake)."""


def safe_glob(pattern: str) -> list[str]:
    """``glob.glob(pattern, recursive=True)``, but a ``**`` walks folders without following links to folders
    (a link to a parent folder would loop without end) and looks at most at ``MAX_GLOB_ENTRIES`` entries
    (ValueError beyond)."""
    if "**" not in pattern:
        return _glob.glob(pattern)
    head, _, _ = pattern.partition("**")
    roots = _glob.glob(head) if _glob.has_magic(head) else [head or "."]
    flat = pattern.replace("/**/", "/").replace("**/", "")
    wide = pattern.replace("**", "*")
    out, seen = [], 0
    for root in roots:
        for folder, dirs, files in os.walk(root or ".", followlinks=False):
            seen += len(dirs) + len(files)
            if seen > MAX_GLOB_ENTRIES:
                raise ValueError(f"looks at more than {MAX_GLOB_ENTRIES:,} files and folders: name a narrower folder")
            for f in files:
                path = os.path.join(folder, f)
                if fnmatch.fnmatchcase(path, wide) or fnmatch.fnmatchcase(path, flat):
                    out.append(path)
    return out


def short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:55] + " ...>"


def load_study(path: str | Path) -> Study:
    """Read, check and expand a study file. Raises :class:`InputError` naming file, line and field."""
    path = Path(path)
    name = str(path)
    data, lines = read_yaml(path)
    study: StudyFile = validate_model(StudyFile, data, name, lines)  # type: ignore[assignment]

    def where(*loc) -> int | None:
        return _line_for(lines, loc)

    problems: list[Problem] = []
    if study.schema_ not in (None, STUDY_SCHEMA):
        problems.append(Problem(name, "schema", f"expected {STUDY_SCHEMA}, got {study.schema_!r}", where("schema")))
    for i, s in enumerate(study.strategies):
        if registry.lookup(s) is None:
            problems.append(Problem(name, f"strategies[{i}]", registry.unknown_message(s), where("strategies", i)))
    for i, a in enumerate(study.algorithms):
        if a not in ALGORITHMS:
            problems.append(Problem(name, f"algorithms[{i}]", f"unknown optimiser {a!r} (one of: {', '.join(ALGORITHMS)})",
                                    where("algorithms", i)))
    if study.builder is not None and registry.builder_name(study.builder) not in registry.BUILDERS:
        problems.append(Problem(name, "builder", registry.builder_message(study.builder), where("builder")))
    if study.objective not in OBJECTIVES:
        problems.append(Problem(name, "objective", f"unknown objective {study.objective!r}: use one of "
                                f"{', '.join(OBJECTIVES)}", where("objective")))
    w = study.weights
    if min(w) < 0 or abs(sum(w) - 1) > 1e-9:
        problems.append(Problem(name, "weights", f"expected two non-negative weights summing to 1 (w_time, w_energy), got {list(w)}",
                                where("weights")))
    lo_seed, hi_seed = bounds.LIMITS["seed"]
    for i, seed in enumerate(study.seeds):
        if not lo_seed <= seed <= hi_seed:
            problems.append(Problem(name, f"seeds[{i}]", f"a seed is a whole number 0 .. 2**63 - 1 (got "
                                    f"{seed if abs(seed) < 10**30 else 'an integer of %d digits' % len(str(abs(seed)))})",
                                    where("seeds", i)))
    if study.tolerance_s is not None and study.tolerance_s > bounds.LIMITS["time_s"][1]:
        problems.append(Problem(name, "tolerance_s", f"must be at most a week, {bounds.LIMITS['time_s'][1]:,.0f} s "
                                f"(got {study.tolerance_s:g})", where("tolerance_s")))
    lo_step, hi_step = bounds.LIMITS["step_m"]
    if not lo_step <= study.model.step_m <= hi_step:
        problems.append(Problem(name, "model.step_m", f"must be in [{lo_step:g}, {hi_step:,.0f}] m (got "
                                f"{study.model.step_m:g}): the reporting grid spacing", where("model", "step_m")))
    if len(set(study.seeds)) != len(study.seeds):
        problems.append(Problem(name, "seeds", "a seed is listed twice", where("seeds")))
    times = []
    for i, t in enumerate(study.times or []):
        try:
            times.append((_time_value(t, name), t))
        except ValueError as exc:
            problems.append(Problem(name, f"times[{i}]", str(exc), where("times", i)))
    base = path.parent
    if not study.routes and not study.journeys:
        problems.append(Problem(name, "routes", "name the routes or the journeys to run (routes:, journeys:, or both)",
                                where("routes") or where("journeys") or 1))
    routes = [f for f, _ in _study_files(name, "routes", study.routes, base, where, problems)]
    journeys = _study_files(name, "journeys", study.journeys, base, where, problems)
    if problems:
        raise InputError(problems)
    routes = list(_by_file(routes).values())  # a route matched by two globs, or named by two paths, runs once
    first: dict[str, tuple[Path, int]] = {}
    for f, i in journeys:  # so does a journey (named by its first entry)
        first.setdefault(_same(f), (f, i))
    journeys = list(first.values())
    unique: dict[tuple, object] = {}
    for t, raw in times:  # 200 and 200.0, or 1.1x and +10%, are one planned time: one run
        unique.setdefault(t, (t, raw))
    times = list(unique.values())
    _check_count(name, study, len(routes) + len(journeys), len(times))

    m = study.model
    options = ModelOptions(step_m=m.step_m, point_mass=m.point_mass,
                           air_brake=(not m.point_mass) if m.air_brake is None else m.air_brake,
                           rotating_mass=m.rotating_mass, strict_limits=m.strict_limits)
    consists = [c if not (Path(c).suffix in (".yaml", ".yml") or "/" in c) or Path(c).is_absolute() else str(base / c)
                for c in study.consists]
    stock = None if study.stock_dir is None else str(base / study.stock_dir)
    planned = _planned_times(name, routes, consists, stock, options, times, where, study.tolerance_s)
    planned.update(_journey_times(name, journeys, consists, stock, options, times, where, study.tolerance_s))
    common = RunSettings(options, weights=tuple(study.weights), tolerance_s=study.tolerance_s, window=study.window,
                         builder=study.builder, yardstick=study.gap, objective=study.objective)
    specs: list[RunSpec] = []
    for kind, files in (("route", routes), ("journey", [j for j, _ in journeys])):
        for f in files:
            for c in consists:
                for t_s, label in planned[(f, c)]:
                    for s in study.strategies:
                        pairs = [(a, seed) for a in study.algorithms for seed in study.seeds] if registry.STRATEGIES[s].seeded \
                            else [(study.algorithms[0], study.seeds[0])]
                        for a, seed in pairs:
                            settings = common.replace(algorithm=a, seed=seed, time_s=t_s)
                            specs.append(RunSpec(**{kind: str(f)}, consist=c, strategy=s, settings=settings,
                                                 stock_dir=stock, tags=(("time", label),) if label else ()))
    return Study(path, study, list(dict.fromkeys(specs)))  # a factor that comes to a time also given in seconds: once


MAX_STUDY_RUNS = 100_000
"""A study file expands to at most this many runs (each an optimisation of seconds to minutes: 100,000 is weeks on
a cluster, and the largest store whose summaries, exports and plots are measured). Counted from the lists' lengths
before any run is made, so a file whose lists multiply to millions is refused at once, not after it fills memory."""


def _check_count(name: str, study, files: int, times: int) -> None:
    """Refuse a study whose product of lists exceeds :data:`MAX_STUDY_RUNS`, before it is expanded."""
    per_time = sum(len(study.algorithms) * len(study.seeds) if registry.STRATEGIES[s].seeded else 1
                   for s in study.strategies)
    count = files * len(study.consists) * max(times, 1) * per_time
    if count > MAX_STUDY_RUNS:
        raise InputError(Problem(name, "", f"expands to {count:,} runs ({files:,} routes and journeys x "
                                 f"{len(study.consists):,} consists x {max(times, 1):,} times x {per_time:,} strategy, "
                                 f"optimiser and seed runs), more than the limit of {MAX_STUDY_RUNS:,} runs of one study "
                                 "file: split it into several studies (one store can take them all)"))


def _same(path: Path) -> str:
    """The file ``path`` is, whatever the path that names it (``r.yaml``, ``./r.yaml``, a link to it)."""
    return os.path.realpath(path)


def _by_file(paths: list[Path]) -> dict[str, Path]:
    out: dict[str, Path] = {}
    for p in paths:
        out.setdefault(_same(p), p)
    return out


_KINDS = {"routes": ("route", "locoplan/route@1", "journeys"), "journeys": ("journey", JOURNEY_SCHEMA, "routes")}


def _declared(path: Path) -> str | None:
    """The kind of file ``path`` declares (its schema), None when it cannot be read (its loader says why)."""
    try:
        return file_schema(path)
    except InputError:
        return None


def _study_files(name: str, key: str, patterns: list[str], base: Path, where, problems: list[Problem]) -> list[tuple[Path, int]]:
    """The files of a study's ``routes`` or ``journeys`` entries (files or globs, relative to the study's folder),
    each with the index of the entry that named it. A glob takes the files of its kind (passing over the other
    locoplan kinds, study files among them: a glob may match the study itself); a file named outright
    that is another locoplan kind (a journey under routes) is a problem naming the entry."""
    what, schema, other = _KINDS[key]
    out: list[tuple[Path, int]] = []
    for i, pattern in enumerate(patterns):
        full = Path(pattern) if Path(pattern).is_absolute() else base / pattern
        if any(c in pattern for c in "*?["):
            try:
                found = sorted(Path(p) for p in safe_glob(str(full)) if p.endswith((".yaml", ".yml")))
            except ValueError as exc:
                problems.append(Problem(name, f"{key}[{i}]", f"{pattern!r}: {exc}", where(key, i)))
                continue
            found = [f for f in found if _declared(f) not in (set(SCHEMAS) | {STUDY_SCHEMA}) - {schema}]
            if not found:
                problems.append(Problem(name, f"{key}[{i}]", f"{pattern!r} matches no {what} file (looked in {full.parent})",
                                        where(key, i)))
            out += [(f, i) for f in found]
        elif not full.is_file():
            why = (f"{full} is a folder: name the {what} files in it, e.g. '{pattern.rstrip('/')}/*.yaml'" if full.is_dir()
                   else f"{full} is not a regular file" if full.exists() else f"no such {what} file: {full}")
            problems.append(Problem(name, f"{key}[{i}]", why, where(key, i)))
        elif (declared := _declared(full)) in set(SCHEMAS) - {schema}:
            hint = f": list it under {other}" if declared == _KINDS[other][1] else ""
            problems.append(Problem(name, f"{key}[{i}]", f"{pattern!r} is a {declared} file, not a {what}{hint}", where(key, i)))
        else:
            out.append((full, i))
    return out


def _journey_times(name, journeys, consists, stock, options, times, where, tolerance_s=None) -> dict:
    """(journey, consist) -> [(total running time [s] or None, label)]: a journey's running time is its total,
    dwells excluded; a factor is of its fastest total (its legs' fastest runs), rounded up to 0.1 s as
    ``locoplan journey --time`` rounds it; no times: the journey's own (``timetable``)."""
    from .journey import legs_of, total_running_time

    out = {}
    trains = {c: load_train(c, stock) for c in consists}
    for j, i in journeys:
        journey, route = load_journey(j)
        if not times:
            try:
                total_running_time(journey, None, str(j))
            except InputError:
                raise InputError(Problem(name, f"journeys[{i}]", f"{j} gives no running time (no run_time_s, no time_s at "
                                         "its last station): give the total running times (seconds, factors of the fastest "
                                         "run such as '1.1x', or supplements on it such as '+10%')", where("journeys", i))) from None
        for c in consists:
            try:
                legs = legs_of(journey, route, trains[c], options)
            except InfeasibleError as exc:
                if any(kind == "x" for (kind, _), _ in times):
                    raise InfeasibleError(f"{name}:{where('journeys', i) or '?'}: journeys[{i}]: times are factors of the "
                                          f"fastest run, but {j} has none with '{trains[c].name}': {exc}; drop that journey "
                                          "or consist, or give seconds") from None
                legs = None
            if legs and tolerance_s is not None:
                shortest = min(leg.fastest_s for leg in legs)
                if tolerance_s >= shortest:
                    raise InputError(Problem(name, "tolerance_s", f"a punctuality window of +-{tolerance_s:g} s is not below "
                                             f"the fastest run of a leg of {j} ({shortest:.1f} s): each leg is held to it, "
                                             "and its window would open at or before departure", where("tolerance_s")))
            if not times:
                out[(j, c)] = [(None, "timetable")]
                continue
            fastest = None if legs is None else sum(leg.fastest_s for leg in legs)
            out[(j, c)] = [(bounds.time_of((kind, value), fastest), f"{value:g}{kind}") for (kind, value), _ in times]
    return out


def _planned_times(name, routes, consists, stock, options, times, where, tolerance_s=None) -> dict:
    """(route, consist) -> [(T0 [s] or None, label)]: factors times the fastest run, rounded up to 0.1 s
    (rounding down could put T0 below the fastest run)."""
    out = {}
    trains = {c: load_train(c, stock) for c in consists}
    for r in routes:
        route = load_route(r)
        for c in consists:
            if not times:
                if route.schedule is None:
                    raise InputError(Problem(name, "times", f"route {r} has no schedule: give the planned running "
                                             "times (seconds, factors of the fastest run such as '1.1x', or supplements on it such as '+10%')", where("routes")))
                out[(r, c)] = [(None, "schedule")]
                continue
            fastest = None
            rows = []
            for i, ((kind, value), raw) in enumerate(times):
                if kind == "x":
                    if fastest is None:
                        calc = TractionCalculator(route, trains[c], options)
                        run = calc.evaluate(("T",), np.zeros((1, 0)))
                        fastest = float(run.running_time_s[0])
                        if not (bool(run.feasible[0]) and math.isfinite(fastest)):
                            # no fastest run, so no factor of it: say why, as a command on this route would
                            raise InfeasibleError(
                                f"{name}:{where('times', i) or '?'}: times[{i}]: {raw!r} is a factor of the fastest "
                                f"run, but no run of '{route.name}' ({r}) with '{trains[c].name}' reaches the stop "
                                f"(the fastest run: {run.reason(0)}); drop that route or consist, or give seconds")
                    rows.append((math.ceil(value * fastest * 10 - 1e-9) / 10, f"{value:g}x"))
                else:
                    rows.append((value, f"{value:g}s"))
                t0 = rows[-1][0]
                tol = tolerance_s if tolerance_s is not None else (route.schedule.tolerance_s if route.schedule else None)
                if tol is not None and t0 is not None and tol >= t0:
                    raise InputError(Problem(name, "tolerance_s" if tolerance_s is not None else f"times[{i}]",
                                             f"a punctuality window of +-{tol:g} s is not below the planned running time "
                                             f"{t0:g} s ({r}): the window would open at or before departure",
                                             where("tolerance_s") if tolerance_s is not None else where("times", i)))
            out[(r, c)] = rows
    return out
