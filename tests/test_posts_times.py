"""Positions as kilometre posts and stations in every output, times as people write them, and the
time-distance diagram: on a short line with stations and a chainage whose posts jump and count down after
a mileage change (tests/data/routes/posts-6km.yaml: 100.000 km at the start, 47.350 km counting down from
3 km on)."""

import csv
import io
import json

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan import bounds
from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.io.load import load_route
from locoplan.settings import RunSettings

runner = CliRunner()
POSTS = "tests/data/routes/posts-6km.yaml"
STATIONS = {"Aston": 0.0, "Brook junction": 2400.0, "Cole": 4150.0, "Dunmore": 6000.0}
POST_AT = {"Aston": 100.0, "Brook junction": 102.4, "Cole": 46.2, "Dunmore": 44.35}


def _run(root, monkeypatch, args, code=0):
    monkeypatch.chdir(root)
    monkeypatch.setenv("COLUMNS", "100")
    result = runner.invoke(app, args)
    assert result.exit_code == code, result.output
    return result.output


# ------------------------------------------------------------------------------------------ times
@pytest.mark.parametrize("text, seconds", [
    ("1500", 1500.0), ("1500s", 1500.0), ("25min", 1500.0), ("25 min", 1500.0), ("25m", 1500.0),
    ("00:25:00", 1500.0), ("0:25:00", 1500.0), ("1h05", 3900.0), ("1h05min", 3900.0), ("1h5m30s", 3930.0),
    ("1.5h", 5400.0), ("25min30", 1530.0)])
def test_running_times_as_people_write_them(text, seconds):
    assert bounds.time_request(text) == ("s", seconds)


@pytest.mark.parametrize("text", ["1.1x", "+10%"])
def test_factors_of_the_fastest_run_stay(text):
    assert bounds.time_request(text) == ("x", pytest.approx(1.1))


@pytest.mark.parametrize("text", ["25:00", "abc", "1h1h", "5s3", "min", "25mins", "1:75:00"])
def test_a_malformed_time_names_the_option_and_the_forms(text):
    with pytest.raises(InputError) as exc:
        bounds.time_request(text, "--time")
    msg = str(exc.value)
    assert "--time" in msg and all(form in msg for form in ("1500", "25min", "1h05", "0:25:00", "1.1x", "+10%"))


def test_times_lists_take_the_forms_and_ranges_stay_ranges():
    assert bounds.times_request("25min,0:26:00,1.1x") == [("s", 1500.0), ("s", 1560.0), ("x", pytest.approx(1.1))]
    assert bounds.times_request("00:25:00") == [("s", 1500.0)]
    assert bounds.times_request("1400:1600:100") == [("s", 1400.0), ("s", 1500.0), ("s", 1600.0)]


def test_clock_times_give_the_running_time():
    assert bounds.clock_request(None, "08:00", "08:25") == "1500"
    assert bounds.clock_request(None, "23:50", "00:15") == "1500"  # over midnight: the next day's arrival
    assert bounds.clock_request("1500", "08:00", None) == "1500"  # --depart alone only sets the clock
    for depart, arrive, time, flag in [(None, "08:25", None, "--arrive"), ("08:00", "08:25", "1500", "--arrive"),
                                       ("08:00", "08:00", None, "--arrive"), ("8:60", "09:00", None, "--depart"),
                                       ("08:00", "24:10", None, "--arrive")]:
        with pytest.raises(InputError) as exc:
            bounds.clock_request(time, depart, arrive)
        assert flag in str(exc.value)


@pytest.fixture(scope="module")
def by_time_form(root):
    """optimize's --json on freight-20km for the same running time written four ways."""
    import os

    old = os.getcwd()
    os.chdir(root)
    try:
        out = {}
        for name, args in {"seconds": ["--time", "1500"], "minutes": ["--time", "25min"],
                           "h:mm:ss": ["--time", "00:25:00"], "clocks": ["--depart", "08:00", "--arrive", "08:25"]}.items():
            result = runner.invoke(app, ["optimize", "routes/freight-20km.yaml", "--no-gap", "--json", *args])
            assert result.exit_code == 0, result.output
            out[name] = json.loads(result.stdout)
        return out
    finally:
        os.chdir(old)


