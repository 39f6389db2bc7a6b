"""Quadrature nodes, weights and Lagrange differentiation matrices on [-1, 1].

Layer 1 of the optimal-control stack (nodes -> transcription -> problem -> solve). Everything here is
pure: the functions keyed on an integer ``n`` are cached with :func:`functools.lru_cache` and return
*read-only* NumPy arrays, so a caller can never corrupt the cache.

* Legendre-Gauss (LG) nodes and weights by the Golub-Welsch eigenvalue method, exactly as in the
  paper's Theorem 1 and eq. 32-33: the symmetric tridiagonal Jacobi matrix has ``alpha_n = 0`` on the
  diagonal and ``beta_n = n / sqrt(4 n^2 - 1)`` beside it; its eigenvalues are the roots of ``P_n``
  and the weights are ``w_k = mu_0 v_{1k}^2 = 2 v_{1k}^2`` (``v_{1k}`` = first component of the k-th
  normalised eigenvector). Eq. 33 of the paper quotes the equivalent closed form
  ``2 / ((1 - tau_k^2) P_n'(tau_k)^2)``.
* Legendre-Gauss-Radau (LGR) nodes and weights (left end point ``-1`` included) by Golub's
  modification of the same Jacobi matrix (the last diagonal entry is changed so that ``-1`` is an
  eigenvalue), so the LGR rule comes from one symmetric eigenproblem too.
* Lagrange differentiation matrices (the paper's eq. 19-20) in barycentric form with the "negative sum
  trick" on the diagonal, which is the numerically stable way of writing eq. 20.

Conventions for the pseudospectral methods:

* Gauss pseudospectral method (Benson / Huntington, the paper's eq. 17-24): the state is interpolated on the
  ``n + 1`` support points ``(-1, tau_1, ..., tau_n)`` and collocated at the ``n`` LG points, so
  :func:`gauss_differentiation_matrix` is ``n x (n + 1)``.
* Radau pseudospectral method (Garg et al.): the state is interpolated on ``(tau_1 = -1, ..., tau_n,
  +1)`` and collocated at the ``n`` LGR points, so :func:`radau_differentiation_matrix` is
  ``n x (n + 1)`` as well.
"""

from __future__ import annotations

from functools import lru_cache
from numbers import Integral

import numpy as np

from ..errors import InputError

__all__ = [
    "MAX_NODES",
    "barycentric_matrix",
    "barycentric_weights",
    "differentiation_matrix",
    "gauss_differentiation_matrix",
    "gauss_support_points",
    "interpolation_matrix",
    "legendre_gauss",
    "legendre_gauss_radau",
    "legendre_jacobi_matrix",
    "radau_differentiation_matrix",
    "radau_support_points",
]

#: Largest node count accepted (far beyond anything a pseudospectral segment needs; keeps the
#: dense eigenproblem and the ``n x (n + 1)`` matrices small).
MAX_NODES = 1000


def _check_n(n, what: str, minimum: int = 2) -> int:
    if isinstance(n, bool) or not isinstance(n, Integral):
        raise InputError(f"{what}: the number of nodes must be an integer, got {n!r}")
    n = int(n)
    if n < minimum:
        raise InputError(f"{what}: the number of nodes must be at least {minimum}, got {n}")
    if n > MAX_NODES:
        raise InputError(f"{what}: the number of nodes must be at most {MAX_NODES}, got {n}")
    return n


def _readonly(*arrays: np.ndarray):
    for a in arrays:
        a.setflags(write=False)
    return arrays if len(arrays) > 1 else arrays[0]


def _as_points(points, what: str) -> np.ndarray:
    x = np.array(points, dtype=float).reshape(-1)
    if x.size < 1 or not np.all(np.isfinite(x)):
        raise InputError(f"{what}: points must be a non-empty sequence of finite numbers")
    if np.unique(x).size != x.size:
        raise InputError(f"{what}: points must be distinct")
    return x


# --------------------------------------------------------------------------------------------------
# Golub-Welsch
# --------------------------------------------------------------------------------------------------


