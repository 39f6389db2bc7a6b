"""The compiled loop (``sim/kernel.py``) against computations that share none of its code:

- a fine-step integration of the same plans (``fastest_oracle.FastestOracle.drive``: RK4 in e over 5 m steps,
  its own interpolation, resistance and braking envelope) in every model without the air brake's cycle:
  running time within 0.3 %, traction energy within 0.1 %, and the same verdict (arrives or comes to rest);
- the energy balance of runs that cycle the air brake: the work of traction, brakes, resistance and gravity
  cell by cell adds up to the change of kinetic energy.
"""

import numpy as np
import pytest

from fastest_oracle import FastestOracle
from locoplan.model.route import Route
from locoplan.physics.resistance import train_resistance_kn
from locoplan.sim.calculator import ModelOptions, TractionCalculator

TIME_RTOL = 3e-3
"""The loop takes each cell (50 m by default) in one second-order step with the conditions mixed by their shares
of it; the oracle 5 m RK4 steps. Measured: 0.1 % at most, 0.02 % typically (0.25 % on a plan that crawls)."""
ENERGY_RTOL = 2e-3
"""Measured: 0.11 % at most, where a train braked back to its cruise speed after a descent its brakes cannot hold
reaches it within one cell using its surplus kinetic energy (the oracle brakes at once); 0.06 % elsewhere."""


def _hilly(freight):
    """freight-20km with a neutral section and a descent steep enough that holding needs the air brake."""
    route, _ = freight
    data = route.model_dump(by_alias=True)
    data["neutral_sections"] = [{"from_m": 10600, "to_m": 10650, "coast_before_s": 10, "coast_after_s": 10}]
    data["gradients"][9]["permille"] = -16.0
    return Route.model_validate(data)


CASES = [("seeds", ModelOptions.papers()), ("no-air-brake", ModelOptions(air_brake=False)),
         ("air-brake-modulated", ModelOptions(air_cycle=False))]


@pytest.mark.parametrize("name,options", CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("hilly", [False, pytest.param(True, marks=pytest.mark.slow)], ids=["freight-20km", "hilly-ns"])
def test_plans_agree_with_a_fine_step_integration(freight, name, options, hilly):
    route, train = freight
    if hilly:
        route = _hilly(freight)
    calc = TractionCalculator(route, train, options)
    oracle = FastestOracle.of(calc, 5.0)
    rng = np.random.default_rng(3)
    arrived = stopped = 0
    for seq, n_sw, cruise in ((tuple("TCTKCB"), 4, None), (("T", "C", "B"), 1, 60.0), (tuple("TKCTCB"), 4, None)):
        for _ in range(4):
            x = np.concatenate([np.sort(rng.uniform(0, route.length_m, n_sw)), [np.nan]])  # bare B: at the curve
            res = calc.evaluate(seq, x[None, :], cruise_kmh=None if cruise is None else [cruise])
            t_ref, w_ref = oracle.drive(seq, x, cruise)
            assert bool(res.feasible[0]) == (t_ref == t_ref), (seq, x, res.reason(0), t_ref)
            if res.feasible[0]:
                arrived += 1
                assert res.running_time_s[0] == pytest.approx(t_ref, rel=TIME_RTOL), (seq, x)
                assert res.traction_energy_kwh[0] == pytest.approx(w_ref, rel=ENERGY_RTOL), (seq, x)
            else:
                stopped += 1
    assert arrived >= 4 and stopped >= 1  # the sample holds both verdicts


@pytest.mark.slow
def test_runs_that_cycle_the_air_brake_balance_their_energy(heavy_haul):
    """The heavy-haul line's 30.5 km at -12 per mille, which the two HXD1s' electric brake cannot hold: random
    plans cycle the air brake (applied, released, recharged); over each run as far as it goes, traction less
    braking, resistance and gravity work equals the change of kinetic energy (to 5e-4 of the work done), and
    in every cell to 3 % (the loop takes the resistance at its predicted mid-speed, the balance at the mean e)."""
    route, train = heavy_haul
    calc = TractionCalculator(route, train)
    rng = np.random.default_rng(5)
    n = 40
    cycled = 0
    for seq, n_sw, cruise, drop in ((("T", "K", "C", "B"), 3, None, None),
                                    (("T", "C", "K", "B"), 3, None, rng.uniform(-0.3, 2.5, n)),
                                    (("T", "K", "B"), 2, rng.uniform(50, 80, n), None)):
        x = np.sort(rng.uniform(0, route.length_m, (n, n_sw)), axis=1)
        res = calc.evaluate(seq, x, profile=True, cruise_kmh=cruise, release_margin=drop)
        p = res.profile
        cycled += int((res.air_applications >= 2).sum())
        for i in range(n):
            e = (p.v_kmh[i] / 3.6) ** 2 / 2
            ran = np.isfinite(e[1:]) & np.isfinite(e[:-1]) & (e[1:] + e[:-1] > 0)
            if res.failure_m[i] == res.failure_m[i]:  # up to the cell where it fails (comes to rest) only
                ran &= calc.s_m[1:] < res.failure_m[i]
            v_mid = np.sqrt(e[1:] + e[:-1]) * 3.6
            forces = (p.traction_kn[i], -p.brake_kn[i], -train_resistance_kn(v_mid, train.resistance_kn),
                      -calc.gravity_kn)
            work = calc.h_m * sum(forces)
            gained = calc.m_eff_t * np.diff(e)
            scale = calc.h_m * sum(np.abs(f) for f in forces)
            assert np.abs(gained - work)[ran].sum() <= 5e-4 * scale[ran].sum(), i
            assert np.all(np.abs(gained - work)[ran] <= 0.03 * scale[ran]), i
    assert cycled > n // 2  # cycles, not single applications


@pytest.mark.slow
def test_a_plan_does_not_depend_on_its_batch(freight):
    """A stalled plan creeping at the speed floor takes no number from its neighbours in the batch: each plan
    gets the numbers it gets alone."""
    route, train = freight
    seq = tuple("TKTCTCKCB")
    X = np.sort(np.random.default_rng(1).uniform(0, 20000, (60, 7)), axis=1)
    X = np.concatenate([X, np.full((60, 1), np.nan)], axis=1)
    calc = TractionCalculator(route, train, ModelOptions(strict_limits=True))
    batch = calc.evaluate(seq, X)
    for i in range(len(X)):
        one = calc.evaluate(seq, X[i:i + 1])
        assert one.reason_code[0] == batch.reason_code[i]
        np.testing.assert_allclose(one.running_time_s[0], batch.running_time_s[i], rtol=1e-12, equal_nan=True)
