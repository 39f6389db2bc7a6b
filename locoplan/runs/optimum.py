"""The optimum's energy E*(T): the least traction energy any plan can spend to run a route in T.

A provider is a function ``(route, train, options, time_s) -> E* [kWh] or None`` registered with
:func:`register_optimum`; ``pareto`` asks :func:`optimum_energy_kwh` at each planned time. The one
registered here is the MPOC paper's minimum-energy optimal control (``ocp.bound.energy_bound``, the
``bound`` command). Where no provider knows E* (none registered, or the solve fails) the answer is
None, and ``pareto`` and the store's summary say it is not known rather than inventing one.
"""

from __future__ import annotations

from typing import Any, Callable

from ..errors import LocoplanError

OptimumFn = Callable[[Any, Any, Any, float], "float | None"]
_PROVIDERS: list[tuple[str, OptimumFn]] = []


def register_optimum(name: str):
    """Decorator: add a provider of E*. The first provider that returns a number wins."""
    def deco(fn: OptimumFn) -> OptimumFn:
        _PROVIDERS.append((name, fn))
        return fn
    return deco


def optimum_providers() -> list[str]:
    return [name for name, _ in _PROVIDERS]


def optimum_energy_kwh(route, train, options, time_s: float) -> float | None:
    """E* [kWh] of ``route`` with ``train`` under ``options`` for a running time of ``time_s`` [s],
    or None when no provider knows it."""
    for _, fn in _PROVIDERS:
        value = fn(route, train, options, time_s)
        if value is not None:
            return float(value)
    return None


@register_optimum("minimum-energy optimal control (the bound command)")
def _mpoc_bound(route, train, options, time_s: float) -> float | None:
    from ..ocp.bound import energy_bound  # CasADi: imported when an optimum is asked for

    try:
        return energy_bound(route, train, options, time_s).energy_kwh
    except LocoplanError:  # a time the optimum cannot reach, a solver failure: no E* here
        return None
