"""Figures of the optimal-control runs (matplotlib, Agg backend, written atomically).

* :func:`plot_run`: one solution as the paper's Fig. 5/7 (traction / brake force ``F_u`` against time
  with the force bounds) and Fig. 6/8 (distance ``s`` and speed ``v`` against time with the limit),
  with the NLP's node values, the re-simulated run and the exact optimum for reference.
* :func:`plot_study`: the two-stage Gauss paper's study: control curves of CVP, GPM and two-stage for each test (as
  the paper's Fig. 5/7, node values joined by straight lines) and the measured solve times.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, Problem
from ..physics.units import kmh, kmh_from_e
from .files import atomic_write

__all__ = ["plot_energy_run", "plot_energy_time", "plot_run", "plot_study"]

_COLOURS = {"cvp": "#2ca02c", "gpm": "#d62728", "two-stage": "#1f77b4"}
_GLOBAL = "#9467bd"  # two-stage with the paper's global stage 2


def _figure_path(path) -> tuple[Path, str]:
    path = Path(path)
    if path.suffix.lower() not in (".png", ".svg", ".pdf"):
        raise InputError(Problem(str(path), "--plot", "use a .png, .svg or .pdf file name"))
    from .files import existing_folder

    existing_folder(path.parent if str(path.parent) else Path("."), str(path), "--plot")  # created on writing
    return path, path.suffix.lower().lstrip(".")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, fmt: str, plt) -> None:
    try:
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=130, bbox_inches="tight"))
    finally:
        plt.close(fig)


def _node_controls(solution) -> tuple[np.ndarray, np.ndarray]:
    """The NLP's control values and their times (LG points of every segment, or the CVP grid)."""
    if solution.method == "cvp":
        return np.asarray(solution.time_s), np.asarray(solution.control_kn)
    t = np.concatenate([p.times for p in solution.control_pieces])
    u = np.concatenate([p.values for p in solution.control_pieces])
    return t, u


def _legend_beside(ax) -> None:
    """The legend right of the axes, where it covers no line (the bounds and the limit run the whole width)."""
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, borderaxespad=0)


