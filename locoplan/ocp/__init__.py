"""Optimal control of a train run (seed 000): Gauss pseudospectral, two-stage re-collocation, CVP.

Layers, each using only the ones before it:

* :mod:`locoplan.ocp.nodes`: LG / LGR nodes and weights (Golub-Welsch), differentiation matrices;
* :mod:`locoplan.ocp.transcription`: generic problem description, GPM (single / hp mesh, separate
  control node sets) and CVP transcriptions to a CasADi/IPOPT NLP, the two-stage re-collocation;
* :mod:`locoplan.ocp.problems`: the minimum-time train problem (numbers only);
* :mod:`locoplan.ocp.solve`: :func:`solve_min_time` and :func:`resimulate`.
"""

from .problems import MinTimeTrainProblem, davis_resistance_kn, seed000_problem
from .solve import METHODS, OcpSolution, Resimulation, resimulate, solve_min_time

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
