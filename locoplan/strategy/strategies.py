"""Built-in driving strategies of seed 002 (section 4.2.3, Tables 8-9), in a registry.

Each strategy takes a ``StrategyContext`` and returns a ``StrategyOutcome`` (a condition sequence,
its switching points and, for four-stage, a cruise speed). The CLI's ``--strategy`` and
``--strategies`` choices come from ``STRATEGIES``.

- ``time-saving``: the fastest run (Fig. 4).
- ``energy-saving``: traction and coasting alternate (one traction run to start and one before each
  long up-grade), switching points chosen by the optimiser for the least traction energy, timetable
  ignored (Table 8). Its energy is the default E_min of eq. 11.
- ``four-stage``: traction to a cruise speed, cruise, coast, brake; cruise speed and coasting point
  searched on a grid so that the train is on time with the least energy.
- ``proposed``: the sequence builder's sequence (section 2), switching points by ISSA / SSA / PSO
  minimising eq. 10 inside the punctuality window of eq. 3 (when the context has a tolerance).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..errors import InfeasibleError, InputError, Problem
from ..model.plan import Plan
from ..optimize.problem import SwitchingProblem
from ..optimize.registry import get_algorithm, load_optimizer_params
from ..sim.calculator import TractionCalculator
from .sequence import build_sequence, classify_grades, fastest_runs


@dataclass
class StrategyContext:
    """What a strategy may use. ``calc`` reports; ``search`` (a coarser grid) is what optimisers
    evaluate, converged to a few hundredths of a percent of ``calc`` (README, 'step size')."""

    calc: TractionCalculator
    search: TractionCalculator
    t0_s: float
    e_min_kwh: float | None = None
    weights: tuple[float, float] = (0.5, 0.5)
    algorithm: str = "issa"
    seed: int = 1
    params_path: str | None = None
    callback: Callable[[int, float], None] | None = None
    tolerance_s: float | None = None
    use_window: bool = True
    yardstick: bool = True
    """Report each plan's gap to the optimum E* (seed 001) at its own running time."""
    _e_min_cache: dict = field(default_factory=dict)

    @property
    def ranking_tolerance_s(self) -> float | None:
        """The punctuality window the optimiser ranks by (None with --no-window: eq. 10 alone)."""
        return self.tolerance_s if self.use_window else None

    def rng(self, salt: int = 0) -> np.random.Generator:
        return np.random.default_rng([self.seed, salt])

    def e_min(self) -> float:
        """E_min of eq. 11: the user's value, else the energy-saving strategy's energy."""
        if self.e_min_kwh is not None:
            return self.e_min_kwh
        if "e" not in self._e_min_cache:
            out = energy_saving(self)
            res = self.calc.evaluate(out.plan.conditions, out.plan.switches_m)
            self._e_min_cache["e"] = float(res.traction_energy_kwh[0])
            self._e_min_cache["outcome"] = out
        return self._e_min_cache["e"]


@dataclass(frozen=True)
class StrategyOutcome:
    plan: Plan
    cruise_kmh: float | None = None
    algorithm: str | None = None
    history: np.ndarray | None = None
    n_evaluations: int = 0
    solve_time_s: float = 0.0
    e_min_kwh: float | None = None
    time_range_s: tuple[float, float] | None = None
    """Shortest and longest running time [s] among the feasible plans the strategy evaluated: what it
    can reach on this route (named when the asked time is outside it)."""
    calc: TractionCalculator | None = None
    """The calculator to run the plan on when not the context's (mpoc-n: the route without its
    neutral sections, which the real train cannot drive)."""


StrategyFn = Callable[[StrategyContext], StrategyOutcome]
STRATEGIES: dict[str, StrategyFn] = {}
TIMETABLED: set[str] = set()
"""Strategies whose job is to meet the planned running time (a miss is a failure, exit 1); the others
(time-saving, energy-saving) ignore the timetable by definition."""


def register(name: str, timetabled: bool = False):
    def deco(fn: StrategyFn) -> StrategyFn:
        STRATEGIES[name] = fn
        if timetabled:
            TIMETABLED.add(name)
        return fn
    return deco


def get_strategy(name: str) -> StrategyFn:
    try:
        return STRATEGIES[name]
    except KeyError:
        raise InputError(Problem("", "--strategy", f"unknown strategy {name!r} (one of: {', '.join(STRATEGIES)})")) from None


def _plan(conditions, switches) -> Plan:
    return Plan(tuple(conditions), (0.0, *[float(x) for x in switches], float("nan")))


ENERGY_SAVING_ALGORITHM = "issa"
"""The energy-saving baseline is always searched by ISSA (seed 002's own optimiser, which also finds the
lowest energies here), so that E_min does not change with the --algorithm being studied."""


def _optimise(ctx: StrategyContext, problem: SwitchingProblem, salt: int, algorithm: str | None = None):
    name = algorithm or ctx.algorithm
    params = load_optimizer_params(name, ctx.params_path if name == ctx.algorithm else None).model_dump()
    opt = get_algorithm(name)()
    opt.setup(problem, ctx.rng(salt), **params)
    return opt.run(callback=ctx.callback)


@register("time-saving")
def time_saving(ctx: StrategyContext) -> StrategyOutcome:
    """The fastest run (seed 002 Fig. 4): max traction everywhere, held at each limit, braking only
    where the braking curves of the limit drops and of the stop demand it. In the calculator this is
    the single condition T: the braking envelope supplies every brake application."""
    return StrategyOutcome(Plan(("T",), (0.0,)))


