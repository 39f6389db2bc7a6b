"""Sparrow search algorithm (SSA) of Xue & Shen (2020), the baseline of the ISSA paper (Table 5).

The population is sorted by fitness each iteration and split into three roles:

* producers (discoverers): the best ``PD`` fraction. With alarm value ``R2 ~ U[0, 1)`` below the safety
  threshold ``ST`` no predator is around and they search widely,
  ``X <- X * exp(-i / (alpha * iter_max))`` (i = rank, alpha ~ U(0, 1]); otherwise they fly off,
  ``X <- X + Q * J`` (Q ~ N(0, 1), J a row of ones).
* followers (scroungers): all others. The worse half (rank i > n/2) is starving and flies elsewhere,
  ``X <- Q * exp((X_worst - X) / i^2)``; the rest feed next to the best producer ``X_P``,
  ``X <- X_P + |X - X_P| A^+ J`` with A a row of random +-1 and ``A^+ = A^T (A A^T)^-1 = A^T / d``, so
  every coordinate moves by the same scalar ``sum_j a_j |x_j - x_P,j| / d``.
* scouts (vigilant sparrows): a random ``SD`` fraction of the whole population, whose update replaces the
  one above. At the edge of the group (f > f_best) they move towards the best,
  ``X <- X_best + beta * |X - X_best|`` (beta ~ N(0, 1) per coordinate); the best one itself steps away,
  ``X <- X + K * |X - X_worst| / (f - f_worst + eps)`` (K ~ U[-1, 1]).

Every update rule is a pure module-level function taking its random numbers as arguments, so tests can pin
them; the ``SSA`` class only orders the population and draws the numbers, in a fixed order, from the
generator given to ``setup``.

Choices where the published description leaves room (documented so results can be compared):

* one batch evaluation per iteration: all roles are computed from the positions and fitness known at the
  start of the iteration (the last evaluated ones), ``X_P`` is the updated position of the rank-1 producer and ``X_worst``/``f_worst`` are the
  worst of the current population; ``X_best``/``f_best`` are the best ever found (elitist).
* R2 is drawn once per iteration (one alarm for the whole flock); alpha and Q once per producer.
* the ISSA paper's Table 5 prints "R2 = 0.8": R2 is a random alarm value in SSA, so 0.8 is read as the safety
  threshold ST (the paper itself calls it the "warning threshold").
* the roles are applied in the unit box ``z = (x - lower) / (upper - lower)`` and mapped back. SSA's rules
  hold absolute constants -- a flight of ``Q ~ N(0, 1)``, shrinking towards the origin, ``Q * exp(...)`` --
  so in raw coordinates the algorithm would behave differently for metres and kilometres (in metres a
  fleeing producer moves ~1 m and starving followers collapse onto 0). In the unit box a flight is about
  one search range, shrinking heads to the lower bound, and the run does not depend on the unit. The
  equations themselves are unchanged. (On a 5-D sphere over 0..20 000 m this cut ISSA's median error
  from ~60 m to ~16 m over 30 seeds.) The Levy step of ISSA is affine-invariant and runs in raw units.
* the exponent of the starving-follower rule is clipped to +-700 so it stays finite; ``repair`` then
  brings the row back into the bounds.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from .base import Evaluation, Optimizer, OptimizerParams

__all__ = [
    "SSA",
    "SSAParams",
    "follower_update",
    "n_producers",
    "n_scouts",
    "producer_update",
    "scout_update",
]

_EXP_LIMIT = 700.0  # exp(709) is the largest finite float64


class SSAParams(OptimizerParams):
    """SSA parameters (the ISSA paper's Table 5: PD = 20 %, SD = 10 %, "R2" = 0.8 read as ST)."""

    producer_fraction: float = Field(0.2, gt=0.0, lt=1.0, description="PD: share of producers (discoverers)")
    scout_fraction: float = Field(0.1, ge=0.0, le=1.0, description="SD: share of scouts (vigilant sparrows)")
    safety_threshold: float = Field(0.8, ge=0.5, le=1.0, description="ST: producers flee when the alarm R2 >= ST")


def n_producers(pop_size: int, fraction: float) -> int:
    """Number of producers: ``round(PD * n)``, at least 1 and at most n - 1 (so a follower exists when n >= 2)."""
    return int(min(max(1, round(fraction * pop_size)), max(1, pop_size - 1)))


def n_scouts(pop_size: int, fraction: float) -> int:
    """Number of scouts: ``round(SD * n)``, between 0 and n."""
    return int(min(max(0, round(fraction * pop_size)), pop_size))


def producer_update(
    X: np.ndarray, rank: np.ndarray, alpha: np.ndarray, R2: float, ST: float, Q: np.ndarray, max_iter: int
) -> np.ndarray:
    """SSA producer (discoverer) update (Xue & Shen 2020, eq. 3).

    X: (k, d) producers' positions (variable unit, e.g. m). rank: (k,) their 1-based rank in the sorted
    population. alpha: (k,) draws from U(0, 1]. R2: alarm value in [0, 1]. ST: safety threshold.
    Q: (k,) draws from N(0, 1). max_iter: iterations of the run.
    Returns new (k, d) positions: ``X * exp(-rank / (alpha * max_iter))`` if R2 < ST, else ``X + Q``
    (Q added to every coordinate).
    """
    X = np.asarray(X, dtype=float)
    if R2 < ST:
        factor = np.exp(-np.asarray(rank, dtype=float) / (np.asarray(alpha, dtype=float) * max_iter))
        return X * factor[:, None]
    return X + np.asarray(Q, dtype=float)[:, None]


def follower_update(
    X: np.ndarray,
    rank: np.ndarray,
    X_P: np.ndarray,
    X_worst: np.ndarray,
    Q: np.ndarray,
    A: np.ndarray,
    pop_size: int,
) -> np.ndarray:
    """SSA follower (scrounger) update (Xue & Shen 2020, eq. 4).

    X: (k, d) followers' positions. rank: (k,) 1-based ranks in the sorted population of ``pop_size``.
    X_P: (d,) best producer position after the producer update. X_worst: (d,) worst position.
    Q: (k,) draws from N(0, 1). A: (k, d) random signs (+1/-1).
    Returns new (k, d) positions: ``Q * exp((X_worst - X) / rank^2)`` where rank > pop_size / 2,
    else ``X_P + (sum_j A_j |X_j - X_P,j| / d)`` on every coordinate (the ``|X - X_P| A^+ J`` product).
    """
    X = np.asarray(X, dtype=float)
    rank = np.asarray(rank, dtype=float)
    X_P = np.asarray(X_P, dtype=float)
    d = X.shape[1]
    exponent = np.clip((np.asarray(X_worst, dtype=float) - X) / rank[:, None] ** 2, -_EXP_LIMIT, _EXP_LIMIT)
    starving = np.asarray(Q, dtype=float)[:, None] * np.exp(exponent)
    shift = (np.asarray(A, dtype=float) * np.abs(X - X_P)).sum(axis=1) / d
    feeding = X_P + shift[:, None]
    return np.where((rank > pop_size / 2)[:, None], starving, feeding)


def scout_update(
    X: np.ndarray,
    f: np.ndarray,
    X_best: np.ndarray,
    f_best: float,
    X_worst: np.ndarray,
    f_worst: float,
    beta: np.ndarray,
    K: np.ndarray,
    eps: float = 1e-50,
) -> np.ndarray:
    """SSA scout (vigilant sparrow) update (Xue & Shen 2020, eq. 5).

    X: (k, d) scouts' positions, f: (k,) their fitness. X_best, f_best: best position/fitness found.
    X_worst, f_worst: worst of the current population. beta: (k, d) (or broadcastable) N(0, 1) draws.
    K: (k,) U[-1, 1] draws. eps: guards the division when f == f_worst.
    Returns new (k, d) positions: ``X_best + beta * |X - X_best|`` where f > f_best, else
    ``X + K * |X - X_worst| / (f - f_worst + eps)``.
    """
    X = np.asarray(X, dtype=float)
    f = np.asarray(f, dtype=float)
    X_best = np.asarray(X_best, dtype=float)
    edge = X_best + np.asarray(beta, dtype=float) * np.abs(X - X_best)
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        centre = X + np.asarray(K, dtype=float)[:, None] * np.abs(X - np.asarray(X_worst, dtype=float)) / (
            (f - f_worst)[:, None] + eps
        )
    return np.where((f > f_best)[:, None], edge, centre)


class SSA(Optimizer):
    """Standard sparrow search algorithm with the ISSA paper's feasible initialisation and infeasible replacement.

    One ask/tell round per iteration (pop_size evaluations plus any replacement samples).
    """

    name = "ssa"
    Params = SSAParams

    def _init_state(self) -> None:
        # the roles work in the unit box (see module docstring); a zero-width variable keeps span 1
        self._span = np.where(self.upper > self.lower, self.upper - self.lower, 1.0)

    def _producers(self, Xp: np.ndarray, rank: np.ndarray, R2: float, t: int, best: np.ndarray) -> np.ndarray:
        """Producer update (unit box) of this algorithm; draws its random numbers (alpha, Q) from ``self.rng``."""
        k = Xp.shape[0]
        alpha = 1.0 - self.rng.random(k)  # U(0, 1]: alpha = 0 would divide by zero
        Q = self.rng.standard_normal(k)
        return producer_update(Xp, rank, alpha, R2, self.params.safety_threshold, Q, self.params.max_iter)

    def _ssa_update(self) -> np.ndarray:
        """Producer, follower and scout updates of the current population, back in the variables' unit.

        Rows come out sorted by the fitness they had (not yet repaired or evaluated).
        """
        p = self.params
        n, d = self.X.shape
        t = self.iteration + 1  # 1-based iteration being computed
        order = np.argsort(self.fitness, kind="stable")
        Xs, fs = (self.X[order] - self.lower) / self._span, self.fitness[order]
        best = (self.best_x - self.lower) / self._span
        rank = np.arange(1, n + 1)
        n_p = n_producers(n, p.producer_fraction)

        R2 = float(self.rng.random())
        X_new = Xs.copy()
        X_new[:n_p] = self._producers(Xs[:n_p], rank[:n_p], R2, t, best)

        k = n - n_p
        Q = self.rng.standard_normal(k)
        A = 2.0 * self.rng.integers(0, 2, size=(k, d)) - 1.0
        X_new[n_p:] = follower_update(Xs[n_p:], rank[n_p:], X_new[0], Xs[-1], Q, A, n)

        n_s = n_scouts(n, p.scout_fraction)
        idx = self.rng.choice(n, size=n_s, replace=False)
        beta = self.rng.standard_normal((n_s, d))
        K = self.rng.uniform(-1.0, 1.0, n_s)
        X_new[idx] = scout_update(Xs[idx], fs[idx], best, self.best_fitness, Xs[-1], fs[-1], beta, K)
        return self.lower + X_new * self._span

    def _ask(self) -> np.ndarray:
        return self._repair(self._ssa_update())

    def _accept_update(self, X: np.ndarray, ev: Evaluation) -> None:
        """The ISSA paper's step 5 (replace infeasible), then adopt the population and update the best."""
        X, ev, _ = self._replace_infeasible(X, ev)
        self.X, self.fitness = X, ev.fitness
        self._update_best(X, ev)

    def _tell(self, X: np.ndarray, ev: Evaluation) -> None:
        self._accept_update(X, ev)
        self._end_iteration()
