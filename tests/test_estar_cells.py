"""E* on the calculator's cells (ocp/cells.py) by the structured interior-point method (ocp/ipm.py):
the banded solve, the rounded force curves, the physics of the optimum, the grids' convergence that
makes their difference an honest accuracy, and E* below every plan the calculator can drive."""

from __future__ import annotations

import numpy as np
import pytest

from locoplan.io.load import load_route, load_train
from locoplan.ocp.band_kernel import band_factor, band_solve
from locoplan.ocp.cells import CellEnergyProblem, cell_calculator, cell_problem, solve_cells, solve_estar
from locoplan.physics.backend import RoundedCurve, piecewise_linear, piecewise_linear_rounded, rounded_curve_at
from locoplan.physics.units import KJ_PER_KWH, kmh
from locoplan.sim.calculator import ModelOptions, TractionCalculator, neutral_spans_m

SMALL = "tests/data/routes/mpoc-small.yaml"
T_SMALL = 364.0
MODELS = [ModelOptions(), ModelOptions(point_mass=True), ModelOptions(air_brake=False)]
IDS = ["default", "point-mass", "no-air-brake"]


@pytest.fixture(scope="module")
def small(root):
    return load_route(root / SMALL), load_train(root / "configs/consists/HXD1-C80x30.yaml")


def test_banded_lu_solves_an_indefinite_banded_system_like_a_dense_solve():
    """Zero diagonals (the KKT matrix's multiplier rows) need the row interchanges."""
    rng = np.random.default_rng(3)
    n, bw = 60, 4
    a = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - bw), min(n, i + bw + 1)):
            a[i, j] = rng.normal()
    a[np.arange(0, n, 4), np.arange(0, n, 4)] = 0.0
    full = np.zeros((n, 3 * bw + 1))
    for i in range(n):
        for j in range(max(0, i - bw), min(n, i + bw + 1)):
            full[j, 2 * bw + i - j] = a[i, j]
    b = rng.normal(size=(n, 2))
    x = b.copy()
    piv = np.empty(n, dtype=np.int64)
    assert band_factor(full, bw, bw, piv) == 0
    band_solve(full, bw, bw, piv, x)
    assert np.allclose(x, np.linalg.solve(a, b), rtol=0, atol=1e-10)


def test_rounded_curve_is_the_curve_away_from_its_corners_and_smooth_at_them():
    xs, ys, w = np.array([0.0, 10.0, 20.0, 40.0]), np.array([500.0, 500.0, 300.0, 150.0]), 0.2
    x = np.linspace(-5.0, 45.0, 200001)
    v, s, c = piecewise_linear_rounded(x, xs, ys, w)
    exact = piecewise_linear(x, xs, ys)
    near = np.min(np.abs(x[:, None] - xs[None, :]), axis=1) < w / 2
    assert np.array_equal(v[~near], exact[~near])
    dslope = np.abs(np.diff(np.concatenate([[0.0], np.diff(ys) / np.diff(xs), [0.0]])))
    assert np.max(np.abs(v - exact)) <= dslope.max() * w / 8 + 1e-12  # the bound the docstring states
    fd = np.gradient(v, x)
    assert np.max(np.abs(fd - s)[2:-2]) < 1e-3 * np.max(np.abs(s))  # the slope is continuous: C1
    assert np.all(c[~near] == 0.0)


def test_the_scalar_rounded_curve_is_the_rounded_curve():
    """``rounded_curve_at`` (what the compiled cell evaluation runs) gives ``RoundedCurve``'s numbers, on a
    curve alone and on one lying in a longer array (the compiled problem keeps its curves end to end), at
    random speeds, at the points, inside their rounded corners and beyond both ends."""
    rng = np.random.default_rng(11)
    xs, ys, w = np.array([0.0, 10.0, 20.0, 40.0, 41.0]), np.array([500.0, 500.0, 300.0, 150.0, 90.0]), 0.2
    curve = RoundedCurve(xs, ys, w)
    x = np.concatenate([rng.uniform(-5.0, 45.0, 4000), xs, (xs + rng.uniform(-0.1, 0.1, (50, xs.size))).ravel()])
    cx, cy = np.concatenate([[-3.0, 7.0], xs, [1.0]]), np.concatenate([[1.0, 2.0], ys, [5.0]])
    ref = np.array(curve(x))
    for arr_x, arr_y, lo in ((xs, ys, 0), (cx, cy, 2)):
        got = np.array([rounded_curve_at(v, arr_x, arr_y, w, lo, lo + xs.size) for v in x]).T
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0)


