"""Adhesion (``adhesion_mu`` in a locomotive's file, ``physics/adhesion.py``): traction and the electric brake are
each at most mu(v) x m g. One function in the physics and one field in the vehicle file; every method reads the
train's curves, so the calculator, the DP, E* and the strategies all honour it. Checked with tests/data/consists/HXD1-wet-rail-C80x30.yaml:
an HXD1 on a wet rail (Curtius-Kniffler's mu, 650 kN at a start of the 760 kN its motors give) hauling 30 C80."""

import numpy as np
import pytest

from locoplan.errors import InputError
from locoplan.io.load import load_route, load_train
from locoplan.ocp.bound import energy_bound
from locoplan.physics.adhesion import adhesion_force_kn, adhesion_limited
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions, TractionCalculator

G = 9.81


def test_the_limited_curve_is_the_exact_minimum_of_the_two():
    """At 20,000 speeds from 0 to beyond both curves' ends, the limited curve (read as every curve is read,
    linear between points, flat beyond) equals min(curve, mu(v) m g) to 1e-9 kN, on random curves that cross."""
    rng = np.random.default_rng(7)
    v = np.linspace(0.0, 150.0, 20001)
    crossings = 0
    for _ in range(50):
        speeds = np.sort(rng.choice(np.arange(0, 130, 5), rng.integers(2, 8), replace=False)).astype(float)
        curve = np.column_stack([speeds, rng.uniform(200, 800, len(speeds))])
        mu_v = np.sort(rng.choice(np.arange(0, 130, 7), rng.integers(2, 6), replace=False)).astype(float)
        mu = np.column_stack([mu_v, rng.uniform(0.1, 0.4, len(mu_v))])
        out = adhesion_limited(curve, mu, 200.0)
        want = np.minimum(np.interp(v, curve[:, 0], curve[:, 1]), np.interp(v, mu[:, 0], mu[:, 1]) * 200.0 * G)
        np.testing.assert_allclose(np.interp(v, out[:, 0], out[:, 1]), want, rtol=0, atol=1e-9)
        crossings += len(out) - len(np.union1d(curve[:, 0], mu[:, 0]))
    assert crossings > 20  # the sample has curves that cross between their points


@pytest.fixture(scope="module")
def wet(root):
    return load_route(root / "routes/freight-20km.yaml"), load_train(root / "tests/data/consists/HXD1-wet-rail-C80x30.yaml")


@pytest.fixture(scope="module")
def dry(root):
    return load_train(root / "configs/consists/HXD1-C80x30.yaml")


def test_the_train_has_the_limited_curves(wet, dry):
    """The wet-rail HXD1's traction is 0.3315 x 200 t x g = 650.4 kN at a start (760 kN on a dry rail), its own
    curve again from where mu(v) m g passes it (near 80 km/h); its electric brake 461 kN above the adhesion from
    about 58 km/h down; the rest of the train (mass, resistance, air brake) is the dry train's."""
    _, train = wet
    assert float(np.interp(0.0, train.traction_speed_kmh, train.traction_kn)) == pytest.approx(0.3315 * 200 * G, rel=1e-9)
    assert float(np.interp(0.0, dry.traction_speed_kmh, dry.traction_kn)) == pytest.approx(760.0)
    v = np.linspace(0, 120, 1201)
    mu_mg = adhesion_force_kn(v, *np.array([[0, 10, 20, 30, 40, 50, 60, 70, 80, 100, 120],
                                            [0.3315, 0.2999, 0.2782, 0.2624, 0.2503, 0.2408, 0.2331, 0.2268, 0.2215,
                                             0.2131, 0.2067]]), 200.0)
    for (sv, sf), (dv, df) in (((train.traction_speed_kmh, train.traction_kn), (dry.traction_speed_kmh, dry.traction_kn)),
                               ((train.electric_brake_speed_kmh, train.electric_brake_kn),
                                (dry.electric_brake_speed_kmh, dry.electric_brake_kn))):
        np.testing.assert_allclose(np.interp(v, sv, sf), np.minimum(np.interp(v, dv, df), mu_mg), atol=1e-9)
    binds = np.interp(v, train.electric_brake_speed_kmh, train.electric_brake_kn) < 461.0 - 1e-6
    assert 56 < v[binds].min() < 60  # the electric brake is cut from about 58 km/h up
    assert train.mass_t == dry.mass_t and train.resistance_kn == dry.resistance_kn
    np.testing.assert_array_equal(train.air_brake_kn, dry.air_brake_kn)


