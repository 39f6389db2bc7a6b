"""Improved sparrow search algorithm (ISSA) of the ISSA paper, section 3: adaptive weight + Levy flight + greedy.

Changes to the standard SSA (``ssa.py``; followers and scouts are unchanged):

* eq. 5 producer update with a non-linear adaptive weight
  ``w(t) = w_max - (w_max - w_min) * (t / t_max)^2``:
  ``X <- X + w * (X_best - X) * r`` (r ~ U[0, 1)) if R2 < ST, else ``X <- X + Q * J``;
* eq. 6-8 Levy-flight perturbation, applied to each sparrow with probability ``1 - P`` where
  ``P = 1 - t / t_max`` (i.e. when ``rand > P``): ``X <- X + l (.) Levy``, ``l = 0.1 * (X - X_best)``,
  ``Levy = mu / |v|^(1/eta)`` with ``mu ~ N(0, sigma_mu^2)``, ``v ~ N(0, 1)`` (Mantegna's algorithm,
  eta = 1.5, sigma_mu from eq. 8);
* eq. 9 greedy acceptance: the perturbed position replaces the sparrow only if its fitness is not worse.

Iteration order (the ISSA paper's sec. 3.2 steps 4-7): SSA roles update -> evaluate -> remove infeasible and refill
with feasible samples (step 5) -> Levy perturbation of the chosen sparrows -> evaluate them -> greedy
acceptance (an infeasible perturbed position is never accepted) -> update the global best. So an ISSA
iteration is two ask/tell rounds; the second only evaluates the perturbed rows.

Choices where the paper leaves room (plus those listed in ``ssa.py``; as there, the role updates including
eq. 5 run in the unit box of the bounds, which matters only for the absolute ``Q`` flight; the Levy step is
affine-invariant and runs in the variables' own unit):

* t runs 1..t_max within a run (MATLAB-style iteration counter), so the last iteration uses w_min and
  perturbs every sparrow (P = 0); ``adaptive_weight`` itself gives w(0) = w_max.
* "rand" in eq. 5 is one U[0, 1) number per producer, so a producer moves along the line towards X_best
  (eq. 5 writes Q * J for a per-row scalar and rand without J; per-row keeps switching points ordered).
* the "(+)" of eq. 6 is read as the entry-wise product (as in cuckoo search); the text's "matrix product"
  does not fit the shapes. One Levy number per coordinate.
* eq. 9's legend swaps "before" and "after"; the rule implemented is the one the text describes: keep the
  better of the two, the perturbed one on a tie (eq. 9's ">=").
* perturbed rows that ``repair`` maps back onto the unperturbed position (e.g. the best sparrow itself,
  whose l = 0) are not evaluated again.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, model_validator

from .base import Evaluation
from .ssa import SSA, SSAParams

__all__ = [
    "ISSA",
    "ISSAParams",
    "adaptive_weight",
    "greedy_accept",
    "levy_perturb",
    "levy_probability",
    "levy_step",
    "mantegna_sigma",
    "producer_update",
]


class ISSAParams(SSAParams):
    """ISSA parameters (the ISSA paper's Table 5: PD = 20 %, SD = 10 %, ST = 0.8, w_max = 0.9, w_min = 0.4; eta = 1.5)."""

    w_max: float = Field(0.9, ge=0.0, description="adaptive weight at the first iteration (eq. 5)")
    w_min: float = Field(0.4, ge=0.0, description="adaptive weight at the last iteration (eq. 5)")
    levy_eta: float = Field(1.5, gt=0.0, lt=2.0, description="Levy exponent eta of Mantegna's algorithm (eq. 7-8)")
    levy_scale: float = Field(0.1, gt=0.0, description="step control factor: l = levy_scale * (X - X_best) (eq. 6)")

    @model_validator(mode="after")
    def _weights_ordered(self) -> ISSAParams:
        if self.w_min > self.w_max:
            raise ValueError(f"w_min ({self.w_min}) must not exceed w_max ({self.w_max})")
        return self


def adaptive_weight(t: float, t_max: float, w_max: float, w_min: float) -> float:
    """Non-linear adaptive weight of the ISSA paper's eq. 5: ``w_max - (w_max - w_min) * (t / t_max)^2``.

    t: current iteration, t_max: iterations of the run (same unit). Returns the dimensionless weight,
    w_max at t = 0 falling quadratically to w_min at t = t_max.
    """
    return w_max - (w_max - w_min) * (t / t_max) ** 2


def producer_update(
    X: np.ndarray, X_best: np.ndarray, w: float, r: np.ndarray, R2: float, ST: float, Q: np.ndarray
) -> np.ndarray:
    """ISSA producer update, the ISSA paper's eq. 5.

    X: (k, d) producers' positions (e.g. m). X_best: (d,) best position found. w: adaptive weight.
    r: (k,) U[0, 1) draws (or (k, d) for one per coordinate). R2: alarm value, ST: safety threshold.
    Q: (k,) N(0, 1) draws. Returns new (k, d) positions: ``X + w * (X_best - X) * r`` if R2 < ST, else
    ``X + Q`` on every coordinate.
    """
    X = np.asarray(X, dtype=float)
    if R2 < ST:
        r = np.asarray(r, dtype=float)
        r = r[:, None] if r.ndim == 1 else r
        return X + w * (np.asarray(X_best, dtype=float) - X) * r
    return X + np.asarray(Q, dtype=float)[:, None]


def mantegna_sigma(eta: float) -> float:
    """Standard deviation sigma_mu of the numerator in Mantegna's algorithm (the ISSA paper's eq. 8).

    ``[Gamma(1 + eta) sin(pi eta / 2) / (eta Gamma((1 + eta) / 2) 2^((eta - 1) / 2))]^(1 / eta)``;
    0.6966 for eta = 1.5. Dimensionless.
    """
    num = math.gamma(1.0 + eta) * math.sin(math.pi * eta / 2.0)
    den = eta * math.gamma((1.0 + eta) / 2.0) * 2.0 ** ((eta - 1.0) / 2.0)
    return (num / den) ** (1.0 / eta)


def levy_step(u: np.ndarray, v: np.ndarray, eta: float) -> np.ndarray:
    """Levy-distributed steps by Mantegna's algorithm (the ISSA paper's eq. 7).

    u, v: arrays of standard normal N(0, 1) draws, same shape. eta: Levy exponent (1.5).
    Returns ``sigma_mu * u / |v|^(1 / eta)`` (dimensionless, same shape): mu = sigma_mu * u ~ N(0, sigma_mu^2),
    v ~ N(0, 1) as eq. 8 requires.
    """
    u = np.asarray(u, dtype=float)
    v = np.abs(np.asarray(v, dtype=float))
    v = np.where(v == 0.0, np.finfo(float).tiny, v)  # a draw of exactly 0 would give inf
    return mantegna_sigma(eta) * u / v ** (1.0 / eta)


def levy_probability(t: float, t_max: float) -> float:
    """Adaptive selection probability P of the ISSA paper's eq. 6: ``1 - t / t_max`` (perturb when rand > P)."""
    return 1.0 - t / t_max


def levy_perturb(X: np.ndarray, X_best: np.ndarray, step: np.ndarray, scale: float = 0.1) -> np.ndarray:
    """Levy-flight perturbation of the ISSA paper's eq. 6: ``X + scale * (X - X_best) * step`` (entry-wise).

    X: (k, d) positions, X_best: (d,) best position, step: (k, d) Levy steps, scale: the 0.1 of
    ``l = 0.1 (X - X_best)``. Returns new (k, d) positions in the unit of X.
    """
    X = np.asarray(X, dtype=float)
    return X + scale * (X - np.asarray(X_best, dtype=float)) * np.asarray(step, dtype=float)


def greedy_accept(
    X_old: np.ndarray,
    f_old: np.ndarray,
    X_new: np.ndarray,
    f_new: np.ndarray,
    feasible_old: np.ndarray | None = None,
    feasible_new: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Greedy acceptance of the ISSA paper's eq. 9, row by row.

    X_old, X_new: (k, d) positions before/after the perturbation; f_old, f_new: (k,) their fitness.
    feasible_old, feasible_new: optional (k,) bool (default all True). A new row is accepted if it is
    feasible and ``f_new <= f_old`` (or the old row is infeasible). Returns ``(X, f, accepted)``: new (k, d)
    and (k,) arrays and the (k,) bool mask of accepted rows.
    """
    f_old = np.asarray(f_old, dtype=float)
    f_new = np.asarray(f_new, dtype=float)
    ok_old = np.ones(f_old.shape, bool) if feasible_old is None else np.asarray(feasible_old, bool)
    ok_new = np.ones(f_new.shape, bool) if feasible_new is None else np.asarray(feasible_new, bool)
    accepted = ok_new & (~ok_old | (f_new <= f_old))
    X = np.where(accepted[:, None], np.asarray(X_new, dtype=float), np.asarray(X_old, dtype=float))
    return X, np.where(accepted, f_new, f_old), accepted


class ISSA(SSA):
    """The ISSA paper's improved SSA: eq. 5 producers, Levy perturbation with greedy acceptance (eq. 6-9)."""

    name = "issa"
    Params = ISSAParams

    def _init_state(self) -> None:
        super()._init_state()
        self._levy_rows: np.ndarray | None = None
        self._levy_candidates: np.ndarray | None = None

    def _producers(self, Xp: np.ndarray, rank: np.ndarray, R2: float, t: int, best: np.ndarray) -> np.ndarray:
        p = self.params
        k = Xp.shape[0]
        r = self.rng.random(k)
        Q = self.rng.standard_normal(k)
        w = adaptive_weight(t, p.max_iter, p.w_max, p.w_min)
        return producer_update(Xp, best, w, r, R2, p.safety_threshold, Q)

    def _ask(self) -> np.ndarray:
        if self._levy_candidates is not None:
            return self._levy_candidates
        return self._repair(self._ssa_update())

    def _tell(self, X: np.ndarray, ev: Evaluation) -> None:
        if self._levy_candidates is None:
            self._accept_update(X, ev)  # steps 4-5
            if not self._prepare_levy():
                self._end_iteration()
            return
        # step 6 (second round): greedy acceptance of the evaluated perturbations
        rows = self._levy_rows
        X_acc, f_acc, _ = greedy_accept(self.X[rows], self.fitness[rows], X, ev.fitness, None, ev.feasible)
        self.X = self.X.copy()
        self.fitness = self.fitness.copy()
        self.X[rows], self.fitness[rows] = X_acc, f_acc
        self._update_best(X, ev)  # step 7
        self._levy_rows = self._levy_candidates = None
        self._end_iteration()

    def _prepare_levy(self) -> bool:
        """Draw step 6's perturbations; returns False if no sparrow is perturbed this iteration."""
        p = self.params
        n, d = self.X.shape
        t = self.iteration + 1
        chosen = self.rng.random(n) > levy_probability(t, p.max_iter)
        u = self.rng.standard_normal((n, d))
        v = self.rng.standard_normal((n, d))
        step = levy_step(u, v, p.levy_eta)
        with np.errstate(over="ignore", invalid="ignore"):
            cand = levy_perturb(self.X, self.best_x, step, p.levy_scale)
        cand = self._repair(cand)
        chosen &= np.any(cand != self.X, axis=1)  # unchanged rows need no evaluation
        if not chosen.any():
            return False
        self._levy_rows = np.flatnonzero(chosen)
        self._levy_candidates = cand[chosen]
        return True
