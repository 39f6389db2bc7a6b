"""The compiled loop (numba, the default backend) against the numpy loop it replaced: same arithmetic,
so every number agrees to 1e-9 relative on random plans, every model option and every verdict."""

import numpy as np
import pytest

from locoplan.model.route import Route
from locoplan.sim.calculator import ModelOptions, TractionCalculator

RTOL = 1e-9


def _hilly(freight):
    """freight-20km with a neutral section and a descent steep enough that holding needs the air brake."""
    route, _ = freight
    data = route.model_dump(by_alias=True)
    data["neutral_sections"] = [{"from_m": 10600, "to_m": 10650, "coast_before_s": 10, "coast_after_s": 10}]
    data["gradients"][9]["permille"] = -16.0
    return Route.model_validate(data)


CASES = [("default", ModelOptions()), ("seeds", ModelOptions.seeds()), ("strict", ModelOptions(strict_limits=True)),
         ("rotating", ModelOptions(rotating_mass=0.06, step_m=20.0)), ("no-air-brake", ModelOptions(air_brake=False))]
"""On the hilly line the seeds' model and the electric brake alone cannot hold the limit down the -16 per mille
descent: the envelope falls below it there (the train enters slower), in both backends alike."""


@pytest.mark.parametrize("name,options", CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("hilly", [False, True], ids=["freight-20km", "hilly-ns"])
@pytest.mark.slow
def test_backends_agree(freight, name, options, hilly):
    route, train = freight
    if hilly:
        route = _hilly(freight)
    ref = TractionCalculator(route, train, options, backend="numpy")
    new = TractionCalculator(route, train, options)
    # the braking envelope too is computed by each backend (Python loop / kernel.braking_envelope)
    np.testing.assert_array_equal(ref.s_m, new.s_m)
    np.testing.assert_allclose(ref.e_envelope, new.e_envelope, rtol=1e-12, atol=1e-12)
    if hilly and not options.air_brake:
        assert not ref.brake_holds_limit.all() and ref.impossible is None
    rng = np.random.default_rng(11)
    n = 120
    for seq, n_sw, cruise in ((tuple("TKTCTCKCB"), 7, None), (("T", "C", "B"), 1, rng.uniform(40, 80, n)),
                              (("T", "K", "C", "B"), 3, None)):
        X = np.sort(rng.uniform(0, route.length_m, (n, n_sw)), axis=1)
        if seq[-1] == "B" and n_sw == len(seq) - 2:  # the final bare B: brake where the braking curve begins
            X = np.concatenate([X, np.full((n, 1), np.nan)], axis=1)
        a = ref.evaluate(seq, X, profile=True, cruise_kmh=cruise)
        b = new.evaluate(seq, X, profile=True, cruise_kmh=cruise)
        if name == "default" and len(seq) > 4:
            assert 0 < b.feasible.sum() < n  # the sample mixes verdicts
        np.testing.assert_allclose(a.failure_m, b.failure_m, equal_nan=True)
        _same_runs(a, b)


def _same_runs(a, b):
    """Two backends' results of one batch alike: verdicts, times, energies, the profiles and the air brake's cycle."""
    np.testing.assert_array_equal(a.reason_code, b.reason_code)
    np.testing.assert_allclose(a.running_time_s, b.running_time_s, rtol=RTOL, equal_nan=True)
    np.testing.assert_allclose(a.traction_energy_kwh, b.traction_energy_kwh, rtol=RTOL)
    for field in ("t_s", "v_kmh", "traction_kn", "brake_kn", "event_m"):
        np.testing.assert_allclose(getattr(a.profile, field), getattr(b.profile, field), rtol=RTOL, atol=1e-9,
                                   equal_nan=True, err_msg=field)
    np.testing.assert_array_equal(a.profile.condition, b.profile.condition)
    _same_cycles(a, b)


def _same_cycles(a, b):
    """The air brake's cycle alike in both backends: its state per cell, applications and recharge margins."""
    assert (a.profile.air is None) == (b.profile.air is None)
    if a.profile.air is not None:
        np.testing.assert_array_equal(a.profile.air, b.profile.air)
        np.testing.assert_array_equal(a.air_applications, b.air_applications)
        np.testing.assert_allclose(a.air_margin_s, b.air_margin_s, rtol=RTOL, atol=1e-9)
        np.testing.assert_allclose(a.air_wait_s, b.air_wait_s, rtol=RTOL, atol=1e-9, equal_nan=True)


@pytest.mark.slow
def test_backends_agree_on_air_brake_cycles(heavy_haul):
    """The heavy-haul line's 30.5 km at -12 per mille, which the two HXD1s' electric brake cannot hold: random
    plans (some with a cruise speed, some with their own release margin) cycle the air brake, some are refused
    for applying it again before its recharge is over, in both backends alike."""
    route, train = heavy_haul
    ref = TractionCalculator(route, train, backend="numpy")
    new = TractionCalculator(route, train)
    rng = np.random.default_rng(5)
    n = 40
    for seq, n_sw, cruise, drop in ((("T", "K", "C", "B"), 3, None, None), (("T", "C", "K", "B"), 3, None,
                                                                            rng.uniform(-0.3, 2.5, n)),
                                    (("T", "K", "B"), 2, rng.uniform(50, 80, n), None)):
        X = np.sort(rng.uniform(0, route.length_m, (n, n_sw)), axis=1)
        a = ref.evaluate(seq, X, profile=True, cruise_kmh=cruise, release_margin=drop)
        b = new.evaluate(seq, X, profile=True, cruise_kmh=cruise, release_margin=drop)
        _same_runs(a, b)
        assert (b.air_applications >= 2).sum() > n // 4  # cycles, not single applications


@pytest.mark.slow
def test_a_plan_does_not_depend_on_its_batch(freight):
    """A stalled plan creeping at the speed floor used to take its time from its neighbours' arithmetic in
    the numpy loop; both backends now give each plan the numbers it gets alone."""
    route, train = freight
    seq = tuple("TKTCTCKCB")
    X = np.sort(np.random.default_rng(1).uniform(0, 20000, (60, 7)), axis=1)
    X = np.concatenate([X, np.full((60, 1), np.nan)], axis=1)
    for backend in ("numpy", "numba"):
        calc = TractionCalculator(route, train, ModelOptions(strict_limits=True), backend=backend)
        batch = calc.evaluate(seq, X)
        for i in range(len(X)):
            one = calc.evaluate(seq, X[i:i + 1])
            assert one.reason_code[0] == batch.reason_code[i]
            np.testing.assert_allclose(one.running_time_s[0], batch.running_time_s[i], rtol=1e-12, equal_nan=True)
