"""E* of a journey: the least traction energy over several stop-to-stop legs in a total running time, with
windows at the stations, and how that optimum shares the time among the legs.

The legs are the whole line cut at the stops (``model.route.route_slice``), each on its own E* grid
(``ocp.cells``: the calculator's cells, graded towards its two rest points, with a node at every timing
point inside it). Joined end to end (a stop is one node, the train at rest there) they make one
minimum-energy problem for the structured interior-point method: every leg's cells, the total running
time, and a window on the running time at every station (the timetable's clock less the dwells before
it). Legs separated by a stop are coupled only by time, so the optimum spends it where a second saves
the most: the marginal energy dE_i*/dT_i is the same on every leg not held by a window (the KKT
conditions of the joint problem; the running time's and the windows' multipliers are those marginal
energies). A timing point the train passes couples the legs on either side by the speed there as well:
it is a node inside its leg, with its window on the running time at that node.

Each leg's part of the joint optimum is that leg's E* at its allocated time (the legs are independent
once their times are fixed), so the journey's E* is their sum. The accuracy comes from two nested grids
as for one route (``ocp.cells.solve_estar``).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np

from ..errors import InfeasibleError
from ..model.route import Route
from ..model.train import Train
from ..physics.units import KJ_PER_KWH
from ..sim.calculator import ModelOptions, TractionCalculator
from .cells import (COARSE_STEP_M, FINEST_STEP_M, CellEnergyProblem, CellSolution, cell_calculator, grid_accuracy,
                    initial_speeds, warm_point)
from .ipm import CellIPM, IPMSettings


@dataclass
class JoinedCells:
    """Several legs' E* grids end to end, with what ``CellEnergyProblem`` reads of a calculator."""

    train: Train
    s_m: np.ndarray
    h_m: np.ndarray
    gravity_kn: np.ndarray
    traction_allowed: np.ndarray
    e_envelope: np.ndarray
    m_eff_t: float
    electric_brake_speed_kmh: np.ndarray
    electric_brake_kn: np.ndarray
    air_brake_speed_kmh: np.ndarray
    air_brake_kn: np.ndarray
    leg_cells: list[tuple[int, int]]
    """Each leg's cells: (first, past the last)."""

    @classmethod
    def join(cls, calcs: list[TractionCalculator], offsets_m: list[float]) -> "JoinedCells":
        s, h, g, a, env, legs = [], [], [], [], [], []
        n = 0
        for i, (c, off) in enumerate(zip(calcs, offsets_m)):
            nodes = c.s_m + off
            s.append(nodes if i == 0 else nodes[1:])  # a stop is one node
            e = c.e_envelope.copy()
            e[0] = e[-1] = 0.0
            env.append(e if i == 0 else e[1:])
            h.append(c.h_m)
            g.append(c.gravity_kn)
            a.append(c.traction_allowed)
            legs.append((n, n + len(c.h_m)))
            n += len(c.h_m)
        c0 = calcs[0]
        return cls(c0.train, np.concatenate(s), np.concatenate(h), np.concatenate(g), np.concatenate(a),
                   np.concatenate(env), c0.m_eff_t, c0.electric_brake_speed_kmh, c0.electric_brake_kn,
                   c0.air_brake_speed_kmh, c0.air_brake_kn, legs)


@dataclass(frozen=True)
class JoinedSolution:
    """The joint optimum on one grid: E* [kWh], each leg's energy [kWh] and running time [s], the running
    time at every node [s], the solution (a start for the next grid) and the grid."""

    energy_kwh: float
    leg_energy_kwh: np.ndarray
    leg_time_s: np.ndarray
    node_time_s: np.ndarray
    solution: CellSolution
    grid: JoinedCells


@dataclass(frozen=True)
class JourneyEStar:
    """E* of the legs joined: on the finest grid, its relative accuracy (the last two grids' difference),
    whether that met the tolerance, the grids' steps [m] and cells, and the finest grid's solution."""

    energy_kwh: float
    accuracy: float
    converged: bool
    steps_m: tuple
    cells: tuple
    finest: JoinedSolution
    solve_time_s: float

    @property
    def leg_energy_kwh(self) -> np.ndarray:
        return self.finest.leg_energy_kwh

    @property
    def leg_time_s(self) -> np.ndarray:
        return self.finest.leg_time_s

    def time_at(self, at_m: float) -> float:
        """The optimum's running time [s] at a node (a station) of the line."""
        s = self.finest.grid.s_m
        k = int(np.argmin(np.abs(s - at_m)))
        return float(self.finest.node_time_s[k])


