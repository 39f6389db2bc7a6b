"""Inertia-weight particle swarm optimisation (PSO), the second baseline of the ISSA paper (Table 5).

Standard global-best PSO (Shi & Eberhart 1998) per particle i and coordinate j:

    V <- clamp(w V + c1 r1 (P_i - X) + c2 r2 (G - X), -v_clamp, v_clamp),   X <- X + V

with r1, r2 ~ U[0, 1) per coordinate, P_i the particle's best position, G the swarm's best, and an inertia
weight falling linearly from w_max = 0.9 to w_min = 0.4 over the run (Table 5 gives no inertia weight; this is
the usual Shi & Eberhart schedule). Table 5: c1 = c2 = 2.

Velocity clamp. Table 5 gives ``Vmax = 4`` without a unit. Our variables are switching-point positions in
metres on a route of about 20 km, so 4 m would freeze the swarm and 4 x range would disable the clamp. The
paper states the route length in km (Table 1: 20 km), so Vmax = 4 is read as 4 km on the 20 km route, i.e.
a fifth of the search range. The clamp is therefore made relative to each variable's own range:

    v_clamp = v_max / v_max_reference * (upper - lower),  with v_max = 4, v_max_reference = 20  (= 20 % of range)

which is scale-free (the same behaviour for any route length or unit) and a customary size for a PSO
velocity limit. Both numbers are parameters (``pso.yaml``).

Initial velocities are U(-v_clamp, v_clamp). After each move the swarm is evaluated, infeasible particles
are replaced by fresh feasible samples (the ISSA paper's sec. 3.2 step 5, shared with SSA/ISSA); a replaced
particle keeps its personal best and restarts with zero velocity. Personal bests only ever hold feasible
positions. Positions are ``repair``-ed (clipped/sorted) after the move; velocities are not altered.

The update rules are pure functions taking their random numbers as arguments; the ``PSO`` class only draws
them, in a fixed order, from the generator given to ``setup``.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field, model_validator

from .base import Evaluation, Optimizer, OptimizerParams

__all__ = ["PSO", "PSOParams", "inertia_weight", "pso_move", "pso_velocity", "velocity_clamp"]


class PSOParams(OptimizerParams):
    """PSO parameters (the ISSA paper's Table 5: c1 = c2 = 2, Vmax = 4; inertia 0.9 -> 0.4 is our choice)."""

    c1: float = Field(2.0, ge=0.0, description="cognitive learning factor")
    c2: float = Field(2.0, ge=0.0, description="social learning factor")
    v_max: float = Field(4.0, gt=0.0, description="Vmax of Table 5 (km on the paper's 20 km route)")
    v_max_reference: float = Field(
        20.0, gt=0.0, description="length Vmax is measured against: clamp = v_max / v_max_reference * range"
    )
    w_max: float = Field(0.9, ge=0.0, description="inertia weight at the first iteration")
    w_min: float = Field(0.4, ge=0.0, description="inertia weight at the last iteration")

    @model_validator(mode="after")
    def _weights_ordered(self) -> PSOParams:
        if self.w_min > self.w_max:
            raise ValueError(f"w_min ({self.w_min}) must not exceed w_max ({self.w_max})")
        return self


def inertia_weight(t: float, t_max: float, w_max: float, w_min: float) -> float:
    """Linearly decreasing inertia weight: ``w_max - (w_max - w_min) * t / t_max`` (dimensionless)."""
    return w_max - (w_max - w_min) * t / t_max


def velocity_clamp(lower: np.ndarray, upper: np.ndarray, v_max: float, v_max_reference: float) -> np.ndarray:
    """Per-variable velocity limit ``v_max / v_max_reference * (upper - lower)``, in the variables' unit per iteration."""
    return v_max / v_max_reference * (np.asarray(upper, dtype=float) - np.asarray(lower, dtype=float))


def pso_velocity(
    V: np.ndarray,
    X: np.ndarray,
    P_best: np.ndarray,
    G_best: np.ndarray,
    w: float,
    c1: float,
    c2: float,
    r1: np.ndarray,
    r2: np.ndarray,
    v_clamp: np.ndarray | float,
) -> np.ndarray:
    """Inertia-weight PSO velocity update.

    V, X, P_best: (n, d) velocities (unit/iteration), positions and personal bests; G_best: (d,) swarm best.
    w, c1, c2: inertia and learning factors. r1, r2: (n, d) U[0, 1) draws. v_clamp: (d,) or scalar limit.
    Returns the new (n, d) velocity ``clip(w V + c1 r1 (P_best - X) + c2 r2 (G_best - X), -v_clamp, v_clamp)``.
    """
    X = np.asarray(X, dtype=float)
    V_new = (
        w * np.asarray(V, dtype=float)
        + c1 * np.asarray(r1, dtype=float) * (np.asarray(P_best, dtype=float) - X)
        + c2 * np.asarray(r2, dtype=float) * (np.asarray(G_best, dtype=float) - X)
    )
    v_clamp = np.asarray(v_clamp, dtype=float)
    return np.clip(V_new, -v_clamp, v_clamp)


def pso_move(X: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Position update ``X + V`` (n, d); the caller repairs the result into the bounds."""
    return np.asarray(X, dtype=float) + np.asarray(V, dtype=float)


class PSO(Optimizer):
    """Global-best inertia-weight PSO with feasible initialisation and infeasible replacement."""

    name = "pso"
    Params = PSOParams

    def _init_state(self) -> None:
        p = self.params
        self.v_clamp = velocity_clamp(self.lower, self.upper, p.v_max, p.v_max_reference)
        self.V = self.rng.uniform(-1.0, 1.0, self.X.shape) * self.v_clamp
        self.P = self.X.copy()
        self.f_P = self.fitness.copy()
        self._V_pending: np.ndarray | None = None

    def _ask(self) -> np.ndarray:
        p = self.params
        t = self.iteration + 1
        w = inertia_weight(t, p.max_iter, p.w_max, p.w_min)
        r1 = self.rng.random(self.X.shape)
        r2 = self.rng.random(self.X.shape)
        self._V_pending = pso_velocity(self.V, self.X, self.P, self.best_x, w, p.c1, p.c2, r1, r2, self.v_clamp)
        return self._repair(pso_move(self.X, self._V_pending))

    def _tell(self, X: np.ndarray, ev: Evaluation) -> None:
        X, ev, replaced = self._replace_infeasible(X, ev)
        self.V = self._V_pending.copy()
        self.V[replaced] = 0.0
        self.X, self.fitness = X, ev.fitness
        better = ev.fitness < self.f_P  # every row is feasible after the replacement
        self.P = np.where(better[:, None], X, self.P)
        self.f_P = np.where(better, ev.fitness, self.f_P)
        self._update_best(X, ev)
        self._end_iteration()
