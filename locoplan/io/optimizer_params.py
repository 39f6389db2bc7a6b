"""Optimiser parameter files: read and validated into the algorithm's ``Params`` model.

``read_optimizer_params(path, name, params_cls)`` reads the parameters of optimiser ``name`` from a YAML
file and validates them with its ``Params`` model, which lives beside the algorithm (``optimize/``: one
definition of the defaults and their sources) and is handed in, so that reading stays below the
algorithms. The shipped files (``default_params_path``: ``locoplan/catalogue/optimizers/<name>.yaml``)
hold the ISSA paper's Table 5 values, population 50 and 100 iterations, the same as the models' defaults.
``runner.load_optimizer_params(name, path=None)`` composes the two for callers; the optimisers
themselves take the parameter object, never a path::

    params = load_optimizer_params("issa", "my-issa.yaml")
    result = get_algorithm("issa")().setup(problem, rng, **params.model_dump()).run()

A parameter file is a YAML mapping with ``schema: locoplan/optimizer@1``, ``algorithm: <name>`` and the
algorithm's parameters (see its ``Params`` model); unknown keys and bad values raise ``InputError`` naming
the file, the field and its line.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError, Problem
from .load import read_yaml, validate_model

__all__ = ["SCHEMA", "default_params_path", "read_optimizer_params"]

SCHEMA = "locoplan/optimizer@1"

_CATALOGUE = Path(__file__).resolve().parent.parent / "catalogue" / "optimizers"


def default_params_path(name: str) -> Path:
    """Shipped parameter file of algorithm ``name``: ``locoplan/catalogue/optimizers/<name>.yaml``."""
    return _CATALOGUE / f"{str(name).strip().lower()}.yaml"


def read_optimizer_params(path: str | Path | None, name: str, params_cls):
    """Read and validate the parameters of optimiser ``name`` from ``path`` (None: the shipped file) with its
    ``params_cls`` (the algorithm's ``Params`` model).

    Returns the frozen model (pop_size, max_iter and the algorithm's parameters); ``params.model_dump()``
    gives the keyword arguments of ``Optimizer.setup``. Raises ``InputError`` for a missing/unreadable/malformed
    file, a wrong ``schema``/``algorithm`` entry, an unknown key or an invalid value, naming file, field and line.
    """
    cls = params_cls
    key = str(name).strip().lower()
    file = Path(path) if path is not None else default_params_path(key)
    where = str(file)
    data, all_lines = read_yaml(file)
    lines = {k[0]: v for k, v in all_lines.items() if len(k) == 1}

    problems = []
    schema = data.pop("schema", None)
    if schema != SCHEMA:
        problems.append(Problem(file=where, field="schema", message=f"expected {SCHEMA!r}, got {schema!r}",
                                line=lines.get("schema")))
    algorithm = data.pop("algorithm", None)
    if str(algorithm).strip().lower() != key:
        problems.append(Problem(file=where, field="algorithm", message=f"expected {key!r}, got {algorithm!r}",
                                line=lines.get("algorithm")))
    params = None
    try:
        params = validate_model(cls, data, where, all_lines)
    except InputError as exc:
        problems.extend(exc.problems)
    if problems:
        raise InputError(problems)
    return params
