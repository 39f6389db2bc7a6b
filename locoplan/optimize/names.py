"""The optimisers' names, in the order the help lists them: :data:`locoplan.optimize.registry.ALGORITHMS`
maps each to its class. Plain data, importable without numpy, so that ``locoplan --help`` does not load the
optimisers."""

from __future__ import annotations

ALGORITHM_NAMES: tuple[str, ...] = ("issa", "ssa", "pso")
