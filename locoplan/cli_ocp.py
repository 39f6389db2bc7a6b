"""``locoplan ocp`` and ``locoplan ocp-study``: optimal control on the command line (the two-stage Gauss paper's minimum time, the MPOC paper's minimum energy).

Thin commands over :mod:`locoplan.ocp.min_time_run` and :mod:`locoplan.ocp.min_time_study`; :func:`register` adds them to a typer app (the main
app in :mod:`locoplan.cli`, or a fresh one in tests).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.markup import escape

from .cli_common import api  # imported when a command runs (cli_common.LazyModule)
from .cli_common import ModelGroup, err, guarded, json_out, out, record_error
from .ocp.registry import (
    DEFAULT_ENERGY_CONSIST,
    DEFAULT_METHOD,
    DEFAULT_OCP_CONSIST,
    OBJECTIVES,
    OCP_METHODS,
    STAGE2_MODES,
)

if TYPE_CHECKING:
    from .api import ModelRequest

__all__ = ["register"]

ENERGY_MODEL = ModelGroup({
    "step": "Energy: grid of the traction calculator that checks the plan [m].",
    "point_mass": "Energy: the papers' point-mass train, braked by its locomotives alone.",
    "air_brake": "Energy: brake with the wagons' air brakes too (default: on, off with --point-mass).",
    "rotating_mass": "Energy: uniform rotating-mass allowance gamma (default: each vehicle's own factor).",
    "strict_limits": "Energy: the checking calculator fails a plan that coasts up to a limit.",
}, step_m=50.0)
"""``ocp``'s model options: they shape the energy objective's train (the minimum-time problem is the
paper's point mass on one gradient)."""


methods = ", ".join(OCP_METHODS)


@guarded
def ocp(route: Path = typer.Argument(..., help="Route YAML file (--objective time: one gradient and one speed limit)."),
        consist: Optional[str] = typer.Option(None, "--consist", help=f"Consist YAML file or catalogue name (default: {DEFAULT_OCP_CONSIST} for time, {DEFAULT_ENERGY_CONSIST} for energy).", show_default=False),
        stock_dir: Optional[Path] = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first."),
        objective: str = typer.Option("time", "--objective", help=f"Objective: {', '.join(OBJECTIVES)}."),
        method: Optional[str] = typer.Option(None, "--method", help=f"Transcription: {methods} (default: two-stage for time, radau for energy).", show_default=False),
        nodes: Optional[int] = typer.Option(None, "--nodes", help="Control nodes (default: the paper's 17 / 34 / 20)."),
        state_nodes: Optional[int] = typer.Option(None, "--state-nodes", help="State LG points (default: two-stage 2 x nodes, even; gpm = nodes)."),
        stage2: str = typer.Option("hp", "--stage2", help=f"Stage 2 of two-stage (ignored by the other methods): {', '.join(STAGE2_MODES)} (global = the paper's)."),
        time_s: Optional[str] = typer.Option(None, "--time", help="Energy: planned running time T [s]: seconds (1500), a factor of the fastest run (1.1x) or a supplement on it (+10%) (default: the route's schedule)."),
        mesh_tol: float = typer.Option(1e-5, "--mesh-tol", help="Energy: relative discretisation error the hp refinement reaches."),
        max_phase_degree: int = typer.Option(10, "--max-phase-degree", help="Energy: most LGR points per mesh interval."),
        efficiency: Optional[str] = typer.Option(None, "--efficiency", help="Energy: traction efficiency, a number or speed_kmh:eta pairs (default: work at the wheel)."),
        regen: float = typer.Option(0.0, "--regen", help="Energy: credited share of the electric brake's work (the air brake returns nothing)."),
        comfort: Optional[float] = typer.Option(None, "--comfort", help="Energy: largest acceleration / deceleration [m/s^2] (a comfort bound; off by default)."),
        model: ModelRequest = ENERGY_MODEL,
        as_json: bool = typer.Option(False, "--json", help="Machine-readable result on stdout (nothing else there)."),
        out_file: Optional[Path] = typer.Option(None, "--out", help="Re-simulated profile as .csv, or summary + profile as .json."),
        plot: Optional[Path] = typer.Option(None, "--plot", help="Time: control and state curves; energy: speed, limit, forces, neutral sections and the mesh. .png, .svg or .pdf."),
        ):
    """Optimal control: the minimum running time, or the minimum traction energy in a running time
    (--objective energy); checked by re-simulation (exit 1 if not confirmed). Methods: Liu Ping et al.,
    two-stage adaptive Gauss collocation pseudospectral method (time); multi-phase Radau control after
    Bai Yun et al., energy-saving high-speed train operation (energy)."""
    from .io.load import load_route, load_train
    from .ocp.registry import check_options

    method = method or DEFAULT_METHOD.get(objective, "two-stage")
    if objective == "energy":  # the minimum-time machinery (ocp.min_time_run) is not loaded for it
        check_options(method, None, None, stage2, objective)
        from .cli_energy import run_energy_ocp

        run_energy_ocp(route, consist or DEFAULT_ENERGY_CONSIST, stock_dir, time_s, mesh_tol, max_phase_degree,
                       efficiency, regen, comfort, model, as_json, out_file, plot, nodes, state_nodes)
        return
    check_options(method, nodes, state_nodes, stage2, objective)
    from .ocp.min_time_run import solve_ocp
    from .reporting.ocp_study import check_output_path, write_ocp_output

    check_output_path(out_file, "--out", (".csv", ".json"))
    check_output_path(plot, "--plot", (".png", ".svg", ".pdf"))
    r = load_route(route)
    train = load_train(consist or DEFAULT_OCP_CONSIST, stock_dir)
    run = solve_ocp(r, train, method, nodes, state_nodes=state_nodes, stage2=stage2, objective=objective,
                    route_file=route)
    if out_file and out_file.suffix.lower() == ".csv":  # the profile's columns in the order of every command's CSV
        from .reporting.files import atomic_write_text
        from .reporting.writers import PROFILE_COLUMNS, rows_csv

        atomic_write_text(out_file, rows_csv(run.profile_rows(), PROFILE_COLUMNS))
    elif out_file:
        write_ocp_output(out_file, run)
    if plot:
        from .reporting.plot_ocp import plot_run

        plot_run(plot, run)
    if as_json:
        json_out(run.summary)
    else:
        from .reporting.ocp_tables import time_summary_table
        from .reporting.tables import show

        show(out, time_summary_table(run.summary, out.width))
    if api.confirmed_verdict(run.feasible, run.summary["reason"]).exit_code:
        record_error(f"not confirmed: {run.summary['objective']:.3f} s is not reported as a result: {run.summary['reason']}")
        err.print(f"[bold red]not confirmed:[/] {run.summary['objective']:.3f} s is not reported as a result: "
                  f"{escape(run.summary['reason'])}", highlight=False, soft_wrap=True)
        raise typer.Exit(api.EXIT_FAILED)

@guarded
def ocp_study(consist: str = typer.Option(DEFAULT_OCP_CONSIST, "--consist", help="Consist YAML file or catalogue name."),
              repeats: int = typer.Option(1, "--repeats", help="Solves per row; the solve time is their median."),
              as_json: bool = typer.Option(False, "--json", help="Machine-readable result on stdout (nothing else there)."),
              out_file: Optional[Path] = typer.Option(None, "--out", help="Study as .json, .csv (one line per row) or .md."),
              plot: Optional[Path] = typer.Option(None, "--plot", help="Control curves and solve times, .png, .svg or .pdf."),
              ):
    """Minimum running time by CVP 20/40, GPM 34/48 and two-stage 17/24 collocation (hp and the paper's
    global stage 2), side by side. Method: Liu Ping et al., optimal operation of electric locomotives by a
    two-stage adaptive Gauss collocation pseudospectral method (its Tables 2-3)."""
    from .io.load import load_route, load_train
    from .ocp.min_time_study import run_study
    from .reporting.ocp_study import check_output_path, write_study_output

    from .bounds import count

    count(repeats, "--repeats", 1, 100, "solves per row, whose median is the solve time (each row takes seconds)")
    check_output_path(out_file, "--out", (".json", ".csv", ".md"))
    check_output_path(plot, "--plot", (".png", ".svg", ".pdf"))
    from .cli_common import step_progress
    from .ocp.registry import STUDY_ROUTES, study_route_files
    from .ocp.min_time_study import STUDY_RUNS

    with step_progress("ocp-study solves", len(STUDY_RUNS) * len(STUDY_ROUTES),
                       not as_json) as step:
        train = load_train(consist)
        routes = {k: (load_route(p), p) for k, p in study_route_files().items()}
        study = run_study(train, routes, repeats=repeats, progress=step)
    if out_file:
        write_study_output(out_file, study)
    if plot:
        from .reporting.plot_ocp import plot_study

        plot_study(plot, study)
    if as_json:
        json_out(study.to_dict())
    else:
        from .reporting.ocp_tables import ratio_table, study_tables
        from .reporting.tables import fit, show

        # at 80 columns the least needed columns are left out (a note names them; --out .md has all)
        for table in study_tables(study):
            show(out, fit(table, out.width, drop=(9, 8, 2)))
        ratios = ratio_table(study)
        n = len(ratios.columns) - 5  # per-test columns 2 .. n+1, then mean, paper mean, paper claim
        show(out, fit(ratios, out.width, drop=(n + 4, n + 3, *range(n + 1, 1, -1))))  # the mean stays
        out.print("stage 2 u / x: control parameters / state LG points (segments) of the final NLP", highlight=False)
        for r in study.rows:
            if not r["feasible"]:
                out.print(f"[red]not confirmed[/] Table {r['table']} {r['label']} {r['control_nodes']}: {escape(r['reason'])}",
                          highlight=False)  # wrapped at spaces to the width


def register(app: typer.Typer) -> None:
    """Add the ``ocp`` and ``ocp-study`` commands to ``app``."""
    app.command("ocp")(ocp)
    app.command("ocp-study")(ocp_study)