def test_a_time_written_any_way_plans_the_same(by_time_form):
    base = by_time_form["seconds"]
    assert base["planned_time_s"] == 1500.0
    for name, d in by_time_form.items():
        assert (d["planned_time_s"], d["running_time_s"], d["traction_energy_kwh"], d["plan"]) == (
            base["planned_time_s"], base["running_time_s"], base["traction_energy_kwh"], base["plan"]), name


@pytest.mark.parametrize("args, flag", [(["--time", "25:00"], "--time"), (["--arrive", "08:25"], "--arrive"),
                                        (["--depart", "8h", "--arrive", "08:25"], "--depart"),
                                        (["--time", "1500", "--depart", "08:00", "--arrive", "08:25"], "--arrive")])
def test_bad_times_on_the_command_line_are_exit_2(root, monkeypatch, args, flag):
    for command in (["optimize", POSTS], ["bound", POSTS], ["simulate", POSTS, "--strategy", "four-stage"]):
        out = _run(root, monkeypatch, [*command, *args], code=2)
        assert flag in out and "Traceback" not in out


def test_a_post_form_other_than_km_or_plus_is_exit_2(root, monkeypatch):
    out = _run(root, monkeypatch, ["optimize", POSTS, "--chainage", "miles"], code=2)
    assert "--chainage" in out and "12+345" in out


def test_every_command_that_takes_time_takes_clocks(root, monkeypatch):
    for command in ("simulate", "optimize", "compare", "sweep", "study", "bound", "ocp", "advise", "journey"):
        out = _run(root, monkeypatch, [command, "--help"])
        assert "--depart" in out and "--arrive" in out, command


# ------------------------------------------------------------------------------------------ posts in outputs
@pytest.fixture(scope="module")
def optimized(root, tmp_path_factory):
    """optimize on the posts line: the table (posts as 12+345), the profile CSV, the plots; and its --json."""
    import os

    tmp = tmp_path_factory.mktemp("posts")
    old = os.getcwd()
    os.chdir(root)
    os.environ["COLUMNS"] = "100"
    try:
        table = runner.invoke(app, ["optimize", POSTS, "--chainage", "plus", "--out", str(tmp / "p.csv"),
                                    "--plot", str(tmp / "p.png"), "--plot-td", str(tmp / "td.svg"),
                                    "--depart", "08:00"])
        assert table.exit_code == 0, table.output
        js = runner.invoke(app, ["optimize", POSTS, "--json"])
        assert js.exit_code == 0, js.output
    finally:
        os.environ.pop("COLUMNS", None)
        os.chdir(old)
    return table.output, tmp, json.loads(js.stdout)


def test_optimize_table_gives_posts_and_stations(optimized):
    text, _, data = optimized
    assert "km post" in text and "100+000" in text
    for c in data["sequence"]:  # each condition's start at its post, as the route's chainage counts it
        km = c["from_km_post"]
        assert f"{int(round(km * 1000)) // 1000}+{int(round(km * 1000)) % 1000:03d}" in text
    for name in STATIONS:
        assert name.split()[0] in text
    assert "Brook junction (102+400)" in " ".join(text.split())  # the summary's stations row
    t = data["running_time_s"]
    assert f"(departs 08:00:00, arrives 08:{int(round(t)) // 60:02d}:{int(round(t)) % 60:02d})" in text


def test_profile_csv_has_posts_and_stations_after_its_columns(optimized, root):
    _, tmp, _ = optimized
    rows = list(csv.DictReader(io.StringIO((tmp / "p.csv").read_text())))
    head = list(rows[0])
    assert head[:8] == ["s_m", "t_s", "v_kmh", "limit_kmh", "gradient_permille", "condition", "traction_kn", "brake_kn"]
    assert head[-2:] == ["km_post", "station"]
    route = load_route(root / POSTS)
    s = np.array([float(r["s_m"]) for r in rows])
    post = np.array([float(r["km_post"]) for r in rows])
    up, down = s < 3000, s >= 3000
    assert np.all(np.diff(post[up]) > 0) and np.all(np.diff(post[down]) < 0)  # up, then down after the change
    assert post[up] == pytest.approx(100.0 + s[up] / 1000, abs=1e-6)
    assert post[down] == pytest.approx(47.35 - (s[down] - 3000) / 1000, abs=1e-6)
    named = {r["station"]: float(r["s_m"]) for r in rows if r["station"]}
    assert set(named) == set(STATIONS)
    step = max(np.diff(s))
    for name, at in STATIONS.items():  # at the node nearest each station
        assert abs(named[name] - at) <= step / 2 + 1e-9
    assert route.stations[1].name == "Brook junction"


