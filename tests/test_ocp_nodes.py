"""Nodes layer: LG / LGR rules (Golub-Welsch, seed eq. 32-33) and Lagrange differentiation (eq. 20)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.polynomial import legendre as leg

from locoplan.errors import InputError
from locoplan.ocp import nodes

EPS = np.finfo(float).eps
SIZES = list(range(2, 41)) + [47, 48, 64, 100, 150]


def _lgr_reference(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Independent LGR rule: -1 and the roots of P_{n-1} + P_n (numpy companion matrix, polished by
    Newton steps in the Legendre basis); weights 2/n^2 at -1 and (1 - x) / (n^2 P_{n-1}(x)^2)."""
    c = np.zeros(n + 1)
    c[n - 1] = c[n] = 1.0
    dc = leg.legder(c)
    x = np.sort(leg.legroots(c).real)
    for _ in range(3):
        x[1:] -= leg.legval(x[1:], c) / leg.legval(x[1:], dc)
    x[0] = -1.0
    pn1 = leg.legval(x, np.eye(n)[n - 1])
    w = (1.0 - x) / (n * n * pn1 * pn1)
    w[0] = 2.0 / (n * n)
    return x, w


@pytest.mark.parametrize("n", SIZES)
def test_legendre_gauss_matches_numpy_to_machine_precision(n):
    x, w = nodes.legendre_gauss(n)
    xr, wr = leg.leggauss(n)
    assert x.shape == w.shape == (n,)
    np.testing.assert_allclose(x, xr, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(w, wr, rtol=0, atol=32 * EPS)
    assert np.all(np.diff(x) > 0) and -1 < x[0] and x[-1] < 1
    assert math.isclose(w.sum(), 2.0, rel_tol=0, abs_tol=8 * EPS)


@pytest.mark.parametrize("n", [2, 3, 7, 34, 48])
def test_golub_welsch_matrix_and_eq33_weights(n):
    h = nodes.legendre_jacobi_matrix(n)
    k = np.arange(1, n)
    assert np.all(np.diag(h) == 0.0)  # alpha_n = 0
    np.testing.assert_allclose(np.diag(h, 1), k / np.sqrt(4.0 * k * k - 1.0), rtol=0, atol=EPS)  # beta_n
    x, w = nodes.legendre_gauss(n)
    np.testing.assert_allclose(np.linalg.eigvalsh(h), x, rtol=0, atol=8 * EPS)
    # eq. 33 closed form: w_k = 2 / ((1 - tau_k^2) P_n'(tau_k)^2)
    dp = leg.legval(x, leg.legder(np.eye(n + 1)[n]))
    np.testing.assert_allclose(w, 2.0 / ((1.0 - x * x) * dp * dp), rtol=1e-12, atol=0)


@pytest.mark.parametrize("n", SIZES)
def test_legendre_gauss_radau_matches_independent_reference(n):
    x, w = nodes.legendre_gauss_radau(n)
    xr, wr = _lgr_reference(n)
    assert x[0] == -1.0 and np.all(np.diff(x) > 0) and x[-1] < 1.0
    np.testing.assert_allclose(x, xr, rtol=0, atol=16 * EPS)
    # the closed-form reference weights lose a few digits near +1 (P_{n-1} is steep there); the
    # Golub-Welsch weights are the more accurate ones (checked against 40-digit arithmetic)
    np.testing.assert_allclose(w, wr, rtol=0, atol=1e-13)
    assert math.isclose(w.sum(), 2.0, rel_tol=0, abs_tol=16 * EPS)


def _monomial_integrals(k):
    return 0.0 if k % 2 else 2.0 / (k + 1)


@pytest.mark.parametrize("n", [2, 3, 5, 10, 17, 24])
def test_lg_integrates_degree_2n_minus_1_exactly_and_no_more(n):
    x, w = nodes.legendre_gauss(n)
    for k in range(2 * n):
        assert abs(w @ x**k - _monomial_integrals(k)) < 64 * EPS, k
    # a degree-2n polynomial is not integrated exactly: the degree bound is sharp
    p2n = np.eye(2 * n + 1)[2 * n]
    assert abs(w @ leg.legval(x, p2n) - 0.0) > 1e-6


@pytest.mark.parametrize("n", [2, 3, 5, 10, 17, 24])
def test_lgr_integrates_degree_2n_minus_2_exactly_and_no_more(n):
    x, w = nodes.legendre_gauss_radau(n)
    for k in range(2 * n - 1):
        assert abs(w @ x**k - _monomial_integrals(k)) < 64 * EPS, k
    p = np.eye(2 * n)[2 * n - 1]  # P_{2n-1}: integral 0
    assert abs(w @ leg.legval(x, p)) > 1e-6


def _random_legendre_series(deg, seed):
    return np.random.default_rng(seed).standard_normal(deg + 1)


@pytest.mark.parametrize("n", [2, 3, 4, 8, 16, 34, 48])
def test_gauss_differentiation_matrix_exact_up_to_degree_n(n):
    d = nodes.gauss_differentiation_matrix(n)
    support = nodes.gauss_support_points(n)
    assert d.shape == (n, n + 1)
    assert support[0] == -1.0
    np.testing.assert_array_equal(support[1:], nodes.legendre_gauss(n)[0])
    for deg in range(n + 1):
        c = _random_legendre_series(deg, deg)
        exact = leg.legval(support[1:], leg.legder(c))
        err = np.max(np.abs(d @ leg.legval(support, c) - exact))
        assert err <= 1e-12 * max(1.0, np.max(np.abs(exact))) * n, (deg, err)
    np.testing.assert_allclose(d.sum(axis=1), 0.0, atol=1e-12)  # constants have zero derivative


@pytest.mark.parametrize("n", [2, 3, 4, 8, 16, 34, 48])
def test_radau_differentiation_matrix_exact_up_to_degree_n(n):
    d = nodes.radau_differentiation_matrix(n)
    support = nodes.radau_support_points(n)
    assert d.shape == (n, n + 1) and support[0] == -1.0 and support[-1] == 1.0
    for deg in range(n + 1):
        c = _random_legendre_series(deg, 100 + deg)
        exact = leg.legval(support[:-1], leg.legder(c))
        err = np.max(np.abs(d @ leg.legval(support, c) - exact))
        assert err <= 1e-12 * max(1.0, np.max(np.abs(exact))) * n, (deg, err)


def test_differentiation_matrix_matches_eq20_closed_form():
    """Barycentric D equals eq. 20 (b'(tau_k) / ((tau_k - tau_i) b'(tau_i)), b''/(2 b') on the diagonal)."""
    pts = nodes.gauss_support_points(6)
    b = np.poly(pts)
    db, ddb = np.polyder(b), np.polyder(b, 2)
    ref = np.empty((pts.size, pts.size))
    for k, tk in enumerate(pts):
        for i, ti in enumerate(pts):
            ref[k, i] = (np.polyval(ddb, tk) / (2 * np.polyval(db, tk)) if k == i
                         else np.polyval(db, tk) / ((tk - ti) * np.polyval(db, ti)))
    np.testing.assert_allclose(nodes.differentiation_matrix(pts), ref, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(nodes.gauss_differentiation_matrix(6), ref[1:], rtol=1e-11, atol=1e-11)


def test_interpolation_matrix_reproduces_polynomials_and_nodes():
    pts = nodes.gauss_support_points(9)
    t = np.linspace(-1, 1, 41)
    c = _random_legendre_series(9, 7)
    e = nodes.interpolation_matrix(pts, t)
    np.testing.assert_allclose(e @ leg.legval(pts, c), leg.legval(t, c), atol=1e-12)
    np.testing.assert_array_equal(nodes.interpolation_matrix(pts, pts), np.eye(pts.size))
    # large point counts do not overflow (log-scaled barycentric weights)
    big = nodes.gauss_support_points(600)
    assert np.all(np.isfinite(nodes.barycentric_weights(big)))


def test_cached_and_read_only():
    assert nodes.legendre_gauss(12) is nodes.legendre_gauss(12)
    assert nodes.gauss_differentiation_matrix(12) is nodes.gauss_differentiation_matrix(12)
    for arr in (*nodes.legendre_gauss(12), *nodes.legendre_gauss_radau(12), nodes.gauss_differentiation_matrix(12),
                nodes.radau_differentiation_matrix(12), nodes.gauss_support_points(12), nodes.legendre_jacobi_matrix(12)):
        assert not arr.flags.writeable
        with pytest.raises(ValueError):
            arr[0] = 0.0


@pytest.mark.parametrize("bad", [1, 0, -3, 2.5, "3", None, True, nodes.MAX_NODES + 1])
@pytest.mark.parametrize(
    "fn",
    [nodes.legendre_gauss, nodes.legendre_gauss_radau, nodes.gauss_differentiation_matrix,
     nodes.radau_differentiation_matrix],
)
def test_bad_node_counts_raise_input_error(fn, bad):
    with pytest.raises(InputError, match="number of nodes"):
        fn(bad)


def test_bad_points_raise_input_error():
    with pytest.raises(InputError, match="distinct"):
        nodes.differentiation_matrix([0.0, 0.5, 0.5])
    with pytest.raises(InputError, match="finite"):
        nodes.barycentric_weights([0.0, np.nan])
