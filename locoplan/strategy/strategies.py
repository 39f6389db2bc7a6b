"""Built-in driving strategies, in a registry: name -> function(calculator, **kw) -> Plan.

Later strategies (energy-saving, four-stage, proposed; seed 002 section 4.2.3) register here too,
and the CLI's ``--strategy`` choices come from the registry keys.
"""

from __future__ import annotations

from typing import Callable

from ..errors import InputError, Problem
from ..model.plan import Plan
from ..sim.calculator import TractionCalculator

StrategyFn = Callable[..., Plan]
STRATEGIES: dict[str, StrategyFn] = {}


def register(name: str):
    def deco(fn: StrategyFn) -> StrategyFn:
        STRATEGIES[name] = fn
        return fn
    return deco


def get_strategy(name: str) -> StrategyFn:
    try:
        return STRATEGIES[name]
    except KeyError:
        raise InputError(Problem("", "--strategy", f"unknown strategy {name!r} (one of: {', '.join(sorted(STRATEGIES))})")) from None


@register("time-saving")
def time_saving(calc: TractionCalculator, **_) -> Plan:
    """The fastest run (seed 002 Fig. 4): max traction everywhere, held at each limit, braking only
    where the braking curves of the limit drops and of the stop demand it. In the calculator this is
    the single condition T: the braking envelope supplies every brake application."""
    return Plan(("T",), (0.0,))
