"""Physics against hand-worked values (SPEC section 1, seed 002 Tables 2-3, seed 004 claims 5-6)."""

import numpy as np
import pytest

from locoplan.physics.gradient import (curve_gradient_permille, equivalent_gradient_permille,
                                       strip_gradient_permille, tunnel_gradient_permille)
from locoplan.physics.resistance import basic_resistance_kn, basic_resistance_n_per_kn, train_resistance_kn
from locoplan.physics.traction import gradient_force_kn, max_force_kn


def test_basic_resistance_hxd1_by_hand():
    # w0 = 1.40 + 0.0038*50 + 0.0003*50^2 = 2.34 N/kN; 200 t weigh 1962 kN -> 4.59108 kN
    assert basic_resistance_n_per_kn(50.0, 1.40, 0.0038, 0.0003) == pytest.approx(2.34, abs=1e-12)
    assert basic_resistance_kn(50.0, 1.40, 0.0038, 0.0003, 200.0) == pytest.approx(4.59108, abs=1e-9)


def test_basic_resistance_vectorised_c80_loaded():
    # C80 loaded to 100 t: at 0 and 80 km/h, w0 = 0.92 and 0.92 + 0.384 + 0.8 = 2.104 N/kN
    got = basic_resistance_kn(np.array([0.0, 80.0]), 0.92, 0.0048, 0.000125, 100.0)
    np.testing.assert_allclose(got, [0.92 * 0.981, 2.104 * 0.981], rtol=1e-12)


def test_train_coefficients_are_mass_weighted_sums(freight):
    _, train = freight
    # HXD1 200 t + 50 C80 at 100 t: A = (1.40*200 + 0.92*5000) * 9.81/1000
    a, b, c = train.resistance_kn
    assert a == pytest.approx((1.40 * 200 + 0.92 * 5000) * 9.81 / 1000, rel=1e-12)
    assert b == pytest.approx((0.0038 * 200 + 0.0048 * 5000) * 9.81 / 1000, rel=1e-12)
    assert c == pytest.approx((0.0003 * 200 + 0.000125 * 5000) * 9.81 / 1000, rel=1e-12)
    assert train.mass_t == 5200 and train.length_m == pytest.approx(35.2 + 600)
    assert train.max_speed_kmh == 100  # the wagons' limit is lower than the locomotive's
    v = 60.0
    per_vehicle = basic_resistance_kn(v, 1.40, 0.0038, 0.0003, 200) + 50 * basic_resistance_kn(v, 0.92, 0.0048, 0.000125, 100)
    assert train_resistance_kn(v, train.resistance_kn) == pytest.approx(per_vehicle, rel=1e-12)


def test_additional_resistances_by_hand():
    assert curve_gradient_permille(600.0) == pytest.approx(1.0)
    # seed 004 claim 6: 600 * Lc / (Rc * L_train) for a curve shorter than the train
    assert curve_gradient_permille(600.0, 500.0, 635.2) == pytest.approx(600 * 500 / (600 * 635.2))
    assert curve_gradient_permille(600.0, 800.0, 635.2) == pytest.approx(1.0)  # longer than the train: 600/R
    assert tunnel_gradient_permille(1100.0) == pytest.approx(0.143)


def test_equivalent_gradient_on_freight_route(freight):
    route, train = freight
    L = train.length_m
    s = np.array([100.0, 3300.0, 3800.0, 3900.0, 12000.0, 16300.0])
    got = equivalent_gradient_permille(route, s, L)
    short_curve = 600 * 500 / (600 * L)  # the 500 m curve at 3200 m is shorter than the 635.2 m train
    expected = [0.0, -5 + short_curve, -5 + short_curve, -5.0, 12 + 0.00013 * 1100, -7 + 600 * 600 / (500 * L)]
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_strip_mode_averages_over_the_train(freight):
    route, _ = freight
    # 600 m train, head at 3700 m: body 3100..3700 on -5 per mille, the whole 500 m curve (R 600) under it
    assert strip_gradient_permille(route, 3700.0, 600.0) == pytest.approx(-5 + 1.0 * 500 / 600, abs=2e-3)
    # head at 1800 m: half the body on 0 per mille, half on +1 per mille
    assert strip_gradient_permille(route, 1800.0, 600.0) == pytest.approx(0.5, abs=2e-3)
    # the strip conserves the curve's work: integral over head positions = 600/R * Lc
    bare = route.model_copy(update={"curves": [c for c in route.curves if c.from_m != 3200]})
    s = np.arange(3000.0, 4500.0, 1.0)
    extra = strip_gradient_permille(route, s, 600.0) - strip_gradient_permille(bare, s, 600.0)
    assert extra.sum() * 1.0 == pytest.approx(1.0 * 500, rel=5e-3)


def test_force_curves_and_gravity(freight):
    _, train = freight
    # between (45.47, 760) and (50, 691.2): linear
    expected = 760 - (47 - 45.47) / (50 - 45.47) * (760 - 691.2)
    assert max_force_kn(47.0, train.traction_speed_kmh, train.traction_kn) == pytest.approx(expected)
    assert max_force_kn(130.0, train.traction_speed_kmh, train.traction_kn) == pytest.approx(288.0)
    assert max_force_kn(30.0, *train.brake_curve(air=False)) == pytest.approx(461.0)  # the HXD1's electric brake
    # + 50 loaded C80: braking ratio 0.20 x 100 t x 9.81 x phi_h(30) = 0.322 * 180 / 210, at beta_c = 0.5
    assert max_force_kn(30.0, train.brake_speed_kmh, train.brake_kn) == pytest.approx(461.0 + 50 * 0.2 * 981 * 0.322 * 180 / 210 * 0.5)
    assert gradient_force_kn(10.0, 5200.0) == pytest.approx(510.12)
