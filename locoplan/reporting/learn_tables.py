"""Tables of the pattern-curve commands: ``drivers simulate`` (the synthetic runs), ``learn`` (the good
drivers and the fit report) and ``advise`` (the sections of the advice)."""

from __future__ import annotations

import math
from pathlib import Path

from rich.markup import escape
from rich.table import Table

def groups_table(title: str, groups: list[dict]) -> Table:
    table = Table(title=escape(title), title_justify="left")
    for col in ("mass [t]", "planned [s]", "runs", "mean time [s]", "late / early", "energy mean [kWh]", "min", "max"):
        table.add_column(escape(col), justify="right")
    for g in groups:
        table.add_row(f"{g['mass_t']:g}", f"{g['scheduled_time_s']:g}", str(g["runs"]), f"{g['mean_time_s']:.1f}",
                      f"{g['late_runs']} / {g['early_runs']}", f"{g['mean_energy_kwh']:.1f}", f"{g['min_energy_kwh']:.1f}",
                      f"{g['max_energy_kwh']:.1f}")
    return table


def fit_tables(report: dict) -> list[Table]:
    data = report["data"]
    routes = {g["route"] for g in data["groups"]}
    one_route = len(routes) == 1  # then the route is named once, in the title, not in every row
    t1 = Table(title=escape(f"good drivers: {data['good_runs']} good runs of {data['runs']} "
                            f"({data['synthetic_runs']} synthetic), {data['drivers']} drivers"
                            + (f"; route {next(iter(routes))}" if one_route else "")), title_justify="left")
    for col in (() if one_route else ("route",)) + ("mass [t]", "planned [s]", "runs", "drivers", "good drivers",
                                                    "good runs", "mean E [kWh]", "good mean E", "best E"):
        t1.add_column(escape(col), justify="left" if col == "route" else "right")
    for g in data["groups"]:
        t1.add_row(*(() if one_route else (escape(g["route"]),)), f"{g['mean_mass_t']:g}", f"{g['scheduled_time_s']:g}",
                   str(g["runs"]), str(g["drivers"]), str(g["good_drivers"]), str(g["good_runs"]), f"{g['mean_energy_kwh']:.1f}",
                   "-" if g["good_mean_energy_kwh"] is None else f"{g['good_mean_energy_kwh']:.1f}", f"{g['best_energy_kwh']:.1f}")
    up, lo = report["upper"], report["lower"]
    t2 = Table(title=escape("order by cross-validation (folds of whole runs); CV error: share (upper), km/h (lower)"),
               title_justify="left")
    for col in ("layer", "order", "CV RMSE", "in-sample R²", "chosen"):
        t2.add_column(escape(col), justify="left" if col == "layer" else "right")
    for form, rows in up["cv"].items():
        for r in rows:
            t2.add_row(f"upper ({form})", str(r["order"]), f"{r['cv_rmse']:.5f}", f"{r['in_sample_r2']:.4f}",
                       "<-" if form == up["form"] and r["order"] == up["order"] else "")
    for r in lo["cv"]:
        t2.add_row("lower", str(r["order"]), f"{r['cv_rmse']:.3f}", f"{r['in_sample_r2']:.4f}", "<-" if r["order"] == lo["order"] else "")
    t3 = Table(title=escape(f"fit report: {report['heldout'].get('runs', 0)} held-out runs (never fitted), "
                            f"{report['fit'].get('runs', 0)} fit runs"), title_justify="left")
    for col in ("runs", "shares R²", "share RMSE", "section time MAE [s]", "speed R² (1 division)", "RMSE [km/h]",
                "speed R² (chained)", "RMSE [km/h]"):
        t3.add_column(escape(col), justify="right" if col != "runs" else "left")
    for name in ("heldout", "fit"):
        r = report[name]
        if not r.get("runs"):
            continue
        u, l_ = r["upper"], r["lower"]
        t3.add_row(f"{name} ({r['runs']})", f"{u['r2']:.4f}", f"{u['rmse_share']:.5f}", f"{u['mean_abs_error_s']:.1f}",
                   f"{l_['one_step_r2']:.4f}", f"{l_['one_step_rmse_kmh']:.2f}", f"{l_['chained_r2']:.4f}",
                   f"{l_['chained_rmse_kmh']:.2f}")
    return [t1, t2, t3]


