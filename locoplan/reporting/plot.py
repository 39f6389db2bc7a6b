"""Speed profiles over the limits, with the gradient profile under them (matplotlib, no display)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, Problem
from ..sim.result import Profile
from .files import atomic_write

COND_COLOURS = {"T": "#d62728", "K": "#1f77b4", "C": "#2ca02c", "B": "#7f7f7f", "E": "#9467bd"}


FIGURE_SUFFIXES = (".png", ".svg", ".pdf")
"""A figure's file types, by extension (PDF and SVG for papers, PNG for a look)."""


def check_plot_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise InputError(Problem(str(path), "plot", "use a .png, .svg or .pdf file name"))
    return path


FITNESS = "best fitness"
ENERGY = "best traction energy [kWh]"
"""What a convergence history measures (``histories`` items' third element; fitness when absent)."""


def history_quantity(strategy: str) -> str:
    """What a strategy's optimiser history measures: the energy-saving search minimises energy [kWh],
    the others eq. 10's fitness."""
    return ENERGY if strategy == "energy-saving" else FITNESS


def run_title(route: str, train: str, label: str, summary: dict) -> str:
    """A plot title: route, train, what was run, and its time and energy, or why it has no plan
    (never "nan s")."""
    t, e = summary.get("running_time_s"), summary.get("traction_energy_kwh")
    if summary.get("feasible") and t is not None and e is not None and np.isfinite(t):
        return f"{route} — {train}: {label}, {t:.1f} s, {e:.1f} kWh"
    return f"{route} — {train}: {label}, no feasible plan ({summary.get('reason') or 'infeasible'})"


def plot_profiles(path: str | Path, profiles: list[tuple[str, Profile]], title: str,
                  histories: list[tuple] | None = None, route=None, coupler_limit_kn: float | None = None,
                  form: str = "km") -> None:
    """Draw one or more speed profiles (label, one-plan Profile) against the speed limit, with the
    equivalent gradient underneath (the ISSA paper's Fig. 15) and, if given, optimiser convergence curves
    (best value per iteration, Fig. 17: items (label, history) for a fitness, or (label, history,
    quantity) e.g. :data:`ENERGY`, or (label, history, quantity, reported value): the value the table
    reports, drawn at the curve's end; one panel per quantity); ``.png``, ``.svg`` or ``.pdf`` by extension,
    written atomically. A plan that failed (stalled, overshot) is drawn up to where it failed. With
    ``route``, the file's own limit and gradient are drawn beside the train's, and the stations, neutral
    sections, tunnels and curves are marked, and the position axis reads the route's kilometre posts where it
    has a chainage (written in ``form``: ``km`` or ``plus``). A train of several vehicles has a panel of its
    largest coupler forces along the route (tension up, compression down), with ``coupler_limit_kn`` if given."""
    path = check_plot_path(path)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    couplers = any(p.coupler_tension_kn is not None for _, p in profiles)
    if histories:
        # one convergence panel per quantity: a fitness (no unit) and an energy [kWh] never share an axis
        groups: dict[str, list] = {}
        for item in histories:
            label, hist = item[0], item[1]
            final = item[3] if len(item) > 3 else None
            groups.setdefault(item[2] if len(item) > 2 and item[2] else FITNESS, []).append((label, hist, final))
        fig = plt.figure(figsize=(11, 11 if couplers else 9))
        grid = fig.add_gridspec(4 if couplers else 3, len(groups), height_ratios=[3, 1, 1, 2] if couplers else [3, 1, 2],
                                hspace=0.35, wspace=0.25)
        ax = fig.add_subplot(grid[0, :])
        axg = fig.add_subplot(grid[1, :], sharex=ax)
        axk = fig.add_subplot(grid[2, :], sharex=ax) if couplers else None
        for k, (quantity, items) in enumerate(groups.items()):
            axc = fig.add_subplot(grid[-1, k])
            for label, hist, final in items:
                colour = _colour(label, profiles)
                searched = final is not None and np.isfinite(final)
                axc.plot(np.arange(1, len(hist) + 1), hist, lw=1.5, color=colour,
                         label=f"{label} (best per iteration, search grid)" if searched else label)
                if searched:
                    # the search runs on a coarser grid: the value reported (re-simulated on the reporting
                    # grid, as in the table) ends the curve, so figure and table agree
                    axc.plot([len(hist)], [final], "o", color=colour, ms=5,
                             label=f"{label}: {final:.5g} reported (reporting grid)")
            axc.set_xlabel("iteration")
            axc.set_ylabel(quantity)
            axc.grid(alpha=0.3)
            if len(groups) == 1:  # beside, as above
                axc.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
            else:  # panels side by side: inside, where matplotlib finds the fewest points
                axc.legend(loc="best", fontsize=8)
    elif couplers:
        fig, (ax, axg, axk) = plt.subplots(3, 1, figsize=(11, 8.5), sharex=True, gridspec_kw={"height_ratios": [3, 1, 1]})
    else:
        fig, (ax, axg) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    draw_profiles(ax, axg, profiles, title, route, form)
    if couplers:
        axg.set_xlabel("")
        draw_couplers(axk, profiles, coupler_limit_kn)
        axk.set_xlabel(axg.get_xlabel() or position_label(route, form))
    if not histories:
        fig.tight_layout()
    fmt = path.suffix.lower().lstrip(".")
    try:  # bbox "tight": the legends beside the axes and a long title are inside the figure, never cut
        atomic_write(path, lambda p: fig.savefig(p, format=fmt, dpi=130, bbox_inches="tight"))
    finally:
        plt.close(fig)


