"""The decisions of the command line, as library functions: a script that calls these gets the same
checks, planned running times, tolerances and exit codes as ``locoplan`` does.

Nothing here prints or exits. A check raises :class:`~locoplan.errors.InputError` (exit 2); a run that
does not do its job is a message in a :class:`Verdict` (exit 1). The command line (``cli*.py``) parses
its options into these calls and prints what comes back; tables and files are in
:mod:`locoplan.reporting`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Optional

from . import bounds
from .runner import punctuality_tolerance  # noqa: F401  (the window of a re-plan: cli_replan)
from .errors import InputError, LocoplanError, Problem
from .errors import EXIT_FAILED, EXIT_INTERRUPTED, EXIT_INVALID, EXIT_OK, EXIT_RULE, VERDICTS
from .settings import RunSettings
from .sim.calculator import DEFAULT_STEP_M, ModelOptions


CMDLINE = bounds.CMDLINE


# ------------------------------------------------------------------------------------------ the train model
@dataclass(frozen=True)
class ModelRequest:
    """The train-model switches as a user gives them (the command line's model options, once).

    step_m: reporting grid [m]; point_mass: the papers' point mass; air_brake: None = on, off with
    ``point_mass``; rotating_mass: gamma in [0, 1), None = each vehicle's own factor; strict_limits:
    coasting up to a limit makes a plan infeasible. :meth:`options` checks them and gives the
    calculator's :class:`~locoplan.sim.calculator.ModelOptions`.
    """

    step_m: float = DEFAULT_STEP_M
    point_mass: bool = False
    air_brake: Optional[bool] = None
    rotating_mass: Optional[float] = None
    strict_limits: bool = False

    def options(self) -> ModelOptions:
        bounds.step(self.step_m)
        if self.rotating_mass is not None and not 0 <= self.rotating_mass < 1:
            raise InputError(Problem(CMDLINE, "--rotating-mass", f"must be in [0, 1) (got {self.rotating_mass:g})"))
        air = (not self.point_mass) if self.air_brake is None else self.air_brake
        return ModelOptions(step_m=self.step_m, point_mass=self.point_mass, air_brake=air,
                            rotating_mass=self.rotating_mass, strict_limits=self.strict_limits)


# ------------------------------------------------------------------------------------------ option values
def names(text: str, option: str) -> list[str]:
    """A comma list of names (strategies, optimisers, fields): at least one."""
    found = [x.strip() for x in text.split(",") if x.strip()]
    if not found:
        raise InputError(Problem("", option, "name at least one"))
    return found


def weights(text: str, option: str = "--weights") -> tuple[float, float]:
    """Fitness weights ``w_time,w_energy``."""
    return bounds.weights(text, option)


def value_grid(text: str, option: str) -> list[float]:
    """``'0.1:0.9:0.1'`` (start:stop:step, inclusive) or ``'1470,1500,1530'``: time weights
    (``--weight-grid``), factors of the fastest run (``--factors``, 1 .. 10) or running times [s]."""
    return (bounds.TEXT_NUMBERS.get(option) or bounds.TEXT_NUMBERS["--times"])(text, option)


def positive_numbers(text: str, option: str) -> tuple[float, ...]:
    """A comma list of positive numbers (``--masses``, ``--times`` of the drivers' simulation)."""
    try:
        values = tuple(float(x) for x in bounds.items(text, option)) if text.strip() else ()
    except ValueError:
        raise InputError(Problem(CMDLINE, option, f"expected a comma list of numbers, got {text!r}")) from None
    if not values or min(values) <= 0:
        raise InputError(Problem(CMDLINE, option, f"expected positive numbers, got {text!r}"))
    return values


def seed_list(text: str, option: str = "--seeds") -> tuple[int, ...]:
    """A comma list of whole-number seeds."""
    return tuple(bounds.seed_list(text, option))


def one_of(first: Optional[object], second: Optional[object], option: str, message: str,
           exactly: bool = False) -> None:
    """Two options that exclude each other: not both (``exactly``: and not neither)."""
    if (first is not None and second is not None) or (exactly and first is None and second is None):
        raise InputError(Problem(CMDLINE if exactly else "", option, message))


def check_choice(value: Optional[str], choices: Iterable[str], option: str, what: str) -> None:
    """``value`` (None: not given) is one of ``choices``."""
    choices = list(choices)
    if value is not None and value not in choices:
        raise InputError(Problem("", option, f"unknown {what} {value!r} (one of: {', '.join(choices)})"))


def check_fields(wanted: Iterable[str], fields: Iterable[str], option: str) -> None:
    """Every field of ``wanted`` (a summary's grouping) is one the rows have."""
    fields = set(fields)
    unknown = [g for g in wanted if g not in fields]
    if unknown:
        raise InputError(Problem("", option, f"unknown field {unknown[0]!r} (fields: {', '.join(sorted(fields))})"))


# ------------------------------------------------------------------------------------------ validate
@dataclass
class Validation:
    """``validate``: per file ``{"file", "valid", ...}`` (valid: ``kind``, ``summary``, ``description``,
    ``warnings``; else ``problems``), every problem and every warning (implausible but valid)."""

    results: list[dict]
    problems: list[Problem]
    warnings: list[Problem]

    @property
    def exit_code(self) -> int:
        return EXIT_INVALID if self.problems else EXIT_OK

    def to_dict(self) -> dict:
        from dataclasses import asdict

        return {"valid": not self.problems, "results": self.results, "problems": [asdict(p) for p in self.problems],
                "warnings": [asdict(w) for w in self.warnings]}


def validate_files(files: Iterable, stock_dir=None) -> Validation:
    """Check route, vehicle, consist and journey files (and the ``--stock-dir`` folder); every problem of every
    file is collected, none is raised."""
    from dataclasses import asdict

    from .io.load import check_folder, load_journey, read_yaml, route_warnings, validate_data
    from .reporting.tables import describe, describe_data

    report = Validation([], [], [])
    try:
        if stock_dir is not None:
            check_folder(stock_dir, "--stock-dir")
    except InputError as exc:
        report.problems += exc.problems
    for f in files:
        try:
            data, lines = read_yaml(f)
            model = validate_data(data, str(f), lines)
            if data.get("schema") == "locoplan/journey@1":
                model, _ = load_journey(f)  # its route too, and the stations against it
            d = describe_data(model, str(f), stock_dir)
            warns = route_warnings(model, str(f), lines) if d["kind"] == "route" else []
            report.results.append({"file": str(f), "valid": True, "kind": d["kind"], "summary": describe(model, str(f), stock_dir),
                                   "description": d, "warnings": [asdict(w) for w in warns]})
            report.warnings += warns
        except InputError as exc:
            report.problems += exc.problems
            report.results.append({"file": str(f), "valid": False, "problems": [asdict(p) for p in exc.problems]})
    return report




# ------------------------------------------------------------------------------------------ planned time
@dataclass(frozen=True)
class PlannedTime:
    """A planned running time as asked: ``time_s`` None = the route's schedule; ``note`` says what a
    factor of the fastest run came to (None for seconds as given)."""

    time_s: Optional[float]
    note: Optional[str] = None


def planned_time(text: Optional[str], route, train=None, options: Optional[ModelOptions] = None,
                 option: str = "--time") -> PlannedTime:
    """``--time`` in seconds: seconds as given; a factor (``1.1x``) or a supplement (``+10%``) of the
    fastest run of ``route`` and ``train`` (loaded models; the calculator is built only for a factor)."""
    req = bounds.time_request(text, option)
    if req is None or req[0] == "s":
        return PlannedTime(None if req is None else req[1])
    fastest = fastest_run_s(route, train, options, f"{option} {text}")
    t = bounds.time_of(req, fastest)
    return PlannedTime(t, f"{option} {text}: T0 = {t:g} s ({req[1]:g} x the fastest run, {fastest:.1f} s)")


def fastest_run_s(route, train, options: Optional[ModelOptions], asked: str) -> float:
    """The fastest run's time [s] that a factor (``asked``, e.g. ``--time 1.1x``) is taken of; InfeasibleError with
    the physical reason on a line the train cannot run at all."""
    from .sim.calculator import TractionCalculator

    return TractionCalculator(route, train, options or ModelOptions()).fastest_time_for_factor_s(asked)


@dataclass(frozen=True)
class PlannedTimes:
    """Planned running times as asked (``--times``), in seconds; ``note`` says what the factors of the
    fastest run came to (None when every time was given in seconds)."""

    times_s: list[float]
    note: Optional[str] = None


def planned_times(requests: list, route=None, train=None, options: Optional[ModelOptions] = None,
                  option: str = "--times", fastest_s: Optional[Callable[[], float]] = None) -> PlannedTimes:
    """``--times`` in seconds (``requests`` from :func:`locoplan.bounds.times_request`): seconds as given,
    factors and supplements of the fastest run of ``route`` and ``train`` (loaded models; the calculator is
    built only when a factor is among them), or of what ``fastest_s()`` returns (a journey's fastest total)."""
    if all(kind == "s" for kind, _ in requests):
        return PlannedTimes([v for _, v in requests])
    fastest = fastest_s() if fastest_s is not None else fastest_run_s(route, train, options, option)
    times = [bounds.time_of(r, fastest) for r in requests]
    shown = ", ".join(f"{t:g}" for t in times)
    return PlannedTimes(times, f"{option}: T0 = {shown} s (the fastest run is {fastest:.1f} s)")


def window_half_width(summary: dict) -> Optional[float]:
    """The punctuality tolerance +- [s] a run was held to (None: no window, ranked by fitness alone)."""
    window = summary.get("window_s")
    return None if window is None else (window[1] - window[0]) / 2


# ------------------------------------------------------------------------------------------ one plan
@dataclass
class Plan:
    """One plan of ``simulate`` or ``optimize``: the loaded route and train, the strategy context and the
    run (``run.summary`` is the --json object, ``run.result.profile`` the profile); ``failures`` is the
    schedule's verdict (infeasible; a timetabled strategy outside T0 +- tolerance)."""

    route: object
    train: object
    context: object
    run: object

    @property
    def summary(self) -> dict:
        return self.run.summary

    @property
    def failures(self) -> list[Optional[str]]:
        from .runner import schedule_verdict

        return [schedule_verdict(self.context, self.run)]


def simulate(route, train, settings: RunSettings, *, strategy: Optional[str] = None,
             sequence: Optional[str] = None) -> Plan:
    """``simulate``: the traction calculation of a ``sequence`` ("T:0,K:2200,C:9000,B") or of a built-in
    ``strategy`` (default time-saving); a measured plan's punctuality is reported, not held to a window.
    ``settings`` (:class:`locoplan.settings.RunSettings`): the model, the planned time, E_min, the seed and
    algorithm and the builder; the planned time is needed only by a strategy that plans to it, and the gap to E*
    is not computed."""
    from .runner import make_context, run_sequence, run_strategy

    from .strategy.registry import lookup

    one_of(strategy or None, sequence or None, "--sequence", "give either --strategy or --sequence, not both")
    entry = lookup(strategy) if strategy else None  # a strategy that plans to a time needs one (the schedule's)
    ctx = make_context(route, train, settings.replace(need_time=bool(entry and entry.needs_time), yardstick=False))
    run = (run_sequence(ctx, sequence) if sequence is not None
           else run_strategy(ctx, strategy or "time-saving", with_fitness=settings.e_min_kwh is not None))
    return Plan(route, train, ctx, run)


def optimize(route, train, settings: RunSettings, *,
             callback: Optional[Callable[[int, float], None]] = None) -> Plan:
    """``optimize``: the proposed strategy (condition sequence + optimised switching points) with ``settings``
    (:class:`locoplan.settings.RunSettings`; ``yardstick``: the gap to E*); E_min, when not given, from the
    energy-saving run first. ``callback(iteration, best)`` follows the search."""
    from .optimize.registry import get_algorithm
    from .runner import make_context, run_strategy

    get_algorithm(settings.algorithm)
    ctx = make_context(route, train, settings, callback=callback)
    if settings.e_min_kwh is None:
        ctx.e_min()  # the energy-saving run first, so that a progress bar then shows the proposed run alone
    run = run_strategy(ctx, "proposed")
    run.summary["solve_time_s"] = round(run.outcome.solve_time_s, 3)
    return Plan(route, train, ctx, run)


# ------------------------------------------------------------------------------------------ verdicts
def group_reasons(messages: Iterable[str]) -> list[str]:
    """``['four-stage: R', 'proposed: R']`` -> ``['four-stage, proposed: R']``: a reason shared by several
    strategies is said once, naming them all (order kept)."""
    groups: dict[str, list[str]] = {}
    for m in messages:
        name, sep, reason = m.partition(": ")
        if not sep or " " in name:
            name, reason = "", m
        groups.setdefault(reason, []).append(name)
    return [(", ".join(n for n in names if n) + ": " if any(names) else "") + reason for reason, names in groups.items()]


@dataclass
class Verdict:
    """What a command's results come to: ``failures`` (each a result that did not do its job, said
    once) make exit 1; ``notes`` are said and change nothing."""

    failures: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def exit_code(self) -> int:
        return EXIT_FAILED if self.failures else EXIT_OK


def verdict(failures: Iterable[Optional[str]], restate: Callable[[str], str] = lambda m: m) -> Verdict:
    """The one rule of every command: a result that fails its job (a reason) is exit 1, each reason said
    once (``restate`` may say where a value came from)."""
    return Verdict(group_reasons(restate(m) for m in dict.fromkeys(failures) if m))


def compare_verdict(summaries: list[dict], failures: list[str], named: bool, timetabled: Iterable[str],
                    restate: Callable[[str], str] = lambda m: m) -> Verdict:
    """``compare``: a strategy named by the user that fails its job is exit 1; with the default list,
    only when no timetabled strategy is on time (a failed one is then its row and a note)."""
    timetabled = set(timetabled)
    on_time = any(s["strategy"] in timetabled and s["feasible"] and s["punctual"] for s in summaries)
    if not named and on_time:
        return Verdict(notes=group_reasons(dict.fromkeys(failures)))
    return verdict(failures, restate)


def confirmed_verdict(feasible: bool, reason: Optional[str]) -> Verdict:
    """An optimal control is a result only when the calculator confirms it (re-simulation)."""
    return Verdict() if feasible else Verdict([reason or ""])


# ------------------------------------------------------------------------------------------ optimal control
def check_energy_ocp(nodes: Optional[int], state_nodes: Optional[int], mesh_tol: float, max_degree: int) -> None:
    """``ocp --objective energy``: the Radau method refines its own mesh (no node counts), within a
    relative tolerance in (0, 1) and 4 .. 30 LGR points per interval."""
    problems = []
    if nodes is not None or state_nodes is not None:
        problems.append(Problem("ocp", "--nodes" if nodes is not None else "--state-nodes",
                                "radau refines its own mesh; set --mesh-tol and --max-phase-degree instead"))
    if not (0 < mesh_tol < 1):
        problems.append(Problem("ocp", "--mesh-tol", f"must be in (0, 1) (got {mesh_tol:g})"))
    if not 4 <= max_degree <= 30:
        problems.append(Problem("ocp", "--max-phase-degree", f"must be between 4 and 30 LGR points (got {max_degree})"))
    if problems:
        raise InputError(problems)


def bound_times(time_s: Optional[str], times: Optional[str]) -> Optional[list[tuple[str, float]]]:
    """``bound``: one time (``--time``, None) or a curve of running times (``--times``, each > 0 s), as
    :func:`locoplan.bounds.times_request` gives them (turned into seconds by :func:`planned_times`)."""
    one_of(times, time_s, "--times", "give either --time or --times, not both")
    return bounds.times_request(times, "--times") if times else None


def energy_curve(route, train, options: ModelOptions, times_s: list[float], *, mesh_tol: float, max_degree: int,
                 curve: bool, step: Callable[[str], None] = lambda text: None, check: bool = False,
                 objective: str = "traction") -> dict:
    """The least energy E* at each running time: ``{"route", "consist", "objective", "results": [rows]}``, the
    traction work or (``objective="net"``) the net energy, each row with the optimum's traction work and what
    its electric brake recovers. On a ``curve`` a time whose optimum fails is its row with a ``reason``; a
    single time raises. ``check``: each E* also by the second, independent method (``ocp.bound.check_bound``:
    multi-phase Radau collocation, ``mesh_tol`` and ``max_degree`` its settings) and the two's difference."""
    from .ocp.bound import check_bound, energy_bound, energy_bounds

    bounds.objective(objective)
    rows = []
    if curve:
        curve_bounds = dict(zip(times_s, energy_bounds(route, train, options, times_s, objective=objective,
                                                       progress=lambda t: step(f"E* at {t:g} s"))))
    for t in times_s:
        if not curve:
            step(f"E* at {t:g} s")
        try:
            if curve:
                b = curve_bounds[t]
                if isinstance(b, LocoplanError):
                    raise b
            else:
                b = energy_bound(route, train, options, t, objective=objective)
            acc = b.accuracy_percent

            def rounded(x):
                return None if x is None else round(x, 3)

            row = {"time_s": t, "energy_kwh": round(b.energy_kwh, 3), "traction_energy_kwh": rounded(b.traction_kwh),
                   "recovered_energy_kwh": rounded(b.recovered_kwh),
                   "net_energy_kwh": None if b.traction_kwh is None or b.recovered_kwh is None
                   else round(b.traction_kwh - b.recovered_kwh, 3), "converged": b.converged,
                   "accuracy_percent": None if acc is None else float(f"{acc:.2g}"),
                   "slope_kwh_per_s": None if b.slope_kwh_per_s is None else round(b.slope_kwh_per_s, 5),
                   "method": b.method, "cells": b.cells, "solve_time_s": round(b.solve_time_s, 3), "reason": None}
            if not curve and objective == "traction":
                row.update(cycle_optimum_row(route, train, options, t))
            if check:
                step(f"E* at {t:g} s, second method")
                c = check_bound(route, train, options, t, mesh_tol=mesh_tol, max_degree=max_degree, objective=objective)
                acc_c = c.accuracy_percent
                row["check"] = {"method": "multi-phase Radau collocation", "lgr_points": c.cells,
                                "energy_kwh": round(c.energy_kwh, 3),
                                "accuracy_percent": None if acc_c is None else float(f"{acc_c:.2g}"),
                                "difference_percent": round(100 * (b.energy_kwh - c.energy_kwh) / c.energy_kwh, 4),
                                "solve_time_s": round(c.solve_time_s, 3)}
            rows.append(row)
        except LocoplanError as exc:
            if not curve:
                raise
            rows.append({"time_s": t, "energy_kwh": None, "traction_energy_kwh": None, "recovered_energy_kwh": None,
                         "net_energy_kwh": None, "converged": False, "accuracy_percent": None,
                         "slope_kwh_per_s": None, "method": None, "cells": None, "solve_time_s": None,
                         "reason": str(exc)})
    return {"route": route.name, "consist": train.name, "objective": objective, "results": rows}


def cycle_optimum_row(route, train, options: ModelOptions, time_s: float) -> dict:
    """``bound`` where the consist's air brake cycles on the line: the least energy of a drive that keeps the cycle
    (``strategy.cycle_start.cycle_optimum``) beside E*, with its accuracy; {} where the model has no cycle or it
    cannot bind there (the cycle optimum is E* itself), so that ``bound`` is unchanged for them."""
    from .strategy.cycle_start import cycle_optimum

    co = cycle_optimum(route, train, options, time_s)
    if not co.cycles or co.energy_kwh is None:
        return {}
    acc = co.accuracy_percent
    return {"optimum_with_cycle_kwh": round(co.energy_kwh, 3),
            "optimum_with_cycle_accuracy_percent": None if acc is None else float(f"{acc:.2g}"),
            "optimum_with_cycle_cells_m": [g["cell_m"] for g in co.grids],
            "optimum_with_cycle_solve_time_s": round(co.solve_time_s, 3)}


def curve_verdict(rows: list[dict]) -> Verdict:
    """``bound``'s curve: each running time asked for without an optimum is a failure (exit 1, as on
    every command: the other times' rows are still written and shown)."""
    return verdict(f"E* at {row['time_s']:g} s: {row['reason'] or 'no optimum'}" for row in rows
                   if row["energy_kwh"] is None)


def curve_exit_code(rows: list[dict]) -> int:
    """``bound``: exit 1 when a running time asked for has no optimum (:func:`curve_verdict`)."""
    return curve_verdict(rows).exit_code


# ------------------------------------------------------------------------------------------ drivers
def check_counts(**counts: int) -> None:
    """Counts that must be at least 1 (``drivers=40, runs=5``), named by their flags."""
    for name, value in counts.items():
        if value < 1:
            raise InputError(Problem(CMDLINE, "--" + name.replace("_", "-"), "must be >= 1"))


__all__ = ["EXIT_OK", "EXIT_RULE", "EXIT_FAILED", "EXIT_INVALID", "EXIT_INTERRUPTED", "VERDICTS", "Plan", "simulate", "optimize", "Validation", "validate_files", "ModelRequest", "PlannedTime", "PlannedTimes", "Verdict",
           "names", "weights", "check_choice", "check_fields", "value_grid", "positive_numbers", "seed_list", "one_of", "planned_time", "planned_times",
           "window_half_width", "group_reasons", "verdict", "compare_verdict", "confirmed_verdict",
           "check_energy_ocp", "bound_times", "energy_curve", "curve_verdict", "curve_exit_code", "check_counts"]


# ------------------------------------------------------------------------------------------ replay
@dataclass
class Replayed:
    """``locoplan replay``: every run against E* at its own running time (``learn.replay.RunReplay``), the
    ``--json`` document (``runs``, ``summary``, the section rule) and the verdict: a run with no E* (a log
    faster than the model's train can run the line, a consist that cannot run it) fails its job."""

    replays: list
    document: dict
    verdict: Verdict


def replay(runs: list, options: ModelOptions, level_permille: float = 2.0,
           progress: Callable[[object], None] = lambda run: None) -> Replayed:
    """Each logged run (``io.logs.load_logs``) against E* at its own running time, section by section, and the
    summary over the runs (``learn.replay``)."""
    from .learn.replay import replay_logs, summary

    bounds.check_option("--level", level_permille)
    replays = replay_logs(runs, options, level_permille, progress)
    doc = {"model": {"point_mass": options.point_mass, "air_brake": options.air_brake,
                     "rotating_mass": options.rotating_mass},
           "level_permille": level_permille, "summary": summary(replays), "runs": [r.to_dict() for r in replays]}
    return Replayed(replays, doc, verdict(f"{r.run.log_file}: {r.reason}" for r in replays if r.reason))


# ------------------------------------------------------------------------------------------ on board
def replanner(route, train, options: ModelOptions, t0_s: float, tolerance_s: float):
    """The set-up of on-board re-planning (``optimize.replan.Replanner``): the DP's cost-to-go at a ladder of
    prices around T0's; InfeasibleError where the train cannot run the line."""
    from .optimize.replan import Replanner

    return Replanner(route, train, options, planned_s=t0_s, tolerance_s=tolerance_s)


def replan_verdict(summary: dict) -> Verdict:
    """A re-plan outside its window is exit 1 (late even on the fastest remaining run, or early even on the least
    energy), as any plan outside its window."""
    if summary["on_time"]:
        return Verdict()
    w = summary["window_s"]
    if summary["late_s"] > 0:
        why = (f"late: the fastest remaining run arrives at {summary['arrival_s']:.1f} s, "
               f"{summary['late_s']:.1f} s after the planned {summary['planned_arrival_s']:.1f} s (window "
               f"{w[0]:.1f} .. {w[1]:.1f} s)")
    else:
        why = (f"early: the least-energy remaining run arrives at {summary['arrival_s']:.1f} s, before the window "
               f"{w[0]:.1f} .. {w[1]:.1f} s")
    return Verdict([why])


def drive_verdict(summary: dict) -> Verdict:
    """``drive``: the closed loop's job is to arrive inside the window."""
    c = summary["closed_loop"]
    if c.get("inside_window"):
        return Verdict()
    w = summary["window_s"]
    what = f"arrives at {c['arrival_s']:.1f} s" if c.get("arrived") else "does not arrive (" + c.get("note", "") + ")"
    return Verdict([f"the closed-loop run {what}, outside the window {w[0]:.1f} .. {w[1]:.1f} s"])
