"""Optimiser registry and parameter files.

``ALGORITHMS`` maps a name to its class; ``get_algorithm(name)`` looks one up and
``load_optimizer_params(name, path=None)`` reads its parameters from a YAML file (by default the shipped
``locoplan/catalogue/optimizers/<name>.yaml``, which holds seed 002's Table 5 values, population 50 and
100 iterations). Typical use::

    params = load_optimizer_params("issa")
    result = get_algorithm("issa")().setup(problem, rng, **params.model_dump()).run()

A parameter file is a YAML mapping with ``schema: locoplan/optimizer@1``, ``algorithm: <name>`` and the
algorithm's parameters (see its ``Params`` model); unknown keys and bad values raise ``InputError`` naming
the file, the field and its line.
"""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import ValidationError

from ..errors import InputError, Problem
from .base import Optimizer, OptimizerParams, validation_problems
from .issa import ISSA
from .pso import PSO
from .ssa import SSA

__all__ = ["ALGORITHMS", "SCHEMA", "default_params_path", "get_algorithm", "load_optimizer_params"]

SCHEMA = "locoplan/optimizer@1"

ALGORITHMS: dict[str, type[Optimizer]] = {"issa": ISSA, "ssa": SSA, "pso": PSO}

_CATALOGUE = Path(__file__).resolve().parent.parent / "catalogue" / "optimizers"


def get_algorithm(name: str) -> type[Optimizer]:
    """The optimiser class registered as ``name`` (case-insensitive); ``InputError`` listing the known names otherwise."""
    key = str(name).strip().lower()
    if key not in ALGORITHMS:
        known = ", ".join(sorted(ALGORITHMS))
        raise InputError(Problem(file="", field="algorithm", message=f"unknown optimiser {name!r} (known: {known})"))
    return ALGORITHMS[key]


def default_params_path(name: str) -> Path:
    """Shipped parameter file of algorithm ``name``: ``locoplan/catalogue/optimizers/<name>.yaml``."""
    get_algorithm(name)
    return _CATALOGUE / f"{str(name).strip().lower()}.yaml"


def load_optimizer_params(name: str, path: str | Path | None = None) -> OptimizerParams:
    """Read and validate the parameters of optimiser ``name`` from ``path`` (default: the shipped file).

    Returns the algorithm's frozen ``Params`` model (pop_size, max_iter and the algorithm's parameters);
    ``params.model_dump()`` gives the keyword arguments of ``Optimizer.setup``. Raises ``InputError`` for an
    unknown algorithm, a missing/unreadable/malformed file, a wrong ``schema``/``algorithm`` entry, an unknown
    key or an invalid value, naming file, field and line.
    """
    cls = get_algorithm(name)
    key = str(name).strip().lower()
    file = Path(path) if path is not None else default_params_path(key)
    where = str(file)
    if not file.is_file():
        raise InputError(Problem(file=where, field="", message="no such file"))
    try:
        text = file.read_text(encoding="utf-8")
        node = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(Problem(file=where, field="", message=f"cannot read: {exc}")) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise InputError(
            Problem(file=where, field="", message=f"not valid YAML: {getattr(exc, 'problem', None) or exc}",
                    line=mark.line + 1 if mark else None)
        ) from None
    if not isinstance(data, dict) or not isinstance(node, yaml.MappingNode):
        raise InputError(Problem(file=where, field="", message="expected a mapping of parameter names to values", line=1))
    lines = {str(k.value): k.start_mark.line + 1 for k, _ in node.value}

    problems = []
    schema = data.pop("schema", None)
    if schema != SCHEMA:
        problems.append(Problem(file=where, field="schema", message=f"expected {SCHEMA!r}, got {schema!r}",
                                line=lines.get("schema")))
    algorithm = data.pop("algorithm", None)
    if str(algorithm).strip().lower() != key:
        problems.append(Problem(file=where, field="algorithm", message=f"expected {key!r}, got {algorithm!r}",
                                line=lines.get("algorithm")))
    try:
        params = cls.Params.model_validate(data)
    except ValidationError as exc:
        problems.extend(validation_problems(exc, where, lines))
    if problems:
        raise InputError(problems)
    return params