def _until_failure(v_kmh: np.ndarray) -> np.ndarray:
    """The speeds up to where the plan failed: NaN after the first NaN node (the calculator stops a
    failed plan there) and after a stand-still short of the end (a stall), so no line runs on at 0 km/h."""
    v = np.array(v_kmh, dtype=float)
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        v[bad[0]:] = np.nan
    stopped = np.flatnonzero(v[1:-1] <= 0.0) + 1  # at rest before the last node: stalled there
    if stopped.size:
        v[stopped[0] + 1:] = np.nan
    return v


PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf")


def _colour(label: str, profiles) -> str:
    """One colour per strategy in a figure (its profile and its convergence curve alike)."""
    names = [name for name, _ in profiles]
    base = label.split(" (")[0]
    k = names.index(label) if label in names else next((i for i, n in enumerate(names) if n.split(" (")[0] == base),
                                                       len(names) + sum(map(ord, label)) % len(PALETTE))
    return PALETTE[k % len(PALETTE)]


FEATURES = (("neutral_sections", "neutral section", "#ff7f0e", 0.25), ("tunnels", "tunnel", "#7f7f7f", 0.18),
            ("curves", "curve", "#17becf", 0.12))
"""What of the line is marked on a profile: attribute of the route, label, colour, opacity."""


def mark_line(ax, axg, route) -> None:
    """Stations (the route's ends, and its named stations with their names over the panel), neutral sections,
    tunnels and curves as bands over both panels."""
    for attr, label, colour, alpha in FEATURES:
        for k, sec in enumerate(getattr(route, attr)):
            for a in (ax, axg):
                a.axvspan(sec.from_m / 1000, sec.to_m / 1000, color=colour, alpha=alpha, lw=0,
                          label=label if (k == 0 and a is ax) else None)
    for k, at in enumerate((0.0, route.length_m)):
        ax.axvline(at / 1000, color="black", lw=1.0, ls=":", label="station (stop)" if k == 0 else None)
        ax.annotate("▼", (at / 1000, 1.0), xycoords=("data", "axes fraction"), ha="center", va="bottom", fontsize=9)
    inner = [st for st in route.stations if 1e-6 < st.at_m < route.length_m - 1e-6]
    for k, st in enumerate(inner):
        for a in (ax, axg):
            a.axvline(st.at_m / 1000, color="#444444", lw=0.9, ls="-.", gid=f"station:{st.name}",
                      label="station" if (k == 0 and a is ax) else None)
    for st in route.stations:
        ax.annotate(st.name, (st.at_m / 1000, 1.0), xycoords=("data", "axes fraction"), xytext=(0, 12),
                    textcoords="offset points", rotation=90, ha="center", va="bottom", fontsize=7)


def station_pad(route) -> float:
    """Title pad [pt] over a panel with the route's ends (▼) and its stations' names (rotated) above it."""
    longest = max((len(st.name) for st in route.stations), default=0) if route is not None else 0
    return STATION_TITLE_PAD + (12 + 4.6 * longest if longest else 0)


def position_label(route, form: str = "km") -> str:
    """The position axis's label: kilometre posts where the route has a chainage, else km from the start."""
    from .posts import has_chainage

    if has_chainage(route):
        return "kilometre post" + (" [km]" if form == "km" else "")
    return "position [km]"


