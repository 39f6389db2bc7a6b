"""Plots that show the line: stations, neutral sections, tunnels and curves marked; the speed limit as
the route file gives it and as the train meets it (held until its tail clears), each labelled; legends
beside the axes, never over the limit; titles wrapped, never cut. Checked on the artists matplotlib
holds, not on pixels (Agg, headless)."""

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

from locoplan.io.load import load_route, load_train
from locoplan.reporting import plot_ocp
from locoplan.reporting.plot import FILE_LIMIT, TRAIN_LIMIT
from locoplan.settings import RunSettings

LINE = ("neutral section", "tunnel", "curve", "station (stop)")


@pytest.fixture
def figures(monkeypatch):
    """The figures the plot functions would save (drawn, still open), instead of their files."""
    import matplotlib.pyplot as plt

    kept = []

    def keep(fig, path, fmt, plt_):
        fig.canvas.draw()
        kept.append(fig)
    monkeypatch.setattr(plot_ocp, "_save", keep)
    yield kept
    for fig in kept:
        plt.close(fig)


def _legend_labels(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


def _title_fits(fig, ax) -> None:
    title = ax.title
    box, axes, whole = title.get_window_extent(), ax.get_window_extent(), fig.bbox
    assert box.width <= axes.width * 1.02, (title.get_text(), box.width, axes.width)
    assert box.x0 >= whole.x0 and box.x1 <= whole.x1 and box.y1 <= whole.y1


def test_bound_plot_title_wraps_a_long_name_and_keeps_every_word(tmp_path, figures):
    route = "Fribourg/Freiburg - Bern (Swiss Federal Railways, the line through the Sense valley), 31.7 km"
    data = {"route": route, "consist": "Re 620 + 30 x Habbiillnss (1800 t)",
            "results": [{"time_s": 1500.0, "energy_kwh": 675.83}, {"time_s": 1600.0, "energy_kwh": 650.15}]}
    plot_ocp.plot_energy_time(tmp_path / "curve.png", data)
    fig, = figures
    ax = fig.axes[0]
    text = ax.title.get_text()
    assert "\n" in text and text.split() == f"{route} — {data['consist']}: least traction energy E* against running time".split()
    _title_fits(fig, ax)
    x, y = ax.lines[0].get_data()
    assert list(x) == [1500.0, 1600.0] and list(y) == [675.83, 650.15]


@pytest.fixture(scope="module")
def ns_run(root):
    from locoplan.ocp.mpoc import run_mpoc
    from locoplan.sim.calculator import ModelOptions

    route = load_route(root / "routes/freight-20km-ns.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x50.yaml")
    return route, train, run_mpoc(route, train, ModelOptions(), 1500.0)


@pytest.mark.slow
def test_energy_optimum_plot_marks_the_line_and_both_limits(tmp_path, figures, ns_run):
    route, train, run = ns_run
    plot_ocp.plot_energy_run(tmp_path / "e.png", run, route=route)
    fig, = figures
    ax = fig.axes[0]
    labels = _legend_labels(ax)
    for want in (*LINE, FILE_LIMIT, TRAIN_LIMIT, "traction cut (neutral section under the train)"):
        assert want in labels, labels
    # one band per neutral section, tunnel and curve of the file, where the file puts it
    for attr, label in (("neutral_sections", "neutral section"), ("tunnels", "tunnel"), ("curves", "curve")):
        spans = sorted((round(p.get_x(), 6), round(p.get_x() + p.get_width(), 6)) for p in ax.patches
                       if p.get_facecolor() == [p2 for p2 in ax.patches if p2.get_label() == label][0].get_facecolor())
        want = sorted((round(s.from_m / 1000, 6), round(s.to_m / 1000, 6)) for s in getattr(route, attr))
        assert spans == want, attr
    # the train's limit rises a train length after the file's (held until its tail clears)
    lines = {ln.get_label(): ln for ln in ax.lines}
    fx, fy = (np.asarray(a, float) for a in lines[FILE_LIMIT].get_data())
    tx, ty = (np.asarray(a, float) for a in lines[TRAIN_LIMIT].get_data())
    file_rise = next(fx[k] for k in range(1, len(fy)) if fy[k] > fy[k - 1])
    limit_after = fy[np.searchsorted(fx, file_rise)]
    train_rise = next(tx[k] for k in range(1, len(ty)) if ty[k] >= limit_after and tx[k] > file_rise)
    assert (train_rise - file_rise) * 1000 == pytest.approx(train.length_m, abs=25.0)
    # the legend beside the axes, never over the limit line; the title inside the figure
    assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1
    _title_fits(fig, ax)


@pytest.mark.slow
def test_energy_optimum_plot_without_the_route_labels_the_one_limit(tmp_path, figures, ns_run):
    _, _, run = ns_run
    plot_ocp.plot_energy_run(tmp_path / "e.png", run)
    labels = _legend_labels(figures[0].axes[0])
    assert "speed limit" in labels and FILE_LIMIT not in labels and "tunnel" not in labels


def test_pareto_title_wraps_a_long_name_inside_the_figure(tmp_path, monkeypatch):
    """The front's file is not cropped to its artists: a long route name is wrapped, never cut."""
    import matplotlib.pyplot as plt

    from locoplan.reporting import plot_runs

    kept = []
    monkeypatch.setattr(plot_runs, "_save", lambda fig, path: (fig.canvas.draw(), kept.append(fig)))
    pts = [{"strategy": "four-stage", "running_time_s": t, "traction_energy_kwh": e} for t, e in ((1500, 690), (1600, 660))]
    grid = [{"planned_time_s": t, "best_running_time_s": t, "best_energy_kwh": e, "optimum_kwh": None,
             "optimum_time_s": None} for t, e in ((1500, 690), (1600, 660))]
    route = "Fribourg/Freiburg - Bern (Swiss Federal Railways, the line through the Sense valley), 31.7 km"
    front = {"route": route, "consist": "Re 620 + 30 x Habbiillnss (1800 t)", "points": pts, "front": pts,
             "grid": grid, "fastest_time_s": 1400.0}
    plot_runs.plot_pareto(front, tmp_path / "f.png")
    fig, = kept
    ax = fig.axes[0]
    assert "\n" in ax.title.get_text()
    assert ax.title.get_text().split() == f"{route} — {front['consist']}: energy-time front".split()
    _title_fits(fig, ax)
    plt.close(fig)


@pytest.fixture(scope="module")
def ns_profiles(root):
    """Plans on freight-20km-ns whose grids differ: mpoc-n refines its grid at its own switching points."""
    from locoplan import api

    route = load_route(root / "routes/freight-20km-ns.yaml")
    train = load_train(root / "configs/consists/HXD1-C80x50.yaml")
    profiles = {name: api.simulate(route, train, RunSettings(time_s=1500.0), strategy=name).run.result.profile
                for name in ("mpoc-n", "sfs", "time-saving", "four-stage")}
    return route, profiles


@pytest.mark.parametrize("pair", [("mpoc-n", "sfs"), ("time-saving", "mpoc-n"), ("sfs", "four-stage", "mpoc-n")])
def test_compared_profiles_are_each_drawn_on_their_own_grid(pair, ns_profiles):
    """Each strategy's speed line has its own positions as x (grids of different sizes side by side),
    labelled with its name; the limit and gradient come from the first."""
    import matplotlib.pyplot as plt

    from locoplan.reporting.plot import draw_profiles

    route, profiles = ns_profiles
    sizes = {profiles[name].s_m.size for name in pair}
    assert len(sizes) == 2, sizes  # the case that failed: grids of different sizes in one figure
    fig, (ax, axg) = plt.subplots(2, 1)
    try:
        draw_profiles(ax, axg, [(name, profiles[name]) for name in pair], "t", route)
        lines = {ln.get_label(): ln for ln in ax.lines}
        for name in pair:
            x, y = (np.asarray(a, float) for a in lines[name].get_data())
            prof = profiles[name]
            np.testing.assert_allclose(x, prof.s_m / 1000.0)
            np.testing.assert_allclose(y, prof.v_kmh[0], equal_nan=True)
            assert x[-1] == pytest.approx(route.length_m / 1000.0)
        assert [n for n in _legend_labels(ax) if n in pair] == list(pair)
    finally:
        plt.close(fig)


def test_plot_profiles_writes_a_figure_of_plans_on_different_grids(tmp_path, ns_profiles):
    from locoplan.reporting.plot import plot_profiles

    route, profiles = ns_profiles
    out = tmp_path / "c.png"
    plot_profiles(out, [(n, profiles[n]) for n in ("mpoc-n", "sfs", "time-saving")], "t", route=route)
    assert out.stat().st_size > 10_000