def test_the_calculator_pulls_and_brakes_within_the_adhesion(wet, dry):
    """The fastest run on freight-20km: at no cell does its traction pass mu(v) m g at the cell's speed, and it is
    slower than the dry-rail train's."""
    route, train = wet
    calc = TractionCalculator(route, train)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    assert res.feasible[0], res.reason(0)
    p = res.profile
    # the curve falls with speed: the cell's lower speed bounds its force (less 0.1 km/h: the loop takes the force
    # at its predicted mid-speed, which may lie a little below both ends)
    v_lo = np.maximum(np.minimum(p.v_kmh[0, 1:], p.v_kmh[0, :-1]) - 0.1, 0.0)
    cap = np.interp(v_lo, train.traction_speed_kmh, train.traction_kn)
    assert np.all(p.traction_kn[0] <= cap + 1e-6)
    dry_calc = TractionCalculator(route, dry)
    dry_p = dry_calc.evaluate(("T",), np.zeros((1, 0)), profile=True).profile
    assert 600.0 < p.traction_kn[0, 0] <= 650.41 and dry_p.traction_kn[0, 0] == pytest.approx(760.0)  # the start
    assert calc.fastest_time_s > dry_calc.fastest_time_s + 5.0


@pytest.mark.parametrize("options", [ModelOptions(), ModelOptions.papers()], ids=["default", "point-mass"])
def test_estar_honours_the_adhesion_and_stays_below_every_plan(wet, dry, options):
    """At 1.1 x the wet-rail fastest run: E* on the wet rail is above E* on the dry rail at the same time (less
    force can only cost energy; the DP and the strategies read the same curves), and below the energy of every
    strategy's plan that keeps the time."""
    route, train = wet
    t0 = round(1.1 * TractionCalculator(route, train, options).fastest_time_s, 1)
    e_wet = energy_bound(route, train, options, t0)
    e_dry = energy_bound(route, dry, options, t0)
    assert e_wet.energy_kwh > e_dry.energy_kwh * (1 + e_dry.accuracy)
    ctx = make_context(route, train, RunSettings(options, time_s=t0, tolerance_s=0.01 * t0))
    kept = 0
    for name in ("time-saving", "energy-saving", "four-stage", "proposed"):
        s = run_strategy(ctx, name).summary
        if s["feasible"] and abs(s["running_time_s"] - t0) <= ctx.tolerance_s:
            kept += 1
            b = energy_bound(route, train, options, s["running_time_s"])
            assert s["traction_energy_kwh"] >= b.energy_kwh * (1 - b.accuracy) - 0.01, name
    assert kept >= 2


@pytest.mark.parametrize("field,value,words", [
    ("adhesion_mu", "[[0, 1.3], [100, 0.2]]", "mu 1.3 must lie in (0, 1]"),
    ("adhesion_mu", "[[0, 0.3], [0, 0.2]]", "speeds must increase"),
    ("adhesion_mu", "[[0, 0.3]]", "needs at least two [speed_kmh, mu] points"),
])
def test_a_wrong_adhesion_curve_is_refused_with_its_field(tmp_path, root, field, value, words):
    text = (root / "tests/data/rolling_stock/HXD1-wet-rail.yaml").read_text().replace("adhesion_mu: [[0, 0.3315]",
                                                                                "adhesion_mu_old: [[0, 0.3315]")
    text = "\n".join(line for line in text.splitlines() if not line.startswith("adhesion_mu_old")) + f"\n{field}: {value}\n"
    (tmp_path / "HXD1-wet-rail.yaml").write_text(text)
    (tmp_path / "C80.yaml").write_text((root / "configs/rolling_stock/C80.yaml").read_text())
    consist = tmp_path / "c.yaml"
    consist.write_text((root / "tests/data/consists/HXD1-wet-rail-C80x30.yaml").read_text())
    with pytest.raises(InputError) as err:
        load_train(consist, tmp_path)
    assert words in str(err.value) and "adhesion_mu" in str(err.value)


def test_a_wagon_with_adhesion_is_refused(tmp_path, root):
    (tmp_path / "HXD1-wet-rail.yaml").write_text((root / "tests/data/rolling_stock/HXD1-wet-rail.yaml").read_text())
    (tmp_path / "C80.yaml").write_text((root / "configs/rolling_stock/C80.yaml").read_text()
                                       + "adhesion_mu: [[0, 0.3], [100, 0.2]]\n")
    consist = tmp_path / "c.yaml"
    consist.write_text((root / "tests/data/consists/HXD1-wet-rail-C80x30.yaml").read_text())
    with pytest.raises(InputError, match="a wagon has no driven wheels"):
        load_train(consist, tmp_path)


def test_the_numbers_docs_model_md_gives(wet, dry):
    """docs/model.md, 'Adhesion': fastest runs 1,181.8 s (wet) and 1,165.6 s (dry) on freight-20km, E* at 1,300 s
    483.15 kWh (wet) and 475.19 kWh (dry), default model."""
    route, train = wet
    assert TractionCalculator(route, train).fastest_time_s == pytest.approx(1181.8, abs=0.05)
    assert TractionCalculator(route, dry).fastest_time_s == pytest.approx(1165.6, abs=0.05)
    assert energy_bound(route, train, ModelOptions(), 1300.0).energy_kwh == pytest.approx(483.15, abs=0.005)
    assert energy_bound(route, dry, ModelOptions(), 1300.0).energy_kwh == pytest.approx(475.19, abs=0.005)
