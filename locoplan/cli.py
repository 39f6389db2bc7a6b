"""The ``locoplan`` command line: thin typer commands that parse options and call one library function each.

Shared consoles, option declarations and parsing live in :mod:`locoplan.cli_common`; tables in
:mod:`locoplan.reporting.tables`; the other command modules (``cli_ocp``, ``cli_learn``, ``cli_import``,
``cli_batch``) register their commands onto :data:`app` at the end of this module.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.markup import escape

from . import __version__
from .cli_common import (ALGO, BUILDER, CHAINAGE, COMMAND_LINE, COMMAND_PARAMS, CONSIST, EMIN, GAP, JSON, MODEL, OBJECTIVE, PARAMS, PLOT_TD, ROUTE, SEED, STOCK, TIME, TOL, departure_s, plot_runs_td,
                         WEIGHTS,
                         WINDOW, WORKERS, _check_outputs, _emit, _fail_if, _load, _time, _times, fail_on, json_out, locate_schedule,
                         _names, _range, all_or_none, err, guarded, out, run_progress, MAX_PROBLEMS, plain)
from .cli_common import api, bounds  # imported when a command runs (cli_common.LazyModule)
from .errors import EXIT_RULE
from .strategy.registry import STRATEGIES, names as strategy_names

if TYPE_CHECKING:
    from .api import ModelRequest

class _Group(typer.core.TyperGroup):
    """The command group: a usage error (an option's value of the wrong type, an unknown option) with
    --json among the arguments also gives stdout its one JSON object, as every other failure does."""

    def parse_args(self, ctx, args):
        ctx.meta["locoplan.args"] = list(args)  # the command line as given (click consumes it as it goes)
        return super().parse_args(ctx, args)

    def invoke(self, ctx):
        args = ctx.meta.get("locoplan.args", [])
        given = COMMAND_LINE.set(tuple(args))  # what the commands' checks read (cli_common._given)
        cmd = next((c for c in (self.get_command(ctx, a) for a in args if not a.startswith("-")) if c is not None), None)
        params = COMMAND_PARAMS.set(tuple(getattr(cmd, "params", ()) or ()))  # (cli_common._param_names)
        try:
            return super().invoke(ctx)
        except Exception as exc:
            # typer 0.29 carries its own copy of click: know its usage errors by their class name
            if not any(c.__name__ == "UsageError" for c in type(exc).__mro__):
                raise
            if "--json" in args:
                from .cli_common import usage_error_json

                usage_error_json(exc, args)
            raise
        finally:
            COMMAND_PARAMS.reset(params)
            COMMAND_LINE.reset(given)


app = typer.Typer(cls=_Group, add_completion=True, no_args_is_help=True, rich_markup_mode=None,  # help text is plain: "[m]" stays
                  help="Driving-strategy planner for heavy freight trains (traction calculation, optimisation, optimal control).",
                  epilog=EXIT_RULE)


def _version(value: bool):
    if value:
        out.print(f"locoplan {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", "-V", callback=_version, is_eager=True, help="Show the version.")):
    pass


def _base_spec(route: Path, consist: str, stock_dir: Optional[Path], settings, **fields):
    """The spec every run of a multi-run command starts from (runs.plans varies it): ``settings`` a
    ``RunSettings``, ``fields`` the spec's others (``inputs``)."""
    from .runs.spec import RunSpec

    return RunSpec(str(route), str(consist), settings=settings, stock_dir=None if stock_dir is None else str(stock_dir),
                   **fields)


# ------------------------------------------------------------------------------------------ validate
@app.command()
@guarded
def validate(files: list[Path] = typer.Argument(..., help="Route, vehicle or consist YAML files."),
             stock_dir: Optional[Path] = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first."),
             as_json: bool = typer.Option(False, "--json", help="Machine-readable result on stdout.")):
    """Check files; print every problem as file:line: field: message (exit 2), or a summary per file.
    --json: {"valid": bool, "results": [per file: "file", "valid", and "kind" + "description" (what it
    holds) + "summary" if valid, else "problems": [{"file", "line", "field", "message"}]], "problems": [every one]}."""
    report = api.validate_files(files, stock_dir)
    summaries, problems, warnings = report.results, report.problems, report.warnings
    if as_json:
        json_out(report.to_dict())
    else:
        for s in summaries:
            if s["valid"]:
                out.print(f"[green]ok[/]  {escape(s['file'])}: {escape(s['summary'])}", highlight=False)  # wrapped at spaces to the width (80 in a pipe)
    for w in warnings:  # implausible but valid: exit 0, on stderr (with --json too: the object has them)
        err.print(f"[bold yellow]warning:[/] {escape(plain(str(w)))}", highlight=False, soft_wrap=True)
    if not as_json:
        for p in problems[:MAX_PROBLEMS]:
            err.print(f"[bold red]error:[/] {escape(plain(str(p)))}", highlight=False, soft_wrap=True)
        if len(problems) > MAX_PROBLEMS:
            err.print(f"[bold red]error:[/] ... and {len(problems) - MAX_PROBLEMS:,} more problems (the first "
                      f"{MAX_PROBLEMS} are shown; --json lists every one)", highlight=False, soft_wrap=True)
    if report.exit_code:
        raise typer.Exit(report.exit_code)


# ------------------------------------------------------------------------------------------ simulate
def _progress(enabled: bool):
    """A rich progress bar on stderr for optimiser iterations (a no-op callback when disabled)."""
    from contextlib import contextmanager

    from .cli_common import field_column, progress_bar

    @contextmanager
    def cm(label: str, total: int):
        if not enabled or not err.is_terminal:
            yield None
            return
        with progress_bar(field_column("best {task.fields[best]}")) as bar:
            task = bar.add_task(label, total=total, best="-")

            def callback(iteration: int, best: float) -> None:
                bar.update(task, completed=iteration, best=f"{best:.5f}")
            yield callback
    return cm



@app.command()
@guarded
def simulate(route: Path = ROUTE,
             strategy: Optional[str] = typer.Option(None, "--strategy", help=f"Built-in strategy: {', '.join(STRATEGIES)}."),
             sequence: Optional[str] = typer.Option(None, "--sequence", help='Conditions and switching points, e.g. "T:0,K:2200,C:9000,B" (T traction, K cruise, C coast, B brake, E the electric brake alone; bare final B: brake where the braking curve begins).'),
             consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
             out_file: Optional[Path] = typer.Option(None, "--out", help="Profile as .csv, or summary + profile as .json."),
             plot: Optional[Path] = typer.Option(None, "--plot", help="Speed profile over the limits, .png, .svg or .pdf."),
             plot_td: Optional[Path] = PLOT_TD,
             model: ModelRequest = MODEL,
             time_s: Optional[str] = TIME, e_min: Optional[float] = EMIN, seed: int = SEED, algorithm: str = ALGO,
             builder: Optional[str] = BUILDER, chainage: str = CHAINAGE):
    """Traction calculation of one plan: a built-in --strategy or a --sequence of conditions.

    Exit 1 when the plan is infeasible, or when a strategy that plans to the timetable (four-stage,
    proposed, mpoc, sfs) arrives outside T0 +- tolerance, as optimize and compare do. A --sequence,
    time-saving and energy-saving are measured, not planned to T0: how early or late they arrive, and
    whether inside the window, is reported (the table, --json "punctual"), with exit 0."""
    from .reporting.plot import plot_profiles, run_title
    from .reporting.tables import sequence_table, show, summary_table
    from .settings import RunSettings

    api.one_of(strategy or None, sequence or None, "--sequence", "give either --strategy or --sequence, not both")
    _check_outputs(out_file, plot, plot_td=plot_td)
    r, train, opts = _load(route, consist, stock_dir, model)
    settings = RunSettings(opts, time_s=_time(time_s, (r, train), options=opts, quiet=as_json), e_min_kwh=e_min,
                           seed=seed, algorithm=algorithm, builder=builder)
    plan = api.simulate(r, train, settings, strategy=strategy, sequence=sequence)
    summary = plan.summary
    with all_or_none():
        _emit(summary, as_json, out_file, plan.run.result.profile, r)
        if plot:
            plot_profiles(plot, [(summary["strategy"], plan.run.result.profile)],
                          run_title(r.name, train.name, summary["strategy"], summary), route=r,
                          coupler_limit_kn=train.coupler_limit_kn, form=chainage)
        if plot_td:
            plot_runs_td(plot_td, [(summary["strategy"], plan.run.result.profile)],
                         run_title(r.name, train.name, summary["strategy"], summary), r, chainage)
    if not as_json:
        show(out, summary_table(summary, out.width, r, chainage, departure_s())
             + sequence_table(summary["sequence"], out.width, r, chainage))
    # one rule for every command: infeasible is exit 1; a timetabled strategy (proposed, four-stage...) outside
    # T0 +- tolerance too; a --sequence, time-saving and energy-saving are measured, their punctuality reported
    _fail_if(plan.failures)


@app.command()
@guarded
def optimize(route: Path = ROUTE, algorithm: str = ALGO, time_s: Optional[str] = TIME, weights: str = WEIGHTS,
             seed: int = SEED, e_min: Optional[float] = EMIN, params: Optional[Path] = PARAMS,
             consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
             out_file: Optional[Path] = typer.Option(None, "--out", help="Profile as .csv, or summary + profile as .json."),
             plot: Optional[Path] = typer.Option(None, "--plot", help="Speed profile and fitness convergence, .png, .svg or .pdf."),
             plot_td: Optional[Path] = PLOT_TD,
             model: ModelRequest = MODEL,
             tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP,
             objective: str = OBJECTIVE, chainage: str = CHAINAGE):
    """The least-energy plan on time: a condition sequence built from the limits and grades, its switching
    points searched by ISSA (improved sparrow search; or SSA / PSO). Method: Li Wang et al., multi-objective
    optimisation of freight trains on complex lines (ISSA switching points)."""
    from .optimize.registry import get_algorithm
    from .reporting.plot import plot_profiles, run_title
    from .reporting.tables import sequence_table, show, summary_table
    from .settings import RunSettings

    get_algorithm(algorithm)
    w = api.weights(weights)
    bounds.objective(objective)
    _check_outputs(out_file, plot, plot_td=plot_td)
    r, train, opts = _load(route, consist, stock_dir, model)
    time_s = _time(time_s, (r, train), options=opts, quiet=as_json)
    with _progress(not as_json)(f"{algorithm} iterations", _iterations(algorithm, params)) as cb:
        settings = RunSettings(opts, time_s=time_s, e_min_kwh=e_min, weights=w, algorithm=algorithm, seed=seed,
                               params_path=str(params) if params else None, tolerance_s=tolerance, window=window,
                               builder=builder, yardstick=gap, objective=objective)
        plan = api.optimize(r, train, settings, callback=cb)
    summary, run = plan.summary, plan.run
    with all_or_none():
        _emit(summary, as_json, out_file, run.result.profile, r)
        if plot:
            plot_profiles(plot, [("proposed", run.result.profile)],
                          run_title(r.name, train.name, f"proposed ({algorithm}, seed {seed})", summary),
                          histories=[(algorithm, run.outcome.history, None, summary.get("fitness"))]
                          if run.outcome.history is not None else None,
                          route=r, coupler_limit_kn=train.coupler_limit_kn, form=chainage)
        if plot_td:
            plot_runs_td(plot_td, [("proposed", run.result.profile)],
                         run_title(r.name, train.name, f"proposed ({algorithm}, seed {seed})", summary), r, chainage)
    if not as_json:
        show(out, summary_table(summary, out.width, r, chainage, departure_s())
             + sequence_table(summary["sequence"], out.width, r, chainage))
    _fail_if(plan.failures)


def _iterations(algorithm: str, params: Optional[Path]) -> int:
    from .runner import load_optimizer_params

    return int(load_optimizer_params(algorithm, str(params) if params else None).max_iter)



COMPARE_DEFAULT = "time-saving,energy-saving,four-stage,proposed"


@app.command()
@guarded
def compare(route: Path = ROUTE,
            strategies: Optional[str] = typer.Option(None, "--strategies", show_default=False,
                                                     help=f"Comma list of: {', '.join(STRATEGIES)} (default: {COMPARE_DEFAULT}). "
                                                          "Exit 1 when a strategy named here fails its job; without "
                                                          "--strategies, only when no timetabled strategy is on time "
                                                          "(a failed one is its row and a note)."),
            explain: bool = typer.Option(False, "--explain", help="Show the limit and grade classification behind the proposed sequence."),
            algorithm: str = ALGO, time_s: Optional[str] = TIME, weights: str = WEIGHTS, seed: int = SEED,
            e_min: Optional[float] = EMIN, params: Optional[Path] = PARAMS, consist: str = CONSIST,
            stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
            out_file: Optional[Path] = typer.Option(None, "--out", help="Results as .json, or .csv: one row per strategy (columns: docs/cli.md)."),
            plot: Optional[Path] = typer.Option(None, "--plot", help="All strategies' speed profiles over the limits, .png, .svg or .pdf."),
            plot_td: Optional[Path] = PLOT_TD,
            model: ModelRequest = MODEL,
            tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP,
            logs: Optional[list[Path]] = typer.Option(None, "--logs", help="Drivers' log folders (strategy 'drivers')."),
            patterns: Optional[Path] = typer.Option(None, "--patterns", help="Learned patterns.json (strategy 'advice')."),
            workers: int = WORKERS, objective: str = OBJECTIVE, chainage: str = CHAINAGE):
    """Strategies side by side: sequence, switching points, running time, energy (every punctual plan's
    energy also at T0). Method: Li Wang et al., multi-objective optimisation of freight trains on complex
    lines (its Tables 8-9)."""
    from .io.load import load_route, load_train
    from .reporting.plot import history_quantity, plot_profiles
    from .reporting.tables import compare_tables, explain_tables, show
    from .runner import proposed_sequence
    from .runs import make_executor, run_many
    from .runs.plans import compare_fields, compare_specs, energies_at_planned_time

    names = _names(strategies or COMPARE_DEFAULT, "--strategies")
    w = api.weights(weights)
    bounds.objective(objective)
    _check_outputs(out_file, plot, plot_td=plot_td)
    opts = model.options()
    time_s = _time(time_s, route, consist, stock_dir, opts, quiet=as_json)
    from .settings import RunSettings

    settings = RunSettings(opts, algorithm=algorithm, seed=seed, time_s=time_s, weights=w, tolerance_s=tolerance,
                           window=window, builder=builder, e_min_kwh=e_min, params_path=str(params) if params else None,
                           yardstick=gap, objective=objective)
    base = _base_spec(route, consist, stock_dir, settings, inputs=(("logs", logs), ("patterns", patterns)))
    specs = compare_specs(base, names)
    if "proposed" not in names and e_min is None:  # E_min (an energy-saving run) only when a requested strategy needs it
        specs = [replace(x, fitness=False) for x in specs]
    if explain and not as_json:
        show(out, explain_tables(proposed_sequence(load_route(route), load_train(consist, stock_dir), opts), out.width))
    with run_progress("compare runs", len(specs), not as_json) as progress:
        batch = run_many(specs, make_executor(workers), keep_profiles=plot is not None or plot_td is not None,
                         progress=progress)
    for x in batch.records:  # a reason about the route's own schedule names the file and line it came from
        if x.summary.get("reason"):
            x.summary["reason"] = locate_schedule(x.summary["reason"])
    results = {"results": compare_fields([x.summary for x in batch.records])}
    if gap:  # every energy also at T0, so that plans arriving at different times within the window compare
        r_, train_ = load_route(route), load_train(consist, stock_dir)
        results["optimum_at_t0_kwh"] = energies_at_planned_time(results["results"], r_, train_, opts, objective)
    line = load_route(route)
    with all_or_none():
        _emit(results, as_json, out_file, route=line)
        if plot_td:
            first = results["results"][0]
            plot_runs_td(plot_td, [(x.summary["strategy"], x.profile) for x in batch.records if x.profile is not None],
                         f"{first['route']} — {first['consist']}: strategies", line, chainage)
        if plot:
            recs = [x for x in batch.records if x.profile is not None]
            hist = [(x.summary["strategy"], x.history, history_quantity(x.summary["strategy"]),
                     x.summary["traction_energy_kwh"] if x.summary["strategy"] == "energy-saving" else x.summary.get("fitness"))
                    for x in recs if x.history is not None]
            first = results["results"][0]
            plot_profiles(plot, [(x.summary["strategy"], x.profile) for x in recs],
                          f"{first['route']} — {first['consist']}: strategies", histories=hist or None,
                          route=line, form=chainage)
    if not as_json:
        first = results["results"][0]
        show(out, compare_tables(results["results"], f"{first['route']} — {first['consist']}, T0 = {first['planned_time_s']:g} s"
                                 if first.get("planned_time_s") is not None else f"{first['route']} — {first['consist']}", out.width,
                                 line, chainage))
    # named strategies fail by name; the default list fails only when no timetabled one is on time
    fail_on(api.compare_verdict([x.summary for x in batch.records], batch.failures, strategies is not None,
                                strategy_names(timetabled=True),
                                locate_schedule), notes=True)


@app.command()
@guarded
def sweep(route: Path = ROUTE,
          weights: Optional[str] = typer.Option(None, "--weight-grid", help="Time weights w_time, start:stop:step or list, e.g. 0.1:0.9:0.1; w_energy = 1 - w_time."),
          old_weights: Optional[str] = typer.Option(None, "--weights", hidden=True, help="Old name of --weight-grid."),
          times: Optional[str] = typer.Option(None, "--times", help="Planned running times: start:stop:step in seconds, or a comma list of seconds, factors of the fastest run and supplements on it, e.g. 1470,1500,1530 or 1.1x,1.2x or +10%,+20%."),
          algorithm: str = ALGO, seed: int = SEED, e_min: Optional[float] = EMIN, params: Optional[Path] = PARAMS,
          time_s: Optional[str] = TIME, consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
          out_file: Optional[Path] = typer.Option(None, "--out", help="Results as .json, or .csv: one row per run (columns: docs/cli.md)."),
          plot: Optional[Path] = typer.Option(None, "--plot", help="The runs' speed profiles over the limits, .png, .svg or .pdf."),
          model: ModelRequest = MODEL,
          tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP,
          workers: int = WORKERS, chainage: str = CHAINAGE):
    """The optimised plan across fitness weights or planned running times. Method: Li Wang et al.,
    multi-objective optimisation of freight trains on complex lines (its Tables 6-7)."""
    from .io.load import load_route
    from .reporting.plot import plot_profiles
    from .reporting.tables import show, sweep_table
    from .runs import make_executor, run_many
    from .runs.plans import check_time_possible, energy_reduction, time_specs, weight_specs

    if old_weights is not None:  # sweep's --weights was a grid, optimize's a pair: one meaning per name now
        api.one_of(weights, old_weights, "--weight-grid", "give --weight-grid (--weights is its old name), not both")
        weights = old_weights
        err.print("note: sweep's --weights is now --weight-grid (--weights is w_time,w_energy in optimize, compare, study)",
                  highlight=False, markup=False, soft_wrap=True)
    api.one_of(weights, times, "--weight-grid", "give exactly one of --weight-grid or --times", exactly=True)
    asked = None if weights else bounds.times_request(times, "--times")
    values = _range(weights, "--weight-grid") if weights else None
    _check_outputs(out_file, plot)
    opts = model.options()
    time_s = _time(time_s, route, consist, stock_dir, opts, quiet=as_json)
    values = values if weights else _times(asked, route, consist, stock_dir, opts, quiet=as_json)
    from .settings import RunSettings

    settings = RunSettings(opts, algorithm=algorithm, seed=seed, time_s=time_s, e_min_kwh=e_min,
                           params_path=str(params) if params else None, tolerance_s=tolerance, window=window,
                           builder=builder, yardstick=gap)
    base = _base_spec(route, consist, stock_dir, settings)
    specs = weight_specs(base, values) if weights else time_specs(base, values)
    check_time_possible(specs)
    with run_progress("sweep runs", len(specs), not as_json) as progress:
        batch = run_many(specs, make_executor(workers), keep_profiles=plot is not None, progress=progress)
    rows = [x.summary for x in batch.records]
    if times:
        energy_reduction(rows)
    results = {"results": rows}
    with all_or_none():
        _emit(results, as_json, out_file)
        if plot:
            label = (lambda s: f"w_time {s['weights'][0]:g}") if weights else (lambda s: f"T0 {s['planned_time_s']:g} s")
            plot_profiles(plot, [(label(x.summary), x.profile) for x in batch.records if x.profile is not None],
                          f"{rows[0]['route']} — {rows[0]['consist']}: sweep", route=load_route(route), form=chainage)
    if not as_json:
        show(out, sweep_table(rows, f"{rows[0]['route']}: {'Table 6, weights' if weights else 'Table 7, running times'}",
                              by_weights=bool(weights), width=out.width))
    _fail_if(list(dict.fromkeys(batch.failures)))


@app.command()
@guarded
def study(route: Path = ROUTE,
          algorithms: str = typer.Option("issa,ssa,pso", "--algorithms", help="Comma list of optimisers."),
          runs: int = typer.Option(10, "--runs", help="Independent runs per optimiser (seeds seed .. seed+runs-1)."),
          time_s: Optional[str] = TIME, weights: str = WEIGHTS, seed: int = SEED, e_min: Optional[float] = EMIN,
          params_dir: Optional[Path] = typer.Option(None, "--params-dir", help="Folder of <algorithm>.yaml parameter files."),
          consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
          out_file: Optional[Path] = typer.Option(None, "--out", help="Results (runs and the table) as .json, or .csv: one row per run (columns: docs/cli.md)."),
          plot: Optional[Path] = typer.Option(None, "--plot", help="Best runs' speed profiles and convergence curves, .png, .svg or .pdf."),
          model: ModelRequest = MODEL,
          tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP,
          workers: int = WORKERS, chainage: str = CHAINAGE):
    """Each optimiser over several random seeds: best, worst, mean, punctual-and-best. Method: Li Wang et
    al., multi-objective optimisation of freight trains on complex lines (its Tables 10-12)."""
    from .io.load import check_folder, load_route
    from .reporting.plot import plot_profiles
    from .reporting.tables import show, study_table
    from .runner import study_table as study_rows
    from .runs import make_executor, run_many
    from .runs.plans import check_time_possible, study_specs

    algs = _names(algorithms, "--algorithms")
    w = api.weights(weights)
    if params_dir is not None:
        check_folder(params_dir, "--params-dir")
    _check_outputs(out_file, plot)
    opts = model.options()
    time_s = _time(time_s, route, consist, stock_dir, opts, quiet=as_json)
    from .settings import RunSettings

    settings = RunSettings(opts, seed=seed, time_s=time_s, weights=w, e_min_kwh=e_min, tolerance_s=tolerance,
                           window=window, builder=builder, yardstick=gap)
    base = _base_spec(route, consist, stock_dir, settings)
    specs = study_specs(base, algs, runs, params_dir)
    check_time_possible(specs)
    with run_progress("study runs", len(specs), not as_json) as progress:
        batch = run_many(specs, make_executor(workers), keep_profiles=plot is not None, progress=progress)
    results = {a: [x for x in batch.records if x.spec["algorithm"] == a] for a in algs}
    first = batch.records[0].summary
    rows = study_rows(results, api.window_half_width(first))
    e_min_kwh = first.get("e_min_kwh")
    data = {"results": [x.summary for a in algs for x in results[a]], "table": rows,
            "e_min_kwh": e_min_kwh, "planned_time_s": first.get("planned_time_s")}
    with all_or_none():
        _emit(data, as_json, out_file)
        if plot:
            def fitness(x):
                return x.summary["fitness"] if x.summary["fitness"] is not None else math.inf
            best = [min(results[a], key=fitness) for a in algs]
            shown = [(a, b) for a, b in zip(algs, best) if b.profile is not None]
            plot_profiles(plot, [(f"{a} (seed {b.summary['seed']})", b.profile) for a, b in shown],
                          f"{first['route']} — {first['consist']}: best run of each optimiser",
                          histories=[(a, b.history) for a, b in shown if b.history is not None] or None,
                          route=load_route(route), form=chainage)
    if not as_json:
        show(out, study_table(rows, f"{first['route']}: {runs} runs per optimiser (Tables 10-12), E_min "
                                    + ("-" if e_min_kwh is None else f"{e_min_kwh:.1f} kWh"), out.width))
    _fail_if(list(dict.fromkeys(batch.failures)))


from .cli_ocp import register as _register_ocp  # noqa: E402  (the two-stage Gauss paper's commands: ocp, ocp-study)

_register_ocp(app)
from .cli_learn import register as _register_learn  # noqa: E402  (the pattern-curve patent's commands: drivers, learn, advise)

_register_learn(app)

from .cli_import import register as _register_import  # noqa: E402  (locoplan import FORMAT FILES --out DIR)

_register_import(app)

from .cli_energy import register as _register_energy  # noqa: E402  (the MPOC paper's yardstick: bound)

_register_energy(app)

from .cli_journey import register as _register_journey  # noqa: E402  (journeys of several stops)

_register_journey(app)

from .cli_batch import register as _register_batch  # noqa: E402  (batch, results, pareto)

_register_batch(app)

from .cli_replan import register as _register_replan  # noqa: E402  (on board: replan, drive)

_register_replan(app)

from .cli_help import tidy as _tidy_help  # noqa: E402  (every option's value named with its unit, once all are registered)

_tidy_help(app)


def main() -> None:
    from .cli_common import sane_std_streams, std_streams

    sane_std_streams()  # a closed stdout, a terminal that cannot write every character: no traceback
    try:
        with std_streams():  # also what click prints itself (help, usage): stdout's errors named, stderr's dropped
            app()
    except OSError as exc:  # what click prints itself (help, usage) on a full stdout: a message, never a traceback
        import sys

        from .cli_common import _os_problem, _StdoutClosed

        problem = _os_problem(exc)
        if isinstance(problem, _StdoutClosed):
            sys.exit(0)
        try:
            err.print(f"[bold red]error:[/] {escape(plain(str(problem)))}", highlight=False, markup=True, soft_wrap=True)
        except OSError:
            pass
        sys.exit(2)


if __name__ == "__main__":
    main()