def _solve_joined(calcs, offsets, time_s: float, stops_m, windows, start: JoinedSolution | None,
                  leg_times_guess) -> JoinedSolution:
    grid = JoinedCells.join(calcs, offsets)
    prob = CellEnergyProblem(grid, time_s, stops_m=stops_m, windows=windows)
    if start is None and windows:
        # from a cold start the windows' constraints (each over every cell before its station) can hold the
        # first steps to a fraction of a per cent for hundreds of iterations: the optimum without them first
        start = _solve_joined(calcs, offsets, time_s, stops_m, [], None, leg_times_guess)
    if start is None:
        v = [initial_speeds(c, t) for c, t in zip(calcs, leg_times_guess)]
        v0 = np.concatenate([v[0]] + [x[1:] for x in v[1:]])
        x0, settings, mu = prob.start_from_profile(v0), IPMSettings(), None
    else:
        x0, *_ = warm_point(prob, start.solution)
        x0 = prob.start_from_profile((x0 * prob.ref)[0::3])
        settings, mu = IPMSettings(), 1e-2
    res = CellIPM(prob, settings).solve(x0, mu_init=mu)
    if not res.converged and start is not None:  # from the coarser grid's optimum it lost its way: cold
        v = [initial_speeds(c, t) for c, t in zip(calcs, leg_times_guess)]
        res = CellIPM(prob).solve(prob.start_from_profile(np.concatenate([v[0]] + [x[1:] for x in v[1:]])))
    if not res.converged:
        raise InfeasibleError(f"the journey's minimum-energy problem on {prob.N} cells did not converge ({res.status} "
                              f"after {res.iterations} iterations): are its windows and its running time compatible?")
    x = res.x * prob.ref
    v, F, B = x[0::3], x[1::3], x[2::3]
    h = grid.h_m
    tau = 2 * h / np.maximum(v[:-1] + v[1:], 1e-9)
    node_t = np.concatenate([[0.0], np.cumsum(tau)])
    leg_e = np.array([np.sum(h[a:b] * F[a:b]) / KJ_PER_KWH for a, b in grid.leg_cells])
    leg_t = np.array([node_t[b] - node_t[a] for a, b in grid.leg_cells])
    slope = -float(res.zc[0]) * prob.e_ref / prob.t_ref
    sol = CellSolution(float(leg_e.sum()), grid.s_m, v, F, B, slope, res, 0.0)
    return JoinedSolution(float(leg_e.sum()), leg_e, leg_t, node_t, sol, grid)


def journey_estar(legs: list[Route], offsets_m: list[float], train: Train, options: ModelOptions, time_s: float,
                  windows: list[tuple[float, float | None, float | None]], *, tol: float, floor_kwh: float = 0.0,
                  points_m: list[list[float]] | None = None, coarse_step_m: float = COARSE_STEP_M,
                  finest_step_m: float = FINEST_STEP_M) -> JourneyEStar:
    """E* of ``legs`` (routes, each starting at ``offsets_m`` along the line) run one after the other in a
    total running time ``time_s`` [s], with ``windows``: (position along the line [m], earliest, latest
    running time there [s], either None) at stops and timing points; ``points_m``: per leg, the positions
    of its timing points (from its start). Grids halved until two agree to ``tol`` (relative to
    ``max(E*, floor_kwh)``). Raises ``InfeasibleError`` without an optimum."""
    t0 = _time.perf_counter()
    points_m = points_m or [[] for _ in legs]
    n = len(legs)
    from .bound import relaxed
    options = relaxed(options)  # E*'s relaxation: the air brake a continuous force
    fastest = np.array([TractionCalculator(r, train, options).fastest_time_s for r in legs])
    guess = fastest * (time_s / fastest.sum())
    stops = [offsets_m[i] for i in range(1, n)]
    step, calcs, sols, steps = float(coarse_step_m), None, [], []
    while True:
        calcs = [cell_calculator(r, train, options, step, coarser=None if calcs is None else calcs[i], extra_m=points_m[i])
                 for i, r in enumerate(legs)]
        sols.append(_solve_joined(calcs, offsets_m, time_s, stops, windows, sols[-1] if sols else None, guess))
        steps.append(step)
        if len(sols) >= 2:
            acc = grid_accuracy([s.energy_kwh for s in sols], floor_kwh)
            if acc <= tol or step / 2 < finest_step_m - 1e-9:
                break
        step /= 2
    return JourneyEStar(sols[-1].energy_kwh, acc, acc <= tol, tuple(steps), tuple(len(s.grid.h_m) for s in sols),
                        sols[-1], _time.perf_counter() - t0)