NICE_STEPS_KM = (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0)


def post_ticks(route, lo_km: float, hi_km: float, n: int = 8) -> list[float]:
    """Positions [km from the start] in ``lo_km`` .. ``hi_km`` where the route's kilometre post is a round number
    (about ``n`` of them), and where each mileage change begins."""
    changes = route.mileage()
    step = next((x for x in NICE_STEPS_KM if (hi_km - lo_km) / x <= n), NICE_STEPS_KM[-1])
    ends = [c.at_m / 1000 for c in changes[1:]] + [route.length_m / 1000]
    ticks: list[float] = []
    for c, end in zip(changes, ends):
        a, b = max(c.at_m / 1000, lo_km), min(end, hi_km)
        if b < a:
            continue
        sign = -1.0 if c.descending else 1.0
        p0, p1 = sorted((c.km + sign * (a - c.at_m / 1000), c.km + sign * (b - c.at_m / 1000)))
        posts = np.arange(np.ceil(p0 / step - 1e-9), np.floor(p1 / step + 1e-9) + 1) * step
        at = c.at_m / 1000 + sign * (posts - c.km)
        ticks += [x for x in at if a - 1e-9 <= x <= b + 1e-9]
        if c is not changes[0] and lo_km <= c.at_m / 1000 <= hi_km:  # a mileage change: the post jumps here
            ticks.append(c.at_m / 1000)
    ticks = sorted(set(round(x, 9) for x in ticks))
    out: list[float] = []
    for x in ticks:  # no two labels on top of each other
        if not out or x - out[-1] > step / 2:
            out.append(x)
    return out


def posts_axis(axis, route, form: str = "km") -> None:
    """A position axis (matplotlib ``XAxis`` / ``YAxis`` in km from the start) labelled with the route's kilometre
    posts where it has a chainage (ticks at round posts and at each mileage change); as it was without one."""
    from matplotlib.ticker import FixedLocator, FuncFormatter

    from .posts import has_chainage, post_text

    if not has_chainage(route):
        axis.set_label_text(axis.get_label_text() or "position [km]")
        return
    lo, hi = 0.0, route.length_m / 1000
    axis.set_major_locator(FixedLocator(post_ticks(route, lo, hi)))
    axis.set_major_formatter(FuncFormatter(lambda x, pos: post_text(route, x * 1000, form, unit=False)))
    axis.set_label_text(position_label(route, form))


STATION_TITLE_PAD = 15
"""Title pad [pt] over a panel whose stations are marked: the ▼ above the axes stays clear of the title."""

TRAIN_LIMIT = "speed limit for the train (held until its tail clears)"
FILE_LIMIT = "speed limit (route file)"


def draw_limits(ax, s_m: np.ndarray, limit_kmh: np.ndarray, route=None) -> None:
    """The speed limit as the train meets it (``limit_kmh`` per cell of the grid ``s_m``: a rise held
    until the tail clears), and with ``route`` the limit as the route file gives it (dashed, where the two
    differ), each labelled."""
    from .writers import section_values

    s_km = np.asarray(s_m, float) / 1000.0
    if route is not None:
        file_limit = section_values(route.speed_limits, "kmh", np.asarray(s_m, float)[:-1])
        if not np.allclose(file_limit, limit_kmh):
            ax.step(s_km[:-1], file_limit, where="post", color="#555555", lw=1.0, ls="--", label=FILE_LIMIT)
    ax.step(s_km[:-1], limit_kmh, where="post", color="black", lw=1.2,
            label=TRAIN_LIMIT if route is not None else "speed limit")


def fit_title(ax, text: str, **kw):
    """Set ``text`` as the title of ``ax``, wrapped at spaces into lines no wider than the axes (a long
    route or consist name is never cut at the figure's edge). Returns the title."""
    renderer = ax.figure.canvas.get_renderer()
    width = ax.get_window_extent(renderer).width
    title = ax.set_title(text, **kw)
    lines: list[str] = []
    for paragraph in text.split("\n"):
        cur = ""
        for word in paragraph.split(" "):
            cand = f"{cur} {word}" if cur else word
            title.set_text(cand)
            if cur and title.get_window_extent(renderer).width > width:
                lines.append(cur)
                cur = word
            else:
                cur = cand
        lines.append(cur)
    title.set_text("\n".join(lines))
    return title


