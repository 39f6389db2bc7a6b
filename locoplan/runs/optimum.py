"""The optimum's energy E*(T): the least traction energy any plan can spend to run a route in T.

Seed 001's minimum-energy optimal control (the ``bound`` command, built in ``ocp/``) is the yardstick
of every plan. This module is where it slots in: a provider is a function
``(route, train, options, time_s) -> E* [kWh] or None`` registered with :func:`register_optimum`.
Until one is registered :func:`optimum_energy_kwh` returns None, and everything that would show a gap
to the optimum (the store's summary, ``pareto``) says it is not known rather than inventing one.
"""

from __future__ import annotations

from typing import Any, Callable

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
