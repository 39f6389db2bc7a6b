"""Tables of the optimal-control commands: ``ocp`` (minimum time, minimum energy and its mesh),
``ocp-study`` (the two-stage Gauss paper's Tables 2-3 and the solve-time ratios) and ``bound`` (the energy-time curve)."""

from __future__ import annotations

from rich import box
from rich.markup import escape
from rich.table import Table

from .tables import key_value_table
from ..ocp.bound import within_percent
from ..model.conditions import CONDITION_NAMES


def time_summary_table(s: dict, width: int = 80) -> list:
    """``ocp`` (minimum running time): the method, the problem, the optimum and its check."""
    method = s["algorithm"] + (f" (stage 2: {s['stage2']})" if s["stage2"] else "")
    nodes = f"{s['control_nodes']} control" + (f" / {s['state_nodes']} state" if s["state_nodes"] else "")
    if s["algorithm"] == "two-stage":
        nodes += f" (stage 2: {s['final_control_nodes']} / {s['final_state_nodes']}, {s['segments']} segments)"
    confirmed = "[green]yes[/]" if s["feasible"] else f"[red]no[/] ({escape(str(s['reason']))})"
    rows = [
        ("method", method), ("nodes", nodes), ("problem", f"{s['length_m']:g} m, {s['gradient_permille']:g} ‰, "
                                                         f"limit {s['speed_limit_kmh']:g} km/h, force "
                                                         f"{s['force_bounds_kn'][0]:g}..{s['force_bounds_kn'][1]:g} kN"),
        ("objective (NLP)", f"{s['objective']:.4f} s" if s["objective"] is not None else "-"),
        ("exact minimum", f"{s['exact_minimum_s']:.4f} s (gap {s['gap_to_exact_s']:+.4f} s)"),
        ("re-simulated", "does not arrive" if s["resimulated_running_time_s"] is None
         else f"{s['resimulated_running_time_s']:.4f} s"),
        ("max overspeed", f"{s['max_limit_violation_kmh']:.3f} km/h"),
        ("confirmed", confirmed),
    ]
    if s["feasible"]:
        rows += [("running time", f"{s['running_time_s']:.3f} s"),
                 ("traction energy", f"{s['traction_energy_kwh']:.3f} kWh")]
    rows += [("IPOPT", f"{s['status']}, {s['iterations']} iterations"), ("solve time", f"{s['solve_time_s']:.3f} s")]
    if s.get("force_bounds_note"):
        rows.append(("note", escape(s["force_bounds_note"])))
    return key_value_table(f"{s['route']}\n{s['consist']}", rows, width)


_STUDY_HEADS = ("method", "u / x", "stage 2 u / x", "objective", "re-sim.", "- exact", "solve", "ok",
                "paper obj.", "paper solve")


def study_tables(study) -> list[Table]:
    """One compact table per table of the paper (2: level, 3: 30 per mille); full columns are in --out .md."""
    tables = []
    for tab in sorted({r["table"] for r in study.rows}):
        rows = [r for r in study.rows if r["table"] == tab]
        grade = rows[0]["gradient_permille"]
        table = Table(title=f"Table {tab} of the paper ({'level' if grade == 0 else format(grade, 'g') + ' ‰'}, exact "
                            f"minimum {study.exact[tab]:.4f} s): times in s, solve = median of {study.repeats}",
                      title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False, padding=(0, 1))
        for col in _STUDY_HEADS:
            table.add_column(col, justify="left" if col in ("method", "stage 2 u / x") else "right")
        for r in rows:
            st2 = f"{r['final_control_nodes']} / {r['final_state_nodes']} ({r['segments']})" if r["algorithm"] == "two-stage" else "-"
            nodes = f"{r['control_nodes']}" + (f" / {r['state_nodes']}" if r["state_nodes"] else "")
            gap = "-" if r["gap_to_exact_s"] is None else f"{r['gap_to_exact_s']:+.3f}"
            resim = "-" if r["resimulated_running_time_s"] is None else f"{r['resimulated_running_time_s']:.3f}"
            table.add_row(r["label"], nodes, st2, f"{r['objective']:.3f}", resim, gap, f"{r['solve_time_s']:.3f}",
                          "[green]yes[/]" if r["feasible"] else "[red]no[/]",
                          f"{r['seed_objective_s']:.2f}" if r.get("seed_objective_s") else "-",
                          f"{r['seed_solve_time_s']:.2f}" if r.get("seed_solve_time_s") else "-")
        tables.append(table)
    return tables


