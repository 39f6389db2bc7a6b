"""Registries of the optimal-control commands: plain data, importable without CasADi, so that the
CLI's help texts and choices do not load the solver."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources

from ..catalogue import DEFAULT_CONSIST_FILE

DEFAULT_OCP_CONSIST = "configs/consists/HXD1-C64-seed000.yaml"
"""The seed 000 test train: the default of ``--objective time``."""
DEFAULT_ENERGY_CONSIST = DEFAULT_CONSIST_FILE
"""The project's freight train: the default of ``--objective energy``."""


@dataclass(frozen=True)
class OcpMethod:
    """One transcription of the minimum-time problem (see :mod:`locoplan.ocp.solve`).

    ``seed_nodes``: the two control-node counts of the seed's Tables 2-3 (the first is the default).
    ``has_stage2``: the method reads ``stage2``; ``has_state_nodes``: ``state_nodes`` may be given;
    ``objectives``: the objectives it solves.
    """

    key: str
    label: str
    seed_nodes: tuple[int, int]
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
"""The routes of seed 000's Table 2 (level, test 1) and Table 3 (30 per mille, test 2)."""


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
