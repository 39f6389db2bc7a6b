"""Optimal control of a train run: one framework for the two-stage Gauss paper's minimum time (Gauss pseudospectral,
two-stage re-collocation, CVP) and the MPOC paper's multi-phase minimum energy (Radau, hp refinement).

Layers, each using only the ones before it:

* :mod:`~locoplan.ocp.nodes`: LG / LGR nodes and weights (Golub-Welsch), differentiation matrices;
* :mod:`~locoplan.ocp.phase`: the problem notion, phases of a model (``MultiPhaseProblem``; one
  phase with a free end for the minimum-time problem);
* :mod:`~locoplan.ocp.mesh`: the mesh (intervals with collocation points, hp refinement);
* transcriptions, each a module taking a problem and a mesh: :mod:`~locoplan.ocp.radau` (LGR,
  multi-phase), :mod:`~locoplan.ocp.gauss` (LG, free end); the method :mod:`~locoplan.ocp.cvp`
  (control vector parameterisation); :mod:`~locoplan.ocp.recollocation` (the two-stage Gauss paper's stage 2);
* train problems: :mod:`~locoplan.ocp.min_time` (the two-stage Gauss paper) and :mod:`~locoplan.ocp.train_energy`
  (the MPOC paper), both on ``physics``' formulas (``physics.motion`` for the equation of motion);
* solving: :mod:`~locoplan.ocp.solve` (``solve_min_time``, ``resimulate``),
  :mod:`~locoplan.ocp.min_time_run` (a run on a route and train, checked), :mod:`~locoplan.ocp.min_time_study`
  (Tables 2-3); :mod:`~locoplan.ocp.energy` (refinement loop) -> :mod:`~locoplan.ocp.to_plan`
  (drivable plan, checked by the traction calculator) -> :mod:`~locoplan.ocp.mpoc` (end to end) and
  :mod:`~locoplan.ocp.bound` (the yardstick E*).

Rendering lives in :mod:`locoplan.reporting.ocp_study`.
"""

import importlib

_LAZY = {"MinTimeTrainProblem": "min_time", "davis_resistance_kn": "min_time", "gauss_paper_problem": "min_time",
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
    "gauss_paper_problem",
    "solve_min_time",
]