def _cell_problems(route, train, options):
    """The traction and the net problem on a 20 m grid, and a journey's form of the first (a stop inside,
    a window on the running time to it)."""
    calc = cell_calculator(route, train, options, 20.0)
    mid = float(calc.s_m[len(calc.s_m) // 2])
    return (CellEnergyProblem(calc, T_SMALL), cell_problem(calc, T_SMALL, 0.8),
            CellEnergyProblem(calc, T_SMALL, stops_m=(mid,), windows=((mid, 100.0, 200.0),)))


@pytest.mark.parametrize("options", MODELS, ids=IDS)
def test_the_compiled_cell_evaluation_is_the_numpy_one(small, options):
    """``values`` / ``derivatives`` / ``hessian`` (compiled, ocp/cell_kernel.py) equal ``values_numpy`` /
    ``derivatives_numpy`` / ``hessian_numpy`` to 1e-12 relative at random points, speeds from rest to above
    the envelope (every branch of the rounded curves), in the traction and the net problem and with a
    journey's window (several global inequalities). A sum over all cells (the objective, the running
    time) is relative to its terms' magnitudes, and a Hessian entry to its cell's largest term: the
    summation order and a power's last bit differ, the formulas do not."""
    route, train = small
    rng = np.random.default_rng(5)
    for prob in _cell_problems(route, train, options):
        N, q, n = prob.N, len(prob.CAPS), len(prob.lb)
        assert prob.model().active.shape == (N, q)
        for _ in range(3):
            x = rng.uniform(0.0, 1.2, n)
            x[0::q + 1] *= rng.uniform(0.0, 1.3, N + 1) * np.maximum(prob.ub[0::q + 1], 0.05)
            y, z, zc = rng.normal(size=N), rng.uniform(0.0, 2.0, (N, q)), rng.uniform(0.0, 2.0, len(prob.cmask))
            a, b = prob.values(x), prob.values_numpy(x)
            xp = x * prob.ref
            terms = np.sum(prob.h * sum(abs(w) * xp[1 + j::q + 1] for j, w in enumerate(prob.cost())))
            assert abs(a.f - b.f) <= 1e-12 * terms / KJ_PER_KWH / prob.e_ref
            np.testing.assert_allclose(a.e, b.e, rtol=1e-12, atol=0)
            np.testing.assert_allclose(a.g, b.g, rtol=1e-12, atol=0)
            np.testing.assert_allclose(a.c, b.c, rtol=1e-12, atol=1e-12 * np.max(np.abs(prob.cconst)) / prob.t_ref)
            da, db = prob.derivatives(x), prob.derivatives_numpy(x)
            for field in ("grad_f", "grad_e", "grad_g", "grad_c"):
                np.testing.assert_allclose(getattr(da, field), getattr(db, field), rtol=1e-12, atol=0, err_msg=field)
            ha, hb = prob.hessian(x, y, z, zc), prob.hessian_numpy(x, y, z, zc)
            scale = np.max(np.abs(hb), axis=(1, 2))[:, None, None]
            assert np.all(np.abs(ha - hb) <= 1e-12 * (np.abs(hb) + scale))
            assert np.count_nonzero(hb) > 2 * N  # the test sees the speeds' blocks


@pytest.mark.parametrize("options", MODELS, ids=IDS)
def test_the_optimum_keeps_the_physics(small, options):
    """On the solved grid: each cell's work-energy balance holds, the forces stay under their curves (and
    traction and the electric brake are off in the neutral span), the speeds under the braking envelope,
    the train at rest at both ends, and the running time within the asked time."""
    route, train = small
    calc = cell_calculator(route, train, options, 20.0)
    sol = solve_cells(calc, T_SMALL)
    h, v, F, B = np.diff(sol.s_m), sol.v_ms, sol.traction_kn, sol.brake_kn
    p, q = v[:-1], v[1:]
    vm = np.sqrt(0.5 * (p * p + q * q))
    prob = CellEnergyProblem(calc, T_SMALL)
    resist = np.asarray([sum(c * kmh(x) ** i for i, c in enumerate(train.resistance_kn)) for x in vm])
    balance = 0.5 * calc.m_eff_t * (q * q - p * p) - h * (F - B - resist - calc.gravity_kn)
    assert np.max(np.abs(balance) / (h * prob.f_ref)) < 1e-6
    assert v[0] == 0.0 and v[-1] == 0.0
    assert np.all(v <= prob.v_cap + 1e-9)
    t = np.sum(2 * h / (p + q))
    assert t <= T_SMALL * (1 + 1e-7)
    assert t >= T_SMALL * (1 - 1e-4)  # the time is used: more of it would save energy
    assert np.all(F >= -1e-6) and np.all(B >= -1e-6)
    tr_cap = piecewise_linear(kmh(vm), train.traction_speed_kmh, train.traction_kn) * calc.traction_allowed
    assert np.all(F <= tr_cap + 0.6)  # the rounded corners: within 0.5 kN of the curve
    spans = neutral_spans_m(route, train.length_m if options.strip else 0.0)
    mid = 0.5 * (sol.s_m[1:] + sol.s_m[:-1])
    inside = np.zeros(mid.size, dtype=bool)
    for a, b in spans:
        inside |= (mid > a) & (mid < b)
    assert inside.any() and np.all(F[inside] == 0.0)
    air = piecewise_linear(kmh(vm), calc.air_brake_speed_kmh, calc.air_brake_kn)
    assert np.all(B[inside] <= air[inside] + 0.6)  # only the air brake in the span (none without it)
    assert sol.energy_kwh == pytest.approx(np.sum(h * F) / KJ_PER_KWH, rel=1e-12)


@pytest.mark.parametrize("options", MODELS, ids=IDS)
def test_nested_grids_converge_so_that_their_difference_bounds_the_error(small, options):
    """Halving every cell shrinks the change of the optimum more than twice (second order once the rest
    points are graded): then the finer grid's error is at most the two grids' difference, the accuracy
    E* states."""
    route, train = small
    e = solve_estar(route, train, options, T_SMALL, tol=1e-12, first_step_m=40.0, finest_step_m=10.0)
    e40, e20, e10 = e.energies_kwh
    assert abs(e40 - e20) / abs(e20 - e10) > 2.0
    assert e.steps_m == (40.0, 20.0, 10.0) and e.cells[1] >= 2 * e.cells[0] and e.cells[2] >= 2 * e.cells[1]
    assert e.accuracy == pytest.approx(abs(e20 - e10) / e10)


def test_e_star_is_below_what_the_calculator_drives_in_the_same_time(small):
    """A four-stage plan (full traction to a cruise speed, held, coast, brake) on the exact calculator
    never uses less energy than E* at its own running time."""
    from locoplan.ocp.bound import energy_bound

    route, train = small
    calc = TractionCalculator(route, train, ModelOptions())
    for cruise in (45.0, 55.0, 65.0):
        for coast in (2800.0, 3200.0):
            res = calc.evaluate(("T", "C", "B"), np.array([[coast, np.nan]]), cruise_kmh=np.array([cruise]))
            if not res.feasible[0]:
                continue
            b = energy_bound(route, train, ModelOptions(), float(res.running_time_s[0]))
            assert res.traction_energy_kwh[0] >= b.energy_kwh * (1 - 5e-4)


@pytest.mark.parametrize("options", MODELS, ids=IDS)
@pytest.mark.slow
def test_a_curve_on_one_mesh_agrees_with_each_time_solved_alone_within_its_stated_accuracy(small, options, tmp_path,
                                                                                          monkeypatch):
    """``energy_bounds`` solves the times between the curve's ends once each, on the finer end's mesh: every
    point lies within its stated accuracy (plus the single solve's own) of E* solved alone at that time, the
    curve falls as the time grows, and each point's slope (the time's multiplier) lies between its chords."""
    from locoplan.ocp import bound as B

    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(B, "_BOUNDS", {})
    monkeypatch.setattr(B, "_WARM", {})
    route, train = small
    t0 = round(1.08 * TractionCalculator(route, train, options).fastest_time_s)
    times = [t0, t0 + 10.0, t0 + 20.0, t0 + 30.0, t0 + 40.0, t0 + 60.0]
    curve = B.energy_bounds(route, train, options, times)
    assert [b.method for b in curve] == [B.METHOD] + [B.CURVE_METHOD] * 4 + [B.METHOD]
    assert all(b.converged and b.accuracy <= B.CURVE_TOL for b in curve)
    assert len({b.cells for b in curve[1:-1]}) == 1 and curve[1].cells == max(curve[0].cells, curve[-1].cells)
    energies = np.array([b.energy_kwh for b in curve])
    assert np.all(np.diff(energies) < 0)
    monkeypatch.setattr(B, "_BOUNDS", {})
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path / "alone"))
    for b in curve:
        alone = B.energy_bound(route, train, options, b.time_s)
        assert abs(b.energy_kwh - alone.energy_kwh) <= (b.accuracy + alone.accuracy) * abs(alone.energy_kwh) + 1e-9
    for k in (1, 2, 3):  # E*(T) is convex: each point's multiplier lies between the chords on either side
        left = (energies[k] - energies[k - 1]) / (times[k] - times[k - 1])
        right = (energies[k + 1] - energies[k]) / (times[k + 1] - times[k])
        assert left - 1e-3 <= curve[k].slope_kwh_per_s <= right + 1e-3