def ratio_table(study) -> Table:
    pairs = [(p["table"], p["test"]) for p in study.ratios[0]["per_test"]] if study.ratios else []
    table = Table(title="solve-time reduction of two-stage in per cent: measured here (the paper's tables)",
                  title_justify="left", box=box.SIMPLE_HEAD, pad_edge=False, padding=(0, 1))
    table.add_column("two-stage")
    table.add_column("vs")
    for tab, test in pairs:
        table.add_column(f"T{tab} test {test}", justify="right")
    for col in ("mean", "paper mean", "paper claim"):
        table.add_column(col, justify="right")
    for r in study.ratios:
        cells = [f"{p['percent']:.1f} ({p['seed_percent']:.1f})" for p in r["per_test"]]
        table.add_row(r["two_stage"], r["versus"].upper(), *cells, f"{r['mean_percent']:.1f}",
                      f"{r['seed_tables_mean_percent']:.2f}", f"{r['seed_claim_percent']:.2f}")
    return table


def energy_summary_table(s: dict, width: int = 80) -> list:
    """``ocp --objective energy``: the method, the problem, the mesh, the plan and its check."""
    mesh = s["mesh"]
    confirmed = "[green]yes[/]" if s["feasible"] else f"[red]no[/] ({escape(s['reason'] or '')})"
    rows = [
        ("method", f"multi-phase Radau (LGR) collocation, hp mesh refinement ({s['strategy'].upper()})"),
        ("problem", f"minimum {s['energy_model']}; {s['phases']} phases; neutral sections: {s['neutral_sections']}"
                    + (f"; comfort {s['comfort_ms2']:g} m/s²" if s.get("comfort_ms2") else "")),
        ("planned time", f"{s['planned_time_s']:g} s (fastest run {s['fastest_time_s']:.1f} s)"
                         + (f"; the optimum solved for {s['optimum_time_s']:.1f} s"
                            if s.get("optimum_time_s") not in (None, s["planned_time_s"]) else "")),
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
    for key in ("plan_note", "cycle_note", "mesh_note"):
        if s.get(key):
            rows.append(("note", escape(s[key])))
    if s["feasible"]:
        rows += [("running time", f"{s['running_time_s']:.1f} s"), ("traction energy", f"{s['traction_energy_kwh']:.2f} kWh")]
    rows.append(("solve time", f"{s['solve_time_s']:.2f} s in all; the optimal control {s['optimal_control_time_s']:.2f} s "
                               f"(NLP solves {sum(h['solve_time_s'] for h in s['mesh_history']):.2f} s, builds "
                               f"{sum(h['build_time_s'] for h in s['mesh_history']):.2f} s), then the plan and its check"))
    return key_value_table(f"{s['route']}\n{s['consist']}", rows, width)


def mesh_table(history: list[dict]) -> Table:
    table = Table(title="mesh refinement", title_justify="left", box=box.SIMPLE_HEAD)
    for col in ("mesh", "intervals", "LGR points", "max rel. error", "objective [kWh]", "IPOPT it.", "solve [s]",
                "split", "raised"):
        table.add_column(escape(col), justify="right")
    for h in history:
        table.add_row(str(h["iteration"]), str(h["intervals"]), str(h["points"]), f"{h['max_error']:.2g}",
                      f"{h['objective_kwh']:.4f}", str(h["ipopt_iterations"]), f"{h['solve_time_s']:.2f}",
                      str(h["split"]), str(h["raised"]))
    return table


def plan_sequence_table(runs: list[dict]) -> Table:
    table = Table(title="condition sequence (re-simulated plan)", title_justify="left", box=box.SIMPLE_HEAD)
    for col in ("condition", "from [m]", "to [m]"):
        table.add_column(escape(col), justify="right" if col != "condition" else "left")
    for r in runs:
        table.add_row(f"{r['condition']} {CONDITION_NAMES[r['condition']]}", f"{r['from_m']:.0f}", f"{r['to_m']:.0f}")
    return table


def energy_curve_table(route: str, consist: str, rows: list[dict], objective: str = "traction") -> Table:
    """``bound --times``: E* at each running time (a time without an optimum: its reason), with its run's
    traction work and what its electric brake recovers (columns 2 and 3)."""
    what = "net energy" if objective == "net" else "traction energy"
    table = Table(title=escape(f"{route} — {consist}: least {what} E*(T)"), title_justify="left")
    check = any(r.get("check") for r in rows)
    cols = ["T [s]", "E* [kWh]", "traction [kWh]", "recovered [kWh]", "within [%]", "converged", "solve [s]"] + (
        ["2nd method [kWh]", "diff. [%]"] if check else [])
    for col in cols:
        table.add_column(escape(col), justify="right")
    for row in rows:
        if row["energy_kwh"] is None:
            table.add_row(f"{row['time_s']:g}", "-", "-", "-", "-", "-", escape(row["reason"] or ""),
                          *(["-", "-"] if check else []))
        else:
            c = row.get("check")
            table.add_row(f"{row['time_s']:g}", f"{row['energy_kwh']:.2f}", _kwh(row.get("traction_energy_kwh")),
                          _kwh(row.get("recovered_energy_kwh")), _acc(row.get("accuracy_percent")),
                          "yes" if row["converged"] else "no", f"{row['solve_time_s']:.2f}",
                          *([f"{c['energy_kwh']:.2f}", f"{c['difference_percent']:+.3f}"] if c else (["-", "-"] if check else [])))
    return table


def _kwh(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def _acc(pct: float | None) -> str:
    return "?" if pct is None else within_percent(pct).removesuffix(" %")


def energy_bound_line(route: str, consist: str, row: dict, objective: str = "traction") -> str:
    """``bound --time``: the one E* as a line, then its run's traction, recovered and net energy."""
    parts = ("traction_energy_kwh", "recovered_energy_kwh", "net_energy_kwh")
    run = ("" if any(row.get(k) is None for k in parts) else
           f"\nits run: traction {row['traction_energy_kwh']:.2f} kWh, recovered by the electric brake "
           f"{row['recovered_energy_kwh']:.2f} kWh, net {row['net_energy_kwh']:.2f} kWh"
           + (" (E* is the least net energy)" if objective == "net" else ""))
    return (f"E* = {row['energy_kwh']:.2f} kWh  ({escape(route)}, {escape(consist)}, {row['time_s']:g} s; "
            f"{row['cells']:,} cells, "
            + (f"solved in {row['solve_time_s']:.2f} s" if row["solve_time_s"] else "from the cache of earlier solves")
            + f"; within {within_percent(row.get('accuracy_percent'))}"
            + ")"
            + run
            + (f"\nsecond method ({c['method']}, {c['lgr_points']:,} LGR points): {c['energy_kwh']:.2f} kWh "
               f"within {within_percent(c['accuracy_percent'])}; E* - it = {c['difference_percent']:+.3f} %"
               if (c := row.get("check")) else "")
            + cycle_optimum_line(row))


def cycle_optimum_line(row: dict) -> str:
    """``bound --time`` where the air brake cycles: the least energy keeping the cycle, beside E* (which relaxes
    the air brake to a continuous force)."""
    e = row.get("optimum_with_cycle_kwh")
    if e is None:
        return ""
    sizes = [f"{c:.3g}" for c in row.get("optimum_with_cycle_cells_m") or []]
    cells = ", ".join(sizes[:-1]) + (" and " if len(sizes) > 1 else "") + sizes[-1] if sizes else "?"
    took = row.get("optimum_with_cycle_solve_time_s")
    return (f"\nwith the air brake's cycle: {e:.2f} kWh within "
            f"{within_percent(row.get('optimum_with_cycle_accuracy_percent'))} (+{100 * (e / row['energy_kwh'] - 1):.1f} % "
            f"over E*, which relaxes the air brake to a continuous force; a DP over position, speed and the brake's "
            f"state on {cells} m cells, "
            + (f"solved in {took:.2f} s)" if took else "from the cache of earlier solves)"))
