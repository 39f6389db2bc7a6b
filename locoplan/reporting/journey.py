"""``locoplan journey``: its tables, the whole run's profile as CSV, and its plot."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from rich.markup import escape
from rich.table import Table

from ..model.conditions import CONDITIONS
from ..ocp.bound import percent_digits
from .files import atomic_write, atomic_write_text
from .plot import check_plot_path, fit_title


def _pct(x: float | None, digits: int | None) -> str:
    return "-" if x is None or digits is None else f"{x:+.{digits}f}"


def _win(w) -> str:
    lo, hi = w
    if lo is None and hi is None:
        return "-"
    return f"{'' if lo is None else f'{lo:g}'} .. {'' if hi is None else f'{hi:g}'}"


def journey_summary_table(s: dict) -> Table:
    t = Table(title=escape(f"{s['journey']} — {s['consist']}"), title_justify="left", show_header=False)
    t.add_column("")
    t.add_column("")
    acc = s["optimum_accuracy_percent"]
    t.add_row("legs", f"{s['legs']} ({s['stops']} stops, {s['timing_points']} timing points)")
    t.add_row("running time", f"{s['running_time_s']:.1f} s, dwells excluded (fastest {s['fastest_running_time_s']:.1f} s); "
              f"dwells {s['dwell_s']:g} s")
    t.add_row("E* of the journey", f"{s['optimum_kwh']:.2f} kWh (within {acc:g} %), the least traction energy of any "
              "driving with this running time and these windows")
    m = s.get("marginal_kwh_per_s")
    if m:
        t.add_row("marginal energy", f"{-m['max']:.3f} .. {-m['min']:.3f} kWh per second more on a leg (equal on legs "
                  "not held by a window)")
    for name, p in s["plans"].items():
        if p["traction_energy_kwh"] is None:
            t.add_row(name, "not every leg has a feasible plan")
            continue
        pct = p.get("gap_to_optimum_percent")
        gap = ("-" if p["gap_to_optimum_kwh"] is None else f"{pct:+.2f} %" if pct is not None
               else f"{p['gap_to_optimum_kwh']:+.2f} kWh")
        rec = p.get("recovered_energy_kwh")
        lo, hi = p["window_s"]
        on_time = "inside" if lo - 0.05 <= p["running_time_s"] <= hi + 0.05 else "OUTSIDE"
        kept = [st["plans"][name]["in_window"] for st in s["stations"] if st["plans"][name]["in_window"] is not None]
        windows = (f"; windows kept {sum(kept)} of {len(kept)}" if all(kept) else
                   f"; windows MISSED: {', '.join(p['windows_missed'])}") if kept else ""
        t.add_row(name, f"{p['traction_energy_kwh']:.2f} kWh in {p['running_time_s']:.1f} s ({on_time} "
                  f"{s['running_time_s']:.1f} +- {s['tolerance_s']:g} s){windows}; {gap} over E* (each leg at its "
                  "plan's own time)" + ("" if rec is None else f"; recovered by the electric brake {rec:.2f} kWh, "
                                        f"net {p['net_energy_kwh']:.2f} kWh"))
    return t


def journey_legs_table(s: dict) -> Table:
    """Per leg: its fastest run, the allocation's time, the first strategy's plan's time, E* and the plan's energy
    and gap (the plan's station times are in :func:`journey_stations_table`)."""
    strategies = list(s["plans"])
    main = strategies[0] if strategies else None
    t = Table(title="legs: the optimal allocation of the running time", title_justify="left")
    for col in ("leg", "from - to", "fastest [s]", "time [s]", f"{main} [s]" if main else "plan [s]", "E* [kWh]",
                f"{main} [kWh]" if main else "plan [kWh]", "gap"):
        t.add_column(escape(col), justify="left" if col == "from - to" else "right")
    for r in s["legs_table"]:
        p = r["plans"].get(main, {}) if main else {}
        e = p.get("traction_energy_kwh")
        pct = p.get("gap_to_optimum_percent")
        gap = "-" if e is None else (f"{pct:+.2f} %" if pct is not None else f"{p.get('gap_to_optimum_kwh', 0):+.2f} kWh")
        t.add_row(str(r["leg"]), escape(f"{r['from']} - {r['to']}"), f"{r['fastest_s']:.1f}", f"{r['allocated_time_s']:.1f}",
                  "-" if e is None else f"{p['running_time_s']:.1f}", f"{r['optimum_kwh']:.2f}",
                  "-" if e is None else f"{e:.2f}", gap)
    return t


def journey_allocations_table(s: dict) -> Table:
    digits = percent_digits(s["optimum_accuracy_percent"])
    t = Table(title="the same legs' E* under other allocations of the running time", title_justify="left")
    for col in ("allocation", "E* [kWh]", "vs optimal [kWh]", "[%]", "windows missed"):
        t.add_column(escape(col), justify="left" if col in ("allocation", "windows missed") else "right")
    base = s["optimum_kwh"]
    for a in s["allocations"]:
        d = a["optimum_kwh"] - base
        t.add_row(escape(a["allocation"]), f"{a['optimum_kwh']:.2f}", f"{d:+.2f}", _pct(100 * d / base if base > 0 else None, digits),
                  escape(", ".join(a["missed_windows"]) or "none"))
    return t


def journey_stations_table(s: dict, route=None, form: str = "km", depart_s: float | None = None) -> Table:
    """Per station, on the clock since the departure (dwells included): its kilometre post where ``route`` has a
    chainage (written in ``form``), its window, the optimum's time, the first strategy's plan's (arrival at a stop,
    passing at a timing point; with ``depart_s``, seconds since midnight, also as a clock time) and whether it keeps
    the window; then its position, kind, dwell, the timetable's and the fastest run's time (left out first on a
    narrow terminal, :func:`stations_drops`)."""
    from ..bounds import clock_text
    from .posts import has_chainage, post_text

    posts = has_chainage(route)
    main = next(iter(s["plans"]), None)
    t = Table(title="stations (clock since the departure, dwells included)", title_justify="left")
    for col in ("station",) + (("km post",) if posts else ()) + (
            "window [s]", "optimum [s]", f"{main} [s]" if main else "plan [s]", "kept",
            "at [m]", "kind", "dwell [s]", "scheduled [s]", "fastest [s]"):
        t.add_column(escape(col), justify="left" if col in ("station", "kind", "kept") else "right")
    for r in s["stations"]:
        p = r["plans"].get(main, {}) if main else {}
        inside = p.get("in_window")
        clock = "-" if p.get("clock_s") is None else f"{p['clock_s']:.1f}"
        if depart_s is not None and p.get("clock_s") is not None:
            clock += f"\n{clock_text(depart_s + p['clock_s'], with_seconds=True)}"
        t.add_row(escape(r["station"]), *((post_text(route, r["at_m"], form),) if posts else ()),
                  _win(r["window_s"]), f"{r['optimum_s']:.1f}", clock,
                  "-" if inside is None else "yes" if inside else "NO",
                  f"{r['at_m']:g}", "stop" if r["stop"] else "passes", f"{r['dwell_s']:g}",
                  "-" if r["scheduled_s"] is None else f"{r['scheduled_s']:g}",
                  "-" if r["fastest_s"] is None else f"{r['fastest_s']:.1f}")
    return t


def stations_drops(route=None) -> tuple[int, ...]:
    """The columns of :func:`journey_stations_table` left out first on a narrow terminal: position, timetable,
    fastest run, dwell, kind (the kilometre post, where there is one, stays)."""
    from .posts import has_chainage

    k = 1 if has_chainage(route) else 0
    return tuple(i + k for i in (5, 8, 9, 7, 6))


def whole_run(result, strategy: str, journey=None):
    """The plans of one strategy end to end: (leg, position along the line [m], clock [s] (dwells included), speed
    [km/h], condition, traction [kN], brake [kN], station index or None) per node of each leg's profile; with
    ``journey``, a row at each timing point inside a leg too (interpolated between the nodes around it, the
    condition and forces of its cell), and every row at a station names it (at a stop, its arrival and its
    departure). None where a leg has no feasible plan."""
    runs = {r["leg"]: r["run"] for r in result.runs if r["strategy"] == strategy}
    rows, clock = [], 0.0
    for leg in result.legs:
        run = runs.get(leg.index)
        if run is None or not run.summary.get("feasible"):
            return None
        prof = run.result.profile
        n = len(prof.s_m)
        at_node = {0: leg.first, n - 1: leg.last} if journey is not None else {}
        before: dict[int, list] = {}  # node -> the timing points' rows just before it
        for i, at in leg.points if journey is not None else ():
            k = int(np.searchsorted(prof.s_m, at))  # the first node at or beyond the point
            if k < n and abs(prof.s_m[k] - at) < 1e-6:
                at_node[k] = i
                continue
            u = (at - prof.s_m[k - 1]) / (prof.s_m[k] - prof.s_m[k - 1])
            before.setdefault(k, []).append((
                leg.index + 1, leg.from_m + at, clock + (1 - u) * prof.t_s[0, k - 1] + u * prof.t_s[0, k],
                (1 - u) * prof.v_kmh[0, k - 1] + u * prof.v_kmh[0, k], CONDITIONS[int(prof.condition[0, k - 1])],
                prof.traction_kn[0, k - 1], prof.brake_kn[0, k - 1], i))
        for k in range(n):
            cell = min(k, n - 2)
            rows.extend(before.get(k, ()))
            rows.append((leg.index + 1, leg.from_m + prof.s_m[k], clock + prof.t_s[0, k], prof.v_kmh[0, k],
                         CONDITIONS[int(prof.condition[0, cell])], prof.traction_kn[0, cell], prof.brake_kn[0, cell],
                         at_node.get(k)))
        clock += float(prof.t_s[0, -1]) + result.dwells[leg.index]
    return rows


def journey_profile_csv(result, strategy: str, journey, route=None) -> str:
    """The whole run's profile (:func:`whole_run`) as CSV; the rows at a station give its name and window; with
    the line's ``route``, the last column ``km_post`` is each row's kilometre post [km] (its chainage, else the km
    from the start)."""
    from .posts import POST_DIGITS, post_km

    rows = whole_run(result, strategy, journey)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["leg", "s_m", "clock_s", "v_kmh", "condition", "traction_kn", "brake_kn", "station", "earliest_s",
                "latest_s"] + (["km_post"] if route is not None else []))
    for r in rows or []:
        st = None if r[7] is None else journey.stations[r[7]]
        w.writerow([r[0], f"{r[1]:.3f}", f"{r[2]:.3f}", f"{r[3]:.4f}", r[4], f"{r[5]:.3f}", f"{r[6]:.3f}",
                    "" if st is None else st.name, "" if st is None or st.earliest_s is None else f"{st.earliest_s:g}",
                    "" if st is None or st.latest_s is None else f"{st.latest_s:g}"]
                   + ([f"{post_km(route, r[1]):.{POST_DIGITS}f}"] if route is not None else []))
    return buf.getvalue()


