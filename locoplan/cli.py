"""The ``locoplan`` command line: thin typer commands that call one library function each."""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from . import __version__, bounds
from .errors import InputError, LocoplanError, Problem
from .io.load import SCHEMAS, check_folder, load_route_and_train, load_train, read_yaml, resolve_consist_path, stock_dirs_for, validate_data
from .io.report import all_or_none, check_output, to_json, write_output
from .sim.calculator import DEFAULT_STEP_M, ModelOptions
from .optimize.registry import ALGORITHMS
from .strategy.strategies import STRATEGIES
from . import learn as _learn  # noqa: F401,E402  (registers seed 004's compare strategies before --strategies' help)

app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode=None,  # help text is plain: "[m]" stays
                  help="Driving-strategy planner for heavy freight trains (traction calculation, optimisation, optimal control).")
out = Console()
err = Console(stderr=True)

DEFAULT_CONSIST = "configs/consists/HXD1-C80x50.yaml"


def guarded(fn):
    """Turn a user's mistake (LocoplanError) into a red message on stderr and its exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            # outputs appear all or none: kept on success and on a deliberate exit after them (_fail_if)
            with all_or_none(keep=lambda exc: isinstance(exc, typer.Exit)):
                return fn(*args, **kwargs)
        except LocoplanError as exc:
            for text in (str(p) for p in getattr(exc, "problems", None) or [exc]):  # an infeasible request has no file
                err.print(f"[bold red]error:[/] {escape(text)}", highlight=False, markup=True, soft_wrap=True)
            raise typer.Exit(exc.exit_code) from None
    return wrapper


def _fail_if(messages: list) -> None:
    """After every output is written: name each result that failed its job, exit 1 if any did."""
    messages = [m for m in messages if m]
    for m in messages:
        err.print(f"[bold red]error:[/] {escape(m)}", highlight=False, soft_wrap=True)
    if messages:
        raise typer.Exit(1)


def _version(value: bool):
    if value:
        out.print(f"locoplan {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Show the version.")):
    pass


def _options(step: float, point_mass: bool, rotating_mass: Optional[float], strict_limits: bool = False,
             air_brake: Optional[bool] = None) -> ModelOptions:
    bounds.step(step)
    if rotating_mass is not None and not 0 <= rotating_mass < 1:
        raise InputError(Problem("<command line>", "--rotating-mass", f"must be in [0, 1) (got {rotating_mass:g})"))
    air = (not point_mass) if air_brake is None else air_brake
    return ModelOptions(step_m=step, point_mass=point_mass, air_brake=air, rotating_mass=rotating_mass,
                        strict_limits=strict_limits)


# ------------------------------------------------------------------------------------------ validate
def _describe(model, path: str, stock_dir: Optional[Path]) -> str:
    kind = type(model).__name__
    if kind == "Route":
        def count(items, noun):
            return f"{len(items)} {noun}{'' if len(items) == 1 else 's'}"
        parts = [f"{model.length_m / 1000:g} km", count(model.speed_limits, "speed-limit section"),
                 count(model.gradients, "gradient section"), count(model.curves, "curve"),
                 count(model.tunnels, "tunnel"), count(model.neutral_sections, "neutral section")]
        if model.schedule:
            parts.append(f"schedule {model.schedule.run_time_s:g} +- {model.schedule.tolerance_s:g} s")
        return f"route '{model.name}': " + ", ".join(parts)
    if kind == "Vehicle":
        return (f"{model.kind} '{model.name}': {model.mass_t:g} t, {model.length_m:g} m, "
                f"max {model.max_speed_kmh:g} km/h")
    train = load_train(path, stock_dir)
    return (f"consist '{train.name}': {train.n_vehicles} vehicles, {train.mass_t:g} t, "
            f"train length {train.length_m:g} m, max {train.max_speed_kmh:g} km/h")


@app.command()
def validate(files: list[Path] = typer.Argument(..., help="Route, vehicle or consist YAML files."),
             stock_dir: Optional[Path] = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first."),
             as_json: bool = typer.Option(False, "--json", help="Machine-readable result on stdout.")):
    """Check files; print every problem as file:line: field: message (exit 2), or a summary per file."""
    problems: list[Problem] = []
    summaries = []
    try:
        if stock_dir is not None:
            check_folder(stock_dir, "--stock-dir")
    except InputError as exc:
        problems += exc.problems
    for f in files:
        try:
            data, lines = read_yaml(f)
            model = validate_data(data, str(f), lines)
            summaries.append({"file": str(f), "valid": True, "summary": _describe(model, str(f), stock_dir)})
        except InputError as exc:
            problems += exc.problems
            summaries.append({"file": str(f), "valid": False, "problems": [str(p) for p in exc.problems]})
    if as_json:
        print(to_json({"results": summaries}))
    else:
        for s in summaries:
            if s["valid"]:
                out.print(f"[green]ok[/]  {escape(s['file'])}: {escape(s['summary'])}", highlight=False, soft_wrap=True)
        for p in problems:
            err.print(f"[bold red]error:[/] {escape(str(p))}", highlight=False, soft_wrap=True)
    if problems:
        raise typer.Exit(2)


# ------------------------------------------------------------------------------------------ simulate
def _summary_table(summary: dict) -> Table:
    table = Table(title=escape(f"{summary['route']}\n{summary['consist']}"), show_header=False, title_justify="left")
    table.add_column("quantity", style="bold")
    table.add_column("value")
    feasible = "[green]yes[/]" if summary["feasible"] else f"[red]no[/] ({summary['reason']})"
    rows = [("strategy", summary["strategy"] + (f" ({summary['algorithm']}, seed {summary['seed']})" if summary.get("algorithm") else "")),
            ("plan", summary["plan"]), ("feasible", feasible)]
    if summary["running_time_s"] is not None:
        rows.append(("running time", f"{summary['running_time_s']:.1f} s"))
    rows.append(("traction energy", f"{summary['traction_energy_kwh']:.2f} kWh"))
    if summary.get("planned_time_s") is not None and summary["punctuality_error_s"] is not None:
        rows.append(("punctuality error", f"{summary['punctuality_error_s']:.1f} s (planned {summary['planned_time_s']:g} s)"))
    if summary.get("fitness") is not None:
        rows.append(("fitness (eq. 10)", f"{summary['fitness']:.5f} (weights {summary['weights'][0]:g}/{summary['weights'][1]:g}, E_min {summary['e_min_kwh']:.1f} kWh)"))
    if summary.get("cruise_kmh"):
        rows.append(("cruise speed", f"{summary['cruise_kmh']:g} km/h"))
    if summary.get("gap_to_optimum_percent") is not None:
        rows.append(("gap to optimum", f"{summary['gap_to_optimum_percent']:+.2f} % over E*, the least energy in this running time (seed 001)"))
    rows.append(("solve time", f"{summary['solve_time_s']:.3f} s"))
    for k, v in rows:
        table.add_row(k, v)
    return table


def _sequence_table(runs: list[dict]) -> Table:
    table = Table(title="condition sequence", title_justify="left")
    for col in ("condition", "from [m]", "to [m]", "length [m]"):
        table.add_column(escape(col), justify="right" if col != "condition" else "left")
    names = {"T": "T traction", "K": "K cruise", "C": "C coast", "B": "B brake"}
    for r in runs:
        table.add_row(names[r["condition"]], f"{r['from_m']:.0f}", f"{r['to_m']:.0f}", f"{r['to_m'] - r['from_m']:.0f}")
    return table


def _progress(enabled: bool):
    """A rich progress bar on stderr for optimiser iterations (a no-op callback when disabled)."""
    from contextlib import contextmanager

    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    @contextmanager
    def cm(label: str, total: int):
        if not enabled or not err.is_terminal:
            yield None
            return
        with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
                      TextColumn("best {task.fields[best]}"), TimeElapsedColumn(), console=err, transient=True) as bar:
            task = bar.add_task(label, total=total, best="-")

            def callback(iteration: int, best: float) -> None:
                bar.update(task, completed=iteration, best=f"{best:.5f}")
            yield callback
    return cm


def _weights(text: str) -> tuple[float, float]:
    return bounds.weights(text, "--weights")


def _range(text: str, field: str) -> list[float]:
    """'0.1:0.9:0.1' (start:stop:step, inclusive) or '1470,1500,1530': time weights or running times."""
    if field == "--weights":
        return bounds.values(text, field, 0.0, 1.0, why="a time weight (the energy weight is 1 - it)")
    return bounds.values(text, field, *bounds.LIMITS["time_s"], "s", "a planned running time")


def _names(text: str, field: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    if not names:
        raise InputError(Problem("", field, "name at least one"))
    return names


def _load(route: Path, consist: str, stock_dir: Optional[Path], step: float, point_mass: bool,
          rotating_mass: Optional[float], strict_limits: bool, air_brake: Optional[bool] = None):
    opts = _options(step, point_mass, rotating_mass, strict_limits, air_brake)
    return (*load_route_and_train(route, consist, stock_dir), opts)


def _emit(summary_or_results, as_json: bool, out_file: Optional[Path], profile=None) -> None:
    if out_file:
        write_output(out_file, summary_or_results, profile)
    if as_json:
        print(to_json(summary_or_results))


def _check_outputs(out_file: Optional[Path], plot: Optional[Path], csv_ok: bool = True) -> None:
    """Refuse bad output names (type, folder, writable) before any long computation."""
    from .io.plot import check_plot_path

    check_output(out_file, "--out", (".csv", ".json") if csv_ok else (".json",))
    check_output(plot and check_plot_path(plot), "--plot")


# Options shared by the commands (typer has no option groups; these keep them identical)
ROUTE = typer.Argument(..., help="Route YAML file.")
CONSIST = typer.Option(DEFAULT_CONSIST, "--consist", help="Consist YAML file or catalogue name.")
STOCK = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first.")
JSON = typer.Option(False, "--json", help="Machine-readable result on stdout (nothing else there).")
STEP = typer.Option(DEFAULT_STEP_M, "--step", help="Reporting grid spacing [m] (optimisers search on 100 m).")
POINT_MASS = typer.Option(False, "--point-mass", help="The seeds' train model (to reproduce their tables): a point mass at the head, braked by its locomotives alone. Default: the train's real length (gradient averaged over it, a limit held until the tail clears it) and the wagons' air brakes.")
AIR = typer.Option(None, "--air-brake/--no-air-brake", help="Brake with the wagons' air brakes as well as the electric brake (default: on, off with --point-mass).", show_default=False)
ROT = typer.Option(None, "--rotating-mass", help="Uniform rotating-mass allowance gamma, inertial mass M(1+gamma) (default: each vehicle's own factor, 1 if none).", show_default=False)
STRICT = typer.Option(False, "--strict-limits", help="Coasting up to a limit makes a plan infeasible (default: held there by braking).")
TIME = typer.Option(None, "--time", help="Planned running time T0 [s] (default: the route's schedule).")
WEIGHTS = typer.Option("0.5,0.5", "--weights", help="Fitness weights w_time,w_energy of seed 002 eq. 10.")
EMIN = typer.Option(None, "--e-min", help="E_min of eq. 11 [kWh] (default: the energy-saving strategy's energy).")
SEED = typer.Option(1, "--seed", help="Random seed: the same seed gives the same result.")
ALGO = typer.Option("issa", "--algorithm", help=f"Optimiser: {', '.join(ALGORITHMS)}.")
TOL = typer.Option(None, "--tolerance", help="Punctuality window +- [s] (default: the route's schedule tolerance).")
WINDOW = typer.Option(True, "--window/--no-window", help="Keep plans inside T0 +- tolerance (seed 002 eq. 3); --no-window ranks by eq. 10 alone.")
BUILDER = typer.Option(None, "--builder", help="Sequence builder: general (the default; any line) or seed002 (seed 002 section 2 to the letter; the default with --point-mass).", show_default=False)
PARAMS = typer.Option(None, "--params", help="Optimiser parameter YAML (default: configs/optimizers/<algorithm>.yaml).")
GAP = typer.Option(True, "--gap/--no-gap", help="Report each plan's gap to the least energy E* at its own running time (seed 001's optimum; a few seconds per plan).")


@app.command()
@guarded
def simulate(route: Path = ROUTE,
             strategy: Optional[str] = typer.Option(None, "--strategy", help=f"Built-in strategy: {', '.join(STRATEGIES)}."),
             sequence: Optional[str] = typer.Option(None, "--sequence", help='Conditions and switching points, e.g. "T:0,K:2200,C:9000,B" (bare final B: brake where the braking curve begins).'),
             consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
             out_file: Optional[Path] = typer.Option(None, "--out", help="Profile as .csv, or summary + profile as .json."),
             plot: Optional[Path] = typer.Option(None, "--plot", help="Speed profile over the limits, .png or .svg."),
             step: float = STEP, point_mass: bool = POINT_MASS, air_brake: Optional[bool] = AIR, rotating_mass: Optional[float] = ROT, strict_limits: bool = STRICT,
             time_s: Optional[float] = TIME, e_min: Optional[float] = EMIN, seed: int = SEED, algorithm: str = ALGO,
             builder: Optional[str] = BUILDER):
    """Traction calculation of one plan: a built-in --strategy or a --sequence of conditions."""
    from .runner import make_context, run_sequence, run_strategy

    if strategy and sequence:
        raise InputError(Problem("", "--sequence", "give either --strategy or --sequence, not both"))
    _check_outputs(out_file, plot)
    r, train, opts = _load(route, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
    ctx = make_context(r, train, opts, time_s=time_s, e_min_kwh=e_min, seed=seed, algorithm=algorithm, need_time=False,
                       builder=builder, yardstick=False)
    run = run_sequence(ctx, sequence) if sequence is not None else run_strategy(ctx, strategy or "time-saving", with_fitness=e_min is not None)
    summary = run.summary
    _emit(summary, as_json, out_file, run.result.profile)
    if plot:
        from .io.plot import plot_profiles

        plot_profiles(plot, [(summary["strategy"], run.result.profile)],
                      f"{r.name} — {train.name}: {summary['strategy']}, "
                      f"{summary['running_time_s'] or float('nan'):.1f} s, {summary['traction_energy_kwh']:.1f} kWh")
    if not as_json:
        out.print(_summary_table(summary))
        out.print(_sequence_table(summary["sequence"]))
    from .runner import schedule_verdict

    # a plan is checked against the window only when a running time was asked for (--time)
    _fail_if([schedule_verdict(ctx, run, strict=time_s is not None)])


@app.command()
@guarded
def optimize(route: Path = ROUTE, algorithm: str = ALGO, time_s: Optional[float] = TIME, weights: str = WEIGHTS,
             seed: int = SEED, e_min: Optional[float] = EMIN, params: Optional[Path] = PARAMS,
             consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
             out_file: Optional[Path] = typer.Option(None, "--out", help="Profile as .csv, or summary + profile as .json."),
             plot: Optional[Path] = typer.Option(None, "--plot", help="Speed profile and fitness convergence, .png or .svg."),
             step: float = STEP, point_mass: bool = POINT_MASS, air_brake: Optional[bool] = AIR, rotating_mass: Optional[float] = ROT, strict_limits: bool = STRICT,
             tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP):
    """Seed 002: the condition sequence from limits and grades, switching points by ISSA / SSA / PSO."""
    from .optimize.registry import get_algorithm
    from .runner import make_context, run_strategy

    get_algorithm(algorithm)
    w = _weights(weights)
    _check_outputs(out_file, plot)
    r, train, opts = _load(route, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
    with _progress(not as_json)(f"{algorithm} switching points", _iterations(algorithm, params)) as cb:
        ctx = make_context(r, train, opts, time_s=time_s, e_min_kwh=e_min, weights=w, algorithm=algorithm,
                           seed=seed, params_path=str(params) if params else None, callback=cb,
                           tolerance_s=tolerance, window=window, builder=builder, yardstick=gap)
        if e_min is None:
            ctx.e_min()  # the energy-saving run first, so the bar then shows the proposed run alone
        run = run_strategy(ctx, "proposed")
    summary = run.summary
    summary["solve_time_s"] = round(run.outcome.solve_time_s, 3)
    _emit(summary, as_json, out_file, run.result.profile)
    if plot:
        from .io.plot import plot_profiles

        plot_profiles(plot, [("proposed", run.result.profile)],
                      f"{r.name} — {train.name}: proposed ({algorithm}, seed {seed}), "
                      f"{summary['running_time_s']:.1f} s, {summary['traction_energy_kwh']:.1f} kWh",
                      histories=[(algorithm, run.outcome.history)])
    if not as_json:
        out.print(_summary_table(summary))
        out.print(_sequence_table(summary["sequence"]))
    from .runner import schedule_verdict

    _fail_if([schedule_verdict(ctx, run)])


def _iterations(algorithm: str, params: Optional[Path]) -> int:
    from .optimize.registry import load_optimizer_params

    return int(load_optimizer_params(algorithm, str(params) if params else None).max_iter)


def _compare_tables(rows: list[dict], title: str) -> tuple[Table, Table]:
    """Seed 002 Table 8 (each strategy's planned sequence and switching points; the final B begins
    where the stop's braking curve does) and Table 9 (time and energy, re-simulated at the report grid)."""
    t8 = Table(title=escape(f"{title}\nTable 8: condition sequences and switching points"), title_justify="left")
    t8.add_column("strategy")
    t8.add_column("sequence")
    t8.add_column(escape("switching points [m]"), overflow="fold")
    t9 = Table(title="Table 9: running time and traction energy", title_justify="left")
    for col in ("strategy", "time [s]", "|T-T0| [s]", "energy [kWh]", "vs time-saving", "vs E* [%]", "switches", "coasting", "fitness"):
        t9.add_column(escape(col), justify="left" if col == "strategy" else "right")
    base = next((r["traction_energy_kwh"] for r in rows if r["strategy"] == "time-saving"), None)
    for s in rows:
        conds = [c.split(":")[0] for c in s["plan"].split(",")]
        points = list(s["switching_points_m"])
        if conds[-1] == "B" and len(points) < len(conds) - 1 and s["sequence"]:
            points.append(s["sequence"][-1]["from_m"])  # where the final braking curve begins
        seq = "-".join(conds) + (f" (cruise {s['cruise_kmh']:g} km/h)" if s.get("cruise_kmh") else "")
        t8.add_row(s["strategy"], seq, " ".join(f"{x:.0f}" for x in points) or "-")
        t = "-" if s["running_time_s"] is None else f"{s['running_time_s']:.1f}"
        late = "-" if s["punctuality_error_s"] is None else f"{s['punctuality_error_s']:.1f}"
        if s.get("punctual") is False:
            late += " [red]early[/]" if s["running_time_s"] < s["planned_time_s"] else " [red]late[/]"
        rel = "-" if not base else f"{100 * (s['traction_energy_kwh'] / base - 1):+.1f} %"
        name = s["strategy"] + ("" if s["feasible"] else f" [red](infeasible: {s['reason']})[/]")
        gap = "-" if s.get("gap_to_optimum_percent") is None else f"{s['gap_to_optimum_percent']:+.2f}"
        t9.add_row(name, t, late, f"{s['traction_energy_kwh']:.2f}", rel, gap, str(len(conds) - 1),
                   str(conds.count("C")), "-" if s["fitness"] is None else f"{s['fitness']:.4f}")
    return t8, t9


def _explain(ctx) -> None:
    from .strategy.sequence import build_sequence

    seq = build_sequence(ctx.search)
    t = Table(title="speed-limit sections (seed 002 Fig. 2)", title_justify="left")
    for col in ("from [m]", "to [m]", "limit [km/h]", "type"):
        t.add_column(escape(col), justify="right" if col != "type" else "left")
    for s in seq.limits:
        t.add_row(f"{s.from_m:.0f}", f"{s.to_m:.0f}", f"{s.kmh:g}", s.kind)
    out.print(t)
    t = Table(title="grades (seed 002 step 2: can full traction / coasting hold the limit speed?)", title_justify="left")
    for col in ("from [m]", "to [m]", "equiv. gradient [‰]", "speed change [km/h]", "type"):
        t.add_column(escape(col), justify="right" if col != "type" else "left")
    for g in seq.grades:
        t.add_row(f"{g.from_m:.0f}", f"{g.to_m:.0f}", f"{g.permille:+.2f}", f"{g.speed_change_kmh:+.1f}", g.kind)
    out.print(t)
    out.print(f"proposed sequence (nominal switching points, seed 002 step 3): {seq.text()}", highlight=False, soft_wrap=True, markup=False)


@app.command()
@guarded
def compare(route: Path = ROUTE,
            strategies: str = typer.Option("time-saving,energy-saving,four-stage,proposed", "--strategies",
                                           help=f"Comma list of: {', '.join(STRATEGIES)}."),
            explain: bool = typer.Option(False, "--explain", help="Show the limit and grade classification behind the proposed sequence."),
            algorithm: str = ALGO, time_s: Optional[float] = TIME, weights: str = WEIGHTS, seed: int = SEED,
            e_min: Optional[float] = EMIN, params: Optional[Path] = PARAMS, consist: str = CONSIST,
            stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
            out_file: Optional[Path] = typer.Option(None, "--out", help="Results as .json."),
            plot: Optional[Path] = typer.Option(None, "--plot", help="All strategies' speed profiles over the limits (Fig. 15)."),
            step: float = STEP, point_mass: bool = POINT_MASS, air_brake: Optional[bool] = AIR, rotating_mass: Optional[float] = ROT, strict_limits: bool = STRICT,
             tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP,
            logs: Optional[list[Path]] = typer.Option(None, "--logs", help="Drivers' log folders (strategy 'drivers')."),
            patterns: Optional[Path] = typer.Option(None, "--patterns", help="Learned patterns.json (strategy 'advice').")):
    """Seed 002 Tables 8-9: strategies side by side (sequence, switching points, time, energy)."""
    from .optimize.registry import get_algorithm
    from .runner import compare as run_compare, make_context

    get_algorithm(algorithm)
    names = _names(strategies, "--strategies")
    w = _weights(weights)
    _check_outputs(out_file, plot, csv_ok=False)
    r, train, opts = _load(route, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
    ctx = make_context(r, train, opts, time_s=time_s, e_min_kwh=e_min, weights=w, algorithm=algorithm, seed=seed,
                       params_path=str(params) if params else None, tolerance_s=tolerance, window=window, builder=builder, yardstick=gap)
    ctx.inputs.update(logs=logs, patterns=patterns)
    if explain and not as_json:
        _explain(ctx)
    runs = run_compare(ctx, names)
    results = {"results": [x.summary for x in runs]}
    _emit(results, as_json, out_file)
    if plot:
        from .io.plot import plot_profiles

        hist = [(x.name, x.outcome.history) for x in runs if x.outcome.history is not None]
        plot_profiles(plot, [(x.name, x.result.profile) for x in runs], f"{r.name} — {train.name}: strategies",
                      histories=hist or None)
    if not as_json:
        for table in _compare_tables(results["results"], f"{r.name} — {train.name}, T0 = {ctx.t0_s:g} s"):
            out.print(table)
    from .runner import schedule_verdict

    _fail_if([schedule_verdict(ctx, x) for x in runs])


@app.command()
@guarded
def sweep(route: Path = ROUTE,
          weights: Optional[str] = typer.Option(None, "--weights", help="Time weights start:stop:step or list (Table 6), e.g. 0.1:0.9:0.1."),
          times: Optional[str] = typer.Option(None, "--times", help="Planned running times [s] (Table 7), e.g. 1470,1500,1530."),
          algorithm: str = ALGO, seed: int = SEED, e_min: Optional[float] = EMIN, params: Optional[Path] = PARAMS,
          time_s: Optional[float] = TIME, consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
          out_file: Optional[Path] = typer.Option(None, "--out", help="Results as .json."),
          plot: Optional[Path] = typer.Option(None, "--plot", help="The runs' speed profiles over the limits."),
          step: float = STEP, point_mass: bool = POINT_MASS, air_brake: Optional[bool] = AIR, rotating_mass: Optional[float] = ROT, strict_limits: bool = STRICT,
             tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP):
    """Seed 002 Tables 6-7: the proposed strategy across fitness weights or planned running times."""
    from .optimize.registry import get_algorithm
    from .runner import make_context, sweep_times, sweep_weights

    get_algorithm(algorithm)
    if (weights is None) == (times is None):
        raise InputError(Problem("", "--weights", "give exactly one of --weights or --times"))
    values = _range(weights or times, "--weights" if weights else "--times")
    _check_outputs(out_file, plot, csv_ok=False)
    r, train, opts = _load(route, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
    ctx = make_context(r, train, opts, time_s=time_s, e_min_kwh=e_min, algorithm=algorithm, seed=seed,
                       params_path=str(params) if params else None, tolerance_s=tolerance, window=window, builder=builder, yardstick=gap)
    runs = sweep_weights(ctx, values) if weights else sweep_times(ctx, values)
    rows = [x.summary for x in runs]
    if times:
        base = rows[0]["traction_energy_kwh"]
        for x in rows:
            x["energy_reduction_percent"] = round(100 * (1 - x["traction_energy_kwh"] / base), 2)
    results = {"results": rows}
    _emit(results, as_json, out_file)
    if plot:
        from .io.plot import plot_profiles

        label = (lambda x: f"w_time {x.summary['weights'][0]:g}") if weights else (lambda x: f"T0 {x.summary['planned_time_s']:g} s")
        plot_profiles(plot, [(label(x), x.result.profile) for x in runs], f"{r.name} — {train.name}: sweep")
    if not as_json:
        table = Table(title=escape(f"{r.name}: {'Table 6, weights' if weights else 'Table 7, running times'}"), title_justify="left")
        cols = (["w_time", "w_energy"] if weights else ["T0 [s]"]) + ["time [s]", "energy [kWh]", "|T-T0| [s]", "fitness", "vs E* [%]"]
        cols += [] if weights else ["energy reduction [%]"]
        for c in cols:
            table.add_column(escape(c), justify="right")
        for x in rows:
            lead = [f"{x['weights'][0]:g}", f"{x['weights'][1]:g}"] if weights else [f"{x['planned_time_s']:g}"]
            tail = [] if weights else [f"{x['energy_reduction_percent']:.1f}"]
            table.add_row(*lead, f"{x['running_time_s']:.1f}", f"{x['traction_energy_kwh']:.2f}",
                          f"{x['punctuality_error_s']:.1f}", f"{x['fitness']:.4f}" if x["fitness"] is not None else "-",
                          "-" if x.get("gap_to_optimum_percent") is None else f"{x['gap_to_optimum_percent']:+.2f}", *tail)
        out.print(table)
    from .runner import schedule_verdict

    _fail_if([schedule_verdict(ctx, x) for x in runs])


@app.command()
@guarded
def study(route: Path = ROUTE,
          algorithms: str = typer.Option("issa,ssa,pso", "--algorithms", help="Comma list of optimisers."),
          runs: int = typer.Option(10, "--runs", help="Independent runs per optimiser (seeds seed .. seed+runs-1)."),
          time_s: Optional[float] = TIME, weights: str = WEIGHTS, seed: int = SEED, e_min: Optional[float] = EMIN,
          params_dir: Optional[Path] = typer.Option(None, "--params-dir", help="Folder of <algorithm>.yaml parameter files."),
          consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
          out_file: Optional[Path] = typer.Option(None, "--out", help="Results as .json."),
          plot: Optional[Path] = typer.Option(None, "--plot", help="Best runs' speed profiles and convergence curves (Figs. 15, 17)."),
          step: float = STEP, point_mass: bool = POINT_MASS, air_brake: Optional[bool] = AIR, rotating_mass: Optional[float] = ROT, strict_limits: bool = STRICT,
             tolerance: Optional[float] = TOL, window: bool = WINDOW, builder: Optional[str] = BUILDER, gap: bool = GAP):
    """Seed 002 Tables 10-12: each optimiser over several seeds: best, worst, mean, punctual-and-best."""
    from dataclasses import replace

    from .optimize.registry import get_algorithm
    from .runner import make_context, run_strategy, study_table

    algs = _names(algorithms, "--algorithms")
    for a in algs:
        get_algorithm(a)
    bounds.runs(bounds.count(runs, "--runs", 1, bounds.LIMITS["runs"], "independent runs per optimiser") * len(algs), "--runs")
    if params_dir is not None:
        check_folder(params_dir, "--params-dir")
    w = _weights(weights)
    _check_outputs(out_file, plot, csv_ok=False)
    r, train, opts = _load(route, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
    ctx = make_context(r, train, opts, time_s=time_s, e_min_kwh=e_min, weights=w, seed=seed, tolerance_s=tolerance,
                       window=window, builder=builder, yardstick=gap)
    from .runner import check_time_possible

    check_time_possible(ctx)
    ctx.e_min()
    results: dict[str, list] = {}
    for a in algs:
        pfile = params_dir / f"{a}.yaml" if params_dir else None
        results[a] = []
        for i in range(runs):
            results[a].append(run_strategy(replace(ctx, algorithm=a, seed=seed + i,
                                                   params_path=str(pfile) if pfile else None), "proposed"))
    rows = study_table(results, ctx.tolerance_s)
    data = {"results": [x.summary for a in algs for x in results[a]], "table": rows,
            "e_min_kwh": round(ctx.e_min(), 2), "planned_time_s": ctx.t0_s}
    _emit(data, as_json, out_file)
    if plot:
        from .io.plot import plot_profiles

        best = [min(results[a], key=lambda x: x.summary["fitness"] if x.summary["fitness"] is not None else float("inf")) for a in algs]
        plot_profiles(plot, [(f"{a} (seed {b.summary['seed']})", b.result.profile) for a, b in zip(algs, best)],
                      f"{r.name} — {train.name}: best run of each optimiser",
                      histories=[(a, b.outcome.history) for a, b in zip(algs, best)])
    if not as_json:
        table = Table(title=escape(f"{r.name}: {runs} runs per optimiser (Tables 10-12), E_min {ctx.e_min():.1f} kWh"), title_justify="left")
        for c in ("algorithm", "best E [kWh] / T [s]", "worst E / T", "mean E / T", "mean fitness (sd)",
                  "punctual runs", "punctual best E / T / fitness", "mean vs E* [%]", "mean solve [s]"):
            table.add_column(escape(c), justify="right" if c != "algorithm" else "left")
        for x in rows:
            if not x.get("feasible_runs"):
                table.add_row(x["algorithm"], *(["-"] * 8))
                continue
            pb = x["punctual_best"]
            table.add_row(x["algorithm"],
                          f"{x['best']['traction_energy_kwh']:.2f} / {x['best']['running_time_s']:.1f}",
                          f"{x['worst']['traction_energy_kwh']:.2f} / {x['worst']['running_time_s']:.1f}",
                          f"{x['mean_traction_energy_kwh']:.2f} / {x['mean_running_time_s']:.1f}",
                          f"{x['mean_fitness']:.5f} ({x['std_fitness']:.5f})", f"{x['punctual_runs']}/{x['runs']}",
                          "-" if pb is None else f"{pb['traction_energy_kwh']:.2f} / {pb['running_time_s']:.1f} / {pb['fitness']:.5f}",
                          "-" if x.get("mean_gap_to_optimum_percent") is None else f"{x['mean_gap_to_optimum_percent']:+.2f}",
                          f"{x['mean_solve_time_s']:.2f}")
        out.print(table)
    from .runner import schedule_verdict

    _fail_if([schedule_verdict(ctx, x) for a in algs for x in results[a]])


from .cli_ocp import register as _register_ocp  # noqa: E402  (seed 000 commands: ocp, ocp-study)

_register_ocp(app)
from .cli_learn import register as _register_learn  # noqa: E402  (seed 004 commands: drivers, learn, advise)

_register_learn(app)

from .cli_import import register as _register_import  # noqa: E402  (locoplan import FORMAT FILES --out DIR)

_register_import(app)

from .cli_energy import register as _register_energy  # noqa: E402  (seed 001's yardstick: bound)

_register_energy(app)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