def sections_table(sections: list[dict]) -> Table:
    table = Table(title="sections: time shares (upper layer) and speeds at the division points (lower layer)",
                  title_justify="left")
    for col in ("#", "type", "from [m]", "to [m]", "G [‰]", "share", "time [s]", "as run", "pattern [km/h] entry .. exit"):
        table.add_column(escape(col), justify="left" if col in ("type", "pattern [km/h] entry .. exit") else "right")
    for s in sections:
        v = s["pattern_kmh"]
        table.add_row(str(s["index"]), s["type"], f"{s['from_m']:.0f}", f"{s['to_m']:.0f}", f"{s['gradient_permille']:+.2f}",
                      f"{s['share']:.4f}", f"{s['time_s']:.1f}", f"{s['realised_share']:.4f}",
                      " ".join(f"{x:.0f}" for x in v))
    return table


REPLAY_RUNS_SHOWN = 20
"""``replay`` lists at most this many runs in its table (those with the largest excess); ``--json`` has all."""


def _kwh(x) -> str:
    return "-" if x is None else f"{x:,.2f}"


def replay_tables(doc: dict, width: int = 80) -> list:
    """``locoplan replay``: the runs against E* (the ``REPLAY_RUNS_SHOWN`` with the largest excess), then per line
    the excess section by section (the run's own with one run, the mean per run with more), then the total."""
    from .tables import Note, fit

    runs = doc["runs"]
    shown = sorted(runs, key=lambda r: -math.inf if r["excess_kwh"] is None else r["excess_kwh"], reverse=True)
    shown = shown[:REPLAY_RUNS_SHOWN] if len(runs) > REPLAY_RUNS_SHOWN else runs
    title = (f"{len(runs)} runs against E* at their own running times" if len(shown) == len(runs) else
             f"the {len(shown)} runs of {len(runs)} with the largest excess over E* at their own running times")
    t1 = Table(title=escape(title), title_justify="left")
    for col in ("log", "time [s]", "energy [kWh]", "E* [kWh]", "excess [kWh]", "excess [%]", "worst section [km]: kWh"):
        t1.add_column(escape(col), justify="left" if col in ("log", "worst section [km]: kWh") else "right")
    for r in shown:
        worst = max(r["sections"], key=lambda s: s["excess_kwh"]) if r["sections"] else None
        t1.add_row(escape(Path(r["log"]).stem), f"{r['running_time_s']:.1f}", _kwh(r["traction_energy_kwh"]),
                   _kwh(r["optimum_kwh"]), _kwh(r["excess_kwh"]),
                   "-" if r["excess_percent"] is None else f"{r['excess_percent']:.1f}",
                   "-" if worst is None else f"{worst['from_m'] / 1000:,.1f}-{worst['to_m'] / 1000:,.1f}: "
                                             f"{worst['excess_kwh']:+,.1f}")
    blocks: list = fit(t1, width, drop=(5,), wrap=(0, 6))
    for line in doc["summary"]["lines"]:
        n = line["runs"]
        per = "" if n == 1 else ", mean per run"
        t = Table(title=escape(f"{line['route']}: where {'the run' if n == 1 else f'{n} runs'} lost energy, by section"
                               f" [kWh{per}]: excess = energy over the optimum's + value of the time spent + of the speed"
                               " brought in less carried out"),
                  title_justify="left")
        for col in ("#", "type", "km", "energy", "time", "speed", "excess", "share [%]"):
            t.add_column(escape(col), justify="left" if col == "type" else "right")
        total = line["excess_kwh"]
        for s in line["sections"]:
            t.add_row(str(s["index"]), s["type"], f"{s['from_m'] / 1000:,.1f}-{s['to_m'] / 1000:,.1f}",
                      f"{s['energy_kwh'] / n:+,.2f}",
                      f"{s['time_kwh'] / n:+,.2f}", f"{s['speed_kwh'] / n:+,.2f}", f"{s['excess_kwh'] / n:+,.2f}",
                      f"{100 * s['excess_kwh'] / total:.1f}" if total > 0 else "-")
        blocks += fit(t, width, drop=(7,))
    s = doc["summary"]
    if s["compared"]:
        blocks.append(Note(f"{s['compared']} run{'s' if s['compared'] != 1 else ''}: {s['traction_energy_kwh']:,.2f} kWh used, "
                           f"E* {s['optimum_kwh']:,.2f} kWh in the same running times: {s['excess_kwh']:,.2f} kWh "
                           + ("" if s["excess_percent"] is None else f"({s['excess_percent']:.1f} %) ")
                           + "an optimal drive would have saved"))
    if s["compared"] < s["runs"]:
        blocks.append(Note(f"{s['runs'] - s['compared']} of {s['runs']} runs have no E* at their running time (below)"))
    return blocks