def write_journey_csv(path: str | Path, result, strategy: str, journey, route=None) -> None:
    atomic_write_text(Path(path), journey_profile_csv(result, strategy, journey, route))


def journey_places(journey) -> list:
    """The journey's stations for a time-distance diagram: stops and timing points with their windows."""
    from .plot_td import Place

    return [Place(st.name, st.at_m, st.stop, st.earliest_s, st.latest_s) for st in journey.stations]


def plot_journey_td(path: str | Path, result, journey, route, strategies, form: str = "km",
                    depart_s: float | None = None) -> None:
    """The time-distance diagram of the journey: each strategy's plans end to end on the clock since the departure
    (a stop's dwell a level stretch at its station), the journey's stations across it with their windows."""
    from .plot_td import plot_time_distance

    series = []
    for name in strategies:
        rows = whole_run(result, name)
        if rows:
            series.append((name, [r[1] for r in rows], [r[2] for r in rows]))
    s = result.summary
    plot_time_distance(path, series, f"{s['journey']} — {s['consist']}: time-distance diagram", route, form, depart_s,
                       journey_places(journey))


def plot_journey(path: str | Path, result, journey, route, strategy: str, form: str = "km") -> None:
    """The whole run: speed against the line with the limits and the stations, the clock against the line
    with every window, and the running time of each leg under the allocations as bars."""
    path = check_plot_path(path)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = result.summary
    fig, (ax, axc, axb) = plt.subplots(3, 1, figsize=(11, 9), gridspec_kw={"height_ratios": [3, 2, 2]})
    rows = whole_run(result, strategy)
    if rows:
        arr = np.array([(r[1], r[2], r[3]) for r in rows])
        ax.plot(arr[:, 0] / 1000, arr[:, 2], color="#1f77b4", lw=1.2, label=f"{strategy} plan")
        axc.plot(arr[:, 0] / 1000, arr[:, 1], color="#1f77b4", lw=1.2, label=f"{strategy} plan")
    lim_x = [x for sec in route.speed_limits for x in (sec.from_m / 1000, sec.to_m / 1000)]
    lim_y = [sec.kmh for sec in route.speed_limits for _ in (0, 1)]
    ax.plot(lim_x, lim_y, color="#d62728", lw=1.0, ls="--", label="speed limit (route file)")
    opt = [(st["at_m"] / 1000, st["optimum_s"]) for st in s["stations"]]
    axc.plot(*zip(*opt), "o", color="#2ca02c", ms=4, label="E* allocation at the stations")
    for k, st in enumerate(journey.stations):
        x = st.at_m / 1000
        for a in (ax, axc):
            a.axvline(x, color="black", lw=0.8, ls=":" if st.stop else "-.", alpha=0.7)
        ax.annotate(st.name, (x, 1.0), xycoords=("data", "axes fraction"), rotation=90, ha="center", va="bottom", fontsize=7)
        lo, hi = st.earliest_s, st.latest_s
        if lo is not None or hi is not None:
            y0 = lo if lo is not None else hi
            y1 = hi if hi is not None else lo
            axc.plot([x, x], [y0, y1], color="#ff7f0e", lw=4, alpha=0.7, solid_capstyle="butt",
                     label="window" if k == next(i for i, t in enumerate(journey.stations) if t.earliest_s is not None or t.latest_s is not None) else None)
    ax.set_ylabel("speed [km/h]")
    axc.set_ylabel("clock [s]")
    axc.set_xlabel("position along the line [km]")
    from .plot import posts_axis

    for a in (ax, axc):
        posts_axis(a.xaxis, route, form)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    axc.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    legs = np.arange(1, s["legs"] + 1)
    width = 0.8 / max(len(s["allocations"]), 1)
    for k, a in enumerate(s["allocations"]):
        axb.bar(legs + (k - (len(s["allocations"]) - 1) / 2) * width, a["leg_times_s"], width,
                label=f"{a['allocation']}: E* {a['optimum_kwh']:.1f} kWh")
    axb.set_xlabel("leg")
    axb.set_ylabel("running time [s]")
    axb.set_xticks(legs)
    axb.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fit_title(ax, f"{s['journey']} — {s['consist']}: {s['running_time_s']:.0f} s running, E* {s['optimum_kwh']:.1f} kWh",
              pad=48)
    fig.tight_layout()
    fmt = path.suffix.lstrip(".").lower()
    atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=130, bbox_inches="tight"))
    plt.close(fig)