def test_json_has_posts_beside_positions_and_the_stations(optimized):
    _, _, d = optimized
    assert d["km_posts"] == "chainage"
    assert [(st["name"], st["at_m"], st["at_km_post"]) for st in d["stations"]] == [
        (n, STATIONS[n], pytest.approx(POST_AT[n])) for n in STATIONS]
    for c in d["sequence"]:
        for end in ("from", "to"):
            s = c[f"{end}_m"]
            want = 100.0 + s / 1000 if s < 3000 else 47.35 - (s - 3000) / 1000
            assert c[f"{end}_km_post"] == pytest.approx(want, abs=1e-6)
    assert len(d["switching_points_km_post"]) == len(d["switching_points_m"])
    assert d["max_coupler_tension_at_km_post"] == pytest.approx(100.0 + d["max_coupler_tension_at_m"] / 1000, abs=1e-6)


def test_a_route_without_chainage_keeps_metres_and_counts_posts_from_its_start(root, monkeypatch):
    out = _run(root, monkeypatch, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:2200,C:17540,B",
                                   "--json"])
    d = json.loads(out)
    assert d["km_posts"] == "from the start" and d["stations"] == []
    assert d["sequence"][1]["from_km_post"] == pytest.approx(d["sequence"][1]["from_m"] / 1000)
    table = _run(root, monkeypatch, ["simulate", "routes/freight-20km.yaml", "--sequence", "T:0,K:2200,C:17540,B"])
    assert "km post" not in table and "stations" not in table


def test_compare_gives_switching_points_as_posts(root, monkeypatch):
    out = _run(root, monkeypatch, ["compare", POSTS, "--strategies", "time-saving,four-stage", "--no-gap"])
    assert "switching points (km posts)" in out
    assert "stations: Aston (100.000 km), Brook junction (102.400 km), Cole (46.200 km), Dunmore (44.350 km)" in " ".join(
        out.split())


def test_journey_tables_csv_and_json_give_posts(root, monkeypatch, tmp_path):
    args = ["journey", "tests/data/posts/posts-journey.yaml", "--consist", "HXD1-C80x30", "--strategies",
            "four-stage", "--chainage", "plus", "--depart", "08:00", "--arrive", "08:11"]
    out = _run(root, monkeypatch, [*args, "--out", str(tmp_path / "j.csv"), "--plot-td", str(tmp_path / "j.png")])
    assert "km post" in out and "102+400" in out and "46+200" in out and "44+350" in out
    assert "08:00:00" in out  # the stations' clocks from --depart
    assert "660 s, 600 s of running after 60 s of dwells" in " ".join(out.split())
    rows = list(csv.DictReader(io.StringIO((tmp_path / "j.csv").read_text())))
    assert list(rows[0])[-1] == "km_post"
    at = {r["station"]: float(r["km_post"]) for r in rows if r["station"]}
    assert at == {n: pytest.approx(POST_AT[n]) for n in STATIONS}
    assert (tmp_path / "j.png").stat().st_size > 0
    d = json.loads(_run(root, monkeypatch, [*args, "--json"]))
    assert d["running_time_s"] == 600.0
    assert {st["station"]: st["at_km_post"] for st in d["stations"]} == {n: pytest.approx(POST_AT[n]) for n in STATIONS}


# ------------------------------------------------------------------------------------------ plots
def _axis_labels(axis) -> list[str]:
    return [t.get_text() for t in axis.get_ticklabels() if t.get_text()]


def test_profile_plot_reads_posts_and_names_the_stations(root):
    import matplotlib.pyplot as plt

    from locoplan import api
    from locoplan.io.load import load_train
    from locoplan.reporting.plot import draw_profiles

    route = load_route(root / POSTS)
    train = load_train(root / "configs/consists/HXD1-C80x50.yaml")
    plan = api.simulate(route, train, RunSettings(), strategy="time-saving")
    fig, (ax, axg) = plt.subplots(2, 1, sharex=True)
    try:
        draw_profiles(ax, axg, [("time-saving", plan.run.result.profile)], "t", route, "plus")
        fig.canvas.draw()
        labels = _axis_labels(axg.xaxis)
        assert "100+000" in labels and "47+350" in labels and "45+000" in labels
        assert "kilometre post" in axg.get_xlabel()
        names = [t.get_text() for t in ax.texts]
        assert all(n in names for n in STATIONS)
        lines = {ln.get_gid(): ln.get_xdata()[0] for ln in ax.lines if (ln.get_gid() or "").startswith("station:")}
        assert lines == {"station:Brook junction": 2.4, "station:Cole": 4.15}
    finally:
        plt.close(fig)


