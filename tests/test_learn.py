"""Seed 004: driver logs, the driver simulator, segmentation, the pattern layers and the advice.

Small on purpose: a 6 km test line (tests/data/learn/line-6km.yaml), a handful of simulated drivers.
"""

import datetime as dt
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.errors import InputError
from locoplan.io.load import build_train, load_consist, load_route
from locoplan.learn.advise import advise
from locoplan.io.logs import load_logs, read_log_csv
from locoplan.io.patterns import read_patterns_file
from locoplan.learn.drivers import SimulationSpec, consist_for_mass
from locoplan.model.logs import LogData
from locoplan.reporting.logs import log_csv_text, manifest_text, simulate_drivers
from locoplan.learn.patterns import (LOWER_FEATURES, LearnSettings, Patterns, good_drivers, learn, line_model,
                                     select_order)
from locoplan.learn.segments import classify_gradient, equivalent_gradient_pieces, segment_route
from locoplan.physics.units import G_MS2
from locoplan.physics.resistance import train_resistance_kn
from locoplan.physics.traction import max_force_kn
from locoplan.sim.calculator import ModelOptions, TractionCalculator

ROOT = Path(__file__).resolve().parents[1]
LINE = ROOT / "tests/data/learn/line-6km.yaml"
BAD = ROOT / "tests/data/bad_logs"
runner = CliRunner()
SMALL = dict(divisions=4, max_order=2, folds=3)


@pytest.fixture(scope="module")
def base():
    consist, vehicles, files, _, _ = load_consist(ROOT / "configs/consists/HXD1-C80x50.yaml")
    return consist, vehicles, files


def train_of(base, mass):
    return build_train(consist_for_mass(base[0], base[1], mass), base[1])


@pytest.fixture(scope="module")
def sim_logs(tmp_path_factory, base):
    """6 drivers x 1 run x 2 masses x 2 times on the 6 km line, seed 1."""
    out = tmp_path_factory.mktemp("sim") / "logs"
    spec = SimulationSpec(LINE, load_route(LINE), *base, masses_t=(3200, 4200), times_s=(520, 560), n_drivers=6,
                          n_runs=1, seed=1)
    summary = simulate_drivers(spec, out)
    return out, summary


@pytest.fixture(scope="module")
def learned(sim_logs):
    return learn(load_logs(sim_logs[0]), LearnSettings(**SMALL), ModelOptions())


# ------------------------------------------------------------------------------------------ log format
def test_log_round_trip_and_energy_by_hand(tmp_path):
    data = LogData(np.array([0.0, 1.0, 2.0, 3.0]), np.array([0.0, 0.5, 2.0, 4.0]), np.array([0.0, 3.6, 7.2, 7.2]),
                   np.array([720.0, 360.0, -100.0, 0.0]), np.array([8, 4, -1, 0]), np.array(["T", "T", "B", "C"]))
    path = tmp_path / "r.csv"
    path.write_text(log_csv_text(data))
    back = read_log_csv(path)
    assert np.allclose(back.position_m, data.position_m) and list(back.action) == ["T", "T", "B", "C"]
    # sum F+ ds, each row's force held until the next row: 720 * 0.5 + 360 * 1.5 = 900 kJ
    assert back.traction_energy_kwh == pytest.approx(900.0 / 3600.0)
    assert back.running_time_s == 3.0


