"""The ``locoplan`` command line: thin typer commands that call one library function each."""

from __future__ import annotations

import functools
import sys
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from . import __version__
from .errors import InputError, LocoplanError, Problem
from .io.load import SCHEMAS, load_route, load_train, read_yaml, resolve_consist_path, stock_dirs_for, validate_data
from .io.report import to_json, write_output
from .sim.calculator import DEFAULT_STEP_M, ModelOptions
from .strategy.strategies import STRATEGIES

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Driving-strategy planner for heavy freight trains (traction calculation, optimisation, optimal control).")
out = Console()
err = Console(stderr=True)

DEFAULT_CONSIST = "configs/consists/HXD1-C80x50.yaml"


def guarded(fn):
    """Turn a user's mistake (LocoplanError) into a red message on stderr and its exit code."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except LocoplanError as exc:
            problems = getattr(exc, "problems", None) or [Problem("", "", str(exc))]
            for p in problems:
                err.print(f"[bold red]error:[/] {p}", highlight=False, markup=True, soft_wrap=True)
            raise typer.Exit(exc.exit_code) from None
    return wrapper


def _version(value: bool):
    if value:
        out.print(f"locoplan {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Show the version.")):
    pass


def _options(step: float, strip: bool, rotating_mass: float) -> ModelOptions:
    if step <= 0:
        raise InputError(Problem("", "--step", f"must be > 0 m (got {step:g})"))
    if not 0 <= rotating_mass < 1:
        raise InputError(Problem("", "--rotating-mass", f"must be in [0, 1) (got {rotating_mass:g})"))
    return ModelOptions(step_m=step, strip=strip, rotating_mass=rotating_mass)


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
                out.print(f"[green]ok[/]  {s['file']}: {s['summary']}", highlight=False, soft_wrap=True)
        for p in problems:
            err.print(f"[bold red]error:[/] {p}", highlight=False, soft_wrap=True)
    if problems:
        raise typer.Exit(2)


# ------------------------------------------------------------------------------------------ simulate
def _summary_table(summary: dict) -> Table:
    table = Table(title=f"{summary['route']}\n{summary['consist']}", show_header=False, title_justify="left")
    table.add_column("quantity", style="bold")
    table.add_column("value")
    feasible = "[green]yes[/]" if summary["feasible"] else f"[red]no[/] ({summary['reason']})"
    rows = [("strategy", summary["strategy"]), ("plan", summary["plan"]), ("feasible", feasible)]
    if summary["running_time_s"] is not None:
        rows.append(("running time", f"{summary['running_time_s']:.1f} s"))
    rows.append(("traction energy", f"{summary['traction_energy_kwh']:.2f} kWh"))
    if summary.get("planned_time_s") is not None and summary["punctuality_error_s"] is not None:
        rows.append(("punctuality error", f"{summary['punctuality_error_s']:.1f} s (planned {summary['planned_time_s']:g} s)"))
    rows.append(("solve time", f"{summary['solve_time_s']:.3f} s"))
    for k, v in rows:
        table.add_row(k, v)
    return table


def _sequence_table(runs: list[dict]) -> Table:
    table = Table(title="condition sequence", title_justify="left")
    for col in ("condition", "from [m]", "to [m]", "length [m]"):
        table.add_column(col, justify="right" if col != "condition" else "left")
    names = {"T": "T traction", "K": "K cruise", "C": "C coast", "B": "B brake"}
    for r in runs:
        table.add_row(names[r["condition"]], f"{r['from_m']:.0f}", f"{r['to_m']:.0f}", f"{r['to_m'] - r['from_m']:.0f}")
    return table


@app.command()
@guarded
def simulate(route: Path = typer.Argument(..., help="Route YAML file."),
             strategy: Optional[str] = typer.Option(None, "--strategy", help=f"Built-in strategy: {', '.join(STRATEGIES)}."),
             sequence: Optional[str] = typer.Option(None, "--sequence", help='Conditions and switching points, e.g. "T:0,K:2200,C:9000,B" (bare final B: brake where the braking curve begins).'),
             consist: str = typer.Option(DEFAULT_CONSIST, "--consist", help="Consist YAML file or catalogue name."),
             stock_dir: Optional[Path] = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first."),
             as_json: bool = typer.Option(False, "--json", help="Machine-readable result on stdout (nothing else there)."),
             out_file: Optional[Path] = typer.Option(None, "--out", help="Profile as .csv, or summary + profile as .json."),
             plot: Optional[Path] = typer.Option(None, "--plot", help="Speed profile over the limits, .png or .svg."),
             step: float = typer.Option(DEFAULT_STEP_M, "--step", help="Integration grid spacing [m]."),
             strip: bool = typer.Option(False, "--strip", help="Train as a strip: gradient averaged and lowest limit taken over its length."),
             rotating_mass: float = typer.Option(0.0, "--rotating-mass", help="Rotating-mass allowance gamma (inertial mass M(1+gamma))."),
             ):
    """Traction calculation of one plan: a built-in --strategy or a --sequence of conditions."""
    from .simulate import simulate as run_simulation

    if strategy and sequence:
        raise InputError(Problem("", "--sequence", "give either --strategy or --sequence, not both"))
    opts = _options(step, strip, rotating_mass)
    r = load_route(route)
    train = load_train(consist, stock_dir)
    run = run_simulation(r, train, strategy=strategy, sequence=sequence, options=opts)
    summary = run.summary()
    if out_file:
        write_output(out_file, summary, run.result.profile)
    if plot:
        from .io.plot import plot_profiles

        plot_profiles(plot, [(summary["strategy"], run.result.profile)],
                      f"{r.name} — {train.name}: {summary['strategy']}, "
                      f"{summary['running_time_s'] or float('nan'):.1f} s, {summary['traction_energy_kwh']:.1f} kWh")
    if as_json:
        print(to_json(summary))
    else:
        out.print(_summary_table(summary))
        out.print(_sequence_table(summary["sequence"]))
    if not summary["feasible"]:
        raise typer.Exit(1)


def main() -> None:
    app()


if __name__ == "__main__":
    main()
