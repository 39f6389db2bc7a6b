"""Optimiser registry: ``ALGORITHMS`` maps a name to its class.

``get_algorithm(name)`` looks one up; ``default_params(name)`` gives its parameters as the ISSA paper states them
(Table 5, population 50, 100 iterations: the class's ``Params`` defaults). The optimisers take parameter
objects; reading a parameter file is :func:`locoplan.runner.load_optimizer_params`'s job (``io.optimizer_params`` reads)::

    params = default_params("issa")
    result = get_algorithm("issa")().setup(problem, rng, **params.model_dump()).run()

Adding an optimiser is one module (an ``Optimizer`` with its ``Params`` model), one line in
:data:`ALGORITHMS` (its name also in :data:`~locoplan.optimize.names.ALGORITHM_NAMES`, which the help
reads) and its shipped parameter file in ``locoplan/catalogue/optimizers/``.
"""

from __future__ import annotations

from ..errors import InputError, Problem
from .base import Optimizer, OptimizerParams
from .issa import ISSA
from .pso import PSO
from .ssa import SSA

__all__ = ["ALGORITHMS", "default_params", "get_algorithm"]

ALGORITHMS: dict[str, type[Optimizer]] = {"issa": ISSA, "ssa": SSA, "pso": PSO}
"""Name -> class, the names of :data:`~locoplan.optimize.names.ALGORITHM_NAMES` in its order (tests/test_optimizers.py)."""


def get_algorithm(name: str) -> type[Optimizer]:
    """The optimiser class registered as ``name`` (case-insensitive); ``InputError`` listing the known names otherwise."""
    key = str(name).strip().lower()
    if key not in ALGORITHMS:
        known = ", ".join(sorted(ALGORITHMS))
        raise InputError(Problem(file="<command line>", field="--algorithm", message=f"unknown optimiser {name!r} (known: {known})"))
    return ALGORITHMS[key]


def default_params(name: str) -> OptimizerParams:
    """The parameters of optimiser ``name`` when no file gives them: its ``Params`` defaults (the shipped
    ``catalogue/optimizers/<name>.yaml`` holds the same values; tests/test_optimizers.py checks it)."""
    return get_algorithm(name).Params()
