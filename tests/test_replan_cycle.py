"""Re-planning where the air brake cycles (the cycle DP's look-up from the brake's state) and inside a journey's leg.

Oracles: the cycle DP's departure drive (a re-plan from a state on it, in the brake's state the drive has there,
gives back its remainder), the consist's recharge time (after a release no application comes before it is over),
the same state with the brake charged (the recharge binds there: that drive applies sooner, so the check can fail),
the route's limits; for journeys, ``locoplan journey``'s own allocation (each leg's running time, the clock at every
stop) and the stop's window.
"""

from __future__ import annotations

import json
from functools import lru_cache

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan import api
from locoplan.cli import app
from locoplan.io.load import load_route, load_train
from locoplan.optimize.replan import TOO_FAST_KMH, Replanner, TrainState
from locoplan.sim.calculator import ModelOptions, TractionCalculator, limit_kmh_at

runner = CliRunner()
LINES = {
    "heavy-haul-60km": ("routes/heavy-haul-60km.yaml", "configs/consists/HXD1x2-C80x100.yaml"),
    "falling-drops-37km": ("tests/data/routes/falling-drops-37km.yaml", "configs/consists/HXD1-C80x50.yaml"),
}


@pytest.fixture(autouse=True)
def _in_repo(root, monkeypatch):
    monkeypatch.chdir(root)


@lru_cache(maxsize=None)
def _setup(line: str):
    route, consist = LINES[line]
    r = load_route(route)
    train = load_train(consist)
    opts = ModelOptions()
    if r.schedule is not None:
        t0, tol = float(r.schedule.run_time_s), float(r.schedule.tolerance_s)
    else:
        t0 = round(1.15 * TractionCalculator(r, train, opts).fastest_time_s)
        tol = api.punctuality_tolerance(r, t0, None)
    rp = Replanner(r, train, opts, planned_s=t0, tolerance_s=tol)
    plan = rp.replan(TrainState(0.0, 0.0, 0.0))
    return r, train, opts, rp, plan


def _air_at(plan, t_s: float, t_rec: float) -> tuple[str, float | None]:
    """The brake's state on the drive at clock ``t_s`` from its events: applied after an application, recharging
    (and the time left) within the recharge after a release, else charged."""
    before = [e for e in plan.air_events if e[1] <= t_s + 1e-9 and e[3] != "charged"]
    if not before:
        return "charged", None
    last = before[-1]
    if last[3] == "apply":
        return "applied", None
    left = t_rec - (t_s - last[1])
    return ("recharging", left) if left > 1e-6 else ("charged", None)


@pytest.mark.parametrize("line", list(LINES))
def test_the_cycle_binds_and_the_replanner_tracks_it(line):
    r, train, opts, rp, plan = _setup(line)
    assert rp.cyc is not None and not rp.cycle_relaxed
    assert plan.on_time
    assert any(e[3] == "release" and e[0] < r.length_m - 1.0 for e in plan.air_events)  # (a cycle on the way)
    lim = np.minimum(limit_kmh_at(r, plan.s_m, train.length_m if opts.strip else None), train.max_speed_kmh)
    assert np.all(plan.v_kmh <= lim + TOO_FAST_KMH)


@pytest.mark.parametrize("line", list(LINES))
def test_replans_along_the_cycle_drive_give_back_its_remainder(line):
    """20 nodes of the departure drive where it records its energy, each state with the drive's speed, clock and
    the brake's state there, aimed at its arrival: time within 0.5 s, energy within 0.5 % of the remainder."""
    r, train, opts, rp, plan = _setup(line)
    t_rec = rp.cyc.t_rec
    ok = np.flatnonzero(np.isfinite(plan.energy_kwh[1:-1])) + 1
    idx = ok[np.linspace(0, len(ok) - 1, 20).round().astype(int)]
    states = {"charged": 0, "applied": 0, "recharging": 0}
    for i in idx:
        s, v, t = float(plan.s_m[i]), float(plan.v_kmh[i]), float(plan.t_s[i])
        air, left = _air_at(plan, t, t_rec)
        states[air] += 1
        q = rp.replan(TrainState(s, v, t, None, air, left), plan.arrival_s)
        rest = plan.remaining_energy_kwh - float(plan.energy_kwh[i])
        assert q.arrival_s == pytest.approx(plan.arrival_s, abs=0.5), (s, air)
        assert q.remaining_energy_kwh == pytest.approx(rest, rel=0.005, abs=0.01), (s, air)
    assert states["charged"] > 0


