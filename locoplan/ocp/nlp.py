"""What the free-end transcriptions (Gauss, CVP) share: IPOPT's settings, the initial guess on the
normalised end, and turning a model's expressions into CasADi columns.

The guess is a trajectory on ``sigma = s / s_end`` in [0, 1] with a nominal end ``s_end`` (for the
minimum-time problem: ``sigma = t / t_f``), interpolated linearly onto any node set.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, NamedTuple

import casadi as ca
import numpy as np

from ..errors import InputError

IPOPT_QUIET = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"}
"""IPOPT options that silence all solver output."""
IPOPT_DEFAULTS = {**IPOPT_QUIET, "ipopt.max_iter": 3000, "ipopt.tol": 1e-10, "ipopt.acceptable_tol": 1e-7}
"""The tight tolerances every free-end transcription solves with."""


def ipopt_solver(name: str, nlp: dict, ipopt_options: dict | None):
    """A silent IPOPT solver with :data:`IPOPT_DEFAULTS` (``ipopt_options`` override them)."""
    return ca.nlpsol(name, "ipopt", nlp, {**IPOPT_DEFAULTS, **(ipopt_options or {})})


@dataclass(frozen=True)
class Guess:
    """Initial guess on a normalised grid ``sigma = s / s_end`` in [0, 1] (linear interpolation).

    ``states`` is ``n_x x m`` and ``controls`` ``n_u x m`` for the ``m`` grid points ``sigma``;
    ``final_time`` is the guessed end ``s_end`` (a time [s] in the minimum-time problem).
    """

    sigma: np.ndarray
    states: np.ndarray
    controls: np.ndarray
    final_time: float

    def state_at(self, sigma) -> np.ndarray:
        return np.array([np.interp(sigma, self.sigma, row) for row in np.atleast_2d(self.states)])

    def control_at(self, sigma) -> np.ndarray:
        return np.array([np.interp(sigma, self.sigma, row) for row in np.atleast_2d(self.controls)])


def as_column(value, n: int, what: str):
    """A model's result (list, tuple, number or CasADi expression) as an ``n x 1`` CasADi column."""
    if isinstance(value, (list, tuple)):
        value = ca.vertcat(*value)
    if not isinstance(value, (ca.SX, ca.MX)):
        value = ca.SX(value)
    if value.shape != (n, 1):
        if value.shape == (1, n):
            value = value.T
        else:
            raise InputError(f"{what} must return {n} values, got shape {value.shape}")
    return value


class SinglePhase(NamedTuple):
    """The single phase of a free-end problem as a transcription needs it: its functions of ``(x, u, t)``
    with the phase parameters bound in, the path constraints' count, the sizes, scales and nominal length."""

    phase: object
    dynamics: Callable
    lagrange: Callable | None
    path: Callable | None
    n_path: int
    nx: int
    nu: int
    state_scale: np.ndarray
    control_scale: np.ndarray
    length: float


def phase_functions(problem) -> SinglePhase:
    """The single phase of a free-end ``problem`` and its model as functions of ``(x, u, t)``: the
    phase parameters are read once (they must be constant over the phase) and bound in."""
    phase = problem.phase
    if problem.free_end is None:
        raise InputError("Gauss / CVP transcription: needs a free-end single-phase problem (free_end)")
    model = phase.model
    p = {k: float(np.ravel(v)[0]) for k, v in phase.params(np.array([phase.s0])).items()}
    dyn = lambda x, u, t: model.dynamics(x, u, t, p)  # noqa: E731
    lag = None if model.integrand is None else (lambda x, u, t: model.integrand(x, u, t, p))
    path = None if model.path is None else (lambda x, u, t: model.path(x, u, t, p))
    return SinglePhase(phase, dyn, lag, path, model.n_path if model.path is not None else 0, model.n_x, model.n_u,
                       np.asarray(model.state_scale, dtype=float), np.asarray(model.control_scale, dtype=float),
                       float(phase.length))


def final_bounds(problem) -> tuple[np.ndarray, np.ndarray]:
    """Lower / upper bounds of the final state: the problem's ``final_lower`` / ``final_upper`` inside
    the phase's state bounds."""
    ph = problem.phase
    lo = np.maximum(np.array(ph.state_lower, dtype=float), np.array(problem.final_lower, dtype=float))
    hi = np.minimum(np.array(ph.state_upper, dtype=float), np.array(problem.final_upper, dtype=float))
    return lo, hi
