"""Multi-phase optimal control problems, described with numbers and callables (no transcription here).

Layer 2 of the multi-phase stack (nodes -> phase / problem -> transcription -> train problem -> solve),
shaped like dymos' and yapss' phases:

* a :class:`PhaseModel` is the physics: state and control names, the dynamics ``dx/ds``, the
  objective integrand, path constraints ``g <= 0``; every callable takes ``(x, u, s, p)`` with ``x``
  and ``u`` lists of per-state / per-control operands (numpy arrays or CasADi column vectors: the
  same code serves the NLP and its numerical checks), ``s`` the independent variable and ``p`` a
  dict of numeric per-point parameters (e.g. the gravity force at ``s``);
* a :class:`Phase` is one stretch ``[s0, s1]`` of the independent variable with its own bounds and
  parameters (``params(s)``), using a model;
* a :class:`MultiPhaseProblem` chains phases: every state is continuous from one phase into the
  next (the linkage), the first phase starts from ``initial_state``, the last ends in
  ``final_lower .. final_upper``; the objective is the sum of the phases' integrals.

Free end (the two-stage Gauss paper). With ``free_end = (lo, hi)`` the end of the single phase is a decision
variable in ``[lo, hi]`` (a free final time): ``phases[0].s1`` is then only its nominal value, which
scales it in the NLP. ``mayer(x0, xf, s_end)`` adds a terminal term to the objective (the running
time ``t_f`` of the minimum-time problem). The Gauss and CVP transcriptions (:mod:`~locoplan.ocp.gauss`,
:mod:`~locoplan.ocp.cvp`) solve such single-phase problems, with parameters constant over the phase;
the Radau transcription (:mod:`~locoplan.ocp.radau`) solves fixed-end multi-phase ones.

Singular ends. A train starts and stops at rest, where ``dt/ds = 1/v`` is infinite. With
``rest_start`` / ``rest_end`` the transcription maps the first / last mesh interval quadratically
(``s - s0 ~ sigma^2``), on which the states are smooth again, and at the very first point uses the
model's ``singular_start(x, u, s, p)``: the limit of ``dx / d sqrt(s - s0)`` there (``start_path``
holds the conditions that limit needs, e.g. a positive starting acceleration).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import InputError


@dataclass(frozen=True)
class PhaseModel:
    """The physics of a phase. ``path(x, u, s, p)`` returns ``n_path`` expressions bounded above by 0;
    ``integrand`` the objective per unit of ``s`` (``None``: no Lagrange term, the problem's ``mayer``
    is the whole objective). ``state_scale`` / ``control_scale`` are nominal
    magnitudes used to scale the NLP (they do not change the solution)."""

    states: tuple[str, ...]
    controls: tuple[str, ...]
    dynamics: Callable
    integrand: Callable | None
    state_scale: tuple[float, ...]
    control_scale: tuple[float, ...]
    path: Callable | None = None
    n_path: int = 0
    singular_start: Callable | None = None
    start_path: Callable | None = None
    n_start_path: int = 0
    control_paths: tuple[int | None, ...] = ()
    """For each control, the row of ``path`` that is its speed-dependent upper bound (or None)."""

    @property
    def n_x(self) -> int:
        return len(self.states)

    @property
    def n_u(self) -> int:
        return len(self.controls)


@dataclass(frozen=True)
class Phase:
    """``[s0, s1]`` with constant bounds on states and controls and the parameters ``params(s)``
    (a dict of arrays shaped like ``s``); ``info`` is free text for reports (limit, gradient, ...)."""

    name: str
    s0: float
    s1: float
    model: PhaseModel
    params: Callable[[np.ndarray], dict]
    state_lower: tuple[float, ...]
    state_upper: tuple[float, ...]
    control_lower: tuple[float, ...]
    control_upper: tuple[float, ...]
    info: dict = field(default_factory=dict)

    @property
    def length(self) -> float:
        return self.s1 - self.s0


@dataclass(frozen=True)
class MultiPhaseProblem:
    """Consecutive phases with continuous states; rest-to-rest ends optional (see the module text).

    ``initial_state``: a number fixes a state at the start, ``None`` leaves it free;
    ``final_lower`` / ``final_upper``: bounds on the states at the end; ``objective_scale``: nominal
    magnitude of the objective (scaling only); ``free_end`` / ``mayer``: see the module text."""

    phases: tuple[Phase, ...]
    initial_state: tuple[float | None, ...]
    final_lower: tuple[float, ...]
    final_upper: tuple[float, ...]
    objective_scale: float = 1.0
    rest_start: bool = False
    rest_end: bool = False
    free_end: tuple[float, float] | None = None
    mayer: Callable | None = None

    def __post_init__(self):
        if not self.phases:
            raise InputError("multi-phase problem: needs at least one phase")
        nx = self.phases[0].model.n_x
        for what, values in (("initial_state", self.initial_state), ("final_lower", self.final_lower),
                             ("final_upper", self.final_upper)):
            if len(tuple(values)) != nx:
                raise InputError(f"multi-phase problem: {what} needs {nx} values, got {len(tuple(values))}")
        if self.free_end is not None:
            lo, hi = (float(v) for v in self.free_end)
            if len(self.phases) != 1:
                raise InputError("multi-phase problem: a free end needs a single phase")
            if not self.phases[0].s0 < lo <= hi:
                raise InputError(f"multi-phase problem: free end bounds need s0 < lower <= upper, got ({lo}, {hi})")
        if self.phases[0].model.integrand is None and self.mayer is None:
            raise InputError("multi-phase problem: needs an integrand or a Mayer term")
        model = self.phases[0].model
        for a, b in zip(self.phases, self.phases[1:]):
            if abs(a.s1 - b.s0) > 1e-9 * max(1.0, abs(a.s1)):
                raise InputError(f"multi-phase problem: phase '{b.name}' starts at {b.s0:g}, not where "
                                 f"'{a.name}' ends ({a.s1:g})")
            if b.model.states != model.states or b.model.controls != model.controls:
                raise InputError("multi-phase problem: linked phases must share states and controls")
        for p in self.phases:
            if not p.s1 > p.s0:
                raise InputError(f"multi-phase problem: phase '{p.name}' has no length ({p.s0:g} .. {p.s1:g})")
        if self.rest_start and model.singular_start is None:
            raise InputError("multi-phase problem: a rest start needs the model's singular_start")

    @property
    def model(self) -> PhaseModel:
        return self.phases[0].model

    @property
    def s0(self) -> float:
        return self.phases[0].s0

    @property
    def s1(self) -> float:
        return self.phases[-1].s1

    @property
    def phase(self) -> Phase:
        """The only phase of a single-phase problem."""
        if len(self.phases) != 1:
            raise InputError(f"expected a single-phase problem, got {len(self.phases)} phases")
        return self.phases[0]

    def phase_at(self, s) -> np.ndarray:
        """Index of the phase holding each position ``s`` (a boundary belongs to the later phase)."""
        starts = np.array([p.s0 for p in self.phases])
        return np.clip(np.searchsorted(starts, np.asarray(s, dtype=float), side="right") - 1, 0, len(self.phases) - 1)
