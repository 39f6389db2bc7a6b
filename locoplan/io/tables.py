"""Rich tables of every command's results (the writers beside report.py's JSON / CSV and plot.py's
figures). Each function takes result dicts (the SPEC's JSON objects, or rows derived from them) and
returns a ``rich.table.Table``; nothing here runs the model or prints."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from rich.markup import escape
from rich.table import Table


def describe(model, path: str, stock_dir: Optional[Path]) -> str:
    """One line about a validated file (validate's output): a route's length and sections, a vehicle's
    mass, a consist's train."""
    from .load import load_train

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


def summary_table(summary: dict) -> Table:
    """One result (the SPEC's JSON object) as a two-column table."""
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


def sequence_table(runs: list[dict]) -> Table:
    """The applied condition sequence (a summary's ``sequence``)."""
    table = Table(title="condition sequence", title_justify="left")
    for col in ("condition", "from [m]", "to [m]", "length [m]"):
        table.add_column(escape(col), justify="right" if col != "condition" else "left")
    names = {"T": "T traction", "K": "K cruise", "C": "C coast", "B": "B brake"}
    for r in runs:
        table.add_row(names[r["condition"]], f"{r['from_m']:.0f}", f"{r['to_m']:.0f}", f"{r['to_m'] - r['from_m']:.0f}")
    return table


def compare_tables(rows: list[dict], title: str) -> tuple[Table, Table]:
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
        if s["plan"] is None:  # no plan at all (the run was infeasible before it planned)
            t8.add_row(s["strategy"], "-", "-")
            t9.add_row(f"{s['strategy']} [red](infeasible: {escape(str(s['reason']))})[/]", *(["-"] * 8))
            continue
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


def explain_tables(seq) -> list:
    """The limit and grade classification behind the proposed sequence (seed 002 Fig. 2, step 2), and
    the sequence with its nominal switching points (a ``strategy.sequence.build_sequence`` result)."""
    out = []
    t = Table(title="speed-limit sections (seed 002 Fig. 2)", title_justify="left")
    for col in ("from [m]", "to [m]", "limit [km/h]", "type"):
        t.add_column(escape(col), justify="right" if col != "type" else "left")
    for s in seq.limits:
        t.add_row(f"{s.from_m:.0f}", f"{s.to_m:.0f}", f"{s.kmh:g}", s.kind)
    out.append(t)
    t = Table(title="grades (seed 002 step 2: can full traction / coasting hold the limit speed?)", title_justify="left")
    for col in ("from [m]", "to [m]", "equiv. gradient [‰]", "speed change [km/h]", "type"):
        t.add_column(escape(col), justify="right" if col != "type" else "left")
    for g in seq.grades:
        t.add_row(f"{g.from_m:.0f}", f"{g.to_m:.0f}", f"{g.permille:+.2f}", f"{g.speed_change_kmh:+.1f}", g.kind)
    out.append(t)
    out.append(f"proposed sequence (nominal switching points, seed 002 step 3): {seq.text()}")
    return out


def _num(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def sweep_table(rows: list[dict], title: str, by_weights: bool) -> Table:
    """Seed 002 Table 6 (``by_weights``) or Table 7 (planned times, with the energy reduction)."""
    table = Table(title=escape(title), title_justify="left")
    cols = (["w_time", "w_energy"] if by_weights else ["T0 [s]"]) + ["time [s]", "energy [kWh]", "|T-T0| [s]", "fitness", "vs E* [%]"]
    cols += [] if by_weights else ["energy reduction [%]"]
    for c in cols:
        table.add_column(escape(c), justify="right")
    for x in rows:
        lead = [f"{x['weights'][0]:g}", f"{x['weights'][1]:g}"] if by_weights and x.get("weights") else (
            ["-", "-"] if by_weights else [f"{x['planned_time_s']:g}"])
        tail = [] if by_weights else [_num(x.get("energy_reduction_percent"), ".1f")]
        table.add_row(*lead, _num(x["running_time_s"], ".1f"), _num(x["traction_energy_kwh"], ".2f"),
                      _num(x["punctuality_error_s"], ".1f"), _num(x["fitness"], ".4f"),
                      _num(x.get("gap_to_optimum_percent"), "+.2f"), *tail)
    return table


def study_table(rows: list[dict], title: str) -> Table:
    """Seed 002 Tables 10-12 from ``runner.study_table`` rows: per optimiser best, worst, mean, sd,
    punctual runs and the best punctual one."""
    table = Table(title=escape(title), title_justify="left")
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
                      _num(x.get("mean_gap_to_optimum_percent"), "+.2f"), f"{x['mean_solve_time_s']:.2f}")
    return table


HEADS = {"planned_time_s": "T0 [s]", "time_spec": "T0", "consist": "consist", "route": "route"}


def store_summary_table(rows: list[dict], by: list[str], title: str) -> Table:
    """``locoplan results``: one row per group (``runs.summary.summarize_records`` rows)."""
    table = Table(title=escape(title), title_justify="left")
    heads = [HEADS.get(b, b) for b in by] + ["runs", "feasible", "punctual", "E mean [kWh]", "E best", "E sd", "T mean [s]", "T sd", "gap mean [%]",
             "gap best [%]"]
    for i, h in enumerate(heads):
        table.add_column(escape(h), justify="left" if i < len(by) else "right")
    for r in rows:
        table.add_row(*[str(r[k]) if r[k] is not None else "-" for k in by], str(r["runs"]), str(r["feasible_runs"]),
                      str(r["punctual_runs"]), _num(r["energy_mean_kwh"], ".2f"), _num(r["energy_best_kwh"], ".2f"),
                      _num(r["energy_sd_kwh"], ".2f"), _num(r["time_mean_s"], ".1f"), _num(r["time_sd_s"], ".1f"),
                      _num(r["gap_mean_percent"], ".2f"), _num(r["gap_best_percent"], ".2f"))
    return table


def pareto_table(front: dict) -> Table:
    """``locoplan pareto``: per planned time, the best on-time plan (and E* once known), and the front."""
    table = Table(title=escape(f"{front['route']} — {front['consist']}: energy-time front "
                               f"(fastest run {front['fastest_time_s']:.1f} s)"), title_justify="left")
    for c in ("T0 [s]", "factor", "best on-time E [kWh]", "by", "its T [s]", "E* at its T [kWh]", "gap [%]", "on front"):
        table.add_column(escape(c), justify="right" if c != "by" else "left")
    for p in front["grid"]:
        table.add_row(f"{p['planned_time_s']:g}", f"{p['factor']:.3f}", _num(p["best_energy_kwh"], ".2f"),
                      p["best_strategy"] or "-", _num(p["best_running_time_s"], ".1f"), _num(p["optimum_kwh"], ".2f"),
                      _num(p["gap_to_optimum_percent"], ".2f"), "yes" if p["on_front"] else "")
    return table
