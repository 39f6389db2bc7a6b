"""Registries of the optimal-control commands: plain data, importable without CasADi, so that the
CLI's help texts and choices do not load the solver."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

from ..catalogue import DEFAULT_CONSIST_FILE
from ..errors import InputError, Problem

DEFAULT_OCP_CONSIST = "configs/consists/HXD1-C64-seed000.yaml"
"""The two-stage Gauss paper test train: the default of ``--objective time``."""
DEFAULT_ENERGY_CONSIST = DEFAULT_CONSIST_FILE
"""The project's freight train: the default of ``--objective energy``."""


@dataclass(frozen=True)
class OcpMethod:
    """One transcription of the minimum-time problem (see :mod:`locoplan.ocp.solve`).

    ``paper_nodes``: the two control-node counts of the paper's Tables 2-3 (the first is the default).
    ``has_stage2``: the method reads ``stage2``; ``has_state_nodes``: ``state_nodes`` may be given;
    ``objectives``: the objectives it solves.
    """

    key: str
    label: str
    paper_nodes: tuple[int, int]
    description: str
    has_stage2: bool = False
    has_state_nodes: bool = False
    objectives: tuple[str, ...] = ("time",)


OCP_METHODS: dict[str, OcpMethod] = {
    "two-stage": OcpMethod("two-stage", "two-stage", (17, 24),
                           "two-stage adaptive Gauss re-collocation: paired control on 2N LG "
                           "points, then slope-change re-collocation", has_stage2=True, has_state_nodes=True),
    "gpm": OcpMethod("gpm", "GPM", (34, 48), "classical Gauss pseudospectral method: N LG points for "
                     "states and control", has_state_nodes=True),
    "cvp": OcpMethod("cvp", "CVP", (20, 40), "control vector parameterisation: N control values on a "
                     "uniform grid, piecewise linear, RK4 states"),
    "radau": OcpMethod("radau", "Radau", (0, 0), "multi-phase Legendre-Gauss-Radau collocation with hp mesh "
                       "refinement (GPOPS-II's method)", objectives=("energy",)),
}
"""Methods by CLI name; the CLI's ``--method`` choices are these keys."""

STAGE2_MODES: dict[str, str] = {
    "hp": "cut the state mesh at the detected control jumps into segments with movable break points "
          "(our extension, default)",
    "global": "re-collocate the control on the same single global LG mesh (the paper's literal stage 2)",
}
"""Stage-2 variants of the two-stage method."""

OBJECTIVES: dict[str, str | None] = {
    "time": "minimum running time",
    "energy": "minimum traction energy in a running time, multi-phase",
}
"""Objectives by CLI name; ``None`` marks one that is planned but not built."""

DEFAULT_METHOD = {"time": "two-stage", "energy": "radau"}
"""The method ``--method`` defaults to, per objective."""

STUDY_ROUTES: dict[int, str] = {2: "routes/seed000-flat.yaml", 3: "routes/seed000-grade30.yaml"}
"""The routes of the two-stage Gauss paper's Table 2 (level, test 1) and Table 3 (30 per mille, test 2)."""


def study_route_file(rel: str):
    """A study route's file: the one in the current folder when there is one, else the package's copy
    (the default works from any directory and from an installed wheel). Resolves the name only;
    reading it is the caller's (``io.load``)."""
    from pathlib import Path


    p = Path(rel)
    shipped = Path(str(resources.files("locoplan.catalogue") / "routes")) / p.name
    return p if p.exists() or not shipped.exists() else shipped


def study_route_files(routes: dict[int, str] | None = None) -> dict:
    """Table number -> route file of :data:`STUDY_ROUTES` (or ``routes``), resolved by :func:`study_route_file`."""
    return {k: study_route_file(v) for k, v in (routes or STUDY_ROUTES).items()}


SOURCE = "ocp"  # the 'file' of a Problem about a command-line option rather than a file


def check_options(method: str, nodes, state_nodes, stage2: str = "hp", objective: str = "time") -> tuple[int, int | None]:
    """Validate the options of :func:`solve_ocp` before any file is read or NLP built; returns the
    control-node count (the method's default from the paper if ``None``) and the state-node count (or ``None``).
    Every problem is reported at once as an :class:`InputError` naming the option."""
    from . import nodes as _nodes  # numpy: loaded when a command runs, not for its help

    problems: list[Problem] = []
    if objective not in OBJECTIVES:
        problems.append(Problem(SOURCE, "--objective", f"unknown objective {objective!r}; choose one of {', '.join(OBJECTIVES)}"))
    elif OBJECTIVES[objective] is None:
        problems.append(Problem(SOURCE, "--objective", f"'{objective}' is not built yet"))
    spec = OCP_METHODS.get(method)
    if spec is None:
        problems.append(Problem(SOURCE, "--method", f"unknown method {method!r}; choose one of {', '.join(OCP_METHODS)}"))
    elif objective in OBJECTIVES and objective not in spec.objectives:
        fit = [k for k, m in OCP_METHODS.items() if objective in m.objectives]
        problems.append(Problem(SOURCE, "--method", f"{method} solves --objective {'/'.join(spec.objectives)}, not "
                                f"{objective}; use {' or '.join(fit)}"))
        spec = None

    def count(flag: str, value, even: bool = False):
        if value is None:
            return None
        try:
            whole = not isinstance(value, bool) and float(value).is_integer()
        except (TypeError, ValueError):
            whole = False
        if not whole:
            problems.append(Problem(SOURCE, flag, f"must be a whole number, got {value!r}"))
            return None
        n = int(value)
        if not 2 <= n <= _nodes.MAX_NODES:
            problems.append(Problem(SOURCE, flag, f"must be between 2 and {_nodes.MAX_NODES}, got {n}"))
            return None
        if even and n % 2:
            problems.append(Problem(SOURCE, flag, f"the two-stage method pairs the control on the LG points "
                                    f"(U_(2l-1) = U_(2l)), so the state nodes must be even, got {n}"))
            return None
        return n

    n = count("--nodes", nodes)
    m = count("--state-nodes", state_nodes, even=method == "two-stage")
    if spec is not None:
        if m is not None and not spec.has_state_nodes:
            problems.append(Problem(SOURCE, "--state-nodes", f"{method} has no state collocation nodes (RK4 states "
                                    "on the control grid); leave --state-nodes out"))
        if method == "gpm" and m is not None and n is not None and m != n:
            problems.append(Problem(SOURCE, "--state-nodes", f"GPM shares its LG points between states and control: "
                                    f"--state-nodes {m} must equal --nodes {n}"))
        if method == "two-stage" and m is not None and n is not None and m != 2 * n:
            problems.append(Problem(SOURCE, "--state-nodes", f"stage 1 pairs the control, so {m} state nodes give "
                                    f"{m // 2} control nodes, not --nodes {n}"))
        if method == "gpm" and m is not None and n is None:
            n = m
        if method == "two-stage" and m is not None and n is None:
            n = m // 2
        if n is None:
            n = spec.paper_nodes[0]
    if stage2 not in STAGE2_MODES:
        problems.append(Problem(SOURCE, "--stage2", f"unknown stage-2 mode {stage2!r}; choose one of {', '.join(STAGE2_MODES)}"))
    if problems:
        raise InputError(problems)
    return n, m
