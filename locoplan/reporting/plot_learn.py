"""Plots of the pattern-curve patent: the learned pattern curves against the good drivers' data, and an advice."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plot import check_plot_path, draw_limits, draw_profiles, fit_title
from .files import atomic_write
from ..learn.patterns import Learned, smooth_curve


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    plt = _figure()
    fmt = path.suffix.lower().lstrip(".")
    try:
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=120))
    finally:
        plt.close(fig)


def _flat(line, speeds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.concatenate([line.points_m[0]] + [line.points_m[i][1:] for i in range(1, len(line.sections))])
    v = np.concatenate([speeds[0]] + [speeds[i][1:] for i in range(1, len(line.sections))])
    return x, v


def plot_fit(path: str | Path, learned: Learned) -> None:
    """Upper layer: predicted against logged time shares (fit and held-out runs). Lower layer: for the
    job with the most good runs, the good drivers' speed curves against the learned pattern curve
    (chained division points, joined smoothly), and each section's share, logged mean against learned."""
    path = check_plot_path(path)
    plt = _figure()
    pat = learned.patterns
    fig = plt.figure(figsize=(12, 10))
    grid = fig.add_gridspec(2, 2, height_ratios=[1, 1.1], hspace=0.3, wspace=0.25)
    ax_up = fig.add_subplot(grid[0, 0])
    ax_bar = fig.add_subplot(grid[0, 1])
    ax_v = fig.add_subplot(grid[1, :])
    for held, colour, label in ((False, "#1f77b4", "fit runs"), (True, "#d62728", "held-out runs")):
        obs, pred = [], []
        for run, line, (shares, _), h in zip(learned.runs, learned.lines, learned.observed, learned.heldout):
            if h == held:
                obs.append(shares)
                pred.append(pat.shares(line, run.mass_t, run.running_time_s))
        if obs:
            ax_up.scatter(np.concatenate(obs), np.concatenate(pred), s=6, alpha=0.5, color=colour, label=label)
    top = max(ax_up.get_xlim()[1], ax_up.get_ylim()[1])
    ax_up.plot([0, top], [0, top], color="black", lw=0.8)
    rep = pat.report.get("heldout", {}).get("upper", {})
    ax_up.set_title(f"upper layer (time shares): held-out R² {rep.get('r2', float('nan')):.3f}", fontsize=10)
    ax_up.set_xlabel("logged time share")
    ax_up.set_ylabel("learned time share")
    ax_up.legend(fontsize=8)
    ax_up.grid(alpha=0.3)
    # the job with the most good runs
    keys = [(str(r.route_file), r.mass_t, r.scheduled_time_s) for r in learned.runs]
    key = max(set(keys), key=lambda k: (keys.count(k), k))
    sel = [i for i, k in enumerate(keys) if k == key]
    line = learned.lines[sel[0]]
    mass, t0 = key[1], key[2]
    for n, i in enumerate(sel):
        d = learned.runs[i].data
        ax_v.plot(d.position_m / 1000, d.speed_kmh, color="#2ca02c", lw=0.6, alpha=0.5, label="good drivers" if n == 0 else None)
    shares = pat.shares(line, mass, t0)
    x, v = _flat(line, pat.speeds(line, mass, t0, shares))
    fine = np.linspace(0, line.route.length_m, 800)
    ax_v.plot(fine / 1000, smooth_curve(x, v)(fine), color="#d62728", lw=2, label="learned pattern (lower layer, chained)")
    ax_v.plot(x / 1000, v, "o", color="#d62728", ms=3)
    draw_limits(ax_v, line.calc.s_m, line.calc.limit_kmh, line.route)
    for sec in line.sections:
        ax_v.axvline(sec.from_m / 1000, color="grey", lw=0.5)
        ax_v.text(sec.from_m / 1000 + 0.05, 3, sec.kind, fontsize=7, rotation=90, va="bottom")
    rep = pat.report.get("heldout", {}).get("lower", {})
    fit_title(ax_v, f"{line.route.name}, {mass:g} t, {t0:g} s: {len(sel)} good runs; lower layer held-out: one "
                    f"division ahead R² {rep.get('one_step_r2', float('nan')):.3f}, chained R² "
                    f"{rep.get('chained_r2', float('nan')):.3f}", fontsize=10)
    ax_v.set_xlabel("position [km]")
    ax_v.set_ylabel("speed [km/h]")
    ax_v.set_ylim(0, float(line.calc.limit_kmh.max()) * 1.1)
    ax_v.legend(fontsize=8, loc="lower center")
    ax_v.grid(alpha=0.3)
    logged = np.mean([learned.observed[i][0] for i in sel], axis=0)
    idx = np.arange(len(line.sections))
    ax_bar.bar(idx - 0.2, logged, 0.4, color="#2ca02c", label="good drivers (mean)")
    ax_bar.bar(idx + 0.2, shares, 0.4, color="#d62728", label="learned")
    ax_bar.set_xticks(idx, [s.kind.replace("gentle", "g").replace("steep", "s") for s in line.sections], rotation=60, fontsize=7)
    ax_bar.set_ylabel("time share")
    ax_bar.set_title("time share per section (same job)", fontsize=10)
    ax_bar.legend(fontsize=8)
    _save(fig, path)


