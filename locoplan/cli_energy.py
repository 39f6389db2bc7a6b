"""``locoplan ocp --objective energy`` and ``locoplan bound``: the MPOC paper's optimum on the command line.

Thin commands over :mod:`locoplan.ocp.mpoc` and :mod:`locoplan.ocp.bound` (checks and the energy curve
in :mod:`locoplan.api`, tables in :mod:`locoplan.reporting.ocp_tables`); :func:`register` adds ``bound``
to a typer app, :func:`run_energy_ocp` is what ``ocp`` calls for ``--objective energy``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.markup import escape

from .cli_common import api  # imported when a command runs (cli_common.LazyModule)
from .cli_common import CONSIST, JSON, MODEL, OBJECTIVE, ROUTE, STOCK, TIME, _check_outputs, _load, _time, _times, fail_on, guarded, json_out, out, record_error

if TYPE_CHECKING:
    from .api import ModelRequest

__all__ = ["register", "run_energy_ocp"]


def run_energy_ocp(route_path: Path, consist: str, stock_dir: Optional[Path], time_s: Optional[str], mesh_tol: float,
                   max_degree: int, efficiency: Optional[str], regen: float, comfort: Optional[float],
                   model: ModelRequest, as_json: bool, out_file: Optional[Path], plot: Optional[Path], nodes,
                   state_nodes) -> None:
    """``locoplan ocp ROUTE --objective energy``: solve, print, write; exit 1 if not confirmed."""
    from .cli_common import _check_outputs, _load, _time, err, json_out, out
    from .ocp.mpoc import run_mpoc
    from .ocp.train_energy import energy_options
    from .reporting.ocp_tables import energy_summary_table, mesh_table, plan_sequence_table
    from .reporting.tables import fit, show
    from .reporting.writers import optimum_columns, write_output
    from .runner import planned_time

    api.check_energy_ocp(nodes, state_nodes, mesh_tol, max_degree)
    energy = energy_options(efficiency, regen, comfort)
    _check_outputs(out_file, plot)
    r, train, opts = _load(route_path, consist, stock_dir, model)
    t0 = planned_time(r, _time(time_s, (r, train), options=opts, quiet=as_json))
    with err.status("solving the multi-phase optimal control problem"):
        run = run_mpoc(r, train, opts, t0, energy=energy, mesh_tol=mesh_tol, max_degree=max_degree)
    s = run.summary
    if out_file:
        data = dict(s)
        if out_file.suffix.lower() == ".json":
            data["optimum"] = optimum_columns(run)
        write_output(out_file, data, run.check.result.profile, r)
    if plot:
        from .reporting.plot_ocp import plot_energy_run

        plot_energy_run(plot, run, route=r)
    if as_json:
        json_out(s)
    else:
        show(out, energy_summary_table(s, out.width) + fit(plan_sequence_table(s["sequence"]), out.width)
             + fit(mesh_table(s["mesh_history"]), out.width, drop=(8, 7, 5)))
    if api.confirmed_verdict(run.feasible, s["reason"]).exit_code:
        record_error(f"not confirmed: {s['objective']:.3f} kWh is not reported as a result: {s['reason']}")
        err.print(f"[bold red]not confirmed:[/] {s['objective']:.3f} kWh is not reported as a result: "
                  f"{escape(s['reason'])}", highlight=False, soft_wrap=True)
        raise typer.Exit(api.EXIT_FAILED)


@guarded
def bound(route: Path = ROUTE, time_s: Optional[str] = TIME,
          times: Optional[str] = typer.Option(None, "--times", help="Running times: start:stop:step in seconds, or a comma list of seconds, factors of the fastest run (1.1x) and supplements on it (+10%): the energy-time curve."),
          consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
          out_file: Optional[Path] = typer.Option(None, "--out", help="The curve as .csv or .json."),
          plot: Optional[Path] = typer.Option(None, "--plot", help="The energy-time curve, .png, .svg or .pdf."),
          mesh_tol: float = typer.Option(1e-5, "--mesh-tol", help="The Radau method's relative discretisation error to reach (--check)."),
          max_phase_degree: int = typer.Option(10, "--max-phase-degree", help="The Radau method's most LGR points per mesh interval (--check)."),
          check: bool = typer.Option(False, "--check/--no-check", help="Solve each E* a second, independent way (multi-phase Radau collocation with hp mesh refinement, as ocp --objective energy) and show both with their difference."),
          model: ModelRequest = MODEL, objective: str = OBJECTIVE):
    """The least traction energy E* for a running time: the yardstick of every plan. Method: the
    minimum-energy optimal control of the calculator's own train model, solved on the calculator's
    cells by an interior-point method on halved grids until two agree (the stated accuracy); with the
    air brake, also the least energy keeping its cycle."""
    from .cli_common import step_progress
    from .errors import InputError, Problem
    from .reporting.ocp_tables import energy_bound_line, energy_curve_table
    from .reporting.tables import fit, show
    from .reporting.writers import write_rows
    from .runner import planned_time

    values = api.bound_times(time_s, times)
    if out_file is not None and out_file.suffix.lower() not in (".csv", ".json"):
        raise InputError(Problem(str(out_file), "--out", "use .csv or .json"))
    _check_outputs(None, plot)
    if out_file is not None:
        _check_outputs(out_file.with_suffix(".json"), None)
    r, train, opts = _load(route, consist, stock_dir, model)
    ts = (_times(values, (r, train), options=opts, quiet=as_json) if values is not None
          else [planned_time(r, _time(time_s, (r, train), options=opts, quiet=as_json))])
    with step_progress("bound solves", len(ts) * (2 if check else 1), not as_json) as step:
        data = api.energy_curve(r, train, opts, ts, mesh_tol=mesh_tol, max_degree=max_phase_degree,
                                curve=values is not None, step=step, check=check, objective=objective)
    rows = data["results"]
    if out_file:
        write_rows(out_file, data)
    if plot:
        from .reporting.plot_ocp import plot_energy_time

        plot_energy_time(plot, data)
    if as_json:
        json_out(data if values is not None else {**data, **rows[0]})
    elif values is None:
        out.print(energy_bound_line(r.name, train.name, rows[0], objective), highlight=False)
    else:
        show(out, fit(energy_curve_table(r.name, train.name, rows, objective), out.width, drop=(3, 2), wrap=(6,)))
    fail_on(api.curve_verdict(rows))


def register(app: typer.Typer) -> None:
    """Add ``bound`` to ``app``."""
    app.command("bound")(bound)
