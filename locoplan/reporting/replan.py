"""What ``replan`` and ``drive`` print and draw: the advice as JSON and as lines, the closed loop's figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.conditions import CONDITION_NAMES
from .files import atomic_write


def _r(x, digits=3):
    return None if x is None else round(float(x), digits)


def replan_summary(r, route_name: str, train_name: str, tolerance_s: float, cycle_relaxed: bool) -> dict:
    """The --json object (and one --stream line) of a re-plan ``r`` (``optimize.replan.Replan``)."""
    d = {"route": route_name, "consist": train_name,
         "state": {"s_m": r.state.s_m, "v_kmh": r.state.v_kmh, "t_s": r.state.t_s,
                   **({"air": r.state.air} if r.state.air is not None else {}),
                   **({"recharge_left_s": r.state.recharge_left_s} if r.state.recharge_left_s is not None else {})},
         "next_condition": r.next_condition, "next_switch_m": _r(r.next_switch_m, 1),
         "target_speed_kmh": _r(r.target_speed_kmh, 2), "arrival_s": _r(r.arrival_s, 2),
         "planned_arrival_s": _r(r.planned_arrival_s, 2),
         "window_s": [_r(r.planned_arrival_s - tolerance_s, 2), _r(r.planned_arrival_s + tolerance_s, 2)],
         "late_s": _r(r.late_s, 2), "on_time": bool(r.on_time),
         "remaining_energy_kwh": _r(r.remaining_energy_kwh), "remaining_optimum_kwh": _r(r.remaining_optimum_kwh),
         "plan": r.plan, "solve_time_s": _r(r.solve_time_s, 6)}
    if r.air_events is not None:
        d["air_events"] = [{"at_m": _r(x, 1), "t_s": _r(t, 2), "v_kmh": _r(v, 2), "kind": k}
                           for x, t, v, k in r.air_events]
    if cycle_relaxed:
        d["air_brake"] = "a continuous force in the re-plan (its cycle, which binds on this line, is not tracked)"
    return d


def replan_lines(d: dict) -> list[str]:
    """The advice for a person: the condition now, the next switch, the arrival, the energy."""
    st = d["state"]
    lines = [f"{d['route']}, {d['consist']}",
             f"state: {st['s_m']:,.1f} m, {st['v_kmh']:.1f} km/h, {st['t_s']:,.1f} s since departure"]
    if d["next_condition"] is None:
        lines.append("at the stop: nothing to do")
    else:
        now = f"now: {CONDITION_NAMES[d['next_condition']]} ({d['next_condition']})"
        if d["next_switch_m"] is None:
            now += " to the stop"
        else:
            now += f" to {d['next_switch_m']:,.1f} m, {d['target_speed_kmh']:.1f} km/h there"
        lines.append(now)
    w = d["window_s"]
    if d["on_time"]:
        when = "on time"
    elif d["late_s"] > 0:
        when = f"{d['late_s']:.1f} s late even on the fastest run"
    else:
        when = "early even on the least energy"
    lines.append(f"arrives {d['arrival_s']:,.1f} s (planned {d['planned_arrival_s']:,.1f} s, window "
                 f"{w[0]:,.1f} .. {w[1]:,.1f} s): {when}")
    if d["next_condition"] is not None:
        opt = d["remaining_optimum_kwh"]
        lines.append(f"remaining traction energy {d['remaining_energy_kwh']:.2f} kWh"
                     + (f" (the least on the DP's grid in the remaining time: {opt:.2f} kWh)" if opt is not None else ""))
        lines.append(f"plan: {d['plan']}")
    if d.get("leg") is not None:
        g = d["leg"]
        lo, hi = g["stop_window_s"]
        win = "" if lo is None and hi is None else (f" (its window {'..' if lo is None else f'{lo:,.1f}'} .. "
                                                    f"{'' if hi is None else f'{hi:,.1f}'} s)")
        lines.append(f"leg {g['leg']}: {g['from']} - {g['to']}, at {g['to']} {g['arrival_s']:,.1f} s{win}")
        if d.get("next_stops"):
            kept = ", ".join(f"{x['name']} {x['planned_arrival_s']:,.1f} s" for x in d["next_stops"][:4])
            lines.append("next stops kept as planned: " + kept + (", ..." if len(d["next_stops"]) > 4 else ""))
    if d.get("air_events") is not None:
        ev = d["air_events"]
        shown = ", ".join(f"{x['kind']} {x['at_m']:,.1f} m" for x in ev[:4]) + (", ..." if len(ev) > 4 else "")
        lines.append("air brake: " + (shown if ev else "not applied before the stop"))
    if d.get("air_brake"):
        lines.append(f"note: the air brake is {d['air_brake']}")
    return lines


def drive_lines(d: dict) -> list[str]:
    """The three runs side by side."""
    lines = [f"{d['route']}, {d['consist']}; {d['disturbance']}",
             f"planned arrival {d['planned_arrival_s']:,.1f} s, window {d['window_s'][0]:,.1f} .. "
             f"{d['window_s'][1]:,.1f} s",
             f"{'run':<12} {'arrival [s]':>12} {'window':>8} {'energy [kWh]':>13} {'over E*':>9}"]
    for key, name in (("open_loop", "open loop"), ("closed_loop", "closed loop"), ("hindsight", "E* hindsight")):
        r = d[key]
        arr = "-" if r.get("arrival_s") is None or not r.get("arrived", True) else f"{r['arrival_s']:,.1f}"
        inside = "" if key == "hindsight" else ("inside" if r.get("inside_window") else "outside")
        e = r.get("traction_energy_kwh")
        over = r.get("over_hindsight_percent")
        lines.append(f"{name:<12} {arr:>12} {inside:>8} {'-' if e is None else format(e, '.2f'):>13} "
                     f"{'' if over is None else format(over, '+.2f') + ' %':>9}")
    c = d["closed_loop"]
    if c.get("replans"):
        lines.append(f"closed loop: {c['replans']} re-plans (their times in --json)")
    if d.get("air_brake"):
        lines.append(f"note: {d['air_brake']}")
    return lines


def plot_drive(path: str | Path, runs: list[tuple[str, np.ndarray, np.ndarray]], limit: tuple[np.ndarray, np.ndarray],
               title: str) -> None:
    """The runs' speed profiles (label, s [m], v [km/h]) under the limit (s, km/h); written atomically."""
    from .plot import check_plot_path

    path = check_plot_path(path)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 5))
    ax.plot(limit[0] / 1000, limit[1], color="black", lw=1, ls="--", label="limit")
    for label, s, v in runs:
        ax.plot(np.asarray(s) / 1000, v, lw=1.3, label=label)
    ax.set_xlabel("position [km]")
    ax.set_ylabel("speed [km/h]")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fmt = path.suffix.lower().lstrip(".")
    try:
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=130, bbox_inches="tight"))
    finally:
        plt.close(fig)