@lru_cache(maxsize=None)
def legendre_jacobi_matrix(n: int) -> np.ndarray:
    """The ``n x n`` symmetric tridiagonal matrix ``H`` of the paper's Theorem 1 for the Legendre weight.

    Diagonal ``alpha_k = 0``; off-diagonal ``beta_k = k / sqrt(4 k^2 - 1)``, ``k = 1 .. n-1``
    (the paper's eq. 32). Its eigenvalues are the roots of the degree-``n`` Legendre polynomial.
    """
    n = _check_n(n, "Legendre-Gauss nodes")
    k = np.arange(1, n, dtype=float)
    beta = k / np.sqrt(4.0 * k * k - 1.0)
    h = np.diag(beta, 1) + np.diag(beta, -1)
    return _readonly(h)


def _golub_welsch(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lam, vec = np.linalg.eigh(h)
    # mu_0 = int_{-1}^{1} 1 dtau = 2 (the paper's eq. 33 in its eigenvector form)
    w = 2.0 * vec[0, :] ** 2
    return lam, w


def _symmetrise(x: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Average the rule with its mirror image (the exact rule is symmetric); removes ~1 ulp of
    asymmetry left by the eigen-solver. Zero is set exactly for odd ``n``."""
    x = 0.5 * (x - x[::-1])
    w = 0.5 * (w + w[::-1])
    return x, w


@lru_cache(maxsize=None)
def legendre_gauss(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` Legendre-Gauss nodes (ascending, in the open interval (-1, 1)) and weights.

    Exact for polynomials up to degree ``2 n - 1``. Raises :class:`InputError` for ``n < 2``.
    """
    n = _check_n(n, "Legendre-Gauss nodes")
    x, w = _golub_welsch(np.array(legendre_jacobi_matrix(n)))
    x, w = _symmetrise(x, w)
    # scale so that the weights add up to 2 exactly up to rounding (eigenvector normalisation)
    w = w * (2.0 / w.sum())
    return _readonly(x, w)


@lru_cache(maxsize=None)
def legendre_gauss_radau(n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` Legendre-Gauss-Radau nodes (ascending, ``x[0] = -1``) and weights.

    Golub's modification of the Jacobi matrix: with ``J`` the ``(n-1) x (n-1)`` Legendre matrix and
    ``a = -1`` the prescribed node, solve ``(J - a I) delta = beta_{n-1}^2 e_{n-1}`` and use
    ``alpha_{n-1} = a + delta_{n-1}`` as the last diagonal entry of the ``n x n`` matrix. Its
    eigenvalues are ``-1`` and the roots of ``(P_{n-1} + P_n) / (1 + tau)``; the weights come from the
    eigenvectors exactly as for LG. Exact for polynomials up to degree ``2 n - 2``.
    """
    n = _check_n(n, "Legendre-Gauss-Radau nodes")
    a = -1.0
    k = np.arange(1, n, dtype=float)
    beta = k / np.sqrt(4.0 * k * k - 1.0)  # beta_1 .. beta_{n-1}
    j = np.diag(beta[:-1], 1) + np.diag(beta[:-1], -1)  # (n-1) x (n-1)
    rhs = np.zeros(n - 1)
    rhs[-1] = beta[-1] ** 2
    delta = np.linalg.solve(j - a * np.eye(n - 1), rhs)
    h = np.zeros((n, n))
    h[: n - 1, : n - 1] = j
    h[n - 2, n - 1] = h[n - 1, n - 2] = beta[-1]
    h[n - 1, n - 1] = a + delta[-1]
    x, w = _golub_welsch(h)
    order = np.argsort(x)
    x, w = x[order], w[order]
    x[0] = -1.0  # the prescribed node, exactly
    w = w * (2.0 / w.sum())
    return _readonly(x, w)


# --------------------------------------------------------------------------------------------------
# Barycentric Lagrange interpolation / differentiation (generic points)
# --------------------------------------------------------------------------------------------------


def barycentric_weights(points) -> np.ndarray:
    """Barycentric weights ``lambda_j = 1 / prod_{k != j} (x_j - x_k)``, scaled so ``max |lambda| = 1``.

    Computed with logarithms so that no product over- or underflows for large point counts.
    """
    x = _as_points(points, "barycentric weights")
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    logabs = -np.sum(np.log(np.abs(diff)), axis=1)
    sign = np.prod(np.sign(diff), axis=1)
    lam = sign * np.exp(logabs - logabs.max())
    return lam


def differentiation_matrix(points) -> np.ndarray:
    """Square Lagrange differentiation matrix ``D[k, i] = L_i'(x_k)`` on the given points (eq. 20).

    Off-diagonal: ``(lambda_i / lambda_k) / (x_k - x_i)``; diagonal by the negative sum trick
    (each row of ``D`` annihilates constants), which is more accurate than ``b''/(2 b')``.
    """
    x = _as_points(points, "differentiation matrix")
    lam = barycentric_weights(x)
    diff = x[:, None] - x[None, :]
    np.fill_diagonal(diff, 1.0)
    d = (lam[None, :] / lam[:, None]) / diff
    np.fill_diagonal(d, 0.0)
    np.fill_diagonal(d, -d.sum(axis=1))
    return d


def interpolation_matrix(points, targets) -> np.ndarray:
    """Matrix ``E`` with ``E[m, i] = L_i(t_m)``: values at ``targets`` of the Lagrange interpolant of
    values given at ``points`` (second barycentric formula; exact hits return the nodal value)."""
    x = _as_points(points, "interpolation matrix")
    t = np.array(targets, dtype=float).reshape(-1)
    if not np.all(np.isfinite(t)):
        raise InputError("interpolation matrix: targets must be finite numbers")
    return barycentric_matrix(x, barycentric_weights(x), t)


def barycentric_matrix(x: np.ndarray, lam: np.ndarray, t: np.ndarray) -> np.ndarray:
    """:func:`interpolation_matrix` from points ``x`` with their barycentric weights ``lam`` already
    known (no checks: for callers that evaluate the same point sets many times)."""
    diff = t[:, None] - x[None, :]
    exact = diff == 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        terms = lam[None, :] / diff
        e = terms / terms.sum(axis=1, keepdims=True)
    rows = exact.any(axis=1)
    if rows.any():
        e[rows] = exact[rows].astype(float)
    return e


# --------------------------------------------------------------------------------------------------
# Pseudospectral support points and differentiation matrices (cached, read-only)
# --------------------------------------------------------------------------------------------------


@lru_cache(maxsize=None)
def gauss_support_points(n: int) -> np.ndarray:
    """GPM state support points ``(-1, tau_1, ..., tau_n)``: the initial point plus ``n`` LG points."""
    x, _ = legendre_gauss(n)
    return _readonly(np.concatenate(([-1.0], x)))


@lru_cache(maxsize=None)
def gauss_differentiation_matrix(n: int) -> np.ndarray:
    """GPM differentiation matrix, ``n x (n + 1)``: rows = the ``n`` LG collocation points, columns =
    the support points ``(-1, tau_1, ..., tau_n)`` (the paper's eq. 19-20, Benson's form)."""
    d = differentiation_matrix(gauss_support_points(n))[1:, :]
    return _readonly(np.ascontiguousarray(d))


@lru_cache(maxsize=None)
def radau_support_points(n: int) -> np.ndarray:
    """Radau state support points ``(tau_1 = -1, ..., tau_n, +1)``: ``n`` LGR points plus the end."""
    x, _ = legendre_gauss_radau(n)
    return _readonly(np.concatenate((x, [1.0])))


@lru_cache(maxsize=None)
def radau_differentiation_matrix(n: int) -> np.ndarray:
    """Radau (LGR) differentiation matrix, ``n x (n + 1)``: rows = the ``n`` LGR collocation points,
    columns = the support points ``(tau_1 = -1, ..., tau_n, +1)``."""
    d = differentiation_matrix(radau_support_points(n))[:-1, :]
    return _readonly(np.ascontiguousarray(d))
