"""locoplan import osrd / osrd-train / railml: network formats to route, journey, vehicle and consist files.

OSRD's small_infra.json (LGPL-3.0, in ../shared/data/external/osrd/) is checked against a path search written
here, independently of the importer's: a train runs each track one way and changes track only through a switch
port group, never reversing. railML files are written here from the shipped routes and read back.
"""

from __future__ import annotations

import heapq
import itertools
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.importer import run_import
from locoplan.io.load import load_journey, load_route, load_train, load_vehicle
from locoplan.io.readers import ImportOptions
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions

ROOT = Path(__file__).resolve().parents[1]
OSRD = ROOT.parent / "shared" / "data" / "external" / "osrd"
INFRA = OSRD / "small_infra.json"
STOCKS = ["electric_rolling_stock", "fast_rolling_stock", "slow_rolling_stock"]
needs_osrd = pytest.mark.skipif(not INFRA.is_file(), reason="OSRD test data not in ../shared/data/external/osrd")
runner = CliRunner()


def _invoke(args):
    res = runner.invoke(app, args)
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res


# ------------------------------------------------------------------------------------------ an independent search
PORTS = {"point_switch": [("A", "B1"), ("A", "B2")], "crossing": [("A1", "B1"), ("A2", "B2")],
         "double_slip_switch": [("A1", "B1"), ("A1", "B2"), ("A2", "B1"), ("A2", "B2")],
         "single_slip_switch": [("A1", "B1"), ("A2", "B2"), ("A1", "B2")], "link": [("A", "B")]}


def _shortest(infra: dict, a: str, b: str) -> float | None:
    """Length of the shortest run from operational point a to b: nodes are (track, end the train leaves by)."""
    length = {t["id"]: t["length"] for t in infra["track_sections"]}
    nxt: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for sw in infra["switches"]:
        for p, q in PORTS[sw["switch_type"]]:
            e1 = (sw["ports"][p]["track"], sw["ports"][p]["endpoint"])
            e2 = (sw["ports"][q]["track"], sw["ports"][q]["endpoint"])
            nxt.setdefault(e1, []).append(e2)  # leaving by e1 enters by e2
            nxt.setdefault(e2, []).append(e1)
    ops = {op["id"]: [(p["track"], p["position"]) for p in op["parts"]] for op in infra["operational_points"]}
    other = {"BEGIN": "END", "END": "BEGIN"}
    best = math.inf
    for t0, x0 in ops[a]:
        # leave t0 by END (running up) or BEGIN (running down); or reach b on t0 itself
        for t1, x1 in ops[b]:
            if t1 == t0 and x1 != x0:
                best = min(best, abs(x1 - x0))
        dist = {(t0, "END"): length[t0] - x0, (t0, "BEGIN"): x0}
        heap = [(d, n) for n, d in dist.items()]
        heapq.heapify(heap)
        done = set()
        while heap:
            d, (t, leave) = heapq.heappop(heap)
            if (t, leave) in done:
                continue
            done.add((t, leave))
            for t2, enter in nxt.get((t, leave), ()):
                for t1, x1 in ops[b]:
                    if t1 == t2:
                        best = min(best, d + (x1 if enter == "BEGIN" else length[t2] - x1))
                n2 = (t2, other[enter])
                d2 = d + length[t2]
                if d2 < dist.get(n2, math.inf):
                    dist[n2] = d2
                    heapq.heappush(heap, (d2, n2))
    return None if best == math.inf else best


def _osrd(tmp: Path, a: str, b: str, **kw):
    opts = ImportOptions(from_station=a, to_station=b, **kw)
    return run_import("osrd", [INFRA], tmp, opts)


@pytest.fixture(scope="module")
def osrd_paths(tmp_path_factory):
    """Every ordered pair of small_infra's stations: (a, b) -> (route file, expected length or None)."""
    infra = json.loads(INFRA.read_text())
    ops = [op["id"] for op in infra["operational_points"]]
    out = {}
    base = tmp_path_factory.mktemp("osrd")
    for a, b in itertools.permutations(ops, 2):
        expected = _shortest(infra, a, b)
        folder = base / f"{a}-{b}"
        thermal = None
        if expected is not None:  # the same path for a train on its own power (no neutral sections)
            _osrd(base / "thermal" / f"{a}-{b}", a, b, thermal=True)
            thermal = base / "thermal" / f"{a}-{b}" / f"{a}-{b}.yaml"
        try:
            _osrd(folder, a, b)
            route = folder / f"{a}-{b}.yaml"
        except InputError as exc:
            text = str(exc)
            if expected is not None and "cannot start there" in text:  # the start has no catenary: a thermal train
                route = thermal
            else:
                route = text
        out[(a, b)] = (route, expected, thermal)
    return out