def plot_advice(path: str | Path, advice, title: str, form: str = "km") -> None:
    """The advice's speed profile coloured by condition over the limits, with the learned pattern
    (as learned, and scaled to the time: the targets followed), both limits (the route file's and the
    train's), the line's stations, neutral sections, tunnels and curves, and the sections; gradient below."""
    path = check_plot_path(path)
    plt = _figure()
    fig, (ax, axg) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    x, raw = _flat(advice.line, advice.pattern_kmh)
    fine = np.linspace(0, advice.line.route.length_m, 800)
    ax.plot(fine / 1000, smooth_curve(x, raw)(fine), color="#9467bd", lw=1, ls="--", label="learned pattern")
    ax.plot(x / 1000, advice.target_kmh, "o", color="#9467bd", ms=3, label=f"targets (pattern x {advice.scale:.3f})")
    draw_profiles(ax, axg, [("advice", advice.result.profile)], title, advice.line.route, form)
    ax.title.set_fontsize(10)
    for sec in advice.line.sections:
        ax.axvline(sec.from_m / 1000, color="grey", lw=0.5)
        axg.axvline(sec.from_m / 1000, color="grey", lw=0.5)
        axg.text(sec.from_m / 1000 + 0.05, axg.get_ylim()[0], sec.kind, fontsize=7, rotation=90, va="bottom")
    fig.tight_layout()
    _save(fig, path)


def plot_replay(path: str | Path, replays: list, options) -> None:
    """``locoplan replay --plot``: the run with the largest excess against E*'s run at the same running time (speed
    over the line's limits, the sections marked), and below, its excess section by section beside the mean per run
    of every run on the same line and sections (bars: the section's energy over the optimum's plus the time's
    value at the price of time)."""
    from ..ocp.bound import optimum_run
    from ..physics.units import kmh
    from ..sim.calculator import limit_kmh_at

    path = check_plot_path(path)
    done = [r for r in replays if r.compared]
    plt = _figure()
    fig, (ax, axb) = plt.subplots(2, 1, figsize=(11, 7), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    if not done:
        ax.text(0.5, 0.5, "no run has an E* at its running time", ha="center", transform=ax.transAxes)
        _save(fig, path)
        return
    worst = max(done, key=lambda r: r.excess_kwh)
    run, route = worst.run, worst.run.route
    data = run.data
    opt = optimum_run(route, run.train, options, worst.running_time_s)  # kept from the replay: no second solve
    s = np.linspace(0.0, route.length_m, 2001)
    length = None if options is not None and options.point_mass else run.train.length_m
    lim = np.minimum(limit_kmh_at(route, 0.5 * (s[1:] + s[:-1]), length), run.train.max_speed_kmh)
    ax.step(s[:-1] / 1000, lim, where="post", color="black", lw=1.0, label="speed limit")
    ax.plot(data.position_m / 1000, data.speed_kmh, color="#d62728", lw=1.2,
            label=f"{Path(run.log_file).stem}: {worst.traction_energy_kwh:,.1f} kWh in {worst.running_time_s:,.1f} s")
    ax.plot(opt.s_m / 1000, kmh(opt.v_ms), color="#2ca02c", lw=1.2,
            label=f"E* at the same time: {worst.optimum_kwh:,.1f} kWh")
    ax.set_ylabel("speed [km/h]")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, loc="lower center")
    same = [r for r in done if r.run.route.name == route.name
            and [(x.from_m, x.to_m) for x in r.sections] == [(x.from_m, x.to_m) for x in worst.sections]]
    a = np.array([x.from_m for x in worst.sections]) / 1000
    w = np.array([x.to_m - x.from_m for x in worst.sections]) / 1000
    mine = np.array([x.excess_kwh for x in worst.sections])
    mean = np.mean([[x.excess_kwh for x in r.sections] for r in same], axis=0)
    axb.bar(a, mine, width=w * (0.48 if len(same) > 1 else 0.96), align="edge", color="#d62728", alpha=0.8,
            label="this run")
    if len(same) > 1:
        axb.bar(a + 0.5 * w, mean, width=w * 0.48, align="edge", color="#1f77b4", alpha=0.8,
                label=f"mean of {len(same)} runs on this line")
    axb.axhline(0.0, color="black", lw=0.6)
    for x, sec in zip(a, worst.sections):
        for axis in (ax, axb):
            axis.axvline(x, color="grey", lw=0.5)
        axb.text(x + 0.02, 1.0, sec.kind, fontsize=7, rotation=90, va="top", transform=axb.get_xaxis_transform())
    axb.set_ylabel("excess [kWh]")
    axb.set_xlabel("position [km]")
    axb.legend(fontsize=8, loc="lower right")
    share = "" if worst.excess_percent is None else f" ({worst.excess_percent:.1f} % of the run's energy)"
    fit_title(ax, f"{route.name}, {run.train.name}: excess over E* {worst.excess_kwh:+,.1f} kWh{share}, the largest "
                  f"of {len(done)} runs", fontsize=10)
    fig.tight_layout()
    _save(fig, path)