def plot_run(path, run, title: str | None = None) -> None:
    """Draw one :class:`~locoplan.ocp.min_time_run.OcpRun`: ``F_u`` [kN], ``v`` [km/h] and ``s`` [km] against
    time [s] (km/h and km like every plot of locoplan; the paper's own figures use m/s and m). ``.png`` or ``.svg`` by extension, written whole or not at all."""
    path, fmt = _figure_path(path)
    plt = _pyplot()
    p, sol, rs, ex = run.problem, run.solution, run.resimulation, run.exact
    tf = float(sol.objective_s)
    t_end = max(run.end_time_s, tf)
    t = np.linspace(0.0, tf, 4001)
    fig, (ax_u, ax_v, ax_s) = plt.subplots(3, 1, figsize=(10, 9), sharex=True,
                                           gridspec_kw={"height_ratios": [3, 2, 2]})

    raw = sol.control_at(t, clip=False)
    ax_u.axhline(p.f_max_kn, color="black", lw=0.8, ls="--", label=f"bounds {-p.b_max_kn:g} / {p.f_max_kn:g} kN")
    ax_u.axhline(-p.b_max_kn, color="black", lw=0.8, ls="--")
    ax_u.plot(t, ex.force_at(t), color="0.55", lw=2.5, alpha=0.6, label=f"exact optimum ({ex.time_s:.3f} s)")
    tol = 1e-3 * (p.f_max_kn + p.b_max_kn)
    if np.max(raw) > p.f_max_kn + tol or np.min(raw) < -p.b_max_kn - tol:
        ax_u.plot(t, raw, color="#ff7f0e", lw=0.8, ls=":", label="interpolant (unclipped)")
    ax_u.plot(t, sol.control_at(t, clip=True), color=_COLOURS.get(sol.method, "C0"), lw=1.4,
              label="control driven (clipped)")
    tn, un = _node_controls(sol)
    ax_u.plot(tn, un, "o", ms=3, color=_COLOURS.get(sol.method, "C0"), label=f"NLP control values ({sol.control_nodes} parameters)")
    for b in sol.breakpoints_s:
        ax_u.axvline(b, color="0.3", lw=0.6, ls="-.")
    span = p.f_max_kn + p.b_max_kn
    ax_u.set_ylim(-p.b_max_kn - 0.15 * span, p.f_max_kn + 0.15 * span)
    ax_u.set_ylabel("F_u [kN]")
    _legend_beside(ax_u)
    ax_u.grid(alpha=0.3)

    ax_v.axhline(p.speed_limit_kmh, color="black", lw=0.8, ls="--",
                 label=f"limit {p.speed_limit_kmh:g} km/h ({p.speed_limit_ms:.2f} m/s)")
    ax_v.plot(rs.time_s, kmh(np.asarray(rs.speed_ms)), color="C0", lw=1.4, label="re-simulated")
    ax_v.plot(sol.time_s, kmh(np.asarray(sol.speed_ms)), "o", ms=3, color="C1", label="NLP nodes")
    ax_v.set_ylabel("v [km/h]")
    ax_v.set_ylim(0.0, p.speed_limit_kmh * 1.25)
    _legend_beside(ax_v)
    ax_v.grid(alpha=0.3)

    ax_s.axhline(p.length_m / 1000, color="black", lw=0.8, ls="--", label=f"end {p.length_m / 1000:g} km")
    ax_s.plot(rs.time_s, np.asarray(rs.position_m) / 1000, color="C0", lw=1.4, label="re-simulated")
    ax_s.plot(sol.time_s, np.asarray(sol.position_m) / 1000, "o", ms=3, color="C1", label="NLP nodes")
    ax_s.set_ylabel("s [km]")
    ax_s.set_xlabel("t [s]")
    ax_s.set_xlim(0.0, t_end * 1.01)
    _legend_beside(ax_s)
    ax_s.grid(alpha=0.3)

    s = run.summary
    verdict = "confirmed" if s["feasible"] else "NOT confirmed by re-simulation"
    head = title or f"{run.route_name} — {run.train_name}"
    nodes = f"{s['control_nodes']} u / {s['state_nodes']} x nodes" if s["state_nodes"] else f"{s['control_nodes']} u nodes"
    ax_u.set_title(f"{head}\n{s['algorithm']}{' (' + s['stage2'] + ')' if s['stage2'] else ''}, {nodes}: "
                   f"objective {sol.objective_s:.3f} s, {verdict}", fontsize=10)
    fig.tight_layout()
    _save(fig, path, fmt, plt)


def plot_study(path, study) -> None:
    """Draw a :class:`~locoplan.ocp.min_time_study.Study`: for each table the control curves of its first
    CVP, GPM and two-stage (hp) rows (node values joined by straight lines, as the paper's Fig. 5/7),
    and the measured median solve times per row (hatched: not confirmed by re-simulation)."""
    path, fmt = _figure_path(path)
    plt = _pyplot()
    tables = sorted({r["table"] for r in study.rows})
    fig, axes = plt.subplots(2, len(tables), figsize=(6.5 * len(tables), 8), squeeze=False)
    for j, table in enumerate(tables):
        ax = axes[0, j]
        shown = set()
        for (tab, method, nodes, stage2), run in study.runs.items():
            if tab != table or method in shown or stage2 == "global":
                continue
            shown.add(method)
            tn, un = _node_controls(run.solution)
            ax.plot(tn, un, "-o", ms=2.5, lw=1.1, color=_COLOURS[method],
                    label=f"{run.summary['algorithm']} {nodes} ({run.solution.objective_s:.2f} s"
                          f"{'' if run.feasible else ', not confirmed'})")
        p = next(r for (tab, *_), r in study.runs.items() if tab == table).problem
        ax.axhline(p.f_max_kn, color="black", lw=0.7, ls="--")
        ax.axhline(-p.b_max_kn, color="black", lw=0.7, ls="--")
        ax.set_title(f"Table {table}: {p.gradient_permille:g} ‰, exact minimum {study.exact[table]:.3f} s", fontsize=10)
        ax.set_xlabel("t [s]")
        ax.set_ylabel("F_u [kN]")
        ax.legend(fontsize=7, loc="center right")
        ax.grid(alpha=0.3)

        ax = axes[1, j]
        rows = [r for r in study.rows if r["table"] == table]
        x = np.arange(len(rows))
        bars = ax.bar(x, [r["solve_time_s"] for r in rows],
                      color=[_GLOBAL if r["stage2"] == "global" else _COLOURS[r["algorithm"]] for r in rows],
                      alpha=0.85, edgecolor="black", linewidth=0.5)
        for bar, r in zip(bars, rows):
            if not r["feasible"]:
                bar.set_hatch("///")
                bar.set_alpha(0.45)
        ax.set_xticks(x)
        ax.set_xticklabels([f"{r['label']}\n{r['control_nodes']}" for r in rows], fontsize=7, rotation=30, ha="right")
        ax.set_ylabel(f"solve time [s] (median of {study.repeats})")
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle("The paper's Tables 2-3 reproduced (hatched: objective not confirmed by re-simulation)", fontsize=11)
    fig.tight_layout()
    _save(fig, path, fmt, plt)