def test_a_real_log_without_optional_columns_loads_unchanged(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("time_s,position_m,speed_kmh,force_kn\n0,0,0,500\n2.5,1.1,3.2,480.5\n5,4.4,6.1,0\n")
    d = read_log_csv(path)
    assert d.notch is None and d.action is None and d.time_s.tolist() == [0, 2.5, 5]


@pytest.mark.parametrize("case, where, why", [
    ("missing_column", "run.csv:1: header", "required column 'speed_kmh' is missing"),
    ("non_monotone", "run.csv:5: column 2 (position_m)", "positions are not monotone: 1.2 m is behind the previous row's 1.5 m"),
    ("mph", "run.csv:1: column 3 (speed_mph)", "units in mph are not accepted"),
    ("missing_route", "manifest.yaml:3: route", "no such route file: ../../learn/no-such-line.yaml"),
])
def test_bad_logs_exit_2_with_file_line_column_and_nothing_written(case, where, why, tmp_path):
    out = tmp_path / "patterns.json"
    res = runner.invoke(app, ["learn", str(BAD / case), "--out", str(out), "--plot", str(tmp_path / "fit.png")])
    assert res.exit_code == 2, res.output
    assert f"{BAD / case}/{where}" in res.output.replace("\n", "") and why in res.output.replace("\n", "")
    assert "Traceback" not in res.output
    assert list(tmp_path.iterdir()) == []  # no patterns, no plot, no temporary file


def test_bad_csv_cells_are_named_by_line_and_column(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("time_s,position_m,speed_kmh,force_kn,action\n0,0,0,0,T\n1,x,1,0,T\n2,2,-1,0,Q\n2,3,1,0\n")
    with pytest.raises(InputError) as exc:
        read_log_csv(path)
    text = [str(p) for p in exc.value.problems]
    assert f"{path}:3: column 2 (position_m): not a number: 'x'" in text
    assert f"{path}:4: column 3 (speed_kmh): speed must be >= 0 km/h (got -1)" in text
    assert f"{path}:4: column 5 (action): 'Q' is not one of T, K, C, B" in text
    assert f"{path}:5: row: 4 fields, the header has 5" in text


def test_manifest_mass_must_match_the_consist(tmp_path):
    (tmp_path / "r.csv").write_text("time_s,position_m,speed_kmh,force_kn\n0,0,0,0\n1,6000,1,0\n")
    (tmp_path / "manifest.yaml").write_text(manifest_text({
        "schema": "locoplan/driver-logs@1", "route": str(LINE), "consist": "HXD1-C80x50", "synthetic": False,
        "runs": [{"log": "r.csv", "driver_id": "A", "mass_t": 4000, "scheduled_time_s": 1, "actual_time_s": 1,
                  "date": dt.date(2024, 1, 1)}]}))
    with pytest.raises(InputError) as exc:
        load_logs(tmp_path)
    assert "runs[0].mass_t: 4000 t disagrees with the consist 'HXD1 + 50 x C80 (5200 t)'" in str(exc.value)


@pytest.mark.slow
def test_a_log_set_keeps_summaries_and_reads_the_rows_again_as_checked(sim_logs, tmp_path):
    """A log set holds each run's summary, not its rows: ``data`` reads the log again, the same rows as read
    and checked first; a log whose content changed since is refused (file named), not used unchecked."""
    import shutil

    from locoplan.io.logs import LogFile

    out = tmp_path / "logs"
    shutil.copytree(sim_logs[0], out)
    runs = load_logs(out)
    run = runs[0]
    assert isinstance(run.read, LogFile) and "data" not in vars(run)  # no rows held
    first = read_log_csv(run.log_file)
    again = run.data
    assert all(np.array_equal(getattr(again, c), getattr(first, c)) for c in ("time_s", "position_m", "speed_kmh",
                                                                              "force_kn", "notch", "action"))
    assert run.running_time_s == first.running_time_s and run.traction_energy_kwh == first.traction_energy_kwh
    text = run.log_file.read_text()
    run.log_file.write_text(text.replace("\n2.0,", "\n2.00,", 1))  # the same numbers, other bytes: changed all the same
    with pytest.raises(InputError) as exc:
        run.data  # noqa: B018 (reading the property is the check)
    assert f"{run.log_file}: changed while locoplan was using it" in str(exc.value)


# ------------------------------------------------------------------------------------------ simulator
def test_consist_for_mass_uses_the_train_model(base):
    c = consist_for_mass(base[0], base[1], 3700)
    train = build_train(c, base[1])
    assert train.mass_t == pytest.approx(3700.0)
    assert c.vehicles[1].count == 35 and c.vehicles[1].load_t == pytest.approx(80.0)
    c2 = consist_for_mass(base[0], base[1], 3650)  # 35 wagons, load trimmed to 78.57 t
    assert build_train(c2, base[1]).mass_t == pytest.approx(3650.0) and c2.vehicles[1].count == 35


@pytest.mark.slow
def test_simulated_runs_are_physical_arrive_and_keep_the_limits(sim_logs, base):
    out, summary = sim_logs
    runs = load_logs(out)
    assert len(runs) == summary.n_runs == 24 and all(r.synthetic for r in runs)
    manifest = (out / "manifest.yaml").read_text()
    assert "synthetic: true" in manifest and "seed: 1" in manifest and "SYNTHETIC" in manifest
    route = load_route(LINE)
    for r in runs:
        d = r.data
        calc = TractionCalculator(route, r.train)
        assert d.position_m[0] == 0 and d.speed_kmh[0] == 0
        assert d.position_m[-1] == pytest.approx(route.length_m, abs=1e-6) and d.speed_kmh[-1] == 0  # arrived, at rest
        moving = (d.position_m > 1.0) & (d.position_m < route.length_m - 1.0)
        assert np.all(d.speed_kmh[moving] > 0)  # never stalled on the way
        cell = np.clip(np.searchsorted(calc.s_m, d.position_m, side="right") - 1, 0, len(calc.limit_kmh) - 1)
        assert np.all(d.speed_kmh <= calc.limit_kmh[cell] + 0.1)  # the limit, train-length aware
        # the log is consistent with itself: distance = mean speed x time in every step (1 %)
        ds = np.diff(d.position_m)
        dt_ = np.diff(d.time_s)
        v_mean = 0.5 * (d.speed_kmh[:-1] + d.speed_kmh[1:]) / 3.6
        assert np.sum(np.abs(ds - v_mean * dt_)) < 0.01 * route.length_m
        # traction energy at least what the work against resistance and gravity needs (a lower bound)
        assert r.traction_energy_kwh > 0.5 * float(np.sum(calc.h_m * (train_resistance_kn(20.0, r.train.resistance_kn)
                                                                       + np.maximum(calc.gravity_kn, 0)))) / 3600
    late = np.array([abs(r.running_time_s - r.scheduled_time_s) for r in runs])
    assert np.mean(late <= 15.0) >= 0.75  # most within the line's tolerance (some drivers cannot make a tight time)
    e = np.array([r.traction_energy_kwh for r in runs if r.mass_t == 4200 and r.scheduled_time_s == 520])
    assert e.max() / e.min() > 1.05  # good and wasteful drivers differ


@pytest.mark.slow
def test_every_simulated_log_reads_back_even_a_creeping_arrival(base):
    """400 runs of random drivers and cruise speeds on the 6 km line, each log written and read back: every
    one reads (time rises at the 0.1 s the log writes). Among them (seed 0) trains that creep their last
    metre or more at under 0.01 km/h; such an arrival could take 0.05 s, its last two rows had one time, and
    learn refused the log: the arrival step is at least ``MIN_ARRIVAL_S``, and one of them takes exactly
    that. (Which seeds creep depends on how the calculator brakes the line's last limit drop: the assertion
    that the case is there keeps the test honest.)"""
    from locoplan.learn.drivers import MIN_ARRIVAL_S, SpeedNoise, draw_drivers, route_tables, simulate_runs

    from locoplan.io.load import load_train

    calc = TractionCalculator(load_route(LINE), load_train(ROOT / "configs/consists/HXD1-C80x50.yaml"))
    rng = np.random.default_rng(0)
    p = draw_drivers(400, rng)
    cruise = rng.uniform(40, 80, 400)
    out = simulate_runs(calc, route_tables(calc), p, cruise, SpeedNoise(rng, p.noise_kmh, 1500, 400).block(0), 1500.0,
                        record=True)
    assert not any(out.failure)
    for i, log in enumerate(out.logs):
        path = Path(f"run{i}.csv")
        back = read_log_csv(path, log_csv_text(log))
        assert back.time_s[-1] == pytest.approx(log.time_s[-1], abs=0.05)
    last_steps = np.array([log.time_s[-1] - log.time_s[-2] for log in out.logs])
    creeping = [log for log in out.logs if log.position_m[-1] - log.position_m[-2] > 1.0 and log.speed_kmh[-2] < 0.01]
    assert creeping and last_steps.min() == pytest.approx(MIN_ARRIVAL_S)  # the case is here, and its step bounded


@pytest.mark.slow
def test_simulator_same_seed_same_logs_other_seed_differs(sim_logs, tmp_path, base):
    out, _ = sim_logs
    spec = SimulationSpec(LINE, load_route(LINE), *base, masses_t=(3200, 4200), times_s=(520, 560), n_drivers=6,
                          n_runs=1, seed=1)
    again = tmp_path / "again"
    simulate_drivers(spec, again)
    for f in ("manifest.yaml", "logs/D03-m4200-t560-r1.csv", "drivers.csv"):
        assert (again / f).read_bytes() == (out / f).read_bytes()
    other = tmp_path / "other"
    simulate_drivers(SimulationSpec(LINE, load_route(LINE), *base, masses_t=(3200,), times_s=(520,), n_drivers=6,
                                    n_runs=1, seed=2), other)
    assert (other / "logs/D03-m3200-t520-r1.csv").read_bytes() != (out / "logs/D03-m3200-t520-r1.csv").read_bytes()


@pytest.mark.slow
def test_simulator_in_blocks_writes_the_same_logs(sim_logs, tmp_path, base, monkeypatch):
    """The runs searched and recorded a few at a time (the memory bound at 20,000 logs) give the logs of one
    search over all runs: the stopping rule stays shared, so blocks that converge early take the steps of
    the slowest block (checked to happen here), and the noise is the same stream drawn block by block."""
    import locoplan.learn.drivers as drivers

    out, _ = sim_logs
    n_steps = math.ceil(3.0 * 560 * 1.05)  # about the run's: the blocks hold a few runs each
    monkeypatch.setattr(drivers, "BLOCK_BYTES", 5 * 8 * n_steps)
    monkeypatch.setattr(drivers, "RECORD_BYTES_PER_STEP", 16)
    done_after: dict[int, int] = {}  # block -> steps after which it had converged (else it takes them all)
    searching = drivers._Search.searching

    def counted(self):
        still = searching(self)
        done_after.setdefault(id(self), drivers.CALIBRATION_STEPS)
        if not still:
            done_after[id(self)] = min(done_after[id(self)], self.steps)
        return still
    monkeypatch.setattr(drivers._Search, "searching", counted)
    blocks = tmp_path / "blocks"
    # the first mass of the fixture's spec: its runs come first from the same generator
    simulate_drivers(SimulationSpec(LINE, load_route(LINE), *base, masses_t=(3200,), times_s=(520, 560), n_drivers=6,
                                    n_runs=1, seed=1), blocks)
    steps_taken = list(done_after.values())
    assert len(steps_taken) >= 3 and len(set(steps_taken)) > 1, steps_taken
    logs = sorted(p.name for p in (blocks / "logs").iterdir())
    assert len(logs) == 12 and logs == sorted(p.name for p in (out / "logs").iterdir() if "-m3200-" in p.name)
    for name in logs:
        assert (blocks / "logs" / name).read_bytes() == (out / "logs" / name).read_bytes(), name
    assert (blocks / "drivers.csv").read_bytes() == (out / "drivers.csv").read_bytes()


def test_speed_noise_block_by_block_is_one_draw():
    from locoplan.learn.drivers import SpeedNoise

    sigma = np.linspace(0.4, 2.0, 7)
    whole = SpeedNoise(np.random.default_rng(3), sigma, 50, 7)
    rng = np.random.default_rng(3)
    parts = SpeedNoise(rng, sigma, 50, 3)
    assert len(parts.blocks) == 3
    assert np.array_equal(np.vstack([parts.block(b) for b in (2, 0, 1)][1:] + [parts.block(2)]), whole.block(0))
    assert rng.standard_normal() == np.random.default_rng(3).standard_normal(7 * 50 + 1)[-1]  # advanced past the draw


@pytest.mark.slow
def test_a_manifest_of_thousands_of_runs_is_read(tmp_path):
    """drivers simulate writes up to 20,000 runs into one manifest (15 values each): more values than any route
    may hold (100,000), so manifests have a bound of their own; 7,000 runs (105,000 values) are read."""
    from locoplan.io.logs import _yaml_entries

    runs = [{"log": f"logs/D01-m5200-t520-r{i}.csv", "driver_id": "D01", "consist": "consists/m5200.yaml",
             "mass_t": 5200.0, "scheduled_time_s": 520.0, "actual_time_s": 521.0, "date": dt.date(2024, 1, 1)}
            for i in range(7000)]
    path = tmp_path / "manifest.yaml"
    path.write_text(manifest_text({"schema": "locoplan/driver-logs@1", "route": "route.yaml", "synthetic": True,
                                   "runs": runs}))
    model, _ = _yaml_entries(path)
    assert len(model.runs) == 7000


def test_drivers_simulate_refuses_a_used_folder(tmp_path):
    (tmp_path / "old.txt").write_text("x")
    res = runner.invoke(app, ["drivers", "simulate", str(LINE), "--out", str(tmp_path), "--drivers", "2", "--runs", "1"])
    assert res.exit_code == 2 and "exists and is not an empty folder" in res.output
    assert [p.name for p in tmp_path.iterdir()] == ["old.txt"]


# ------------------------------------------------------------------------------------------ segmentation
def test_segment_types_follow_claim_4_physics(base):
    train = train_of(base, 5200)
    v = 60.0
    r = float(train_resistance_kn(v, train.resistance_kn))
    weight = train.mass_t * G_MS2 / 1000  # kN per per mille
    up = (float(max_force_kn(v, train.traction_speed_kmh, train.traction_kn)) - r) / weight  # full traction balances
    down = -(float(max_force_kn(v, train.electric_brake_speed_kmh, train.electric_brake_kn)) + r) / weight
    assert classify_gradient(train, up + 0.01, v) == "steep-up" and classify_gradient(train, up - 0.01, v) == "gentle-up"
    assert classify_gradient(train, down - 0.01, v) == "steep-down" and classify_gradient(train, down + 0.01, v) == "gentle-down"
    assert classify_gradient(train, 2.0, v) == "level" and classify_gradient(train, -2.01, v) == "gentle-down"
    assert 9 < up < 13 and -12 < down < -9  # HXD1 + 50 C80 at 60 km/h


def test_equivalent_gradient_has_claim_6_curve_and_tunnel_terms(base):
    train = train_of(base, 4200)  # 515.2 m long; the 300 m curve is shorter, the 400 m tunnel adds 0.052
    x, g = equivalent_gradient_pieces(load_route(LINE), train.length_m)
    at = lambda s: float(g[np.searchsorted(x, s, side="right") - 1])  # noqa: E731
    assert at(1700) == pytest.approx(6.0 + 0.00013 * 400)
    assert at(2600) == pytest.approx(-5.0 + 600 * 300 / (800 * train.length_m))
    assert at(2500 + train.length_m + 10) == pytest.approx(-5.0)
    secs = segment_route(load_route(LINE), train)
    assert [s.kind for s in secs] == ["level", "gentle-up", "gentle-down", "level", "gentle-down", "level"]
    assert secs[2].gradient_permille == pytest.approx((-5.0 * 1200 + 600 * 300 / 800) / 1200)


# ------------------------------------------------------------------------------------------ learning
def _joined_design(layer, X, kinds):
    """The design matrix as its columns joined, the plain way (what PolyLayer.design fills in place)."""
    from locoplan.learn.segments import SECTION_TYPES

    Z = (np.clip(X, layer.low, layer.high) - layer.mean) / layer.std
    onehot = np.array([[1.0 if k == t else 0.0 for t in SECTION_TYPES] for k in kinds])
    cols = [np.ones((len(Z), 1)), onehot] + [Z ** (2 * i - 1) for i in range(1, layer.order + 1)]
    j = layer.features.index(layer.interact)
    return np.hstack(cols + [Z[:, [j]] * np.delete(Z, j, axis=1)])


def test_layers_in_place_and_in_blocks_give_the_plain_numbers_bit_for_bit(monkeypatch):
    """learn never holds more than one block of a design matrix (20,000 logs make 800,000 rows): filled in
    place, each section type's rows made again rather than copied, predictions a block of rows at a time.
    A fit in one block gives the plain computation's numbers exactly, not within a tolerance; predictions
    are the same in blocks of any size."""
    import locoplan.learn.patterns as patterns
    from locoplan.learn.patterns import PolyLayer, fit_layer
    from locoplan.learn.segments import SECTION_TYPES

    rng = np.random.default_rng(4)
    n = 3001
    X = rng.normal(size=(n, len(LOWER_FEATURES))) * rng.uniform(1, 300, len(LOWER_FEATURES))
    kinds = list(rng.choice(SECTION_TYPES[:4], n))  # one type absent: it keeps the pooled coefficients
    y = rng.normal(size=n)
    for order in (1, 3, 4):
        layer = fit_layer(X, kinds, y, order, LOWER_FEATURES, "position", by_type=True)
        A = _joined_design(layer, X, kinds)
        assert layer.block_rows() > n and np.array_equal(layer.design(X, kinds), A)
        # the fit, as it was: the pooled fit, then each type's rows of the one matrix, shrunk towards it
        penalty = np.full(A.shape[1], patterns.RIDGE * n)
        penalty[0] = 0.0
        pooled = np.linalg.solve(A.T @ A + np.diag(penalty), A.T @ y)
        coef = np.tile(pooled, (len(SECTION_TYPES), 1))
        for i, kind in enumerate(SECTION_TYPES[:4]):
            sel = np.array(kinds) == kind
            At, lam = A[sel], patterns.TYPE_SHRINK * np.ones(A.shape[1])
            coef[i] = np.linalg.solve(At.T @ At + np.diag(lam), At.T @ y[sel] + lam * pooled)
        assert np.array_equal(layer.coef, coef)
        whole = np.einsum("ij,ij->i", A, coef[[SECTION_TYPES.index(k) for k in kinds]])
        assert np.array_equal(layer.predict(X, kinds), whole)
        monkeypatch.setattr(patterns, "BLOCK_BYTES", 56 * 8 * layer.n_coef)  # predictions in blocks of 7 rows
        assert layer.block_rows() == 56 and np.array_equal(layer.predict(X, kinds), whole)
        monkeypatch.undo()
    pooled_layer = PolyLayer(LOWER_FEATURES, 2, X.mean(0), X.std(0), rng.normal(size=1 + 5 + 22 + 10), "position",
                             X.min(0), X.max(0))
    assert np.array_equal(pooled_layer.predict(X, kinds), _joined_design(pooled_layer, X, kinds) @ pooled_layer.coef)


def test_layer_rows_split_into_fit_and_held_out_runs_join_back_unchanged():
    from locoplan.learn.patterns import LayerData

    rng = np.random.default_rng(6)
    run = np.repeat(np.arange(30), 8)
    data = LayerData(rng.normal(size=(240, 3)), list(rng.choice(["level", "steep-up"], 240)), rng.normal(size=240), run,
                     np.tile(np.arange(8), 30))
    fit, held, sel = data.split(rng.permutation(30)[:24])
    assert len(fit.y) == 24 * 8 and len(held.y) == 6 * 8 and set(fit.run).isdisjoint(held.run)
    back = LayerData.joined(fit, held, sel)
    assert back.kinds == data.kinds and all(np.array_equal(getattr(back, f), getattr(data, f)) and
                                            getattr(back, f).dtype == getattr(data, f).dtype for f in ("X", "y", "run", "extra"))


def test_a_fit_larger_than_a_block_sums_its_normal_equations_block_by_block(monkeypatch):
    """Above BLOCK_BYTES the normal equations are summed a block of rows at a time: the same fit up to
    rounding (the sums' order differs), with one block's memory."""
    import locoplan.learn.patterns as patterns
    from locoplan.learn.patterns import fit_layer
    from locoplan.learn.segments import SECTION_TYPES

    rng = np.random.default_rng(5)
    n = 4000
    X = rng.normal(size=(n, len(LOWER_FEATURES))) * rng.uniform(1, 300, len(LOWER_FEATURES))
    kinds = list(rng.choice(SECTION_TYPES, n))
    y = np.sin(X[:, 0] / 100) + 0.1 * rng.normal(size=n)
    whole = fit_layer(X, kinds, y, 3, LOWER_FEATURES, "position", by_type=True)
    made = []
    design = patterns.PolyLayer.design
    monkeypatch.setattr(patterns.PolyLayer, "design", lambda self, X, kinds: made.append(len(X)) or design(self, X, kinds))
    monkeypatch.setattr(patterns, "BLOCK_BYTES", 300 * 8 * whole.n_coef)
    blocks = fit_layer(X, kinds, y, 3, LOWER_FEATURES, "position", by_type=True)
    assert max(made) == 300 and sum(made) == 2 * n  # every row twice (pooled, then its type), 300 at a time
    assert not np.array_equal(blocks.coef, whole.coef)  # summed in another order ...
    assert np.allclose(blocks.predict(X, kinds), whole.predict(X, kinds), rtol=0, atol=1e-10)  # ... the same fit


def test_order_is_chosen_by_cross_validation_not_in_sample_fit():
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, size=(240, 2))
    z = (X - X.mean(axis=0)) / X.std(axis=0)
    y = 1.0 + 0.5 * z[:, 0] - 0.3 * z[:, 1] ** 3 + 0.01 * rng.standard_normal(240)  # order 2 in z, a little noise
    groups = np.repeat(np.arange(24), 10)
    order, table = select_order(X, ["level"] * 240, y, groups, ("a", "b"), 4, 4, np.random.default_rng(1))
    assert order == 2
    assert table[3]["in_sample_r2"] >= table[1]["in_sample_r2"]  # in-sample would have taken more


def _known_logs(folder: Path, base) -> dict:
    """Logs made from a known pattern: good drivers' times split by known shares, their speeds from a
    known linear division recurrence; wasteful drivers drive otherwise and use more energy."""
    route = load_route(LINE)
    settings = LearnSettings(**SMALL)
    (folder / "logs").mkdir(parents=True)
    truth = {"shares": {}, "speeds": {}}
    runs = []
    for mass in (3200, 4200):
        consist = consist_for_mass(base[0], base[1], mass)
        from locoplan.reporting.logs import consist_yaml

        (folder / f"m{mass}.yaml").write_text(consist_yaml(consist))
        line = line_model(route, build_train(consist, base[1]), ModelOptions(), settings)
        ell = np.array([s.length_m for s in line.sections]) / route.length_m
        g = np.array([s.gradient_permille for s in line.sections])
        pace = 1.0 + 0.05 * (g - g.mean()) / g.std()  # slower on up-grades
        shares = pace * ell / np.sum(pace * ell)
        for t0 in (520.0, 540.0, 560.0):
            for driver in ("G1", "G2", "G3", "W1", "W2", "W3"):
                good = driver.startswith("G")
                sh = shares if good else ell
                v = 0.0
                rows_x, rows_t, rows_v = [0.0], [0.0], [0.0]
                t_start = 0.0
                speeds = np.zeros((len(line.sections), line.divisions + 1))
                for i in range(len(line.sections)):
                    speeds[i, 0] = v
                    x = line.points_m[i]
                    for k in range(1, line.divisions + 1):
                        f = line.lower_inputs(i, k, v, sh[i], mass, t0)
                        named = dict(zip(LOWER_FEATURES, f))
                        v = (0.8 * named["entry_kmh"] + 6.0 * named["position"] + 0.4 * named["gradient_permille"]
                             + 0.002 * named["mass_t"] + 5.0 * named["time_ratio"]) if good else 40.0
                        speeds[i, k] = v
                        rows_x.append(x[k])
                        rows_t.append(t_start + sh[i] * t0 * k / line.divisions)
                        rows_v.append(v)
                    t_start += sh[i] * t0
                force = 300.0 if good else 500.0
                name = f"logs/{driver}-{mass}-{t0:g}.csv"
                (folder / name).write_text(log_csv_text(LogData(np.array(rows_t), np.array(rows_x), np.array(rows_v),
                                                                np.full(len(rows_x), force))))
                runs.append({"log": name, "driver_id": driver, "consist": f"m{mass}.yaml", "mass_t": float(mass),
                             "scheduled_time_s": t0, "actual_time_s": round(float(rows_t[-1]), 3), "date": dt.date(2024, 1, 1)})
                if good:
                    truth["shares"][mass] = shares
                    truth["speeds"][(mass, t0)] = speeds
    (folder / "manifest.yaml").write_text(manifest_text({"schema": "locoplan/driver-logs@1", "route": str(LINE),
                                                         "synthetic": True, "runs": runs}))
    return truth


def test_learning_gives_a_known_pattern_back(tmp_path, base):
    truth = _known_logs(tmp_path, base)
    runs = load_logs(tmp_path)
    good, groups = good_drivers(runs, 500.0)
    assert {r.driver_id for r, g in zip(runs, good) if g} == {"G1", "G2", "G3"}  # claim 3
    out = learn(runs, LearnSettings(**SMALL), ModelOptions())
    pat = out.patterns
    # the recurrence is linear: order 1 explains the held-out speeds to the logs' own precision (speeds rounded to
    # 0.001 km/h: an rmse of 0.001 / sqrt(12) = 0.00029 km/h), so a higher order cannot be told apart from it by
    # more than that rounding (the chosen order may be either)
    cv = {r["order"]: r["cv_rmse"] for r in pat.report["lower"]["cv"]}
    floor = 0.001 / math.sqrt(12)
    assert cv[1] < 1.5 * floor and cv[1] - min(cv.values()) < 0.25 * floor
    route = load_route(LINE)
    for mass in (3200, 4200):
        line = line_model(route, train_of(base, mass), ModelOptions(), pat.settings)
        for t0 in (520.0, 540.0, 560.0):
            # the log rounds time to 0.1 s and speed to 0.001 km/h: that is the precision to expect
            assert pat.shares(line, mass, t0) == pytest.approx(truth["shares"][mass], abs=3e-4)
            known = truth["speeds"][(mass, t0)]
            for i, sec in enumerate(line.sections):  # one division ahead, from the known entry speed
                X = np.array([line.lower_inputs(i, k, known[i, k - 1], truth["shares"][mass][i], mass, t0)
                              for k in range(1, line.divisions + 1)])
                assert pat.lower.predict(X, [sec.kind] * line.divisions) == pytest.approx(known[i, 1:], abs=5e-3)
    assert pat.report["heldout"]["lower"]["one_step_r2"] == pytest.approx(1.0, abs=1e-7)
    assert pat.report["heldout"]["upper"]["rmse_share"] < 3e-4


def test_learning_is_deterministic_for_a_seed(sim_logs, tmp_path):
    out, _ = sim_logs
    files = []
    for i, seed in enumerate((1, 1, 2)):
        f = tmp_path / f"p{i}.json"
        res = runner.invoke(app, ["learn", str(out), "--out", str(f), "--seed", str(seed), "--divisions", "4",
                                  "--max-order", "2", "--folds", "3"])
        assert res.exit_code == 0, res.output
        files.append(f.read_text())
    assert files[0] == files[1] and files[0] != files[2]
    data = json.loads(files[0])
    assert data["schema"] == "locoplan/patterns@1" and data["report"]["data"]["synthetic_runs"] == 24


def test_fit_report_and_plot(learned, tmp_path):
    from locoplan.reporting.plot_learn import plot_fit

    rep = learned.patterns.report
    assert rep["heldout"]["runs"] >= 1 and rep["data"]["good_runs"] == rep["heldout"]["runs"] + rep["fit"]["runs"]
    assert rep["heldout"]["upper"]["r2"] > 0.5 and rep["heldout"]["lower"]["one_step_r2"] > 0.8
    plot_fit(tmp_path / "fit.png", learned)
    assert (tmp_path / "fit.png").stat().st_size > 10_000


def test_patterns_file_round_trip_and_bad_file(learned, tmp_path):
    from locoplan.reporting.writers import to_json

    f = tmp_path / "p.json"
    f.write_text(to_json(learned.patterns.to_dict()))
    back = Patterns.from_dict(read_patterns_file(f), str(f))
    line = line_model(load_route(LINE), learned.lines[0].train, ModelOptions(), back.settings)
    assert back.shares(line, 4200, 540) == pytest.approx(learned.patterns.shares(line, 4200, 540))
    data = json.loads(f.read_text())
    data["lower"]["coef"] = data["lower"]["coef"][:3]
    f.write_text(json.dumps(data))
    with pytest.raises(InputError, match="lower.coef"):
        Patterns.from_dict(read_patterns_file(f), str(f))


# ------------------------------------------------------------------------------------------ advice
def test_advice_is_checked_by_the_calculator_and_meets_the_time(learned, base):
    route = load_route(LINE)
    train = train_of(base, 3700)  # a mass not learned from, a time between the learned ones
    a = advise(learned.patterns, route, train, 540.0, ModelOptions())
    assert a.shares.sum() == pytest.approx(1.0) and np.all(a.shares > 0)
    res = a.result
    assert res.feasible[0] and abs(res.running_time_s[0] - 540.0) <= 15.0
    assert a.plan.conditions[0] == "T" and a.plan.conditions[-1] == "B" and math.isnan(a.plan.starts_m[-1])
    # the same sequence evaluated again by a fresh calculator gives the same numbers
    again = TractionCalculator(route, train).evaluate(a.plan.conditions, a.plan.switches_m)
    assert again.traction_energy_kwh[0] == pytest.approx(res.traction_energy_kwh[0])
    assert np.all(a.target_kmh <= np.maximum.reduce([a.target_kmh]))  # shape kept
    assert np.all(res.profile.v_kmh[0][:-1] <= np.concatenate([res.profile.limit_kmh, [0]])[:-1] + 0.5)


def test_advice_plot_shows_the_line_and_both_limits(learned, tmp_path, monkeypatch):
    """advise --plot: the tunnel, the curve and the stations marked; the limit as the file gives it and as
    the train meets it, labelled; the legend beside the axes."""
    import matplotlib.pyplot as plt

    from locoplan.reporting import plot_learn
    from locoplan.reporting.plot import FILE_LIMIT, TRAIN_LIMIT
    from locoplan.reporting.writers import to_json

    kept = []
    monkeypatch.setattr(plot_learn, "_save", lambda fig, path: (fig.canvas.draw(), kept.append(fig)))
    monkeypatch.chdir(ROOT)
    pfile = tmp_path / "p.json"
    pfile.write_text(to_json(learned.patterns.to_dict()))
    res = runner.invoke(app, ["advise", str(LINE), "--patterns", str(pfile), "--mass", "4200", "--time", "560",
                              "--plot", str(tmp_path / "a.png")])
    assert res.exit_code == 0, res.output
    ax = kept[0].axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    for want in ("tunnel", "curve", "station (stop)", FILE_LIMIT, TRAIN_LIMIT):
        assert want in labels, labels
    tunnel, = [p for p in ax.patches if p.get_label() == "tunnel"]
    assert (tunnel.get_x(), tunnel.get_x() + tunnel.get_width()) == pytest.approx((1.5, 1.9))
    assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1
    plt.close(kept[0])


@pytest.mark.slow
def test_advise_and_compare_commands(sim_logs, learned, tmp_path, monkeypatch):
    from locoplan.reporting.writers import to_json

    monkeypatch.chdir(ROOT)
    out, _ = sim_logs
    pfile = tmp_path / "p.json"
    pfile.write_text(to_json(learned.patterns.to_dict()))
    res = runner.invoke(app, ["advise", str(LINE), "--patterns", str(pfile), "--mass", "4200", "--time", "560", "--json",
                              "--out", str(tmp_path / "a.csv"), "--plot", str(tmp_path / "a.png")])
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    assert s["strategy"] == "advice" and s["feasible"] and s["punctual"]
    assert len(s["sections"]) == 6 and sum(x["share"] for x in s["sections"]) == pytest.approx(1.0, abs=1e-4)
    assert (tmp_path / "a.csv").read_text().startswith("s_m,t_s,v_kmh") and (tmp_path / "a.png").exists()
    res = runner.invoke(app, ["compare", str(LINE), "--strategies", "drivers,advice", "--logs", str(out),
                              "--patterns", str(pfile), "--consist", str(out / "consists/m4200.yaml"), "--time", "560",
                              "--e-min", "100", "--json", "--no-gap"])
    assert res.exit_code == 0, res.output
    rows = {r["strategy"]: r for r in json.loads(res.stdout)["results"]}
    d = rows["drivers"]
    runs = [r for r in load_logs(out) if r.mass_t == 4200 and r.scheduled_time_s == 560]
    energies = [r.traction_energy_kwh for r in runs]
    assert d["drivers_mean_kwh"] == pytest.approx(np.mean(energies), abs=0.01)
    assert d["best_driver_kwh"] == pytest.approx(min(energies), abs=0.01)
    assert d["best_driver_kwh"] <= d["good_drivers_mean_kwh"] < d["drivers_mean_kwh"]
    assert rows["advice"]["feasible"] and rows["advice"]["punctual"]
    res = runner.invoke(app, ["compare", str(LINE), "--strategies", "drivers", "--logs", str(out), "--time", "999",
                              "--e-min", "100"])
    assert res.exit_code == 2 and "no logged run of 'Learning test line, 6 km'" in res.output


def test_learn_tables_at_80_columns_keep_headers_and_numbers_whole(sim_logs, tmp_path):
    out, _ = sim_logs
    res = runner.invoke(app, ["learn", str(out), "--out", str(tmp_path / "p.json"), "--divisions", "4",
                              "--max-order", "2", "--folds", "3"], env={"COLUMNS": "80"})
    assert res.exit_code == 0, res.output
    lines = res.stdout.splitlines()
    assert max(len(x) for x in lines) <= 80 and "…" not in res.stdout and "..." not in res.stdout
    text = res.stdout.replace("┃", " ").replace("│", " ")
    assert "planned" in text and "drivers" in text  # headers whole (never "plan…", "driv…")
    data = json.loads((tmp_path / "p.json").read_text())["report"]["data"]
    assert str(data["good_runs"]) in text
