"""Optimal control of a train run: seed 000's minimum time (Gauss pseudospectral, two-stage
re-collocation, CVP) and seed 001's multi-phase minimum energy (Radau, hp mesh refinement).

Seed 001 (multi-phase): :mod:`~locoplan.ocp.phase` (phases, linkage) -> :mod:`~locoplan.ocp.mesh`
(meshes, hp refinement) -> :mod:`~locoplan.ocp.radau` (LGR transcription, IPOPT) ->
:mod:`~locoplan.ocp.train_energy` (the train problem from route breakpoints) ->
:mod:`~locoplan.ocp.energy` (refinement loop) -> :mod:`~locoplan.ocp.drive` (drivable plan, checked
by the traction calculator) -> :mod:`~locoplan.ocp.mpoc` (end to end) and :mod:`~locoplan.ocp.bound`
(the yardstick E*).

Seed 000 layers, each using only the ones before it:

* :mod:`locoplan.ocp.nodes`: LG / LGR nodes and weights (Golub-Welsch), differentiation matrices;
* :mod:`locoplan.ocp.transcription`: generic problem description, GPM (single / hp mesh, separate
  control node sets) and CVP transcriptions to a CasADi/IPOPT NLP, the two-stage re-collocation;
* :mod:`locoplan.ocp.problems`: the minimum-time train problem (numbers only);
* :mod:`locoplan.ocp.solve`: :func:`solve_min_time` and :func:`resimulate`.
"""

import importlib

_LAZY = {"MinTimeTrainProblem": "problems", "davis_resistance_kn": "problems", "seed000_problem": "problems",
         "METHODS": "solve", "OcpSolution": "solve", "Resimulation": "solve", "resimulate": "solve",
         "solve_min_time": "solve"}


def __getattr__(name: str):
    """Load the CasADi-backed modules on first use, so that importing the CLI stays light."""
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(name)


__all__ = [
    "METHODS",
    "MinTimeTrainProblem",
    "OcpSolution",
    "Resimulation",
    "davis_resistance_kn",
    "resimulate",
    "seed000_problem",
    "solve_min_time",
]