@needs_osrd
def test_osrd_every_joined_pair_imports_with_the_shortest_length(osrd_paths):
    joined = 0
    for (a, b), (route, expected, _) in osrd_paths.items():
        if expected is None:
            assert isinstance(route, str) and "no path from" in route and "nearest that can be reached" in route, (a, b)
            continue
        joined += 1
        assert isinstance(route, Path), (a, b, route)
        r = load_route(route)
        assert abs(r.length_m - expected) < 1e-6, (a, b, r.length_m, expected)
        assert r.stations[0].name == a and r.stations[-1].name == b and r.stations[-1].at_m == r.length_m
        journey, _ = load_journey(route.with_name(route.stem + "-journey.yaml"))
        assert [s.name for s in journey.stations] == [s.name for s in r.stations]
    assert joined == 40  # of the 56 ordered pairs (one starts without catenary: --thermal); the others would reverse


@needs_osrd
def test_osrd_reverse_path_mirrors_and_negates_the_slopes(osrd_paths):
    checked = 0
    for (a, b), (route, _, _) in osrd_paths.items():
        back = osrd_paths[(b, a)][0]
        if not isinstance(route, Path) or not isinstance(back, Path):
            continue
        fwd, rev = load_route(route), load_route(back)
        head = lambda p: [ln for ln in p.read_text().splitlines() if ln.startswith("# Path")]  # noqa: E731
        if fwd.length_m != rev.length_m or not head(route):
            continue
        s = np.linspace(0.5, fwd.length_m - 0.5, 2001)
        g = lambda r, x: np.array([next(q.permille for q in r.gradients if q.from_m <= xi < q.to_m) for xi in x])  # noqa: E731
        assert np.allclose(g(rev, fwd.length_m - s), -g(fwd, s)), (a, b)
        checked += 1
    assert checked >= 20


@needs_osrd
def test_osrd_speed_tag_neutral_sections_and_curves(tmp_path):
    _osrd(tmp_path / "tag", "Mid_East_station", "South_East_station", speed_tag="MA100")
    r = load_route(tmp_path / "tag" / "Mid_East_station-South_East_station.yaml")
    # speed_section.2 (TH1 3500-4400) gives MA100 80 km/h, below speed_section.1's 142 km/h where they overlap
    assert min(x.kmh for x in r.speed_limits) == pytest.approx(80.0)
    _osrd(tmp_path / "ns", "West_station", "Mid_West_station")
    r = load_route(tmp_path / "ns" / "West_station-Mid_West_station.yaml")
    # TA0 1960-2000 (lower_pantograph) joins TA6 0-10 across the switch; TA6 8500-8600 lies further on
    assert [(n.from_m, n.to_m) for n in r.neutral_sections] == [(1260, 1310), (9800, 9900)]
    _osrd(tmp_path / "c", "North_station", "South_station")
    r = load_route(tmp_path / "c" / "North_station-South_station.yaml")
    assert r.curves and all(c.radius_m >= 5000 for c in r.curves)


@needs_osrd
def test_osrd_neutral_section_is_coasted_by_every_strategy(tmp_path):
    _osrd(tmp_path, "West_station", "Mid_West_station")
    route = load_route(tmp_path / "West_station-Mid_West_station.yaml")
    ns = route.neutral_sections[0]
    train = load_train("HXD1-C80x50")
    ctx = make_context(route, train, RunSettings(ModelOptions(), time_s=900))
    for name in ("time-saving", "energy-saving", "four-stage", "proposed"):
        run = run_strategy(ctx, name, with_fitness=False)
        p = run.result.profile
        assert bool(run.result.feasible[0]), name
        s = np.asarray(p.s_m)
        mid = 0.5 * (s[:-1] + s[1:])  # cells
        inside = (mid > ns.from_m) & (mid < ns.to_m)
        assert inside.any() and np.all(np.asarray(p.traction_kn)[..., inside] == 0), name


