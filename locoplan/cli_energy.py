"""``locoplan ocp --objective energy`` and ``locoplan bound``: seed 001's optimum on the command line.

Thin commands over :mod:`locoplan.ocp.mpoc` and :mod:`locoplan.ocp.bound`; :func:`register` adds
``bound`` to a typer app, :func:`run_energy_ocp` is what ``ocp`` calls for ``--objective energy``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich import box
from rich.markup import escape
from rich.table import Table

__all__ = ["register", "run_energy_ocp"]


def _summary_table(s: dict, width: int = 80) -> list:
    from .reporting.tables import key_value_table

    mesh = s["mesh"]
    confirmed = "[green]yes[/]" if s["feasible"] else f"[red]no[/] ({escape(s['reason'] or '')})"
    rows = [
        ("method", f"multi-phase Radau (LGR) collocation, hp mesh refinement (seed 001, {s['strategy'].upper()})"),
        ("problem", f"minimum {s['energy_model']}; {s['phases']} phases; neutral sections: {s['neutral_sections']}"
                    + (f"; comfort {s['comfort_ms2']:g} m/s²" if s.get("comfort_ms2") else "")),
        ("planned time", f"{s['planned_time_s']:g} s (fastest run {s['fastest_time_s']:.1f} s)"),
        ("mesh", f"{mesh['intervals']} intervals, {mesh['points']} LGR points, {mesh['moving_points']} on switches; "
                 f"largest error {mesh['max_error']:.2g} (tolerance {mesh['tolerance']:g})"
                 + ("" if mesh["converged"] else " [yellow]not reached[/]")),
        ("objective (NLP)", f"{s['objective']:.3f} kWh"),
        ("plan", escape(s["plan"])),
        ("re-simulated", f"{s['resimulated_running_time_s']:.1f} s, {s['resimulated_energy_kwh']:.3f} kWh "
                         f"({s['plan_energy_gap_percent']:+.2f} % vs the objective), last coasting point moved "
                         f"{s['coast_shift_m']:+.0f} m"),
        ("max overspeed", f"{s['max_limit_violation_kmh']:.3f} km/h"),
    ]
    if s["neutral_margins_s"]:
        rows.append(("neutral coasting", ", ".join(f"{a:.1f} s / {b:.1f} s" for a, b in s["neutral_margins_s"])
                     + " (before the head enters / after the tail leaves)"))
    rows.append(("confirmed", confirmed))
    for key in ("plan_note", "mesh_note"):
        if s.get(key):
            rows.append(("note", s[key]))
    if s["feasible"]:
        rows += [("running time", f"{s['running_time_s']:.1f} s"), ("traction energy", f"{s['traction_energy_kwh']:.2f} kWh")]
    rows.append(("solve time", f"{s['solve_time_s']:.2f} s in all; the optimal control {s['optimal_control_time_s']:.2f} s "
                               f"(NLP solves {sum(h['solve_time_s'] for h in s['mesh_history']):.2f} s, builds "
                               f"{sum(h['build_time_s'] for h in s['mesh_history']):.2f} s), then the plan and its check"))
    return key_value_table(f"{s['route']}\n{s['consist']}", rows, width)


def _mesh_table(history: list[dict]) -> Table:
    table = Table(title="mesh refinement", title_justify="left", box=box.SIMPLE_HEAD)
    for col in ("mesh", "intervals", "LGR points", "max rel. error", "objective [kWh]", "IPOPT it.", "solve [s]",
                "split", "raised"):
        table.add_column(escape(col), justify="right")
    for h in history:
        table.add_row(str(h["iteration"]), str(h["intervals"]), str(h["points"]), f"{h['max_error']:.2g}",
                      f"{h['objective_kwh']:.4f}", str(h["ipopt_iterations"]), f"{h['solve_time_s']:.2f}",
                      str(h["split"]), str(h["raised"]))
    return table


def _sequence_table(runs: list[dict]) -> Table:
    table = Table(title="condition sequence (re-simulated plan)", title_justify="left", box=box.SIMPLE_HEAD)
    for col in ("condition", "from [m]", "to [m]"):
        table.add_column(escape(col), justify="right" if col != "condition" else "left")
    names = {"T": "T traction", "K": "K cruise", "C": "C coast", "B": "B brake"}
    for r in runs:
        table.add_row(names[r["condition"]], f"{r['from_m']:.0f}", f"{r['to_m']:.0f}")
    return table


def _optimum_columns(run) -> dict:
    """The optimum at its collocation points (for ``--out .json``)."""
    import numpy as np

    sol = run.solution.solution
    n = sol.grid.n_col
    v = np.sqrt(2 * np.maximum(sol.X[0, :n], 0.0)) * 3.6
    cols = {"s_m": np.round(sol.grid.s_col, 3).tolist(), "v_kmh": np.round(v, 4).tolist(),
            "t_s": np.round(sol.X[1, :n], 4).tolist()}
    for name, row in zip(sol.problem.model.controls, sol.U):
        cols[f"{name}_kn"] = np.round(row, 3).tolist()
    return cols


def run_energy_ocp(route_path: Path, consist: str, stock_dir: Optional[Path], time_s: Optional[str], mesh_tol: float,
                   max_degree: int, efficiency: Optional[str], regen: float, comfort: Optional[float], step: float,
                   point_mass: bool, air_brake: Optional[bool], rotating_mass: Optional[float], strict_limits: bool,
                   as_json: bool, out_file: Optional[Path], plot: Optional[Path], nodes, state_nodes) -> None:
    """``locoplan ocp ROUTE --objective energy``: solve, print, write; exit 1 if not confirmed."""
    from .cli_common import _check_outputs, _load, err, json_out, out
    from .errors import InputError, Problem
    from .reporting.writers import to_json, write_output
    from .ocp.mpoc import run_mpoc
    from .ocp.train_energy import energy_options
    from .runner import planned_time

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
    energy = energy_options(efficiency, regen, comfort)
    _check_outputs(out_file, plot)
    r, train, opts = _load(route_path, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
    from .cli_common import _time

    t0 = planned_time(r, _time(time_s, (r, train), options=opts, quiet=as_json))
    with err.status("solving the multi-phase optimal control problem"):
        run = run_mpoc(r, train, opts, t0, energy=energy, mesh_tol=mesh_tol, max_degree=max_degree)
    s = run.summary
    if out_file:
        data = dict(s)
        if out_file.suffix.lower() == ".json":
            data["optimum"] = _optimum_columns(run)
        write_output(out_file, data, run.check.result.profile, r)
    if plot:
        from .reporting.plot_ocp import plot_energy_run

        plot_energy_run(plot, run)
    if as_json:
        json_out(s)
    else:
        from .reporting.tables import fit, show

        show(out, _summary_table(s, out.width) + fit(_sequence_table(s["sequence"]), out.width)
             + fit(_mesh_table(s["mesh_history"]), out.width, drop=(8, 7, 5)))
    if not run.feasible:
        err.print(f"[bold red]not confirmed:[/] {s['objective']:.3f} kWh is not reported as a result: "
                  f"{escape(s['reason'])}", highlight=False, soft_wrap=True)
        raise typer.Exit(1)


def register(app: typer.Typer) -> None:
    """Add ``bound`` to ``app``."""
    from .cli_common import (AIR, CONSIST, JSON, POINT_MASS, ROT, ROUTE, STEP, STOCK, STRICT, TIME, _check_outputs, _load, _time, json_out,
                      _range, guarded, out)

    @app.command("bound")
    @guarded
    def bound(route: Path = ROUTE, time_s: Optional[str] = TIME,
              times: Optional[str] = typer.Option(None, "--times", help="Running times [s], start:stop:step or a list: the energy-time curve."),
              consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
              out_file: Optional[Path] = typer.Option(None, "--out", help="The curve as .csv or .json."),
              plot: Optional[Path] = typer.Option(None, "--plot", help="The energy-time curve, .png, .svg or .pdf."),
              mesh_tol: float = typer.Option(1e-5, "--mesh-tol", help="Relative discretisation error to reach."),
              max_phase_degree: int = typer.Option(10, "--max-phase-degree", help="Most LGR points per mesh interval."),
              step: float = STEP, point_mass: bool = POINT_MASS, air_brake: Optional[bool] = AIR,
              rotating_mass: Optional[float] = ROT, strict_limits: bool = STRICT):
        """The least traction energy E* for a running time: the yardstick of every plan. Method: multi-phase
        Radau optimal control after Bai Yun et al. (Beijing Jiaotong University), energy-saving high-speed
        train operation."""
        import csv
        import io

        from .errors import InputError, LocoplanError, Problem
        from .reporting.files import atomic_write_text
        from .reporting.writers import to_json
        from .ocp.bound import energy_bound
        from .runner import planned_time

        if times is not None and time_s is not None:
            raise InputError(Problem("", "--times", "give either --time or --times, not both"))
        values = _range(times, "--times") if times else None
        if values is not None and (not values or min(values) <= 0):
            raise InputError(Problem("", "--times", "running times must be > 0 s"))
        if out_file is not None and out_file.suffix.lower() not in (".csv", ".json"):
            raise InputError(Problem(str(out_file), "--out", "use .csv or .json"))
        _check_outputs(None, plot)
        if out_file is not None:
            _check_outputs(out_file.with_suffix(".json"), None)
        r, train, opts = _load(route, consist, stock_dir, step, point_mass, rotating_mass, strict_limits, air_brake)
        ts = values if values is not None else [planned_time(r, _time(time_s, (r, train), options=opts, quiet=as_json))]
        rows = []
        from .cli_common import step_progress

        with step_progress("bound solves", len(ts), not as_json) as step:
            for t in ts:
                step(f"E* at {t:g} s")
                try:
                    b = energy_bound(r, train, opts, t, mesh_tol=mesh_tol, max_degree=max_phase_degree)
                    rows.append({"time_s": t, "energy_kwh": round(b.energy_kwh, 3), "converged": b.converged,
                                 "mesh_points": b.points, "solve_time_s": round(b.solve_time_s, 3), "reason": None})
                except LocoplanError as exc:
                    if values is None:
                        raise
                    rows.append({"time_s": t, "energy_kwh": None, "converged": False, "mesh_points": None,
                                 "solve_time_s": None, "reason": str(exc)})
        data = {"route": r.name, "consist": train.name, "results": rows}
        if out_file:
            if out_file.suffix.lower() == ".json":
                atomic_write_text(out_file, to_json(data) + "\n")
            else:
                buf = io.StringIO()
                w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
                w.writeheader()
                w.writerows(rows)
                atomic_write_text(out_file, buf.getvalue())
        if plot:
            from .reporting.plot_ocp import plot_energy_time

            plot_energy_time(plot, data)
        if as_json:
            json_out(data if values is not None else {**data, **rows[0]})
        elif values is None:
            row = rows[0]
            out.print(f"E* = {row['energy_kwh']:.2f} kWh  ({escape(r.name)}, {escape(train.name)}, {row['time_s']:g} s; "
                      f"{row['mesh_points']} LGR points, "
                      + (f"solved in {row['solve_time_s']:.2f} s)" if row["solve_time_s"] else "from the cache of earlier solves)"), highlight=False)
        else:
            table = Table(title=escape(f"{r.name} — {train.name}: least traction energy E*(T)"), title_justify="left")
            for col in ("T [s]", "E* [kWh]", "mesh tol. met", "solve [s]"):
                table.add_column(escape(col), justify="right")
            for row in rows:
                if row["energy_kwh"] is None:
                    table.add_row(f"{row['time_s']:g}", "-", "-", escape(row["reason"] or ""))
                else:
                    table.add_row(f"{row['time_s']:g}", f"{row['energy_kwh']:.2f}", "yes" if row["converged"] else "no",
                                  f"{row['solve_time_s']:.2f}")
            from .reporting.tables import fit, show

            show(out, fit(table, out.width, wrap=(3,)))
        if all(row["energy_kwh"] is None for row in rows):
            raise typer.Exit(1)