def draw_profiles(ax, axg, profiles: list[tuple[str, Profile]], title: str, route=None, form: str = "km") -> None:
    """Speed profiles over the limits on ``ax`` (one profile: coloured by condition), the equivalent
    gradient on ``axg``. With ``route``: the file's limit and gradient too (labelled as such, where they
    differ from the train's), the line's stations, neutral sections, tunnels and curves, and its kilometre
    posts on the position axis where it has a chainage (:func:`posts_axis`)."""
    from ..model.conditions import CONDITION_NAMES
    from ..sim.result import CONDITIONS
    from .writers import section_values

    ref = profiles[0][1]
    s_km = ref.s_m / 1000.0
    if route is not None:
        mark_line(ax, axg, route)
    draw_limits(ax, ref.s_m, ref.limit_kmh, route)
    single = len(profiles) == 1
    for label, prof in profiles:
        v = _until_failure(prof.v_kmh[0])
        if single:  # colour the one profile by the condition applied in each cell
            cond = prof.condition[0]
            for code, name in enumerate(CONDITIONS):
                cells = np.flatnonzero(cond == code)
                if not cells.size:
                    continue
                # each cell as its own segment from node k to k + 1, separated by NaN
                xs = np.column_stack([s_km[cells], s_km[cells + 1], np.full(cells.size, np.nan)]).ravel()
                ys = np.column_stack([v[cells], v[cells + 1], np.full(cells.size, np.nan)]).ravel()
                ax.plot(xs, ys, color=COND_COLOURS[name], lw=2, label=CONDITION_NAMES[name])
        else:  # each on its own grid: plans refine the grid at their own switching points
            ax.plot(prof.s_m / 1000.0, v, lw=1.6, label=label, color=_colour(label, profiles))
    if single and ref.air is not None:  # the air brake's applications as shaded spans
        from ..sim.result import AIR_APPLIED, AIR_ON

        on = np.isin(ref.air[0], (AIR_ON, AIR_APPLIED)).astype(np.int8)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], on, [0]])))
        for j, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
            ax.axvspan(s_km[a], s_km[b], color="#d62728", alpha=0.12, lw=0,
                       label=f"air brake applied ({len(edges) // 2})" if j == 0 else None)
    ax.set_ylabel("speed [km/h]")
    ax.set_ylim(0, max(float(ref.limit_kmh.max()), max(float(np.nanmax(p.v_kmh)) for _, p in profiles)) * 1.12)
    ax.set_title(title, wrap=True, pad=station_pad(route) if route is not None else None)
    ax.grid(alpha=0.3)
    # beside the axes, never over the limit line
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
    axg.fill_between(s_km[:-1], ref.gradient_permille, step="post", color="#8c564b", alpha=0.5,
                     label="equivalent gradient over the train" if route is not None else "equivalent gradient")
    if route is not None:
        grade = section_values(route.gradients, "permille", ref.s_m[:-1])
        axg.step(s_km[:-1], grade, where="post", color="#3b1f17", lw=0.9, ls="--", label="gradient (route file)")
        axg.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
    axg.axhline(0, color="black", lw=0.6)
    axg.set_ylabel("gradient [‰]")
    axg.set_xlabel(position_label(route, form))
    axg.grid(alpha=0.3)
    if route is not None:
        posts_axis(axg.xaxis, route, form)


def draw_couplers(ax, profiles: list[tuple[str, Profile]], limit_kn: float | None = None) -> None:
    """The largest tensile (up) and compressive (down) coupler force [kN] in each cell, per profile, with the
    consist's limit on both sides when given."""
    single = len(profiles) == 1
    for label, prof in profiles:
        if prof.coupler_tension_kn is None:
            continue
        s_km = prof.s_m / 1000.0
        colour = "#d62728" if single else _colour(label, profiles)
        name = "" if single else f"{label}: "
        ax.step(s_km[:-1], prof.coupler_tension_kn[0], where="post", color=colour, lw=1.0,
                label=f"{name}largest tension")
        ax.step(s_km[:-1], -prof.coupler_compression_kn[0], where="post", color="#1f77b4" if single else colour,
                lw=1.0, ls="-" if single else "--", label=f"{name}largest compression (down)")
    if limit_kn:
        for sign in (1, -1):
            ax.axhline(sign * limit_kn, color="black", lw=0.9, ls=":", label="coupler limit" if sign > 0 else None)
    ax.axhline(0, color="black", lw=0.6)
    ax.set_ylabel("coupler force [kN]")
    ax.set_xlabel("position [km]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)
