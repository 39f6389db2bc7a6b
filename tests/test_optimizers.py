"""Swarm optimisers (seed 002 sec. 3): pinned update rules, Levy statistics, infeasible handling, convergence."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from locoplan.errors import InfeasibleError, InputError
from locoplan.optimize import issa, pso, ssa
from locoplan.optimize.base import (
    Evaluation,
    NoFeasibleCandidateError,
    Problem,
    check_evaluation,
    replace_infeasible,
    sample_feasible,
)
from locoplan.runner import load_optimizer_params
from locoplan.optimize.registry import ALGORITHMS, get_algorithm

SHIFT = np.array([2.5, -4.0, 6.0, -7.5, 1.0])  # optimum of the toy sphere, away from the origin and the bounds


class Sphere:
    """Shifted 5-D sphere on [-10, 10]^5; ``infeasible(X) -> bool mask`` marks a forbidden part of the box.

    Records every evaluated row, so tests can check what the optimisers asked for.
    """

    def __init__(self, infeasible=None, lo=-10.0, hi=10.0, shift=SHIFT):
        self.n_var = len(shift)
        self.lower = np.full(self.n_var, lo)
        self.upper = np.full(self.n_var, hi)
        self.shift = np.asarray(shift, dtype=float)
        self.infeasible = infeasible
        self.calls = 0
        self.rows: list[np.ndarray] = []

    def evaluate(self, X):
        self.calls += 1
        self.rows.append(np.array(X))
        feasible = np.ones(len(X), bool) if self.infeasible is None else ~self.infeasible(X)
        return Evaluation(((X - self.shift) ** 2).sum(axis=1), feasible)

    def sample(self, n, rng):
        return rng.uniform(self.lower, self.upper, (n, self.n_var))

    def repair(self, X):
        return np.clip(X, self.lower, self.upper)


def half_box_infeasible(X):
    """Infeasible where x0 > 3 or x1 > 0: about 2/3 of the box; the optimum (2.5, -4, ...) is feasible, 0.5 from the edge."""
    return (X[:, 0] > 3.0) | (X[:, 1] > 0.0)


def run(name, problem, seed, **kw):
    return get_algorithm(name)().setup(problem, np.random.default_rng(seed), **kw).run()


# ------------------------------------------------------------------------------------ SSA update rules


def test_ssa_producer_update_search_and_flee():
    X = np.array([[1.0, 2.0], [4.0, -2.0]])
    rank, alpha, Q = np.array([1, 2]), np.array([0.5, 0.25]), np.array([0.7, -1.2])
    # R2 < ST: X * exp(-rank / (alpha * max_iter)) = X * [exp(-0.2), exp(-0.8)]
    out = ssa.producer_update(X, rank, alpha, R2=0.3, ST=0.8, Q=Q, max_iter=10)
    assert_allclose(out, [[0.81873075, 1.63746151], [1.79731586, -0.89865793]], rtol=1e-8)
    # R2 >= ST (equality included): X + Q on every coordinate
    for R2 in (0.9, 0.8):
        assert_allclose(ssa.producer_update(X, rank, alpha, R2, 0.8, Q, 10), [[1.7, 2.7], [2.8, -3.2]])


def test_ssa_follower_update_feeding_and_starving():
    X = np.array([[1.0, 3.0], [2.0, -6.0]])
    rank = np.array([2, 3])  # pop_size 4: rank 2 feeds (<= n/2), rank 3 starves
    X_P, X_worst = np.array([0.0, 1.0]), np.array([5.0, 3.0])
    Q, A = np.array([0.5, -2.0]), np.array([[1.0, -1.0], [-1.0, -1.0]])
    out = ssa.follower_update(X, rank, X_P, X_worst, Q, A, pop_size=4)
    # row 0: X_P + (1*|1-0| - 1*|3-1|) / 2 = X_P - 0.5 on both coordinates
    # row 1: -2 * exp([5-2, 3+6] / 3^2) = -2 * [e^(1/3), e^1]
    assert_allclose(out, [[-0.5, 0.5], [-2.79122485, -5.43656366]], rtol=1e-8)


def test_ssa_scout_update_edge_and_centre():
    X = np.array([[1.0, 1.0], [3.0, 4.0]])
    f = np.array([2.0, 5.0])
    beta, K = np.array([[0.5, -1.0], [2.0, 0.1]]), np.array([0.5, -0.3])
    out = ssa.scout_update(X, f, np.array([0.0, 2.0]), 2.0, np.array([6.0, 0.0]), 10.0, beta, K)
    # row 0 is the best (f == f_best): X + 0.5 * [5, 1] / (2 - 10) ; row 1: X_best + [2, 0.1] * [3, 2]
    assert_allclose(out, [[0.6875, 0.9375], [6.0, 2.2]])


def test_role_counts():
    assert (ssa.n_producers(50, 0.2), ssa.n_scouts(50, 0.1)) == (10, 5)
    assert ssa.n_producers(2, 0.2) == 1 and ssa.n_producers(3, 0.99) == 2  # always one producer and one follower


# ------------------------------------------------------------------------------------ ISSA rules (seed 002)


def test_issa_producer_update_eq5():
    X, X_best = np.array([[2.0, 4.0], [10.0, 0.0]]), np.array([4.0, 4.0])
    r, Q = np.array([0.5, 0.2]), np.array([1.0, -1.0])
    # X + w (X_best - X) r with w = 0.5: [2 + 0.5*2*0.5, 4], [10 - 0.5*6*0.2, 0 + 0.5*4*0.2]
    assert_allclose(issa.producer_update(X, X_best, 0.5, r, R2=0.1, ST=0.8, Q=Q), [[2.5, 4.0], [9.4, 0.4]])
    assert_allclose(issa.producer_update(X, X_best, 0.5, r, R2=0.8, ST=0.8, Q=Q), [[3.0, 5.0], [9.0, -1.0]])


def test_adaptive_weight_quadratic():
    assert issa.adaptive_weight(0, 100, 0.9, 0.4) == pytest.approx(0.9)
    assert issa.adaptive_weight(100, 100, 0.9, 0.4) == pytest.approx(0.4)
    assert issa.adaptive_weight(50, 100, 0.9, 0.4) == pytest.approx(0.9 - 0.5 * 0.25)  # 0.775, not linear 0.65
    t = np.arange(0, 101)
    w = issa.adaptive_weight(t, 100, 0.9, 0.4)
    assert_allclose((0.9 - w) / 0.5, (t / 100) ** 2, atol=1e-12)
    assert np.all(np.diff(w) < 0)


def test_mantegna_sigma_and_pinned_levy_step():
    sigma = issa.mantegna_sigma(1.5)
    assert round(sigma, 4) == 0.6966
    # |8|^(2/3) = 4 and |0.125|^(2/3) = 0.25
    assert_allclose(issa.levy_step(np.array([1.0, -2.0]), np.array([8.0, -0.125]), 1.5), [sigma / 4, -8 * sigma])
    assert issa.mantegna_sigma(1.0) == pytest.approx(1.0)  # Cauchy case: [1 * 1 / (1 * 1 * 1)]^1


def _abs_levy_cdf(m, eta, sigma):
    """P(|mu / |v|^(1/eta)| <= m) = E_v[erf(m |v|^(1/eta) / (sigma sqrt 2))], v ~ N(0, 1), by quadrature."""
    from scipy import integrate

    def integrand(v):
        return math.erf(m * v ** (1 / eta) / (sigma * math.sqrt(2))) * 2 * math.exp(-v * v / 2) / math.sqrt(2 * math.pi)

    return integrate.quad(integrand, 0, np.inf, limit=200)[0]


def test_levy_step_distribution_matches_quadrature():
    """Sampled Mantegna steps vs the exact law of mu/|v|^(1/eta), computed independently by quadrature.

    N = 400 000: the median's standard error is ~0.2 % (tolerance 1 %); P(|s| > 10) ~ 0.0126 has a binomial
    standard error of ~1.4 % (tolerance 7 %). The tail index (log10 of P(>10)/P(>100)) must be eta = 1.5
    within 0.15: heavy tails, where a Gaussian of the same scale has P(>10) ~ 1e-46.
    """
    from scipy import optimize

    eta, sigma, n = 1.5, 0.6965745025576967, 400_000
    rng = np.random.default_rng(2024)
    steps = np.abs(issa.levy_step(rng.standard_normal(n), rng.standard_normal(n), eta))
    median_ref = optimize.brentq(lambda m: _abs_levy_cdf(m, eta, sigma) - 0.5, 1e-3, 100.0)  # 0.63100
    assert np.median(steps) == pytest.approx(median_ref, rel=0.01)
    p10_ref = 1 - _abs_levy_cdf(10.0, eta, sigma)  # 0.01261
    p10, p100 = np.mean(steps > 10), np.mean(steps > 100)
    assert p10 == pytest.approx(p10_ref, rel=0.07)
    assert math.log10(p10 / p100) == pytest.approx(eta, abs=0.15)


def test_levy_probability_and_perturb():
    assert [issa.levy_probability(t, 100) for t in (0, 25, 100)] == pytest.approx([1.0, 0.75, 0.0])
    # l = 0.1 * ([2, 4] - [1, 1]) = [0.1, 0.3]; X + l * [0.5, -2]
    out = issa.levy_perturb(np.array([[2.0, 4.0]]), np.array([1.0, 1.0]), np.array([[0.5, -2.0]]), 0.1)
    assert_allclose(out, [[2.05, 3.4]])


def test_greedy_accept_keeps_better_and_never_infeasible():
    X_old = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    X_new = np.array([[9.0, 9.0], [8.0, 8.0], [7.0, 7.0], [6.0, 6.0]])
    f_old, f_new = np.ones(4), np.array([0.5, 2.0, 1.0, 0.1])
    X, f, accepted = issa.greedy_accept(X_old, f_old, X_new, f_new, None, np.array([True, True, True, False]))
    assert_array_equal(accepted, [True, False, True, False])  # better, worse, tie (eq. 9 ">="), infeasible
    assert_array_equal(X, [[9, 9], [1, 1], [7, 7], [3, 3]])
    assert_array_equal(f, [0.5, 1.0, 1.0, 1.0])
    assert_array_equal(X_old[0], [0, 0])  # inputs untouched


# ------------------------------------------------------------------------------------ PSO rules


def test_pso_velocity_clamp_and_move():
    V, X, P, G = np.array([[1.0, -1.0]]), np.zeros((1, 2)), np.array([[2.0, 0.0]]), np.array([1.0, -4.0])
    r1, r2 = np.array([[0.5, 0.25]]), np.array([[0.25, 0.5]])
    # 0.5*[1,-1] + 2*[0.5,0.25]*[2,0] + 2*[0.25,0.5]*[1,-4] = [3, -4.5], clamped to +-[10, 3]
    V_new = pso.pso_velocity(V, X, P, G, 0.5, 2.0, 2.0, r1, r2, np.array([10.0, 3.0]))
    assert_allclose(V_new, [[3.0, -3.0]])
    assert_allclose(pso.pso_move(X, V_new), [[3.0, -3.0]])
    assert [pso.inertia_weight(t, 100, 0.9, 0.4) for t in (0, 50, 100)] == pytest.approx([0.9, 0.65, 0.4])
    # Vmax = 4 read against a 20 km reference: 20 % of each variable's range
    assert_allclose(pso.velocity_clamp(np.array([0.0, 100.0]), np.array([20000.0, 600.0]), 4.0, 20.0), [4000, 100])


# ------------------------------------------------------------------------------------ feasibility helpers


def test_check_evaluation_non_finite_is_infeasible_and_shapes_checked():
    ev = check_evaluation(Evaluation(np.array([1.0, np.nan, np.inf]), np.array([True, True, True])), 3)
    assert_array_equal(ev.feasible, [True, False, False])
    with pytest.raises(ValueError):
        check_evaluation(Evaluation(np.zeros(2), np.ones(2, bool)), 3)


def test_sample_feasible_fills_small_region_and_raises_when_empty():
    problem = Sphere(infeasible=lambda X: X[:, 0] > -9.6)  # 2 % of the box is feasible
    X, ev, n_eval = sample_feasible(problem, np.random.default_rng(0), 50)
    assert X.shape == (50, 5) and ev.feasible.all() and (X[:, 0] <= -9.6).all()
    assert n_eval == sum(len(r) for r in problem.rows) and problem.calls <= 20

    nowhere = Sphere(infeasible=lambda X: np.ones(len(X), bool))
    with pytest.raises(NoFeasibleCandidateError) as info:
        issa.ISSA().setup(nowhere, np.random.default_rng(0), max_sample_batches=3)
    assert isinstance(info.value, InfeasibleError) and info.value.exit_code == 1
    assert "0 of" in str(info.value) and nowhere.calls == 3


def test_replace_infeasible_refills_only_bad_rows():
    problem = Sphere(infeasible=half_box_infeasible)
    X = np.array([[0.0, -1.0, 0, 0, 0], [5.0, -1.0, 0, 0, 0], [0.0, 1.0, 0, 0, 0]])
    ev = problem.evaluate(X)
    X_new, ev_new, replaced, n_eval = replace_infeasible(problem, np.random.default_rng(1), X, ev)
    assert_array_equal(replaced, [False, True, True])
    assert_array_equal(X_new[0], X[0]) and ev_new.feasible.all() and n_eval > 0
    assert not half_box_infeasible(X_new).any()
    assert_allclose(ev_new.fitness, problem.evaluate(X_new).fitness)
    assert_array_equal(X[1], [5.0, -1.0, 0, 0, 0])  # input untouched


@pytest.mark.parametrize("name", ["issa", "ssa", "pso"])
def test_infeasible_region_final_population_and_best_feasible(name):
    problem = Sphere(infeasible=half_box_infeasible)
    opt = get_algorithm(name)().setup(problem, np.random.default_rng(3))
    assert not half_box_infeasible(opt.population).any()  # step 2: feasible initial population
    res = opt.run()
    assert res.n_infeasible_replaced > 0  # step 5 happened
    assert not half_box_infeasible(opt.population).any()
    assert not half_box_infeasible(res.best_x[None]).any()
    assert res.best_fitness < 1.0  # the optimum is feasible, 0.5 from the forbidden part
    assert res.n_evaluations == sum(len(r) for r in problem.rows)
    rows = np.concatenate(problem.rows)
    assert (rows >= problem.lower).all() and (rows <= problem.upper).all()  # every candidate was repaired


# ------------------------------------------------------------------------------------ whole algorithms


@pytest.mark.parametrize("name", ["issa", "ssa", "pso"])
def test_same_seed_same_result_different_seed_different_result(name):
    kw = dict(pop_size=20, max_iter=15)
    a = run(name, Sphere(infeasible=half_box_infeasible), 7, **kw)
    b = run(name, Sphere(infeasible=half_box_infeasible), 7, **kw)
    c = run(name, Sphere(infeasible=half_box_infeasible), 8, **kw)
    assert_array_equal(a.best_x, b.best_x)
    assert_array_equal(a.history, b.history)
    assert (a.n_evaluations, a.n_infeasible_replaced) == (b.n_evaluations, b.n_infeasible_replaced)
    assert not np.array_equal(a.best_x, c.best_x)


@pytest.mark.parametrize("name", ["issa", "ssa", "pso"])
def test_ask_tell_by_hand_equals_run_and_callback(name):
    calls = []
    problem = Sphere()
    opt = get_algorithm(name)().setup(problem, np.random.default_rng(5), pop_size=20, max_iter=12)
    res = opt.run(callback=lambda it, best: calls.append((it, best)))
    assert [it for it, _ in calls] == list(range(1, 13))
    assert_array_equal([b for _, b in calls], res.history)
    assert len(res.history) == 12 and np.all(np.diff(res.history) <= 0)
    assert res.best_fitness == res.history[-1] == pytest.approx(((res.best_x - SHIFT) ** 2).sum())

    problem2 = Sphere()
    opt2 = get_algorithm(name)().setup(problem2, np.random.default_rng(5), pop_size=20, max_iter=12)
    while not opt2.done:
        X = opt2.ask()
        assert_array_equal(X, opt2.ask())  # asking twice gives the same candidates
        opt2.tell(X, problem2.evaluate(X))
    assert_array_equal(opt2.result().best_x, res.best_x)
    with pytest.raises(RuntimeError):
        opt2.ask()


@pytest.mark.parametrize("name, tol", [("issa", 5e-2), ("ssa", 1.0), ("pso", 1e-3)])
def test_minimises_shifted_sphere(name, tol):
    """5-D sphere shifted to (2.5, -4, 6, -7.5, 1) on [-10, 10]^5, 50 individuals x 100 iterations, seeds 0-2.

    A random initial population starts around f ~ 10-30. Over 30 seeds the worst results were ISSA 8e-3,
    SSA 0.41, PSO 3e-6; the tolerances leave a margin above those.
    """
    for seed in range(3):
        res = run(name, Sphere(), seed)
        assert res.history.shape == (100,)
        assert res.best_fitness < tol, (name, seed, res.best_fitness)


def test_sphere_in_metres_issa():
    """Same sphere over 0..20 000 m: scale-free behaviour, error well under 1 % of the range (200 m)."""
    shift = np.array([2500.0, 7000.0, 11000.0, 15500.0, 18000.0])
    res = run("issa", Sphere(lo=0.0, hi=20000.0, shift=shift), 0)
    assert np.abs(res.best_x - shift).max() < 200.0


def test_problem_protocol_runtime_checkable():
    assert isinstance(Sphere(), Problem)


# ------------------------------------------------------------------------------------ registry and parameter files


def test_registry_names_and_unknown_name():
    from locoplan.optimize.names import ALGORITHM_NAMES

    assert set(ALGORITHMS) == {"issa", "ssa", "pso"}
    assert tuple(ALGORITHMS) == ALGORITHM_NAMES  # the help's list (read without loading the optimisers) is the registry's
    assert get_algorithm("ISSA") is issa.ISSA and get_algorithm("pso") is pso.PSO
    with pytest.raises(InputError) as info:
        get_algorithm("ga")
    assert "issa, pso, ssa" in str(info.value)


def test_shipped_parameter_files_hold_table5():
    p = load_optimizer_params("issa")
    assert (p.pop_size, p.max_iter, p.producer_fraction, p.scout_fraction, p.safety_threshold) == (50, 100, 0.2, 0.1, 0.8)
    assert (p.w_max, p.w_min, p.levy_eta, p.levy_scale) == (0.9, 0.4, 1.5, 0.1)
    s = load_optimizer_params("ssa")
    assert (s.producer_fraction, s.scout_fraction, s.safety_threshold) == (0.2, 0.1, 0.8)
    q = load_optimizer_params("pso")
    assert (q.c1, q.c2, q.v_max, q.pop_size, q.max_iter) == (2.0, 2.0, 4.0, 50, 100)
    for name in ALGORITHMS:  # the files and the built-in defaults agree
        assert load_optimizer_params(name) == get_algorithm(name).Params()
        get_algorithm(name)().setup(Sphere(), np.random.default_rng(0), **load_optimizer_params(name).model_dump())


def test_bad_parameter_file_names_file_field_and_line(tmp_path):
    path = tmp_path / "issa.yaml"
    path.write_text("schema: locoplan/optimizer@1\nalgorithm: issa\nw_maxx: 0.9\nproducer_fraction: 1.5\n")
    with pytest.raises(InputError) as info:
        load_optimizer_params("issa", path)
    found = {(p.field, p.line) for p in info.value.problems}
    assert found == {("w_maxx", 3), ("producer_fraction", 4)}
    assert all(p.file == str(path) for p in info.value.problems)

    path.write_text("schema: locoplan/optimizer@1\nalgorithm: pso\n")
    with pytest.raises(InputError, match="algorithm"):
        load_optimizer_params("issa", path)
    path.write_text("schema: [unclosed\n")
    with pytest.raises(InputError, match="not valid YAML"):
        load_optimizer_params("issa", path)
    with pytest.raises(InputError, match="no such file"):
        load_optimizer_params("issa", tmp_path / "missing.yaml")


def test_setup_rejects_bad_parameters():
    with pytest.raises(InputError, match="w_min"):
        issa.ISSA().setup(Sphere(), np.random.default_rng(0), w_min=0.95)
    with pytest.raises(InputError, match="unknown parameter"):
        pso.PSO().setup(Sphere(), np.random.default_rng(0), vmax=4.0)
    opt = ssa.SSA().setup(Sphere(), np.random.default_rng(0), pop_size=np.int64(10), max_iter=2)  # numpy ints accepted
    assert opt.population.shape == (10, 5)
