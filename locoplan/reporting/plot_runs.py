"""Figures of many runs (the batch store, the energy-time front), beside plot.py's speed profiles.
Every figure is written atomically, ``.png`` or ``.svg`` by the file's extension."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import InputError, Problem
from .files import atomic_write


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path) -> None:
    plt = _pyplot()
    fmt = Path(path).suffix.lower().lstrip(".")
    try:
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=120))
    finally:
        plt.close(fig)


def _line(r: dict) -> str:
    """What a run ran: its route, or its journey (a journey's energy and time are its totals)."""
    return f"{r['journey']} (journey)" if r.get("journey") else r["route"]


def plot_energy_time(rows: list[dict], path: str | Path) -> None:
    """Energy against running time, one panel per (route or journey, consist), one colour per strategy /
    optimiser, the planned times as dotted lines."""
    plt = _pyplot()
    ok = [r for r in rows if r.get("feasible")]
    panels = sorted({(_line(r), r["consist"]) for r in ok})
    if not panels:
        raise InputError(Problem(str(path), "plot", "no feasible run to plot"))
    n = len(panels)
    cols = min(3, n)
    nrows = math.ceil(n / cols)
    fig, axes = plt.subplots(nrows, cols, figsize=(5.2 * cols, 3.8 * nrows), squeeze=False)
    labels = sorted({_label(r) for r in ok})
    colours = {lab: plt.cm.tab10(i % 10) for i, lab in enumerate(labels)}
    for ax, (route, consist) in zip(axes.ravel(), panels):
        sub = [r for r in ok if (_line(r), r["consist"]) == (route, consist)]
        for lab in labels:
            pts = [r for r in sub if _label(r) == lab]
            if pts:
                ax.scatter([r["running_time_s"] for r in pts], [r["traction_energy_kwh"] for r in pts], s=14,
                           color=colours[lab], label=lab, alpha=0.8)
        for t0 in sorted({r["planned_time_s"] for r in sub if r.get("planned_time_s")}):
            ax.axvline(t0, color="grey", lw=0.8, ls=":")
        ax.set_title(f"{route}\n{consist}", fontsize=8)
        ax.set_xlabel("running time [s]")
        ax.set_ylabel("traction energy [kWh]")
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    handles, names = axes.ravel()[0].get_legend_handles_labels()
    fig.legend(handles, names, loc="lower center", ncol=min(6, len(names)), fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    _save(fig, path)


def _label(r: dict) -> str:
    return r["strategy"] + (f" ({r['algorithm']})" if r.get("algorithm") else "")


def plot_boxes(rows: list[dict], path: str | Path) -> None:
    """Box plots per optimiser of each run's energy above the best run of its (route or journey, consist,
    planned time) group, in per cent: how far a seed may land from the best, comparable across lines."""
    plt = _pyplot()
    ok = [r for r in rows if r.get("feasible") and r.get("algorithm")]
    best: dict[tuple, float] = {}

    def group(r: dict) -> tuple:
        return _line(r), r["consist"], r["planned_time_s"]

    for r in ok:
        best[group(r)] = min(best.get(group(r), math.inf), r["traction_energy_kwh"])
    algs = sorted({r["algorithm"] for r in ok})
    if not algs:
        raise InputError(Problem(str(path), "boxplot", "no feasible optimiser run to plot"))
    data = [[100 * (r["traction_energy_kwh"] / best[group(r)] - 1)
             for r in ok if r["algorithm"] == a] for a in algs]
    fig, ax = plt.subplots(figsize=(1.8 * len(algs) + 3, 4.2))
    ax.boxplot(data)
    ax.set_xticks(range(1, len(algs) + 1), [f"{a}\n({len(d)} runs)" for a, d in zip(algs, data)])
    ax.set_yscale("symlog", linthresh=2.0)  # most runs lie within a few per cent, a few far above
    _plain_ticks(ax, max((max(d) for d in data if d), default=1.0))
    ax.set_ylabel("energy above the group's best run [%]")
    ax.set_title("per optimiser, over every (route, consist, planned time)")
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    _save(fig, path)


def _plain_ticks(ax, top: float) -> None:
    """Ticks of a symlog axis as plain per cents (0, 1, 2, 5, 10, 20, 50 ...), never "10^0, 10^1"."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullLocator

    ticks, decade = [0.0], 1.0
    while ticks[-1] < top:  # 1, 2, 5 in every decade up to the largest value
        ticks += [decade, 2 * decade, 5 * decade]
        decade *= 10
    ax.yaxis.set_major_locator(FixedLocator([t for t in ticks if t <= max(2 * top, 2.0)]))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{y:g}"))


def plot_pareto(front: dict, path: str | Path) -> None:
    """The energy-time front: every plan found (by strategy), the non-dominated ones joined, the best
    on-time plan at each planned time, and the optimum E*(T) where it is known."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8.5, 5.2))
    names = sorted({p["strategy"] for p in front["points"]})
    for i, name in enumerate(names):
        pts = [p for p in front["points"] if p["strategy"] == name]
        ax.scatter([p["running_time_s"] for p in pts], [p["traction_energy_kwh"] for p in pts], s=16, alpha=0.55,
                   color=plt.cm.tab10(i % 10), label=name)
    f = front["front"]
    ax.step([p["running_time_s"] for p in f], [p["traction_energy_kwh"] for p in f], where="post", color="black", lw=1.4,
            label="front of the plans found")
    grid = [g for g in front["grid"] if g["best_energy_kwh"] is not None]
    ax.plot([g["best_running_time_s"] for g in grid], [g["best_energy_kwh"] for g in grid], "kD", ms=4,
            label="best on-time plan at each T0")
    opt = [g for g in front["grid"] if g["optimum_kwh"] is not None]
    if opt:
        ax.plot([g["optimum_time_s"] for g in opt], [g["optimum_kwh"] for g in opt], "r-", lw=1.6, label="optimum E*(T)")
    ax.axvline(front["fastest_time_s"], color="grey", ls=":", lw=0.9)
    right = 1.08 * max(g["planned_time_s"] for g in front["grid"])
    beyond = [p for p in front["points"] if p["running_time_s"] > right]
    if beyond:  # the energy-saving run may take several times longer: keep the grid readable, name it
        ax.set_xlim(0.97 * front["fastest_time_s"], right)
        for p in beyond:
            ax.annotate(f"{p['strategy']}: {p['running_time_s']:.0f} s, {p['traction_energy_kwh']:.0f} kWh  →",
                        (right, p["traction_energy_kwh"]), xytext=(-4, 14), textcoords="offset points", ha="right",
                        va="bottom", fontsize=8)
    ax.set_xlabel("total running time, dwells excluded [s]" if front.get("journey") else "running time [s]")
    ax.set_ylabel("traction energy [kWh]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()  # then the title wrapped to the axes' width (the file is not cropped to fit it)
    from .plot import fit_title
    from .tables import front_title

    fit_title(ax, f"{front_title(front)}: energy-time front", fontsize=10)
    fig.tight_layout()
    _save(fig, path)