def energy_saving_sequence(calc: TractionCalculator, threshold_kmh: float = 2.0):
    """T, C alternating: traction to start and before each long up-grade, coasting after; windows
    halfway to the neighbouring nominal switches (a traction run may start well before its grade)."""
    L, gap = calc.route.length_m, calc.train.length_m / 2
    ups = [g for g in classify_grades(calc, threshold_kmh) if g.kind == "long-up"]
    first_cruise = next((r["from_m"] for r in fastest_runs(calc) if r["condition"] != "T"), L / 4)
    nominal = [first_cruise]
    for g in ups:
        if g.from_m - gap > nominal[-1] + gap:
            nominal += [max(nominal[-1] + gap, g.from_m - 500.0), g.to_m]
    nominal = np.array(nominal[: len(nominal)])
    conditions = ("T",) + tuple("C" if i % 2 == 0 else "T" for i in range(len(nominal))) + ("B",)
    if conditions[-2] != "C":  # end on coasting into the final brake
        nominal = nominal[:-1]
        conditions = conditions[:-2] + ("B",)
    edges = np.concatenate([[0.0], nominal, [L]])
    lower = np.maximum(0.5 * (edges[:-2] + edges[1:-1]), gap)
    upper = np.minimum(0.5 * (edges[1:-1] + edges[2:]), L - gap)
    for j in range(1, len(nominal), 2):  # traction before a long up-grade: back to the previous switch
        lower[j] = edges[j] + gap
    return conditions, nominal, lower, upper


@register("energy-saving")
def energy_saving(ctx: StrategyContext) -> StrategyOutcome:
    """Seed 002's energy-saving strategy: the least traction energy with traction and coasting only."""
    cached = ctx._e_min_cache.get("outcome")
    if cached is not None:
        return cached
    t = time.perf_counter()
    conditions, _, lower, upper = energy_saving_sequence(ctx.search)
    problem = SwitchingProblem(ctx.search, conditions, lower, upper, objective="energy")
    result = _optimise(ctx, problem, salt=2, algorithm=ENERGY_SAVING_ALGORITHM)
    return StrategyOutcome(_plan(conditions, result.best_x), algorithm=ENERGY_SAVING_ALGORITHM, history=result.history,
                           n_evaluations=result.n_evaluations, solve_time_s=time.perf_counter() - t)


@register("four-stage", timetabled=True)
def four_stage(ctx: StrategyContext) -> StrategyOutcome:
    """Traction to a cruise speed, cruise (re-accelerating where limits or grades pulled it down),
    coast, brake. Cruise speed and coasting point come from a grid search, refined once: the least
    energy among plans within 1 s of the planned time, else the plan closest to it."""
    t = time.perf_counter()
    calc = ctx.search
    L = calc.route.length_m
    v_top = float(calc.limit_kmh.max())
    v_grid = np.arange(30.0, v_top + 0.5, 1.0)
    x_grid = np.arange(L / 2, L - 50.0, 100.0)
    best = span = None
    for v_step, x_step in ((1.0, 100.0), (0.1, 5.0)):
        if best is not None:
            v_grid = np.arange(best[0] - v_step * 10, best[0] + v_step * 10.5, v_step)
            x_grid = np.arange(best[1] - x_step * 20, best[1] + x_step * 20.5, x_step)
            v_grid, x_grid = v_grid[(v_grid > 0) & (v_grid <= v_top)], x_grid[(x_grid > 0) & (x_grid < L)]
        V, X = (a.ravel() for a in np.meshgrid(v_grid, x_grid))
        res = calc.evaluate(("T", "C", "B"), np.column_stack([X, np.full_like(X, np.nan)]), cruise_kmh=V)
        ok = res.feasible
        if not ok.any():
            raise InfeasibleError("four-stage: no feasible cruise speed / coasting point on this route")
        times = res.running_time_s[ok]
        span = (float(times.min()), float(times.max())) if span is None else (min(span[0], float(times.min())), max(span[1], float(times.max())))
        late = np.abs(res.running_time_s - ctx.t0_s)
        punctual = ok & (late <= 1.0)
        if punctual.any():
            i = int(np.argmin(np.where(punctual, res.traction_energy_kwh, np.inf)))
        else:
            i = int(np.argmin(np.where(ok, late, np.inf)))
        best = (float(V[i]), float(X[i]))
    return StrategyOutcome(_plan(("T", "C", "B"), [best[1]]), cruise_kmh=round(best[0], 2),
                           n_evaluations=0, solve_time_s=time.perf_counter() - t, time_range_s=span)


@register("proposed", timetabled=True)
def proposed(ctx: StrategyContext) -> StrategyOutcome:
    """Seed 002's method: the sequence builder's conditions, switching points minimising eq. 10."""
    e_min = ctx.e_min()
    t = time.perf_counter()
    seq = build_sequence(ctx.search)
    problem = SwitchingProblem(ctx.search, seq.conditions, seq.lower_m, seq.upper_m, t0_s=ctx.t0_s,
                               e_min_kwh=e_min, weights=ctx.weights, tolerance_s=ctx.ranking_tolerance_s)
    result = _optimise(ctx, problem, salt=1)
    return StrategyOutcome(_plan(seq.conditions, result.best_x), algorithm=ctx.algorithm, history=result.history,
                           n_evaluations=result.n_evaluations, solve_time_s=time.perf_counter() - t, e_min_kwh=e_min,
                           time_range_s=problem.time_range_s)


from . import optimal  # noqa: E402,F401  (registers seed 001's mpoc, mpoc-n, mpoc-c and sfs)
