"""One run's settings as one frozen value: :class:`RunSettings`, built once (a command line, a study file's run)
and passed down whole (``runner.make_context``, ``runs.journey.plan_journey``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from .sim.calculator import ModelOptions

if TYPE_CHECKING:
    from .optimize.base import OptimizerParams


@dataclass(frozen=True)
class RunSettings:
    """What decides one run's result besides its route and train. Checked where a context is made
    (``runner.make_context``: errors name the field).

    options: the model. time_s: planned running time [s] (None: the route's schedule); need_time: whether one is
    required (False: a strategy that ignores the timetable). tolerance_s: punctuality window +- [s] (None: the
    route's schedule tolerance, else 1 % of T0); window: rank inside it (False: eq. 10 alone). objective:
    what the energy terms count, ``traction`` or ``net``. builder: sequence builder (None: the general one).
    algorithm, params (or params_path, a file to read them from; neither: the algorithm's defaults), weights
    (w_time, w_energy of eq. 10), seed: the optimiser. e_min_kwh: E_min of eq. 11 (None: computed).
    yardstick: report each plan's gap to the optimum E*."""

    options: ModelOptions = field(default_factory=ModelOptions)
    time_s: float | None = None
    tolerance_s: float | None = None
    window: bool = True
    need_time: bool = True
    objective: str = "traction"
    builder: str | None = None
    algorithm: str = "issa"
    params: OptimizerParams | None = None
    params_path: str | None = None
    weights: tuple[float, float] = (0.5, 0.5)
    seed: int = 1
    e_min_kwh: float | None = None
    yardstick: bool = False

    def __post_init__(self):
        if self.options is None:  # (None: the default model, as before the settings were one value)
            object.__setattr__(self, "options", ModelOptions())
        object.__setattr__(self, "weights", tuple(self.weights))

    def replace(self, **changes) -> RunSettings:
        """A copy with ``changes`` (field=value) made."""
        return dataclasses.replace(self, **changes)