@needs_osrd
def test_osrd_errors(tmp_path):
    res = _invoke(["import", "osrd", str(INFRA), "--from", "Nowhere", "--to", "West_station", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "no operational point 'Nowhere'" in res.stderr and "South_East_station" in res.stderr
    res = _invoke(["import", "osrd", str(INFRA), "--from", "West_station", "--to", "South_West_station", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "no path from 'West_station' to 'South_West_station'" in res.stderr
    assert "nearest that can be reached is 'Mid_West_station'" in res.stderr
    infra = json.loads(INFRA.read_text())
    infra["switches"][2]["ports"]["B1"]["track"] = "TX9"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(infra))
    res = _invoke(["import", "osrd", str(bad), "--from", "West_station", "--to", "Mid_West_station", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "switches[2].ports.B1.track: track 'TX9' is not among the track_sections" in res.stderr
    assert list(tmp_path.iterdir()) == [bad]  # nothing written


def _fast_params():
    from locoplan.runner import load_optimizer_params

    return load_optimizer_params("issa").model_copy(update={"pop_size": 8, "max_iter": 6})


def _optimize_all(paths, trains):
    """optimize on time (1.15 x the fastest run) on each path with each train: thermal trains on the path imported
    with --thermal; an electric train where the path has track without catenary may be unable to run it, and
    then stalls inside such a section (the only reason allowed)."""
    skipped = 0
    for electric_route, thermal_route in paths:
        for train, thermal in trains:
            route = load_route(thermal_route if thermal else electric_route)
            ctx0 = make_context(route, train, RunSettings(ModelOptions(step_m=100), need_time=False))
            fast = run_strategy(ctx0, "time-saving", with_fitness=False)
            if not thermal and not bool(fast.result.feasible[0]):
                at = float(fast.result.failure_m[0])
                assert any(n.from_m <= at <= n.to_m + 5000 for n in route.neutral_sections), (route.name, train.name)
                skipped += 1
                continue
            fastest = fast.summary["running_time_s"]
            ctx = make_context(route, train, RunSettings(ModelOptions(step_m=100), time_s=round(1.15 * fastest),
                                                         params=_fast_params()))
            run = run_strategy(ctx, "proposed", with_fitness=False)
            if not run.summary["punctual"]:  # the small search missed the window: the default search
                ctx = make_context(route, train, RunSettings(ModelOptions(step_m=100), time_s=round(1.15 * fastest)))
                run = run_strategy(ctx, "proposed", with_fitness=False)
            assert bool(run.result.feasible[0]) and run.summary["punctual"], (route.name, train.name, run.summary)
    return skipped


THERMAL = {"electric_rolling_stock": False, "fast_rolling_stock": True, "slow_rolling_stock": True}


@pytest.fixture(scope="module")
def osrd_trains(tmp_path_factory):
    out = tmp_path_factory.mktemp("stock")
    run_import("osrd-train", [OSRD / f"{s}.json" for s in STOCKS], out, ImportOptions())
    return [(load_train(out / "consists" / f"{s}.yaml"), THERMAL[s]) for s in STOCKS] + [(load_train("HXD1-C80x50"), False)]


@needs_osrd
def test_osrd_optimize_on_time_quick(osrd_paths, osrd_trains):
    route, _, thermal = osrd_paths[("West_station", "Mid_West_station")]
    assert _optimize_all([(route, thermal)], osrd_trains) == 0


def _station_pairs() -> list[tuple[str, str]]:
    if not INFRA.exists():
        return []
    return list(itertools.permutations([op["id"] for op in json.loads(INFRA.read_text())["operational_points"]], 2))


@pytest.mark.slow
@needs_osrd
@pytest.mark.parametrize("pair", _station_pairs(), ids="-".join)
def test_osrd_optimize_on_time_every_path(osrd_paths, osrd_trains, pair):
    """(one test per pair of stations, so that parallel workers share them; electric trains coasting 25 km of
    track without catenary, TD1, may stall there: the only failure allowed, checked in ``_optimize_all``)"""
    route, _, thermal = osrd_paths[pair]
    if not isinstance(route, Path):
        pytest.skip(f"no path: {route}")
    _optimize_all([(route, thermal)], osrd_trains)


# ------------------------------------------------------------------------------------------ rolling stock
@needs_osrd
def test_osrd_train_units_converted_exactly(tmp_path):
    run_import("osrd-train", [OSRD / f"{s}.json" for s in STOCKS], tmp_path, ImportOptions())
    for s in STOCKS:
        src = json.loads((OSRD / f"{s}.json").read_text())
        veh = load_vehicle(tmp_path / "rolling_stock" / f"{s}.yaml")
        n = yaml.safe_load((tmp_path / "consists" / f"{s}.yaml").read_text())["vehicles"][0]["count"]
        mass_t = veh.mass_t * n
        assert mass_t == pytest.approx(src["mass"] / 1000, rel=1e-12)
        assert veh.length_m * n == pytest.approx(src["length"], rel=1e-12)
        assert veh.rotating_mass_factor == src["inertia_coefficient"]
        w = mass_t * 9.81  # kN
        rr = src["rolling_resistance"]
        res = veh.resistance_n_per_kn
        for v_ms in (0.0, 10.0, 33.3, 80.0):
            v = v_ms * 3.6
            mine = (res.a + res.b * v + res.c * v * v) * w  # N
            assert mine == pytest.approx(rr["A"] + rr["B"] * v_ms + rr["C"] * v_ms ** 2, rel=1e-9)
        ec = src["effort_curves"]
        curve = ec["modes"][ec["default_mode"]]["default_curve"]
        got = np.array(veh.traction_kn)
        assert np.allclose(got[:, 0], np.array(curve["speeds"]) * 3.6, rtol=1e-9, atol=0)
        assert np.allclose(got[:, 1] * n * 1000, curve["max_efforts"], rtol=1e-9, atol=0)
        assert veh.max_speed_kmh == pytest.approx(src["max_speed"] * 3.6, rel=1e-12)
        consist = yaml.safe_load((tmp_path / "consists" / f"{s}.yaml").read_text())
        assert consist["brake_deceleration_ms2"] == src["gamma"]["value"]


def _flat_route(tmp: Path, kmh: float) -> Path:
    p = tmp / "flat.yaml"
    p.write_text("schema: locoplan/route@1\nname: flat 10 km\nlength_m: 10000\n"
                 f"speed_limits: [{{from_m: 0, to_m: 10000, kmh: {kmh}}}]\n"
                 "gradients: [{from_m: 0, to_m: 10000, permille: 0}]\n")
    return p


@needs_osrd
@pytest.mark.parametrize("stock", STOCKS)
def test_osrd_train_fastest_run_matches_an_independent_integration(tmp_path, stock):
    from scipy.integrate import quad
    from scipy.optimize import brentq

    run_import("osrd-train", [OSRD / f"{stock}.json"], tmp_path, ImportOptions())
    src = json.loads((OSRD / f"{stock}.json").read_text())
    vmax = min(src["max_speed"], 160 / 3.6)
    route = load_route(_flat_route(tmp_path, round(vmax * 3.6, 6)))
    train = load_train(tmp_path / "consists" / f"{stock}.yaml")
    run = run_strategy(make_context(route, train, RunSettings(ModelOptions(), need_time=False)), "time-saving",
                       with_fitness=False)
    got = run.summary["running_time_s"]
    # the same physics written out: M_i dv/dt = F(v) - R(v) accelerating, -(M_i gamma + R(v)) braking
    m_i = src["mass"] * src["inertia_coefficient"]
    rr, gamma = src["rolling_resistance"], src["gamma"]["value"]
    curve = src["effort_curves"]["modes"][src["effort_curves"]["default_mode"]]["default_curve"]
    force = lambda v: np.interp(v, curve["speeds"], curve["max_efforts"])  # noqa: E731
    res = lambda v: rr["A"] + rr["B"] * v + rr["C"] * v * v  # noqa: E731
    acc = lambda v: (force(v) - res(v)) / m_i  # noqa: E731
    dec = lambda v: gamma + res(v) / m_i  # noqa: E731
    s_acc = lambda v: quad(lambda u: u / acc(u), 0, v, limit=200)[0]  # noqa: E731
    s_dec = lambda v: quad(lambda u: u / dec(u), 0, v, limit=200)[0]  # noqa: E731
    length = 10000.0
    if s_acc(vmax) + s_dec(vmax) <= length:
        v_top = vmax
        t = quad(lambda u: 1 / acc(u), 0, vmax, limit=200)[0] + quad(lambda u: 1 / dec(u), 0, vmax, limit=200)[0]
        t += (length - s_acc(vmax) - s_dec(vmax)) / vmax
    else:
        v_top = brentq(lambda v: s_acc(v) + s_dec(v) - length, 0.1, vmax)
        t = quad(lambda u: 1 / acc(u), 0, v_top, limit=200)[0] + quad(lambda u: 1 / dec(u), 0, v_top, limit=200)[0]
    assert got == pytest.approx(t, rel=1e-3), (got, t, v_top)


# ------------------------------------------------------------------------------------------ railML
NS = "http://www.railml.org/schemas/2013"


def _railml_from_route(route, mileage: list[tuple[float, float, bool]] | None = None) -> str:
    """A railML 2.2 file with one track holding the route (up direction): elements at the sections' starts."""
    els = ["<speedChanges>"] + [f'<speedChange id="v{i}" pos="{x.from_m!r}" dir="up" vMax="{x.kmh!r}"/>'
                                for i, x in enumerate(route.speed_limits)] + ["</speedChanges>"]
    els += ["<gradientChanges>"] + [f'<gradientChange id="g{i}" pos="{x.from_m!r}" slope="{x.permille!r}"/>'
                                    for i, x in enumerate(route.gradients)] + ["</gradientChanges>"]
    rad = []
    for i, c in enumerate(route.curves):
        rad.append(f'<radiusChange id="r{i}a" pos="{c.from_m!r}" radius="{c.radius_m!r}"/>')
        rad.append(f'<radiusChange id="r{i}b" pos="{c.to_m!r}" radius="0"/>')
    els += ["<radiusChanges>"] + rad + ["</radiusChanges>"]
    els += ["<tunnels>"] + [f'<tunnel id="tu{i}" pos="{t.from_m!r}" length="{t.to_m - t.from_m!r}"/>'
                            for i, t in enumerate(route.tunnels)] + ["</tunnels>"]
    begin_abs, changes = "", ""
    if mileage:
        begin_abs = f' absPos="{mileage[0][1] * 1000!r}"'
        rows = []
        for k, (at, km, desc) in enumerate(mileage[1:], 1):
            pat, pkm, pdesc = mileage[k - 1]
            before = pkm * 1000 + (-1 if pdesc else 1) * (at - pat)
            rows.append(f'<mileageChange id="m{k}" pos="{at!r}" absPosIn="{before!r}" absPos="{km * 1000!r}" '
                        f'absDir="{"falling" if desc else "raising"}"/>')
        changes = "<mileageChanges>" + "".join(rows) + "</mileageChanges>"
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<railml xmlns="{NS}" version="2.2"><infrastructure id="i">'
            f'<tracks><track id="t1" name="line"><trackTopology><trackBegin id="b" pos="0"{begin_abs}>'
            f'<macroscopicNode ocpRef="A"/></trackBegin><trackEnd id="e" pos="{route.length_m!r}">'
            f'<macroscopicNode ocpRef="B"/></trackEnd>{changes}</trackTopology><trackElements>'
            + "\n".join(els) + '</trackElements></track></tracks><operationControlPoints><ocp id="A" name="Start"/>'
            '<ocp id="B" name="End"/></operationControlPoints></infrastructure></railml>\n')


def _same(a, b, key):
    xa, xb = getattr(a, key), getattr(b, key)
    if key == "curves":  # equal neighbours may come back joined: compare 1/R along the line
        cuts = sorted({x for c in xa + xb for x in (c.from_m, c.to_m)})
        mids = [(u + v) / 2 for u, v in zip(cuts, cuts[1:])]
        k = lambda cs, m: next((1 / c.radius_m for c in cs if c.from_m <= m < c.to_m), 0.0)  # noqa: E731
        assert all(k(xa, m) == pytest.approx(k(xb, m), abs=1e-12) for m in mids)
        return
    assert len(xa) == len(xb), key
    for p, q in zip(xa, xb):
        for k, v in p.model_dump().items():
            assert getattr(q, k) == pytest.approx(v, abs=1e-6), (key, k)


@pytest.mark.parametrize("name", ["freight-20km.yaml", "heavy-haul-60km.yaml", "real/CH_StGallen_Wil.yaml"])
@pytest.mark.parametrize("mileage", [False, True])
def test_railml_round_trip_of_shipped_routes(tmp_path, name, mileage):
    route = load_route(ROOT / "routes" / name)
    posts = [(0.0, 12.5, False), (round(route.length_m / 3, 3), 40.0, True)] if mileage else None
    src = tmp_path / "line.xml"
    src.write_text(_railml_from_route(route, posts))
    for args in ({"tracks": ("t1",)}, {"from_station": "Start", "to_station": "End"}):
        out = tmp_path / ("o" + str(len(args)))
        report = run_import("railml", [src], out, ImportOptions(**args))
        back = load_route(report.written[0][0])
        assert back.length_m == pytest.approx(route.length_m, abs=1e-6)
        for key in ("speed_limits", "gradients", "curves", "tunnels"):
            _same(route, back, key)
        if mileage:
            got = [(c.at_m, c.km, c.descending) for c in back.mileage()]
            assert got == [(pytest.approx(p[0], abs=1e-6), pytest.approx(p[1], abs=1e-9), p[2]) for p in posts]
        else:
            assert back.chainage is None


RAILML_22 = ROOT / "tests" / "data" / "railml" / "two-categories.xml"


def test_railml_train_category_picks_its_limit(tmp_path):
    for cat, expected in ((None, [(0, 3000, 120), (3000, 5500, 100), (5500, 8000, 60)]),
                          ("freight", [(0, 3000, 80), (3000, 5500, 100), (5500, 8000, 60)])):
        out = tmp_path / str(cat)
        run_import("railml", [RAILML_22], out, ImportOptions(from_station="Alpha", to_station="Charlie", category=cat))
        r = load_route(out / "ocpA-ocpC.yaml")
        assert [(x.from_m, x.to_m, x.kmh) for x in r.speed_limits] == expected, cat
    # the other way: the down-direction limit, slopes negated and mirrored, kilometre posts counting the other way
    run_import("railml", [RAILML_22], tmp_path / "down", ImportOptions(from_station="Charlie", to_station="Alpha"))
    r = load_route(tmp_path / "down" / "ocpC-ocpA.yaml")
    assert [x.kmh for x in r.speed_limits] == [90]
    assert [(g.from_m, g.permille) for g in r.gradients if g.permille] == [(3000, 3), (6000, -5.5)]
    assert [(c.at_m, c.km, c.descending) for c in r.mileage()] == [(0, 38, False), (2000, 18, True)]


BOMB = """<?xml version="1.0"?>
<!DOCTYPE railml [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;"><!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">
<!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;"><!ENTITY e "&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;"><!ENTITY f "&e;&e;&e;&e;&e;&e;&e;&e;&e;&e;">
<!ENTITY g "&f;&f;&f;&f;&f;&f;&f;&f;&f;&f;"><!ENTITY h "&g;&g;&g;&g;&g;&g;&g;&g;&g;&g;"><!ENTITY i "&h;&h;&h;&h;&h;&h;&h;&h;&h;&h;">]>
<railml version="2.2"><infrastructure id="x"><tracks><track id="&i;"/></tracks></infrastructure></railml>
"""
EXTERNAL = """<?xml version="1.0"?>
<!DOCTYPE railml [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>
<railml version="2.2"><infrastructure id="x"><tracks><track id="t" name="&xxe;"/></tracks></infrastructure></railml>
"""


@pytest.mark.parametrize("text", [BOMB, EXTERNAL], ids=["entity-bomb", "external-entity"])
def test_railml_entities_are_refused_fast(tmp_path, text):
    src = tmp_path / "evil.xml"
    src.write_text(text)
    t = time.perf_counter()
    res = _invoke(["import", "railml", str(src), "--track", "t", "--out", str(tmp_path / "o")])
    assert time.perf_counter() - t < 1.0
    assert res.exit_code == 2 and "DOCTYPE" in res.stderr and "passwd" not in res.stdout
    assert not (tmp_path / "o").exists()


def test_railml_errors_name_element_and_line(tmp_path):
    text = RAILML_22.read_text().replace('vMax="100"', 'vMax="fast"')
    src = tmp_path / "bad.xml"
    src.write_text(text)
    line = next(i for i, ln in enumerate(text.splitlines(), 1) if 'vMax="fast"' in ln)
    res = _invoke(["import", "railml", str(src), "--from", "Alpha", "--to", "Charlie", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and f"bad.xml:{line}: speedChange@vMax[id=sc3]: speed limit vMax [km/h] must be a number" in res.stderr
    res = _invoke(["import", "railml", str(RAILML_22), "--track", "t1", "--from", "Alpha", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "one of the two" in res.stderr
    res = _invoke(["import", "railml", str(RAILML_22), "--track", "t2", "--track", "t9", "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "no track 't9'" in res.stderr
