"""Rich tables of every command's results (the writers beside report.py's JSON / CSV and plot.py's
figures). Each function takes result dicts (the SPEC's JSON objects, or rows derived from them) and
returns a ``rich.table.Table``; nothing here runs the model or prints."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

from rich.markup import escape
from rich.table import Table
from rich.text import Text
from ..ocp.bound import GAP_DIGIT_PERCENT, percent_digits, within_percent
from ..model.conditions import CONDITION_NAMES

# ------------------------------------------------------------------------------- fitting a width
# A table is printed at the console's width (the terminal's, or COLUMNS, or 80 when piped). Numbers
# are never folded, cut or ended with "…": a column of numbers is as wide as its widest number, a
# header wraps at its spaces, text (names, reasons) wraps at its spaces, and when the table is still
# too wide whole columns are left out, least useful first, and a note under the table names them.
# A plan string, which has no spaces and must stay one piece to be copied, goes on a line of its
# own when it does not fit (printed whole: the terminal wraps it, nothing cuts it).


class Line(str):
    """A line printed whole, never folded or cut by rich (a plan string, a path): the terminal wraps it."""


class Note(str):
    """A line of prose under a table (wrapped at its spaces)."""


def _plain(cell) -> str:
    if isinstance(cell, Text):
        return cell.plain
    if isinstance(cell, str):
        try:
            return Text.from_markup(cell).plain
        except Exception:  # text that only looks like markup
            return cell
    return str(cell)


def _longest_word(text: str) -> int:
    return max((len(w) for w in text.split()), default=0)


def fit(table: Table, width: int, drop: tuple[int, ...] = (), wrap: tuple[int, ...] = ()) -> list:
    """``table`` made to fit ``width`` columns without cutting a number: every column not in ``wrap``
    (indices of text columns that may wrap at their spaces) is at least as wide as its widest cell
    and its header's longest word; while the table is wider than ``width``, the columns in ``drop``
    (indices, the first left out first) are removed. The columns' widths are then fixed here (rich's
    own shrinking would cut numbers). Returns the blocks to print: the table, and a :class:`Note`
    naming the columns left out (every field is in ``--json`` / ``--out``)."""
    cols = list(table.columns)
    low, high = {}, {}
    for i, col in enumerate(cols):
        cells = [_plain(c) for c in col._cells]
        head = _plain(col.header) if table.show_header else ""
        lines = [line for c in cells for line in (c.splitlines() or [""])]
        high[id(col)] = max([len(head)] + [len(x) for x in lines])
        if i in wrap:
            low[id(col)] = max([_longest_word(head)] + [_longest_word(c) for c in cells])
        else:
            low[id(col)] = max([_longest_word(head)] + [len(x) for x in lines])
        col.overflow = "fold"  # should a width ever be too small: fold, never "…"

    def overhead() -> int:
        return table._extra_width + sum(table._get_padding_width(k) for k in range(len(table.columns)))

    dropped = []
    left = list(drop)
    while sum(low[id(c)] for c in table.columns) + overhead() > width and left:
        col = cols[left.pop(0)]
        table.columns[:] = [c for c in table.columns if c is not col]
        for k, c in enumerate(table.columns):
            c._index = k
        dropped.append(" ".join(_plain(col.header).split()))
    # still too wide (a narrow terminal): leave out more columns, the last first, rather than cut a number
    while sum(low[id(c)] for c in table.columns) + overhead() > width and len(table.columns) > 2:
        col = next((c for c in reversed(table.columns[1:]) if cols.index(c) not in wrap), table.columns[-1])
        table.columns[:] = [c for c in table.columns if c is not col]
        for k, c in enumerate(table.columns):
            c._index = k
        dropped.append(" ".join(_plain(col.header).split()))
    # widths: each column's minimum, then what is left shared out up to each column's natural width
    room = width - overhead()
    widths = {id(c): low[id(c)] for c in table.columns}
    spare = room - sum(widths.values())
    while spare > 0:
        short = [c for c in table.columns if widths[id(c)] < high[id(c)]]
        if not short:
            break
        share = max(1, spare // len(short))
        for c in short:
            give = min(share, high[id(c)] - widths[id(c)], spare)
            widths[id(c)] += give
            spare -= give
            if spare <= 0:
                break
    for c in table.columns:
        c.width = widths[id(c)]
    blocks: list = [table]
    if dropped:
        blocks.append(Note(f"(left out at {width} columns: {'; '.join(dropped)}; --json has every field)"))
    return blocks


def show(console, blocks) -> None:
    """Print tables, :class:`Line` s (whole) and :class:`Note` s (wrapped) in order."""
    for b in blocks:
        if isinstance(b, Line):
            console.print(b, soft_wrap=True, markup=False, highlight=False)
        elif isinstance(b, Note):
            console.print(b, markup=False, highlight=False, style="dim")
        else:
            console.print(b)


def describe_data(model, path: str, stock_dir: Optional[Path]) -> dict:
    """A validated file described as data (``validate --json``): its kind and what it holds, in the
    files' own units (route: length, sections, schedule; vehicle: mass, length, top speed; consist: the
    resolved train)."""
    from ..io.load import load_train

    kind = type(model).__name__
    if kind == "Route":
        d = {"kind": "route", "name": model.name, "length_m": model.length_m,
             "speed_limit_sections": len(model.speed_limits), "gradient_sections": len(model.gradients),
             "curves": len(model.curves), "tunnels": len(model.tunnels), "neutral_sections": len(model.neutral_sections),
             "schedule": None}
        if model.schedule:
            d["schedule"] = {"run_time_s": model.schedule.run_time_s, "tolerance_s": model.schedule.tolerance_s}
        return d
    if kind == "Vehicle":
        return {"kind": "vehicle", "name": model.name, "vehicle_kind": model.kind, "mass_t": model.mass_t,
                "length_m": model.length_m, "max_speed_kmh": model.max_speed_kmh}
    if kind == "Journey":
        return {"kind": "journey", "name": model.name, "route": model.route, "stations": len(model.stations),
                "stops": len(model.stops), "run_time_s": model.run_time_s}
    train = load_train(path, stock_dir)
    return {"kind": "consist", "name": train.name, "vehicles": train.n_vehicles, "mass_t": train.mass_t,
            "length_m": train.length_m, "max_speed_kmh": train.max_speed_kmh}


def describe(model, path: str, stock_dir: Optional[Path]) -> str:
    """One line about a validated file (validate's output): a route's length and sections, a vehicle's
    mass, a consist's train."""
    d = describe_data(model, path, stock_dir)
    if d["kind"] == "route":
        def count(n, noun):
            return f"{n} {noun}{'' if n == 1 else 's'}"
        parts = [f"{d['length_m'] / 1000:g} km", count(d["speed_limit_sections"], "speed-limit section"),
                 count(d["gradient_sections"], "gradient section"), count(d["curves"], "curve"),
                 count(d["tunnels"], "tunnel"), count(d["neutral_sections"], "neutral section")]
        if d["schedule"]:
            parts.append(f"schedule {d['schedule']['run_time_s']:g} +- {d['schedule']['tolerance_s']:g} s")
        return f"route '{d['name']}': " + ", ".join(parts)
    if d["kind"] == "vehicle":
        return f"{d['vehicle_kind']} '{d['name']}': {d['mass_t']:g} t, {d['length_m']:g} m, max {d['max_speed_kmh']:g} km/h"
    if d["kind"] == "journey":
        return (f"journey '{d['name']}' over {d['route']}: {d['stations']} stations, {d['stops'] - 1} legs"
                + (f", running time {d['run_time_s']:g} s" if d["run_time_s"] else ""))
    return (f"consist '{d['name']}': {d['vehicles']} vehicles, {d['mass_t']:g} t, "
            f"train length {d['length_m']:g} m, max {d['max_speed_kmh']:g} km/h")


def _num(value, fmt: str, unit: str = "") -> str:
    """A number for a table, "-" when there is none (None, NaN: an infeasible plan has no time)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return format(value, fmt) + unit


def key_value_table(title: str, rows: list[tuple[str, str]], width: int = 80, whole: tuple[str, ...] = ("plan",)) -> list:
    """A two-column table (quantity, value; values are markup, wrapped at their spaces); the value of a
    key in ``whole`` (a plan string: no spaces, copied as one piece) that does not fit the value column
    goes on a line of its own under the table, printed whole. Blocks for :func:`show`."""
    table = Table(title=escape(title), show_header=False, title_justify="left")
    table.add_column("quantity", style="bold")
    table.add_column("value")
    key_width = max(len(k) for k, _ in rows)
    room = width - key_width - 7  # the value column's width inside a table of `width`
    below = []
    for k, v in rows:
        if k in whole and len(_plain(v)) > room:
            below.append(Line(f"{k} {_plain(v)}"))
            v = "(below the table)"
        table.add_row(k, v)
    return [table] + below


def _punctuality(summary: dict) -> str:
    """'76.7 s early, outside the window 1470 .. 1530 s (planned 1500 s)': how far a run is off its
    planned time, in which direction, and whether that is inside the punctuality window."""
    planned = f"(planned {summary['planned_time_s']:g} s)"
    t = summary.get("running_time_s")
    if t is None or summary.get("punctuality_error_s") is None:
        return f"- {planned}"
    off = t - summary["planned_time_s"]
    side = "late" if off > 0 else "early"
    text = f"{abs(off):.1f} s {side}" if round(abs(off), 1) else "0.0 s"
    window = summary.get("window_s")
    if window:
        inside = "inside" if summary.get("punctual") else "[red]outside[/]"
        text += f", {inside} the window {window[0]:g} .. {window[1]:g} s"
    return f"{text} {planned}"


def e_min_origin(summary: dict) -> str:
    """What eq. 11's E_min is, for the fitness row: E* at the punctuality window's end, the ISSA paper's energy-saving
    run, or the user's value."""
    src = summary.get("e_min_source")
    if src == "optimum" and summary.get("e_min_time_s") is not None:
        return f" = E* at {summary['e_min_time_s']:,.1f} s, the window's end"
    if src == "energy-saving":
        return ", the energy-saving run's"
    if src == "given":
        return ", given"
    return ""


def summary_table(summary: dict, width: int = 80, route=None, form: str = "km", depart_s: float | None = None) -> list:
    """One result (the SPEC's JSON object) as a two-column table; blocks for :func:`show` (a plan too
    long for the table's value column follows the table on a line of its own, whole). With ``route``: its
    stations, and positions with their kilometre posts (written in ``form``) where it has a chainage; with
    ``depart_s`` (the departure's clock time, seconds since midnight), the run's departure and arrival clocks."""
    feasible = "[green]yes[/]" if summary["feasible"] else f"[red]no[/] ({escape(str(summary['reason']))})"
    rows = [("strategy", escape(summary["strategy"] + (f" ({summary['algorithm']}, seed {summary['seed']})" if summary.get("algorithm") else ""))),
            ("plan", escape(summary.get("plan") or "-")), ("feasible", feasible)]
    rows.append(("running time", _num(summary["running_time_s"], ".1f", " s") + _clocks(summary["running_time_s"], depart_s)))
    rows.append(("traction energy", _num(summary["traction_energy_kwh"], ".2f", " kWh")
                 + ("" if summary["feasible"] or summary["traction_energy_kwh"] is None else " (until it failed)")))
    rows += energy_rows(summary)
    if summary.get("planned_time_s") is not None:
        rows.append(("punctuality error", _punctuality(summary)))
    if summary.get("fitness") is not None:
        rows.append(("fitness", f"{summary['fitness']:.5f} (weights {summary['weights'][0]:g}/{summary['weights'][1]:g}, "
                     f"E_min {summary['e_min_kwh']:.1f} kWh{e_min_origin(summary)})"))
    if summary.get("cruise_kmh"):
        rows.append(("cruise speed", f"{summary['cruise_kmh']:g} km/h"))
    acc = summary.get("optimum_accuracy_percent")
    least = "the least net energy" if summary.get("objective") == "net" else "the least energy"
    if summary.get("gap_to_optimum_percent") is not None:
        rows.append(("gap to optimum", f"{summary['gap_to_optimum_percent']:+.2f} % over E* (known to {within_percent(acc)}), "
                     f"{least} in this running time"))
    elif summary.get("gap_to_optimum_kwh") is not None:
        why = ("too little for a percentage" if acc is not None and acc < 0.5 * GAP_DIGIT_PERCENT
               else f"E* within {within_percent(acc)}: too uncertain for a percentage to the last digit")
        rows.append(("gap to optimum", f"{summary['gap_to_optimum_kwh']:+.2f} kWh over E* = {summary['optimum_kwh']:.2f} kWh, "
                     f"{least} in this running time ({why})"))
    if summary.get("gap_to_optimum_kwh") is not None and summary.get("min_recharge_margin_s") is not None:
        # (a plan that cycles its air brake: E* holds that descent with the air brake at will)
        rows.append(("E*", "relaxes the air brake to a continuous force (no cycle): a lower bound"))
    rows += cycle_optimum_rows(summary)
    rows += coupler_rows(summary, route, form)
    rows += air_brake_rows(summary)
    if route is not None and route.stations:
        from .posts import station_place

        rows.append(("stations", ", ".join(escape(station_place(route, st, form)) for st in route.stations)))
    rows.append(("solve time", _num(summary.get("solve_time_s"), ".3f", " s")))
    return key_value_table(f"{summary['route']}\n{summary['consist']}", rows, width)


def _clocks(running_time_s, depart_s: float | None) -> str:
    """`` (departs 08:00:00, arrives 08:09:09)`` for a run that departs at ``depart_s`` (seconds since midnight)."""
    from ..bounds import clock_text

    if depart_s is None or running_time_s is None or not math.isfinite(running_time_s):
        return ""
    return (f" (departs {clock_text(depart_s, with_seconds=True)}, arrives "
            f"{clock_text(depart_s + running_time_s, with_seconds=True)})")


def cycle_optimum_rows(summary: dict) -> list[tuple[str, str]]:
    """Where the air brake cycles: the bracket of the optimum, E* (the air brake relaxed) .. the least energy of a
    drive that keeps the cycle, and where the plan sits in it (its gap to the latter in per cent to the digits
    that optimum's accuracy allows)."""
    e_cyc = summary.get("optimum_with_cycle_kwh")
    if e_cyc is None or summary.get("optimum_kwh") is None:
        return []
    acc = summary.get("optimum_with_cycle_accuracy_percent")
    e, e_star = summary["traction_energy_kwh"], summary["optimum_kwh"]
    digits = percent_digits(acc)
    gap = summary.get("gap_to_cycle_optimum_percent")
    where = ("" if gap is None or digits is None else f", {gap:+.{digits}f} % over the latter")
    cost = ("" if e_cyc - e_star <= 1e-9 else
            f": the cycle costs {100.0 * (e_cyc - e_star) / e_star:.1f} %" if gap is not None and e_star > 0 else
            f": the cycle costs {e_cyc - e_star:.2f} kWh")
    return [("optimum bracket", f"{e_star:.2f} .. {e_cyc:.2f} kWh, E* (the air brake relaxed) .. the least energy "
             f"keeping its cycle (within {within_percent(acc)}){cost}; the plan {e:.2f} kWh{where}")]


def energy_rows(summary: dict) -> list[tuple[str, str]]:
    """The recovered and the net energy of a summary (after its traction energy), and which the objective
    counted when it is the net energy."""
    if "recovered_energy_kwh" not in summary:
        return []
    rec = summary["recovered_energy_kwh"]
    net = _num(summary.get("net_energy_kwh"), ".2f", " kWh") + ", traction less recovered"
    if summary.get("objective") == "net" and summary.get("net_energy_kwh") is not None:
        net += " (the objective)"
    return [("recovered energy", _num(rec, ".2f", " kWh") + ("" if rec is None else " by the electric brake")),
            ("net energy", net)]


def coupler_rows(summary: dict, route=None, form: str = "km") -> list[tuple[str, str]]:
    """The largest coupler forces of a run (tension, compression) and where (with its kilometre post where
    ``route`` has a chainage), with the consist's limit."""
    from .posts import where
    ten, com = summary.get("max_coupler_tension_kn"), summary.get("max_coupler_compression_kn")
    if ten is None and com is None:
        return []
    lim = summary.get("coupler_limit_kn")

    def one(value, at, side):
        return f"- {side}" if value is None else f"{value:,.0f} kN {side} (at {where(route, at, form)})"

    text = (f"up to {one(ten, summary.get('max_coupler_tension_at_m'), 'tension')}, "
            f"{one(com, summary.get('max_coupler_compression_at_m'), 'compression')}"
            + (f"; limit {lim:,.0f} kN" if lim else ""))
    return [("coupler forces", text)]


def air_brake_rows(summary: dict) -> list[tuple[str, str]]:
    """The air brake's cycle of a run that cycles it (an application after a release): its applications and
    the shortest recharge margin (none for a run that only brakes to limits and the stop)."""
    n, margin = summary.get("air_applications"), summary.get("min_recharge_margin_s")
    if n is None or margin is None:
        return []
    rows = [("air brake", f"{n} applications; shortest recharge margin {margin:+.1f} s (recharge {summary['recharge_s']:g} s)")]
    placed = summary.get("release_margins")
    if placed:
        rows.append(("releases", "as soon as the brake can recharge before it is needed again: margin "
                     + ", ".join(f"{r['margin']:.2f} on {r['from_m']:,.0f} .. {r['to_m']:,.0f} m" for r in placed)
                     + " (the release speed at most the margin x what the train regains in a recharge time below"
                       " the apply speed, lower where the least hold or the recharge takes it)"))
    return rows


def sequence_table(runs: list[dict], width: int = 80, route=None, form: str = "km") -> list:
    """The applied condition sequence (a summary's ``sequence``). With ``route``: where it has a chainage, the
    kilometre post where each condition begins (written in ``form``); where it has stations, those each
    condition runs past (the last one's the station at the stop too)."""
    from .posts import has_chainage, post_text, stations_in

    posts = has_chainage(route)
    named = route is not None and bool(route.stations)
    table = Table(title="condition sequence", title_justify="left")
    cols = ("condition", "from [m]") + (("km post",) if posts else ()) + ("to [m]", "length [m]") + (
        ("stations",) if named else ())
    for col in cols:
        table.add_column(escape(col), justify="left" if col in ("condition", "stations") else "right")
    for i, r in enumerate(runs):
        post = (post_text(route, r["from_m"], form),) if posts else ()
        names = (escape(", ".join(st.name for st in stations_in(route, r["from_m"], r["to_m"], last=i == len(runs) - 1))
                        or "-"),) if named else ()
        table.add_row(f"{r['condition']} {CONDITION_NAMES[r['condition']]}", f"{r['from_m']:.0f}", *post,
                      f"{r['to_m']:.0f}", f"{r['to_m'] - r['from_m']:.0f}", *names)
    return fit(table, width, drop=(cols.index("length [m]"),) if posts or named else (),
               wrap=(len(cols) - 1,) if named else ())


def _wrap_sequence(conds: list[str], room: int = 17) -> str:
    """'T-K-T-C-...' broken after a '-' into lines of at most ``room`` characters."""
    lines, line = [], ""
    for i, c in enumerate(conds):
        piece = c if not line else f"-{c}"
        last = i == len(conds) - 1  # the last piece needs no room for a '-' after it
        if line and len(line) + len(piece) + (0 if last else 1) > room:  # keep the '-' at the end of the broken line
            lines.append(line + "-")
            line = c
        else:
            line += piece
    return "\n".join(lines + [line])


def compare_tables(rows: list[dict], title: str, width: int = 80, route=None, form: str = "km") -> list:
    """The ISSA paper's Table 8 (each strategy's planned sequence and switching points; the final B begins
    where the stop's braking curve does) and Table 9 (time and energy, re-simulated at the report grid),
    then why any strategy has no plan, and each plan whole (to give ``simulate --sequence``). With a
    ``route`` that has a chainage, the switching points are its kilometre posts (written in ``form``); its
    stations, if any, are listed under Table 8."""
    from .posts import has_chainage, post_text, station_place

    posts = has_chainage(route)
    t8 = Table(title=escape(f"{title}\nTable 8: condition sequences and switching points"), title_justify="left")
    t8.add_column("strategy")
    t8.add_column("sequence")
    t8.add_column(escape("switching points (km posts)" if posts else "switching points [m]"))
    at_t0 = any(r.get("energy_at_t0_kwh") is not None for r in rows)
    net = any(r.get("objective") == "net" for r in rows)
    t9 = Table(title=f"Table 9: running time and {'net' if net else 'traction'} energy"
               + ("; at T0: a punctual plan's energy carried to T0 (its gap over E* added to E* at T0)" if at_t0 else
                  ", each at its own running time"), title_justify="left")
    heads = ("strategy", "time [s]", "|T-T0| [s]", "energy [kWh]", "recovered [kWh]", "net [kWh]") + (
        ("at T0 [kWh]",) if at_t0 else ()) + ("saved vs fastest [%]", "vs E* [%]", "switches", "coasts", "fitness")
    for col in heads:
        t9.add_column(escape(col), justify="left" if col == "strategy" else "right")
    notes, plans = [], []
    why: dict[str, list[str]] = {}  # a reason shared by several strategies is said once, naming them all
    for s in rows:
        if not s["feasible"]:
            why.setdefault(str(s["reason"]), []).append(s["strategy"])
    notes = [Note(f"{', '.join(names)}: no feasible plan: {reason}") for reason, names in why.items()]
    for s in rows:
        if s["plan"] is None:  # no plan at all (the run was infeasible before it planned)
            t8.add_row(escape(s["strategy"]), "-", "-")
            t9.add_row(escape(s["strategy"]) + " [red](no plan)[/]", *(["-"] * (len(heads) - 1)))
            continue
        plans.append((s["strategy"], s["plan"], s.get("cruise_kmh")))
        conds = [c.split(":")[0] for c in s["plan"].split(",")]
        points = list(s["switching_points_m"])
        if conds[-1] == "B" and len(points) < len(conds) - 1 and s["sequence"]:
            points.append(s["sequence"][-1]["from_m"])  # where the final braking curve begins
        seq = _wrap_sequence(conds) + (f"\n(cruise {s['cruise_kmh']:g} km/h)" if s.get("cruise_kmh") else "")
        shown = [post_text(route, x, form, unit=False) for x in points] if posts else [f"{x:.0f}" for x in points]
        t8.add_row(escape(s["strategy"]), seq, " ".join(shown) or "-")
        late = _num(s["punctuality_error_s"], ".1f")
        if s.get("punctual") is False and s["running_time_s"] is not None:
            late += " [red]early[/]" if s["running_time_s"] < s["planned_time_s"] else " [red]late[/]"
        e = s["traction_energy_kwh"]
        name = escape(s["strategy"]) + ("" if s["feasible"] else " [red](infeasible)[/]")
        # the derived columns are the rows' fields (runs.plans.compare_fields), as --json and --out have them
        t9.add_row(name, _num(s["running_time_s"], ".1f"), late, _num(e, ".2f"), _num(s.get("recovered_energy_kwh"), ".2f"),
                   _num(s.get("net_energy_kwh"), ".2f"),
                   *((_num(s.get("energy_at_t0_kwh"), ".2f"),) if at_t0 else ()), _num(s.get("energy_reduction_percent"), ".1f"),
                   _num(s.get("gap_to_optimum_percent"), "+.2f"), _num(s.get("switches"), "d"), _num(s.get("coasts"), "d"),
                   _num(s["fitness"], ".4f"))
    k = 3 if at_t0 else 2  # the columns after "energy": recovered, net, (at T0)
    # left out first at a narrow width: the recovered energy, the energy the objective does not count (net
    # or traction), switches, coasts, the saving against the fastest run; the gap to E* stays longest
    first = (4, 3) if net else (4, 5)
    blocks = fit(t8, width, wrap=(0, 2))
    if route is not None and route.stations:
        blocks.append(Note("stations: " + ", ".join(station_place(route, st, form) for st in route.stations)))
    blocks += fit(t9, width, drop=first + (6 + k, 7 + k, 4 + k, 5 + k, 8 + k), wrap=(0,)) + notes
    if plans:
        blocks.append(Note("plans:"))
        blocks += [Line(f"{name:<{max(len(n) for n, _, _ in plans)}}  {plan}" + (f"  (cruise {c:g} km/h)" if c else ""))
                   for name, plan, c in plans]
    return blocks


def explain_tables(seq, width: int = 80) -> list:
    """The limit and grade classification behind the proposed sequence (the ISSA paper's Fig. 2, step 2), and
    the sequence with its nominal switching points (a ``strategy.sequence.build_sequence`` result)."""
    out = []
    t = Table(title="speed-limit sections and their types", title_justify="left")
    for col in ("from [m]", "to [m]", "limit [km/h]", "type"):
        t.add_column(escape(col), justify="right" if col != "type" else "left")
    for s in seq.limits:
        t.add_row(f"{s.from_m:.0f}", f"{s.to_m:.0f}", f"{s.kmh:g}", s.kind)
    out += fit(t, width, wrap=(3,))
    t = Table(title="grades: can full traction / coasting hold the limit speed?", title_justify="left")
    for col in ("from [m]", "to [m]", "equiv. gradient [‰]", "speed change [km/h]", "type"):
        t.add_column(escape(col), justify="right" if col != "type" else "left")
    for g in seq.grades:
        t.add_row(f"{g.from_m:.0f}", f"{g.to_m:.0f}", f"{g.permille:+.2f}", f"{g.speed_change_kmh:+.1f}", g.kind)
    out += fit(t, width, wrap=(4,))
    out.append(Note("proposed sequence (nominal switching points):"))
    out.append(Line(seq.text()))
    return out


def sweep_table(rows: list[dict], title: str, by_weights: bool, width: int = 80) -> list:
    """The ISSA paper's Table 6 (``by_weights``) or Table 7 (planned times, with the energy reduction)."""
    table = Table(title=escape(title), title_justify="left")
    cols = (["w_time", "w_energy"] if by_weights else ["T0 [s]"]) + ["time [s]", "energy [kWh]", "|T-T0| [s]", "fitness", "vs E* [%]"]
    cols += [] if by_weights else ["energy reduction [%]"]
    for c in cols:
        table.add_column(escape(c), justify="right")
    notes = []
    for x in rows:
        lead = [f"{x['weights'][0]:g}", f"{x['weights'][1]:g}"] if by_weights and x.get("weights") else (
            ["-", "-"] if by_weights else [f"{x['planned_time_s']:g}"])
        tail = [] if by_weights else [_num(x.get("energy_reduction_percent"), ".1f")]
        table.add_row(*lead, _num(x["running_time_s"], ".1f"), _num(x["traction_energy_kwh"], ".2f"),
                      _num(x["punctuality_error_s"], ".1f"), _num(x["fitness"], ".4f"),
                      _num(x.get("gap_to_optimum_percent"), "+.2f"), *tail)
        if not x["feasible"]:
            notes.append(Note(f"{' / '.join(lead)}: no feasible plan: {x['reason']}"))
    n = len(cols)
    return fit(table, width, drop=(n - 1 - (0 if by_weights else 1), 1 if by_weights else n - 1)) + notes


def study_table(rows: list[dict], title: str, width: int = 80) -> list:
    """The ISSA paper's Tables 10-12 from ``runner.study_table`` rows: per optimiser the best and the worst run
    **by fitness** (eq. 10, what the optimisers minimise; the table shows each one's fitness, energy and
    time), means, punctual runs and the punctual run with the least energy."""
    table = Table(title=escape(title + "; best / worst: by fitness"), title_justify="left")
    heads = ("algorithm", "best fitness", "best's E [kWh]", "best's T [s]", "worst fitness", "worst's E [kWh]",
             "worst's T [s]", "mean fitness", "sd fitness", "mean E [kWh]", "mean T [s]", "on time",
             "least E on time [kWh]", "its T [s]", "mean vs E* [%]", "mean solve [s]")
    for c in heads:
        table.add_column(escape(c), justify="right" if c != "algorithm" else "left")
    for x in rows:
        if not x.get("feasible_runs"):
            table.add_row(escape(x["algorithm"]), *(["-"] * (len(heads) - 1)))
            continue
        b, w, pb = x["best"], x["worst"], x["punctual_best"]
        table.add_row(escape(x["algorithm"]),
                      f"{b['fitness']:.5f}", f"{b['traction_energy_kwh']:.2f}", f"{b['running_time_s']:.1f}",
                      f"{w['fitness']:.5f}", f"{w['traction_energy_kwh']:.2f}", f"{w['running_time_s']:.1f}",
                      f"{x['mean_fitness']:.5f}", f"{x['std_fitness']:.5f}",
                      f"{x['mean_traction_energy_kwh']:.2f}", f"{x['mean_running_time_s']:.1f}",
                      f"{x['punctual_runs']}/{x['runs']}",
                      "-" if pb is None else f"{pb['traction_energy_kwh']:.2f}", "-" if pb is None else f"{pb['running_time_s']:.1f}",
                      _num(x.get("mean_gap_to_optimum_percent"), "+.2f"), f"{x['mean_solve_time_s']:.2f}")
    return fit(table, width, drop=(15, 14, 6, 3, 8, 10, 13, 5, 12), wrap=(0,))


HEADS = {"planned_time_s": "T0 [s]", "time_spec": "T0", "consist": "consist", "route": "route"}


def store_summary_table(rows: list[dict], by: list[str], title: str, width: int = 80) -> list:
    """``locoplan results``: one row per group (``runs.summary.summarize_records`` rows). A grouping key
    with one value in every row goes into the title instead of a column (narrow terminals keep the numbers).
    Grouped by route and journey, one column shows what ran (and so its kind): the journey's name for a
    journey run (its line is in ``--json``), the route's for a route run."""
    heads_of = dict(HEADS)
    if "route" in by and "journey" in by:
        rows = [{**r, "route": r["route"] if r.get("journey") is None else f"{r['journey']} (journey)"} for r in rows]
        by = [b for b in by if b not in ("journey", "kind")]
        heads_of["route"] = "route or journey"
    if len(rows) > 1:
        same = [b for b in by if len({str(r[b]) for r in rows}) == 1]
        if same and len(same) < len(by):
            title += "".join(f"\n{heads_of.get(b, b)}: {rows[0][b]}" for b in same)
            by = [b for b in by if b not in same]
    table = Table(title=escape(title), title_justify="left")
    heads = [heads_of.get(b, b) for b in by] + ["runs", "feasible", "punctual", "E mean [kWh]", "E best", "E sd", "T mean [s]", "T sd", "gap mean [%]",
             "gap best [%]"]
    def numeric(key: str) -> bool:  # a grouping key of numbers (planned_time_s) is aligned as numbers are
        return all(isinstance(r[key], (int, float)) and not isinstance(r[key], bool) for r in rows if r[key] is not None)

    for i, h in enumerate(heads):
        table.add_column(escape(h), justify="left" if i < len(by) and not numeric(by[i]) else "right")
    for r in rows:
        table.add_row(*[escape(str(r[k])) if r[k] is not None else "-" for k in by], str(r["runs"]), str(r["feasible_runs"]),
                      str(r["punctual_runs"]), _num(r["energy_mean_kwh"], ".2f"), _num(r["energy_best_kwh"], ".2f"),
                      _num(r["energy_sd_kwh"], ".2f"), _num(r["time_mean_s"], ".1f"), _num(r["time_sd_s"], ".1f"),
                      _num(r["gap_mean_percent"], ".2f"), _num(r["gap_best_percent"], ".2f"))
    k = len(by)
    text = tuple(i for i, b in enumerate(by) if b in ("route", "journey", "consist", "strategy"))
    return fit(table, width, drop=(k + 9, k + 7, k + 5, k + 1, k + 8, k + 4, k + 6, k + 2), wrap=text)


def front_title(front: dict) -> str:
    """What a front is of: the route, or the journey on its line, and the consist."""
    line = f"journey {front['journey']} ({front['route']})" if front.get("journey") else front["route"]
    return f"{line} — {front['consist']}"


def pareto_table(front: dict, width: int = 80) -> list:
    """``locoplan pareto``: per planned time, the best on-time plan (and E* once known), and the front."""
    table = Table(title=escape(f"{front_title(front)}: energy-time front (fastest run {front['fastest_time_s']:.1f} s"
                               + (", dwells excluded)" if front.get("journey") else ")")), title_justify="left")
    for c in ("T0 [s]", "factor", "best on-time E [kWh]", "by", "its T [s]", "E* at its T [kWh]", "gap [%]", "on front"):
        table.add_column(escape(c), justify="right" if c != "by" else "left")
    for p in front["grid"]:
        table.add_row(f"{p['planned_time_s']:g}", f"{p['factor']:.3f}", _num(p["best_energy_kwh"], ".2f"),
                      escape(p["best_strategy"] or "-"), _num(p["best_running_time_s"], ".1f"), _num(p["optimum_kwh"], ".2f"),
                      _num(p["gap_to_optimum_percent"], ".2f"), "yes" if p["on_front"] else "")
    return fit(table, width, drop=(1, 4), wrap=(3,))