def test_time_distance_diagram_draws_the_runs_and_the_stations(root):
    import matplotlib.pyplot as plt

    from locoplan.reporting.plot_td import Place, draw_time_distance

    route = load_route(root / POSTS)
    s2 = np.concatenate([np.linspace(0, 2400, 25), np.linspace(2400, 6000, 37)])
    t2 = np.concatenate([np.linspace(0, 240, 25), np.linspace(300, 600, 37)])  # stands at 2,400 m from 240 to 300 s
    places = [Place("Aston", 0), Place("Brook junction", 2400, True, 200, 260), Place("Cole", 4150, False),
              Place("Dunmore", 6000)]
    fig, ax = plt.subplots()
    try:
        draw_time_distance(ax, [("plan", s2, t2)], route, "km", depart_s=8 * 3600, places=places)
        fig.canvas.draw()
        run = next(ln for ln in ax.lines if ln.get_gid() == "run:plan")
        x, y = run.get_xdata(), run.get_ydata()
        assert np.all(np.diff(x) >= 0) and x[0] == 0 and x[-1] == pytest.approx(10.0)  # the clock, minutes
        assert list(y) == pytest.approx(list(s2 / 1000))
        stations = {ln.get_gid(): (ln.get_ydata()[0], ln.get_linestyle()) for ln in ax.lines
                    if (ln.get_gid() or "").startswith("station:")}
        assert stations == {"station:Aston": (0.0, "-"), "station:Brook junction": (2.4, "-"),
                            "station:Cole": (4.15, "--"), "station:Dunmore": (6.0, "-")}
        window = next(ln for ln in ax.lines if ln.get_gid() == "window:Brook junction")
        assert list(window.get_xdata()) == pytest.approx([200 / 60, 260 / 60]) and set(window.get_ydata()) == {2.4}
        assert "08:00" in _axis_labels(ax.xaxis) and "clock" in ax.get_xlabel()
        assert "100.000" in _axis_labels(ax.yaxis) and "47.350" in _axis_labels(ax.yaxis)
        assert ax.yaxis_inverted()  # the first station at the top
    finally:
        plt.close(fig)


def test_journey_diagram_shows_the_dwell(root, monkeypatch, tmp_path):
    from locoplan.reporting import plot_td

    drawn = {}
    monkeypatch.setattr(plot_td, "plot_time_distance",
                        lambda path, series, title, route, form, depart_s, places: drawn.update(series=series, places=places))
    _run(root, monkeypatch, ["journey", "tests/data/posts/posts-journey.yaml", "--consist", "HXD1-C80x30",
                             "--strategies", "four-stage", "--plot-td", str(tmp_path / "td.png")])
    (label, s, t), = drawn["series"]
    s, t = np.array(s), np.array(t)
    assert label == "four-stage" and np.all(np.diff(t) >= 0)
    at_b = np.flatnonzero(np.abs(s - 2400) < 1e-6)
    assert t[at_b].max() - t[at_b].min() == pytest.approx(60.0)  # stands 60 s at Brook junction
    assert [(p.name, p.at_m, p.stop) for p in drawn["places"]] == [
        ("Aston", 0, True), ("Brook junction", 2400, True), ("Cole", 4150, False), ("Dunmore", 6000, True)]


def test_compare_diagram_has_one_line_per_strategy(root, monkeypatch, tmp_path):
    from locoplan.reporting import plot_td

    drawn = {}
    monkeypatch.setattr(plot_td, "plot_time_distance",
                        lambda path, series, title, route, form, depart_s=None, places=None: drawn.update(series=series))
    _run(root, monkeypatch, ["compare", POSTS, "--strategies", "time-saving,four-stage", "--no-gap",
                             "--plot-td", str(tmp_path / "td.png")])
    assert [label for label, _, _ in drawn["series"]] == ["time-saving", "four-stage"]
    for _, s, t in drawn["series"]:
        assert s[0] == 0 and s[-1] == pytest.approx(6000) and np.all(np.diff(t) > 0)


def test_optimize_writes_its_diagram(optimized):
    _, tmp, _ = optimized
    text = (tmp / "td.svg").read_text()
    assert "Brook junction" in text and "08:0" in text
