"""An application the train cannot release slows it by the air brake alone at every speed, crawling ones too.

A 10,400 t train on a long descent whose neutral section cuts the electric brake for well over a kilometre
(from before the head enters until after the tail has left) applies its air brake at the apply speed; released,
it would regain that speed long before its recharge is over, so the application stays on. Where the air brake
alone slows the train more than the grade pulls it, the train comes to rest in the span: no drive keeps the
rules there, and every plan is refused with that reason (not "stalled", and not a speed held below 15 km/h by a
brake the train does not have there). The same line without the neutral section is driven.
"""

import numpy as np
import pytest

from locoplan.io.load import load_train
from locoplan.model.route import Route
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from locoplan.sim.result import AIR_HELD

GRADE = -14.0


def _line(neutral: bool) -> Route:
    data = {"schema": "locoplan/route@1", "name": "descent with a neutral section", "length_m": 9000.0,
            "speed_limits": [{"from_m": 0.0, "to_m": 9000.0, "kmh": 40.0}],
            "gradients": [{"from_m": 0.0, "to_m": 1000.0, "permille": 0.0},
                          {"from_m": 1000.0, "to_m": 8000.0, "permille": GRADE},
                          {"from_m": 8000.0, "to_m": 9000.0, "permille": 0.0}]}
    if neutral:
        data["neutral_sections"] = [{"from_m": 3000.0, "to_m": 3200.0, "coast_before_s": 10.0, "coast_after_s": 10.0}]
    return Route.model_validate(data)


@pytest.fixture(scope="module")
def train():
    return load_train("configs/consists/HXD1x2-C80x100.yaml")


def test_an_application_it_cannot_release_brings_the_train_to_rest_in_the_span(train):
    calc = TractionCalculator(_line(True), train, ModelOptions())
    assert calc.air_cycle is not None
    cut = calc.traction_allowed == 0.0
    mid = 0.5 * (calc.s_m[1:] + calc.s_m[:-1])
    span = mid[cut].min(), mid[cut].max()
    # the premise, from the model's own forces: released at any speed the train could keep in the span, it gains
    # more than the apply speed during the recharge (coasting down the grade, no electric brake there)
    v = np.linspace(1.0, 40.0, 40)
    k = int(np.flatnonzero(cut)[len(np.flatnonzero(cut)) // 2])
    accel = -np.array([float(calc.forces_kn(x / 3.6, k)[2]) for x in v]) / calc.m_eff_t  # kN / t = m/s^2
    assert accel.min() * calc.air_cycle.recharge_s * 3.6 > 40.0
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)
    assert not res.feasible[0] and int(res.reason_code[0]) == AIR_HELD
    assert span[0] <= float(res.failure_m[0]) <= span[1]
    assert "brought to rest" in res.reason(0) and "could not release" in res.reason(0)
    # up to there the run keeps slowing under the kept-on application: no speed is held below 15 km/h
    p = res.profile
    ok = np.isfinite(p.v_kmh[0]) & (p.s_m >= span[0])
    v_run = p.v_kmh[0][ok]
    slow = v_run[np.argmax(v_run):]
    slow = slow[slow < 15.0]
    assert len(slow) >= 2 and np.all(np.diff(slow) < 0.0)


def test_without_the_neutral_section_the_line_is_driven(train):
    res = TractionCalculator(_line(False), train, ModelOptions()).evaluate(("T",), np.zeros((1, 0)))
    assert res.feasible[0]