@pytest.mark.parametrize("line", list(LINES))
def test_a_replan_just_after_a_release_waits_for_the_recharge(line):
    """From every release of the departure drive (1 m on, the brake recharging since the release), the re-plan
    applies no air brake before the recharge is over; on heavy-haul-60km, from the same states with the brake
    charged, some drive applies sooner (the recharge binds there)."""
    r, train, opts, rp, plan = _setup(line)
    t_rec = rp.cyc.t_rec
    releases = [e for e in plan.air_events if e[3] == "release" and e[0] < r.length_m - 10.0]
    assert releases
    sooner = 0
    for x, t, v, _ in releases:
        dt = 1.0 / (v / 3.6)
        t += dt
        q = rp.replan(TrainState(x + 1.0, v, t, None, "recharging", t_rec - dt), plan.arrival_s)
        applies = [e[1] for e in q.air_events if e[3] == "apply"]
        assert all(a >= t - dt + t_rec - 1e-6 for a in applies), (x, applies[:1])
        assert np.isfinite(q.arrival_s)
        c = rp.replan(TrainState(x + 1.0, v, t, None, "charged"), plan.arrival_s)
        sooner += any(e[1] < t - dt + t_rec - 1.0 for e in c.air_events if e[3] == "apply")
    if line == "heavy-haul-60km":  # (there the recharge binds: every cycle applies again as soon as it may)
        assert sooner > 0