def force_axis_kn(traction_kn, brake_kn, traction_cap_kn, brake_cap_kn, margin: float = 0.12, depth: float = 1.0):
    """The force axis of the energy plot: (lowest, highest, note) [kN]. It spans the traction bound and the
    braking used, but reaches below zero at most ``depth`` x the traction bound: the braking bound (electric
    + air, up to three times the traction) and a final stop at full braking would otherwise squash the
    traction into a strip; the note says how deep what is cut goes."""
    top = max(float(np.max(traction_cap_kn)), float(np.max(traction_kn)), 1.0)
    used = float(np.max(brake_kn)) if np.size(brake_kn) else 0.0
    lo, hi = -min(max(used, 0.25 * top), depth * top) * (1 + margin), top * (1 + margin)
    deepest = max(used, float(np.max(brake_cap_kn)) if np.size(brake_cap_kn) else 0.0)
    what = "braking" if used * (1 + margin) > -lo else "-B max(v)"
    note = f"{what} reaches -{deepest if what != 'braking' else used:,.0f} kN, below the axis" if -deepest < lo else ""
    return lo, hi, note


def plot_energy_run(path, run, title: str | None = None, route=None) -> None:
    """The MPOC paper's Fig. 6/7 for one MPOC run: speed over distance (the optimum, its re-simulated plan and
    the limit, the spans where traction is cut under a neutral section shaded), the optimum's traction
    and braking forces with the consist's speed-dependent bounds, and the mesh (interval boundaries, LGR
    points per interval, moving points on switches). With ``route``: the limit as the route file gives it
    beside the train's, and the line's stations, neutral sections, tunnels and curves marked."""
    path, fmt = _figure_path(path)
    plt = _pyplot()
    from ..physics.traction import max_force_kn
    from .plot import draw_limits, fit_title, mark_line, position_label, posts_axis, station_pad

    sol = run.solution.solution
    grid = sol.grid
    prof = run.check.result.profile
    s = grid.s_col
    n = grid.n_col
    v = kmh_from_e(np.maximum(sol.X[0, :n], 0.0))
    fig, (ax, axf, axm) = plt.subplots(3, 1, figsize=(11, 8.5), sharex=True,
                                      gridspec_kw={"height_ratios": [3, 2, 1]})
    km = 1e-3
    for k, (a, b) in enumerate(run.tep.spans_m):
        for axis in (ax, axf, axm):
            axis.axvspan(a * km, b * km, color="#ffdd88", alpha=0.5, lw=0,
                         label="traction cut (neutral section under the train)" if (k == 0 and axis is ax) else None)
    if route is not None:
        mark_line(ax, axf, route)
    draw_limits(ax, prof.s_m, prof.limit_kmh, route)
    ax.plot(prof.s_m * km, prof.v_kmh[0], color="#1f77b4", lw=1.8, label="plan, re-simulated")
    ax.plot(s * km, v, ".", color="#d62728", ms=3, label="optimum (LGR points)")
    ax.set_ylabel("speed [km/h]")
    ax.set_ylim(0, max(float(np.max(prof.limit_kmh)), float(np.max(v))) * 1.12)
    sm = run.summary
    title = title or (f"{sm['route']} — {sm['consist']}: minimum energy in {sm['planned_time_s']:g} s, "
                      f"{sm['objective']:.1f} kWh (plan {sm['resimulated_energy_kwh']:.1f} kWh, "
                      f"{sm['resimulated_running_time_s']:.1f} s)")
    ax.grid(alpha=0.3)
    # beside the axes, never over the limit line
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
    tm = run.tep.model
    axf.plot(s * km, sol.U[0], ".", color="#d62728", ms=3, label="traction F")
    brake = sol.U[1] + (sol.U[2] if sol.U.shape[0] > 2 else 0.0)
    axf.plot(s * km, -brake, ".", color="#7f7f7f", ms=3, label="braking B (as -B)")
    f_cap = max_force_kn(v, *tm.traction_curve)
    b_cap = max_force_kn(v, *tm.brake_curve)
    axf.plot(s * km, f_cap, "-", color="#d62728", lw=0.6, alpha=0.6, label="F max(v)")
    axf.plot(s * km, -b_cap, "-", color="#7f7f7f", lw=0.6, alpha=0.6, label="-B max(v)")
    lo, hi, note = force_axis_kn(sol.U[0], brake, f_cap, b_cap)
    axf.set_ylim(lo, hi)
    if note:
        axf.text(0.005, 0.03, note, transform=axf.transAxes, fontsize=7, color="#555555", va="bottom")
    axf.axhline(0, color="black", lw=0.5)
    axf.set_ylabel("force [kN]")
    axf.grid(alpha=0.3)
    axf.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)  # beside: never over the points
    for iv in grid.mesh.intervals:
        axm.axvline(iv.s_a * km, color="#9467bd" if iv.free_start is not None else "#bbbbbb",
                    lw=1.2 if iv.free_start is not None else 0.5)
    axm.plot(s * km, [grid.mesh.intervals[i].n for i in grid.interval_col], ".", color="#2ca02c", ms=3)
    axm.set_ylabel("LGR points\nper interval")
    axm.set_xlabel("position [km]  (purple: mesh points moved onto switches"
                   + ("; yellow: traction cut under a neutral section)" if len(run.tep.spans_m) else ")"))
    axm.grid(alpha=0.3)
    fig.tight_layout()  # the legend beside the axes sets their width; the title is wrapped to it
    if route is not None:  # kilometre posts where the route has a chainage
        label = axm.get_xlabel()
        posts_axis(axm.xaxis, route)
        axm.set_xlabel(label.replace("position [km]", position_label(route), 1))
    fit_title(ax, title, **({"pad": station_pad(route)} if route is not None else {}))
    fig.tight_layout()
    _save(fig, path, fmt, plt)


def plot_energy_time(path, data: dict) -> None:
    """The energy-time curve E*(T) of ``locoplan bound --times``: the least traction energy for each
    running time (a planner's trade-off between punctuality margin and energy)."""
    path, fmt = _figure_path(path)
    plt = _pyplot()
    rows = [r for r in data["results"] if r["energy_kwh"] is not None]
    fig, ax = plt.subplots(figsize=(8, 5))
    ax.plot([r["time_s"] for r in rows], [r["energy_kwh"] for r in rows], "o-", color="#1f77b4")
    ax.set_xlabel("running time T [s]")
    ax.set_ylabel("least traction energy E* [kWh]")
    from .plot import fit_title

    ax.grid(alpha=0.3)
    fig.tight_layout()  # then the title wrapped to the axes' width
    fit_title(ax, f"{data['route']} — {data['consist']}: least traction energy E* against running time")
    fig.tight_layout()
    _save(fig, path, fmt, plt)
