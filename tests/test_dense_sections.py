"""A line of gradient sections shorter than a cell (e.g. a survey's 2 m points): the calculator's grid keeps the
uniform cells and the speed limits' ends, and each cell takes the exact mean of the equivalent gradient over the
sections inside it, so that every method's cost follows the line's length, not its number of sections."""

import numpy as np
import pytest

from fastest_oracle import FastestOracle
from locoplan.physics.gradient import mean_gradient_permille
from locoplan.physics.units import G_MS2
from locoplan.sim.calculator import MERGED_ENDS_PER_CELL, ModelOptions, TractionCalculator
from routes import hand_made_route


def _dense(n_sections: int, length: float = 20000.0, seed: int = 3):
    rng = np.random.default_rng(seed)
    ends = np.linspace(0.0, length, n_sections + 1)[1:]
    grades = list(zip(ends, np.round(rng.uniform(-6.0, 6.0, n_sections), 2)))
    return hand_made_route([(8000.0, 80.0), (12000.0, 60.0), (length, 80.0)], grades, length)


@pytest.fixture(scope="module")
def line():
    return _dense(12000)


def test_the_grid_follows_the_length_and_the_limits(line, freight):
    """12,000 sections of 1.67 m: the grid has the uniform 50 m nodes, the limits' ends (and one train length on, in
    the strip model) and the departure's graded nodes, not 12,000 nodes; a line of 50 m sections keeps its ends."""
    _, train = freight
    for options in (ModelOptions(), ModelOptions.papers()):
        calc = TractionCalculator(line, train, options)
        assert len(calc.s_m) < 2 * (line.length_m / options.step_m)
        assert {8000.0, 12000.0} <= set(calc.s_m.tolist())
    coarse = _dense(400)  # 50 m sections: below MERGED_ENDS_PER_CELL ends per cell, each end a node
    assert 400 < MERGED_ENDS_PER_CELL * 400
    assert set(np.linspace(0, 20000, 401).tolist()) <= set(TractionCalculator(coarse, train, ModelOptions.papers()).s_m.tolist())


def test_each_cell_takes_the_exact_mean_of_its_sections(line, freight):
    """Point model: each cell's gravity force is m g times the mean gradient over the cell, computed independently
    from the running integral of the sections (``mean_gradient_permille``), to 1e-9. Strip model: the mean of the
    strip gradient over each cell, by a 20,000-point midpoint sum, to 1e-6 per mille. Both: the gravity work over the line
    equals m g times the height difference."""
    _, train = freight
    calc = TractionCalculator(line, train, ModelOptions.papers())
    a, b = calc.s_m[:-1], calc.s_m[1:]
    want = train.mass_t * G_MS2 * mean_gradient_permille(line, a, b) / 1000.0
    np.testing.assert_allclose(calc.gravity_kn, want, rtol=0, atol=1e-9 * float(np.max(np.abs(want))))
    height = sum((g.to_m - g.from_m) * g.permille for g in line.gradients) / 1000.0
    assert float(np.sum(calc.gravity_kn * calc.h_m)) == pytest.approx(train.mass_t * G_MS2 * height, rel=1e-9, abs=1e-6)
    strip = TractionCalculator(line, train, ModelOptions())
    for k in (5, 137, 250, len(strip.h_m) - 3):
        n = 20000
        x = strip.s_m[k] + (np.arange(n) + 0.5) * (strip.s_m[k + 1] - strip.s_m[k]) / n
        fine = float(np.mean(mean_gradient_permille(line, x - train.length_m, x)))
        assert strip.gradient_permille[k] == pytest.approx(fine, abs=1e-6)


def test_the_fastest_run_is_the_sections_own(line, freight):
    """The fastest run on the merged cells within 0.2 % of an independent fine-step integration over the sections
    themselves (tests/fastest_oracle.py, 1 m steps, each section its own gravity), point model."""
    _, train = freight
    calc = TractionCalculator(line, train, ModelOptions.papers())
    edges = [0.0] + [g.to_m for g in line.gradients]
    mids = 0.5 * (np.array(edges[1:]) + np.array(edges[:-1]))
    limit = np.interp(mids, [0, 8000, 8000.001, 12000, 12000.001, 20000], [80, 80, 60, 60, 80, 80])
    gravity = [train.mass_t * G_MS2 * g.permille / 1000.0 for g in line.gradients]
    oracle = FastestOracle(edges, gravity, limit, np.ones(len(mids)), (train.traction_speed_kmh, train.traction_kn),
                           (calc.electric_brake_speed_kmh, calc.electric_brake_kn), None, train.resistance_kn,
                           calc.m_eff_t, 1.0)
    t_ref, _ = oracle.fastest()
    assert calc.fastest_time_s == pytest.approx(t_ref, rel=2e-3)
