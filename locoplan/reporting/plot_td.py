"""The time-distance diagram of a run, as planners draw a train's path: the clock across, the line down the
side (kilometre posts where the route has a chainage), each station a line across the diagram. Any run
that has positions and times can be drawn: a plan's profile, a journey's legs end to end (stops and dwells
as level stretches), a logged run."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .files import atomic_write
from .plot import PALETTE, check_plot_path, fit_title, posts_axis


@dataclass(frozen=True)
class Place:
    """A station drawn across the diagram: its name, its position [m from the route's start], whether trains
    stop there (a stop: solid line; a timing point passed: dashed), and a window on the run's clock [s since
    the departure] (either end may be None)."""

    name: str
    at_m: float
    stop: bool = True
    earliest_s: Optional[float] = None
    latest_s: Optional[float] = None


def places_of(route) -> list[Place]:
    """The route's stations as :class:`Place` s (its ends as stops; a route without stations: its two ends,
    unnamed)."""
    if route is None:
        return []
    if not route.stations:
        return [Place("start", 0.0), Place("end", route.length_m)]
    return [Place(st.name, st.at_m) for st in route.stations]


def series_of(profile, plan: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(positions [m], times [s]) of one plan of a calculator ``Profile``, up to where it failed."""
    s, t = np.asarray(profile.s_m, float), np.asarray(profile.t_s[plan], float)
    ok = np.isfinite(t) & np.isfinite(np.asarray(profile.v_kmh[plan], float))
    if not ok.all():
        end = int(np.argmin(ok))
        s, t = s[:end], t[:end]
    return s, t


def _clock_formatter(depart_s: Optional[float]):
    from matplotlib.ticker import FuncFormatter

    from ..bounds import clock_text

    if depart_s is None:
        return FuncFormatter(lambda x, pos: f"{x:g}")
    return FuncFormatter(lambda x, pos: clock_text(depart_s + x * 60.0, with_seconds=False))


def draw_time_distance(ax, series: Sequence[tuple[str, Sequence[float], Sequence[float]]], route=None,
                       form: str = "km", depart_s: Optional[float] = None,
                       places: Optional[Sequence[Place]] = None) -> None:
    """On ``ax``: each run of ``series`` (label, positions [m from the route's start], times [s since the
    departure]) as a line, the clock across (minutes since the departure, or clock times hh:mm from
    ``depart_s``, seconds since midnight) and the line down the side (km from the start, labelled with the
    route's kilometre posts where it has a chainage, in ``form``); each of ``places`` (default: the route's
    stations) a line across the diagram with its name, and its window as a bar on its line. Line ``gid`` s:
    ``run:LABEL``, ``station:NAME``, ``window:NAME``."""
    from matplotlib.ticker import MaxNLocator

    places = places_of(route) if places is None else list(places)
    for k, (label, s_m, t_s) in enumerate(series):
        s, t = np.asarray(s_m, float), np.asarray(t_s, float)
        ax.plot(t / 60.0, s / 1000.0, color=PALETTE[k % len(PALETTE)], lw=1.6, label=label, gid=f"run:{label}")
    trans = ax.get_yaxis_transform()
    windowed = False
    for k, pl in enumerate(places):
        y = pl.at_m / 1000.0
        ax.axhline(y, color="#444444", lw=0.8, ls="-" if pl.stop else "--", alpha=0.8, gid=f"station:{pl.name}",
                   label=("station (stop)" if pl.stop else "timing point") if k == next(
                       i for i, q in enumerate(places) if q.stop == pl.stop) else None)
        ax.text(1.01, y, pl.name, transform=trans, va="center", ha="left", fontsize=7)
        if pl.earliest_s is not None or pl.latest_s is not None:
            lo = pl.earliest_s if pl.earliest_s is not None else pl.latest_s
            hi = pl.latest_s if pl.latest_s is not None else pl.earliest_s
            ax.plot([lo / 60.0, hi / 60.0], [y, y], color="#ff7f0e", lw=5, alpha=0.6, solid_capstyle="butt",
                    gid=f"window:{pl.name}", label=None if windowed else "window")
            windowed = True
    ax.xaxis.set_major_locator(MaxNLocator(nbins=10, steps=[1, 2, 5, 10]))
    ax.xaxis.set_major_formatter(_clock_formatter(depart_s))
    ax.set_xlabel("clock [hh:mm]" if depart_s is not None else "time since the departure [min]")
    if route is not None:
        ax.set_ylim(-0.02 * route.length_m / 1000, 1.02 * route.length_m / 1000)
        posts_axis(ax.yaxis, route, form)
    else:
        ax.set_ylabel("position [km]")
    ax.invert_yaxis()  # the first station at the top, as a timetable lists it
    ax.grid(alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8, ncol=4, frameon=False)


def plot_time_distance(path: str | Path, series: Sequence[tuple[str, Sequence[float], Sequence[float]]], title: str,
                       route=None, form: str = "km", depart_s: Optional[float] = None,
                       places: Optional[Sequence[Place]] = None) -> None:
    """:func:`draw_time_distance` as a figure of its own, ``.png``, ``.svg`` or ``.pdf`` by extension, written
    whole or not at all."""
    path = check_plot_path(path)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 6.5))
    try:
        draw_time_distance(ax, series, route, form, depart_s, places)
        fig.tight_layout()
        fit_title(ax, title)
        fmt = path.suffix.lower().lstrip(".")
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=130, bbox_inches="tight"))
    finally:
        plt.close(fig)