def test_air_state_options_are_checked():
    base = ["replan", "routes/freight-20km.yaml", "--at-m", "5000", "--speed-kmh", "60", "--elapsed-s", "400"]
    for extra, word in ((["--air", "recharging"], "--recharge-left-s"), (["--air", "half"], "--air"),
                        (["--recharge-left-s", "10"], "--recharge-left-s"),
                        (["--air", "recharging", "--recharge-left-s", "600"], "recharge takes"),
                        (["--air", "applied", "--no-air-brake"], "no air brake")):
        res = runner.invoke(app, [*base, *extra])
        assert res.exit_code == 2, (extra, res.output)
        assert word in res.output, (extra, res.output)
    res = runner.invoke(app, [*base, "--air", "recharging", "--recharge-left-s", "30", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["state"]["air"] == "recharging" and d["state"]["recharge_left_s"] == 30
    assert all(e["t_s"] >= 430 - 1e-6 for e in d["air_events"] if e["kind"] == "apply")
    assert "air_brake" not in d  # (tracked: no note)


def test_air_state_in_the_stream():
    lines = ['{"s_m": 5000, "v_kmh": 60, "t_s": 400, "air": "recharging", "recharge_left_s": 40}',
             '{"s_m": 5000, "v_kmh": 60, "t_s": 400, "air": "recharging"}',
             '{"s_m": 5000, "v_kmh": 60, "t_s": 400, "air": "on"}',
             '{"s_m": 5000, "v_kmh": 60, "t_s": 400, "recharge_left_s": "ten"}']
    res = runner.invoke(app, ["replan", "routes/freight-20km.yaml", "--stream"], input="\n".join(lines) + "\n")
    assert res.exit_code == 2
    out = [json.loads(x) for x in res.stdout.splitlines()]
    assert [o["exit_code"] for o in out] == [0, 2, 2, 2]
    assert all(e["t_s"] >= 440 - 1e-6 for e in out[0]["air_events"] if e["kind"] == "apply")
    assert "recharge_left_s" in " ".join(out[1]["errors"])
    assert "air" in " ".join(out[2]["errors"])


JOURNEY = "routes/journeys/CN_Songjiazhuang_Yizhuang-journey.yaml"


@lru_cache(maxsize=None)
def _journey_clock() -> list[float]:
    """The journey's plan (``locoplan journey``'s allocation, ``runs.journey.allocate``): the clock at each leg's
    stop (its running times plus the dwells before it)."""
    from locoplan.io.load import load_journey
    from locoplan.runs.journey import allocate, dwell_before, legs_of, total_running_time

    j, line = load_journey(JOURNEY)
    train = load_train("configs/consists/HXD1-C80x50.yaml")
    legs = legs_of(j, line, train, ModelOptions())
    times, at = allocate(j, legs, train, ModelOptions(), total_running_time(j, None, JOURNEY))
    return [float(at[leg.last]) + dwell_before(j, leg.last) for leg in legs]


def test_a_replan_inside_a_journeys_leg_keeps_the_next_stops():
    """A state inside the fourth leg (stop 4 at 6,272 m - stop 5 at 8,254 m), 130 s after its planned departure at
    40 km/h: the leg re-planned to its stop, arriving inside the window around the journey's planned clock there,
    the plan and the switches inside the leg, and every later stop's planned clock given as kept."""
    clock = _journey_clock()
    k = 3
    res = runner.invoke(app, ["replan", JOURNEY, "--at-m", "7000", "--speed-kmh", "40", "--elapsed-s",
                              f"{clock[k - 1] + 130:.1f}", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    leg = d["leg"]
    assert leg["leg"] == k + 1 and leg["from"] == "stop 4" and leg["to"] == "stop 5" and leg["stop_m"] == 8254
    assert leg["planned_arrival_s"] == pytest.approx(clock[k], abs=0.5)
    lo, hi = d["window_s"]
    assert lo <= leg["arrival_s"] <= hi and d["on_time"] and leg["inside_stop_window"]
    assert [x["name"] for x in d["next_stops"]] == [f"stop {i}" for i in range(6, 15)]
    for x, c in zip(d["next_stops"], clock[k + 1:]):
        assert x["kept"] and x["planned_arrival_s"] == pytest.approx(c, abs=0.5)
    assert 7000 <= (d["next_switch_m"] or 8254) <= 8254
    assert all(7000 - 1e-6 <= float(p.split(":")[1]) <= 8254 for p in d["plan"].split(",") if ":" in p)
    # a state at the stop that starts the leg, at rest, on its planned departure: the leg as planned
    res = runner.invoke(app, ["replan", JOURNEY, "--at-m", "6272", "--speed-kmh", "0", "--elapsed-s",
                              f"{clock[k - 1]:.1f}", "--json"])
    d = json.loads(res.stdout)
    assert res.exit_code == 0 and d["leg"]["leg"] == k + 1
    assert d["arrival_s"] == pytest.approx(clock[k], abs=max(d["window_s"][1] - clock[k], 0.5))


@pytest.mark.parametrize("line", list(LINES))
def test_a_switch_probed_from_a_nodes_state_is_the_whole_drive(line):
    """A re-plan places the switch from the faster price to the slower by probing drives that go on from the faster
    drive's state at a node it decides at (``CycleReplanner.drive_on``): each probe's arrival equals that of the
    whole drive with the switch at that node, run from the train's state (to 1e-6 s), at every such node tried, from
    states along and beside the departure drive, in every air state the drive has there."""
    r, train, opts, rp, plan = _setup(line)
    cy = rp.cyc
    n, P = cy.n, len(rp.prices)
    rng = np.random.default_rng(3)
    checked = 0
    for i in rng.choice(len(plan.s_m) - 1, size=8, replace=False):
        st = TrainState(float(plan.s_m[i]), 0.95 * float(plan.v_kmh[i]), float(plan.t_s[i]), None,
                        *_air_at(plan, float(plan.t_s[i]), cy.t_rec))
        k0 = min(max(int(np.searchsorted(cy.s_nodes, st.s_m, side="right")) - 1, 0), n - 1)
        x0 = max(float(st.s_m - cy.s_nodes[k0]), 0.0)
        e0 = (st.v_kmh / 3.6) ** 2 / 2
        s0, tau0 = cy.air_state(st)
        hi = int(rng.integers(1, P))
        if not np.isfinite(cy.drive(k0, x0, e0, s0, tau0, hi, hi, n)[0]):
            continue
        t_fast, nodes = cy.t.copy(), cy.nodes.copy()
        decides = np.flatnonzero(nodes[k0 + 1:n, 0] >= 0.0) + k0 + 1
        for k in rng.choice(decides, size=min(3, len(decides)), replace=False):
            t_on, w_on = cy.drive_on(int(k), (nodes[k], t_fast[k]), hi - 1)
            whole = cy.drive(k0, x0, e0, s0, tau0, hi, hi - 1, int(k))[0]
            assert t_fast[k] + t_on == pytest.approx(whole, abs=1e-6) or not (np.isfinite(t_on) or np.isfinite(whole))
            checked += 1
    assert checked >= 12
