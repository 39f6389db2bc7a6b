"""Built-in driving strategies of the ISSA paper (section 4.2.3, Tables 8-9), and the context every strategy gets.

Each strategy takes a ``StrategyContext`` and returns a ``StrategyOutcome`` (a condition sequence,
its switching points and, for four-stage, a cruise speed). The CLI's ``--strategy`` and
``--strategies`` choices and each strategy's traits come from ``strategy/registry.py``.

- ``time-saving``: the fastest run (Fig. 4).
- ``energy-saving``: the least traction energy, timetable ignored (Table 8). Its energy is the default
  E_min of eq. 11.
- ``four-stage``: traction to a cruise speed, cruise, coast, brake; cruise speed and coasting point
  searched on a grid so that the train is on time with the least energy.
- ``proposed``: a condition sequence built from the route, switching points by ISSA / SSA / PSO
  minimising eq. 10 inside the punctuality window of eq. 3.

Two sequence builders (``StrategyContext.builder``):
- ``general`` (the default): ``strategy/general_builder.py``, the sequence read off the drive that is optimal at a
  price of time (``optimize/dp.py``, bisected to the planned time); energy-saving is the same drive at
  the lowest price (deterministic: E_min does not depend on the seed), four-stage may coast from
  anywhere. Works on any line (issue 8, docs/real-lines.md).
- ``issa-paper``: the ISSA paper's section 2 to the letter (``strategy/sequence.py``): grades classified at the
  limit speed, the fastest run's conditions elsewhere; energy-saving alternates traction and coasting;
  four-stage coasts in the second half. With the papers' train model (``--point-mass``) it reproduces
  the ISSA paper's tables as this project first measured them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from ..errors import InfeasibleError
from ..model.plan import Plan
from ..optimize.base import NoFeasibleCandidateError, OptimizerParams
from ..optimize.problem import E_MIN_RUN_M, MARGIN_MIN, SwitchingProblem
from ..optimize.registry import default_params, get_algorithm
from ..sim.calculator import TractionCalculator
from ..sim.result import AIR_APPLIED, BatchResult
from .sequence import build_sequence, classify_grades, fastest_runs
from .general_builder import sequence_from_drive, sequence_from_optimum, with_holds


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
    params: OptimizerParams | None = None
    """The parameters of ``algorithm`` (None: its defaults, the ISSA paper's Table 5); read from a file by the caller."""
    callback: Callable[[int, float], None] | None = None
    tolerance_s: float | None = None
    use_window: bool = True
    yardstick: bool = False
    """Report each plan's gap to the optimum E* (the MPOC paper) at its own running time."""
    builder: str = "general"
    objective: str = "traction"
    """What the energy terms count (``physics.energy.OBJECTIVES``): the optimisers' eq. 10, E_min, E* and the
    gap to it; ``net`` is the traction work less what the electric brake recovers."""
    price_hint_kwh_per_s: float | None = None
    """The price of time at ``t0_s`` where the caller knows it (E*'s -dE*/dT there, e.g. a journey's leg): the
    priced-drive search of the general builder starts from it (``optimize.dp.PricedDriveSolver.for_time``)."""
    _e_min_cache: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    """Strategy inputs from the command line beyond route and train, as given (e.g. compare's --logs and
    --patterns: paths, named in messages)."""
    loaded: dict = field(default_factory=dict)
    """The same inputs read (the drivers' runs, the patterns): ``runner.run_strategy`` reads them with the
    readers of the strategy's registry entry, so a strategy never opens a file."""

    @property
    def ranking_tolerance_s(self) -> float | None:
        """The punctuality window the optimiser ranks by (None with --no-window: eq. 10 alone)."""
        return self.tolerance_s if self.use_window else None

    def rng(self, salt: int = 0, seed: int | None = None) -> np.random.Generator:
        return np.random.default_rng([self.seed if seed is None else seed, salt])

    def e_min(self) -> float:
        """E_min of eq. 11 [kWh]: the user's value; else, with the general builder and a planned time, the least
        energy of any punctual plan, E*(T0 + tolerance) (E* falls with the running time, so every plan on time
        has E >= E_min and eq. 10's |E - E_min| is its excess over the optimum); else (the ISSA paper's builder, no
        planned time, or no E* there) the energy-saving strategy's energy, the ISSA paper's own E_min (traction, or
        net with the ``net`` objective). ``e_min_source`` says which."""
        if self.e_min_kwh is not None:
            return self.e_min_kwh
        if "e" not in self._e_min_cache:
            e = self._e_min_optimum() if self.builder != "issa-paper" else None
            if e is not None:
                self._e_min_cache["e"], self._e_min_cache["source"] = e, "optimum"
            else:
                self._e_min_cache["e"], self._e_min_cache["source"] = self._e_min_energy_saving(), "energy-saving"
        return self._e_min_cache["e"]

    @property
    def e_min_known(self) -> float | None:
        """E_min where known without computing it: the user's, or what ``e_min()`` found (None before)."""
        return self.e_min_kwh if self.e_min_kwh is not None else self._e_min_cache.get("e")

    @property
    def priced_drive(self):
        """The priced-drive DP of this context (:func:`drive_solver`), None before a strategy built one."""
        return self._e_min_cache.get("dp")

    @priced_drive.setter
    def priced_drive(self, dp) -> None:
        """Share another context's DP on the same calculators (a solve rewrites its work arrays: no result changes)."""
        if dp is None:
            self._e_min_cache.pop("dp", None)
        else:
            self._e_min_cache["dp"] = dp

    @property
    def e_min_source(self) -> str | None:
        """Where E_min came from: ``given`` (--e-min), ``optimum`` (E* at the window's end) or ``energy-saving``
        (the ISSA paper's); None before it is known."""
        if self.e_min_kwh is not None:
            return "given"
        return self._e_min_cache.get("source")

    @property
    def e_min_time_s(self) -> float | None:
        """The running time [s] E_min is E* at (the window's slow end), where it is the optimum's."""
        return self._e_min_cache.get("time_s") if self.e_min_source == "optimum" else None

    def _e_min_optimum(self) -> float | None:
        """E*(T0 + tolerance) [kWh] (``ocp.bound.energy_bound``, cached with the yardstick's), or None without a
        planned time or where E* has no optimum there."""
        from ..errors import LocoplanError
        from ..ocp.bound import energy_bound  # the optimum: imported when a planned run needs it

        if math.isnan(self.t0_s):
            return None
        t = self.t0_s + (self.tolerance_s or 0.0)
        c = self.calc
        try:
            b = energy_bound(c.route, c.train, c.options, t, calc=c, objective=self.objective)
        except LocoplanError:
            return None
        if not math.isfinite(b.energy_kwh):
            return None
        self._e_min_cache["time_s"] = t
        self._e_min_cache["bound"] = b
        # traction work is never negative (below 0 is the solver's tolerance); a net energy may be
        return b.energy_kwh if self.objective != "traction" else max(b.energy_kwh, 0.0)

    def _e_min_energy_saving(self) -> float:
        """The ISSA paper's E_min: the energy-saving strategy's energy, floored at ``E_MIN_FLOOR_SHARE`` of the fastest
        run's (a falling line may be coasted from end to end, and eq. 11 divides by E_min)."""
        out = energy_saving(self)
        res = evaluate_outcome(self.calc, out, recovered=self.objective == "net")
        e = float(res.energy_kwh(self.objective)[0])
        fastest = float(self.calc.evaluate(("T",), np.zeros((1, 0))).traction_energy_kwh[0])
        self._e_min_cache["outcome"] = out
        return max(e, E_MIN_FLOOR_SHARE * fastest, 1e-3)


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
    result: "BatchResult | None" = None
    """A strategy that measured rather than planned (drivers' logs) gives its result; None = evaluate the plan."""
    extra: dict | None = None
    """More fields for the strategy's summary (e.g. the drivers' mean and best energies)."""


def evaluate_outcome(calc: TractionCalculator, outcome: StrategyOutcome, profile: bool = False, recovered: bool = False):
    """Simulate a strategy's plan (with its cruise speed, if any) on ``calc``."""
    plan = outcome.plan
    cruise = None if outcome.cruise_kmh is None else [outcome.cruise_kmh]
    return (outcome.calc or calc).evaluate(plan.conditions, plan.switches_m, profile=profile, cruise_kmh=cruise,
                                           recovered=recovered, **plan.cycle_kwargs())


def _plan(conditions, switches, problem: SwitchingProblem | None = None) -> Plan:
    """A plan from an optimiser's vector: its switching points, and with ``problem`` its release margins too."""
    x = np.asarray(switches, dtype=float).reshape(-1)
    margins = ()
    if problem is not None and problem.n_regions:
        x, d = x[:problem.n_switches], x[problem.n_switches:]
        margins = tuple((float(a), float(b), float(v)) for (a, b), v in zip(problem.regions_m, d))
    return Plan(tuple(conditions), (0.0, *[float(v) for v in x], float("nan")), margins)


def _cycles(ctx: StrategyContext) -> dict:
    """A switching problem's air-brake cycles: the descents where the air brake cycles on the reporting grid, the
    release margin of each a variable of the search."""
    regions = ctx.calc.cycle_regions_m
    return {"regions_m": regions} if len(regions) else {}


ENERGY_SAVING_ALGORITHM = "issa"
"""The energy-saving baseline is always searched by ISSA (the ISSA paper's own optimiser, which also finds the
lowest energies here), so that E_min does not change with the --algorithm being studied."""
E_MIN_SEED = 1
"""...nor with --seed: its search always starts from this seed, so that fitness values (eq. 10-11) of
runs with different seeds are comparable."""
E_MIN_FLOOR_SHARE = 0.01
RANKING_MARGIN = 0.9


def _optimise(ctx: StrategyContext, problem: SwitchingProblem, salt: int, algorithm: str | None = None,
              seed: int | None = None, x0: np.ndarray | None = None):
    name = algorithm or ctx.algorithm
    given = ctx.params if name == ctx.algorithm else None
    params = (given if given is not None else default_params(name)).model_dump()
    opt = get_algorithm(name)()
    try:
        opt.setup(problem, ctx.rng(salt, seed), x0=x0, **params)
        return opt.run(callback=ctx.callback)
    except NoFeasibleCandidateError as exc:  # say what the traction calculation found, not only that it failed
        why = problem.last.failures() if getattr(problem, "last", None) is not None else ""
        raise InfeasibleError(f"{exc}{': the last batch, ' + why if why else ''}") from None


def _confirmed(ctx: StrategyContext, problem: SwitchingProblem, result, prefer_best: bool = False) -> np.ndarray:
    """The best of the optimiser's final population re-simulated on the reporting grid (the search grid
    is coarser: a plan feasible there may stall or break a limit here): the reported plan is one the
    reporting grid confirms. ``prefer_best``: keep the search's best if the reporting grid confirms it."""
    X = result.population if result.population is not None else np.atleast_2d(result.best_x)
    X = np.concatenate([np.atleast_2d(result.best_x), X])
    check = replace(problem, calc=ctx.calc)
    fitness = check.fitness(check.simulate(X))
    if prefer_best and np.isfinite(fitness[0]):
        return result.best_x
    return X[int(np.argmin(fitness))] if np.isfinite(fitness).any() else result.best_x


def time_saving(ctx: StrategyContext) -> StrategyOutcome:
    """The fastest run (the ISSA paper's Fig. 4): max traction everywhere, held at each limit, braking only
    where the braking curves of the limit drops and of the stop demand it. In the calculator this is
    the single condition T: the braking envelope supplies every brake application."""
    return StrategyOutcome(Plan(("T",), (0.0,)))


def energy_saving_sequence(calc: TractionCalculator, threshold_kmh: float = 2.0):
    """The ISSA paper's builder: T, C alternating: traction to start and before each long up-grade, coasting
    after; windows halfway to the neighbouring nominal switches (a traction run may start well before
    its grade)."""
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


def energy_saving(ctx: StrategyContext) -> StrategyOutcome:
    """The least traction energy, timetable ignored. issa-paper: traction and coasting only (the ISSA paper's
    energy-saving strategy), switching points by ISSA; general: the drive at the lowest price of time
    (``optimize/dp.py``), as a condition sequence."""
    cached = ctx._e_min_cache.get("outcome")
    if cached is not None:
        return cached
    t = time.perf_counter()
    if ctx.builder == "issa-paper":
        conditions, _, lower, upper = energy_saving_sequence(ctx.search)
        problem = SwitchingProblem(ctx.search, conditions, lower, upper, objective="energy", energy=ctx.objective)
        result = _optimise(ctx, problem, salt=2, algorithm=ENERGY_SAVING_ALGORITHM, seed=E_MIN_SEED)
        x = _confirmed(ctx, problem, result, prefer_best=True)
        return StrategyOutcome(_plan(conditions, x), algorithm=ENERGY_SAVING_ALGORITHM, history=result.history,
                               n_evaluations=result.n_evaluations, solve_time_s=time.perf_counter() - t)
    solver = drive_solver(ctx)
    price = LEAST_PRICE_KWH_PER_S
    for attempt in range(ENERGY_SAVING_PRICE_STEPS):
        drive = solver.solve(price)
        if drive is None:
            raise InfeasibleError(no_drive_message(ctx))
        seq = sequence_from_drive(solver.calc, drive)
        out = StrategyOutcome(_plan(seq.conditions, seq.nominal_m), algorithm=None)
        if attempt == ENERGY_SAVING_PRICE_STEPS - 1 or evaluate_outcome(ctx.calc, out).feasible[0]:
            break
        # the grid's drive crawls over a crest that the exact calculator stalls on: a little more speed
        price *= ENERGY_SAVING_PRICE_FACTOR
    return replace(out, solve_time_s=time.perf_counter() - t)


LEAST_PRICE_KWH_PER_S = 1e-4
"""The price of time [kWh/s] of the energy-saving drive: low enough that no energy is spent to save time."""
ENERGY_SAVING_PRICE_STEPS = 8
ENERGY_SAVING_PRICE_FACTOR = 3.0
"""Where the least-price drive's plan stalls on the exact calculator (the DP's 0.5 km/h speed grid lets it
crawl over a crest at a speed the calculator's sub-steps do not keep), the price rises by this factor, at
most ``ENERGY_SAVING_PRICE_STEPS - 1`` times (1e-4 to 0.07 kWh/s), until the plan reaches the stop."""


DP_MIN_CELLS = 300
"""The priced-drive DP places switching points on cell edges: it works on cells of at most 100 m, and on
a short line on at least this many (not finer than 10 m)."""


def drive_solver(ctx: StrategyContext):
    """The priced-drive DP (``optimize.dp.PricedDriveSolver``) over the search grid (finer on short lines),
    built once per context."""
    from ..optimize.dp import PricedDriveSolver  # numba: imported when a drive is needed, not at start-up

    if "dp" not in ctx._e_min_cache:
        calc = ctx.search
        cell = max(10.0, min(100.0, calc.route.length_m / DP_MIN_CELLS))
        if cell < calc.options.step_m:
            calc = TractionCalculator(calc.route, calc.train, replace(calc.options, step_m=cell))
        ctx._e_min_cache["dp"] = PricedDriveSolver(calc, cell_m=cell)
    return ctx._e_min_cache["dp"]


def no_drive_message(ctx: StrategyContext) -> str:
    return (f"no drive of '{ctx.search.route.name}' with '{ctx.search.train.name}' reaches the stop within its "
            f"limits (the fastest run: {ctx.calc.evaluate(('T',), np.zeros((1, 0))).reason(0)})")


def four_stage(ctx: StrategyContext) -> StrategyOutcome:
    """Traction to a cruise speed, cruise (re-accelerating where limits or grades pulled it down),
    coast, brake. Cruise speed and coasting point come from a grid search, refined once: the least
    energy among plans within 1 s of the planned time, else the plan closest to it. The issa-paper builder
    coasts in the second half of the route and refines on the search grid, as first measured; the
    general one may coast from anywhere and refines on the reporting grid (its plan is confirmed there)."""
    t = time.perf_counter()
    calc = ctx.search
    L = calc.route.length_m
    v_top = float(calc.limit_kmh.max())
    general = ctx.builder != "issa-paper"
    v_grid = np.arange(10.0 if general else 30.0, v_top + 0.5, 1.0)
    x_grid = np.arange(100.0 if general else L / 2, L - 50.0, 100.0)
    best = span = None
    for v_step, x_step in ((1.0, 100.0), (0.1, 5.0)):
        if best is not None:
            calc = ctx.calc if general else calc
            v_grid = np.arange(best[0] - v_step * 10, best[0] + v_step * 10.5, v_step)
            x_grid = np.arange(best[1] - x_step * 20, best[1] + x_step * 20.5, x_step)
            v_grid, x_grid = v_grid[(v_grid > 0) & (v_grid <= v_top)], x_grid[(x_grid > 0) & (x_grid < L)]
        V, X = (a.ravel() for a in np.meshgrid(v_grid, x_grid))
        res = calc.evaluate(("T", "C", "B"), np.column_stack([X, np.full_like(X, np.nan)]), cruise_kmh=V,
                            recovered=ctx.objective == "net")
        ok = res.feasible
        if not ok.any():
            raise InfeasibleError("four-stage: no feasible cruise speed / coasting point on this route")
        times = res.running_time_s[ok]
        span = (float(times.min()), float(times.max())) if span is None else (min(span[0], float(times.min())), max(span[1], float(times.max())))
        late = np.abs(res.running_time_s - ctx.t0_s)
        punctual = ok & (late <= 1.0)
        if punctual.any():
            i = int(np.argmin(np.where(punctual, res.energy_kwh(ctx.objective), np.inf)))
        else:
            i = int(np.argmin(np.where(ok, late, np.inf)))
        best = (float(V[i]), float(X[i]))
    return StrategyOutcome(_plan(("T", "C", "B"), [best[1]]), cruise_kmh=round(best[0], 2),
                           n_evaluations=0, solve_time_s=time.perf_counter() - t, time_range_s=span)


SEARCH_GRID_TIME_SHARE = 0.25
"""The optimisers search the coarser grid only where it times the nominal plan to within this share of
the punctuality window of the reporting grid (on freight-20km: 0.05 % apart, against a window of 2 %)."""


def _search_grid_for(ctx: StrategyContext, seq) -> TractionCalculator:
    """The search grid, unless it misjudges the nominal plan's running time against the reporting grid by
    more than ``SEARCH_GRID_TIME_SHARE`` of the window (a train crawling over crests, or coasting for tens
    of kilometres at low speed, is timed differently on 100 m and 50 m cells): then the reporting grid."""
    if ctx.search is ctx.calc or not ctx.tolerance_s:
        return ctx.search
    x = np.array([[*seq.nominal_m, np.nan]])
    t_search = float(ctx.search.evaluate(seq.conditions, x).running_time_s[0])
    t_calc = float(ctx.calc.evaluate(seq.conditions, x).running_time_s[0])
    close = abs(t_search - t_calc) <= SEARCH_GRID_TIME_SHARE * ctx.tolerance_s  # False with a nan
    return ctx.search if close else ctx.calc


def _punctual(ctx: StrategyContext, problem: SwitchingProblem, x) -> bool:
    """Whether ``problem``'s candidate ``x`` runs within the window on the reporting grid (no window: True)."""
    if not ctx.tolerance_s or math.isnan(ctx.t0_s):
        return True
    res = replace(problem, calc=ctx.calc).simulate(np.atleast_2d(np.asarray(x, dtype=float)))
    return bool(res.feasible[0]) and abs(float(res.running_time_s[0]) - ctx.t0_s) <= ctx.tolerance_s


def proposed(ctx: StrategyContext) -> StrategyOutcome:
    """The ISSA paper's method: a condition sequence from the route, switching points minimising eq. 10."""
    e_min = ctx.e_min()
    t = time.perf_counter()
    common = dict(t0_s=ctx.t0_s, e_min_kwh=e_min, weights=ctx.weights, tolerance_s=ctx.ranking_tolerance_s,
                  energy=ctx.objective)
    if ctx.builder == "issa-paper":
        seq = build_sequence(ctx.search)
        problem = _problem(ctx, ctx.search, seq, common, centred=False)
        result = _optimise(ctx, problem, salt=1)
        x = result.best_x
        return StrategyOutcome(_plan(seq.conditions, x, problem), algorithm=ctx.algorithm, history=result.history,
                               n_evaluations=result.n_evaluations, solve_time_s=time.perf_counter() - t,
                               e_min_kwh=e_min, time_range_s=problem.time_range_s)
    # the optimiser's window is a little narrower than the reported one: the reporting grid re-simulates
    if ctx.ranking_tolerance_s is not None:
        common["tolerance_s"] = RANKING_MARGIN * ctx.ranking_tolerance_s
    common["min_gap_m"] = min_run_m(ctx.calc.train)
    best, evaluations, failure = None, 0, None
    for start in (_optimum_start, _held_burst_start, _cycle_start, _drive_start):
        if best is not None and _close_enough(ctx, best):
            break
        seq = start(ctx)
        if seq is None:
            continue
        try:
            found = _search(ctx, seq, common)
        except InfeasibleError as exc:  # no plan of this sequence drives: the other start's, if it finds one
            failure = exc
            continue
        evaluations += found[2].n_evaluations if found[2] is not None else 0
        if best is None or found[4] < best[4]:
            best = found
    if best is None:
        if failure is not None:
            raise failure
        raise InfeasibleError(f"proposed: {no_drive_message(ctx)}")
    if not _close_enough(ctx, best):
        found = _electric_braking(ctx, best, common)
        if found is not None:
            evaluations += found[2].n_evaluations if found[2] is not None else 0
            if found[4] < best[4]:
                best = found
    seq, problem, result, x, _ = best
    if problem is None:  # one condition, then the stop: nothing to search
        return StrategyOutcome(_plan(seq.conditions, []), algorithm=None, solve_time_s=time.perf_counter() - t,
                               e_min_kwh=e_min)
    result = replace(result, n_evaluations=evaluations)
    return StrategyOutcome(_plan(seq.conditions, x, problem), algorithm=ctx.algorithm, history=result.history,
                           n_evaluations=result.n_evaluations, solve_time_s=time.perf_counter() - t,
                           e_min_kwh=e_min, time_range_s=problem.time_range_s)


CLOSE_SHARE = 0.005
CLOSE_KWH = 0.15
"""The optimum's start is searched first; the next start (the drive optimal with the air brake's cycle, where it
binds; the priced DP drive) only where the best plan so far is not on time on the reporting grid, or exceeds E*
at its own running time by more than ``CLOSE_SHARE`` of it (or ``CLOSE_KWH`` where that is more), and the optimum
with the cycle too where the cycle binds: the best plan is kept."""


def _close_enough(ctx: StrategyContext, found) -> bool:
    """Whether the plan ``_search`` found (seq, problem, result, x, fitness) is on time on the reporting grid and
    within ``CLOSE_SHARE`` of E* at its own running time (``ocp.bound.energy_bound``, as its gap will be)."""
    from ..errors import LocoplanError
    from ..ocp.bound import energy_bound

    seq, problem, _, x, f = found
    if not math.isfinite(f) or ctx.e_min_source != "optimum":
        return False
    if problem is not None:
        res = replace(problem, calc=ctx.calc).simulate(np.atleast_2d(x))
    else:
        res = ctx.calc.evaluate(seq.conditions, np.full((1, len(seq.conditions) - 1), np.nan), recovered=ctx.objective == "net")
    t = float(res.running_time_s[0])
    if not res.feasible[0] or (ctx.tolerance_s and abs(t - ctx.t0_s) > ctx.tolerance_s):
        return False
    c = ctx.calc
    try:
        e_star = energy_bound(c.route, c.train, c.options, t, calc=c, objective=ctx.objective).energy_kwh
    except LocoplanError:
        return False
    e = float(res.energy_kwh(ctx.objective)[0])
    if e - e_star <= max(CLOSE_SHARE * abs(e_star), CLOSE_KWH):
        return True
    co = _cycle_optimum(ctx, t)  # where the air brake cycles, the optimum that keeps the cycle is the yardstick
    return co is not None and e - co.energy_kwh <= max(CLOSE_SHARE * abs(co.energy_kwh), CLOSE_KWH)


def _cycle_optimum(ctx: StrategyContext, time_s: float):
    """The optimum with the air brake's cycle at ``time_s`` (``cycle_start.cycle_optimum``, cached beside E*), or
    None where the model has no cycle, it cannot bind on the line, or the objective is not the traction energy."""
    from ..errors import LocoplanError
    from .cycle_start import cycle_optimum

    c = ctx.calc
    if c.air_cycle is None or ctx.objective != "traction":
        return None
    try:
        co = cycle_optimum(c.route, c.train, c.options, time_s, calc=c)
    except LocoplanError:
        return None
    return co if co.cycles and co.energy_kwh is not None and co.drive is not None else None


def _cycle_start(ctx: StrategyContext):
    """The condition sequence of the drive that is optimal with the air brake's cycle at the planned time
    (``cycle_start.drive_sequence``), or None where the cycle cannot bind."""
    from .cycle_start import drive_sequence

    if math.isnan(ctx.t0_s):
        return None
    co = _cycle_optimum(ctx, ctx.t0_s + OPTIMUM_START_SHARE * (ctx.tolerance_s or 0.0))
    if co is None:
        return None
    seq = drive_sequence(ctx.calc, co.drive)
    return seq if len(seq.conditions) > 1 else None


def _optimum_start(ctx: StrategyContext):
    """The condition sequence and switching points of E*'s own solution near the planned time
    (``general_builder.sequence_from_optimum``), or None where E* has none. E* is a relaxation of the plan's model
    (forces modulated at will, its own grid): where the sequence read off E* at T runs outside the window on the
    calculator (a heavy train crawling over crests holds a speed a little off E*'s, and a crawl's time is
    sensitive to it), it is read off E* at the time that brings it back, by secant steps on that time (at most
    ``CALIBRATION_STEPS``)."""
    from ..errors import LocoplanError
    from ..ocp.bound import optimum_solution

    if math.isnan(ctx.t0_s):
        return None
    c = ctx.calc
    tol = ctx.tolerance_s or 0.0
    target = ctx.t0_s + OPTIMUM_START_SHARE * tol
    fastest = c.fastest_time_s
    t_opt, seen = target, []
    best = None
    for _ in range(CALIBRATION_STEPS + 1):
        try:
            grid, sol = optimum_solution(c.route, c.train, c.options, t_opt, objective=ctx.objective)
        except LocoplanError:
            break
        seq = sequence_from_optimum(ctx.search, grid, sol, min_run_m(ctx.calc.train))
        # timed on the grid the search will run on: the search grid where it times the plan as the reporting grid
        # does (``_search_grid_for``), else the reporting grid (a slow plan's crawl the coarse grid misjudges)
        x = np.array([[*seq.nominal_m, np.nan]])
        res = ctx.calc.evaluate(seq.conditions, x)
        t_plan = float(res.running_time_s[0]) if res.feasible[0] else math.nan
        if ctx.search is not ctx.calc and math.isfinite(t_plan):
            rs = ctx.search.evaluate(seq.conditions, x)
            t_s = float(rs.running_time_s[0]) if rs.feasible[0] else math.nan
            if abs(t_s - t_plan) <= SEARCH_GRID_TIME_SHARE * tol:
                t_plan = t_s
        miss = abs(t_plan - target) if math.isfinite(t_plan) else math.inf
        if best is None or miss < best[0]:
            best = (miss, seq)
        if not tol or miss <= CALIBRATION_SHARE * tol or not math.isfinite(t_plan):
            break
        seen.append((t_opt, t_plan))
        if len(seen) == 1:
            t_next = t_opt + (target - t_plan)
        else:
            (a, ta), (b, tb) = seen[-2], seen[-1]
            t_next = b + (target - tb) * (b - a) / (tb - ta) if tb != ta else b + (target - tb)
        t_opt = max(t_next, fastest * (1 + 1e-3))
    return None if best is None else best[1]


def _held_burst_start(ctx: StrategyContext):
    """The optimum's sequence (``_optimum_start``) with each burst of traction (a run of T no longer than the shortest
    run, between runs of other conditions: where E* pushes a crawling train over a crest with a partial force for a
    cell or two) held instead (K, the speed at which it begins held with partial traction): full traction for the
    shortest run gives far more than E*'s burst, and the time it gains must be spent again later. None where the
    sequence has no such burst."""
    seq = _optimum_start(ctx)
    if seq is None or len(seq.nominal_m) < 2:
        return None
    gap = min_run_m(ctx.calc.train)
    starts = np.concatenate([[0.0], seq.nominal_m])
    ends = np.concatenate([seq.nominal_m, [ctx.calc.route.length_m]])
    body = list(seq.conditions[:-1])
    conds = list(seq.conditions)
    hit = False
    for j in range(1, len(body) - 1):
        if body[j] == "T" and ends[j] - starts[j] <= gap * (1 + 1e-6) and body[j - 1] != "T" and body[j + 1] != "T":
            conds[j] = "K"
            hit = True
    if not hit:
        return None
    return replace(seq, conditions=tuple(conds))


CALIBRATION_STEPS = 3
CALIBRATION_SHARE = 0.5
"""``_optimum_start`` reads the sequence off E* at another time while its plan misses the middle of the window by
more than this share of the window, at most ``CALIBRATION_STEPS`` times."""


MIN_RUN_M = 100.0
"""The general builder's shortest run of one condition [m]: half the train (the ISSA paper's eq. 3), at most this.
Eq. 3 is the ISSA paper's own rule (``--builder issa-paper`` keeps it); on a line of short pitches a long train's
optimum climbs each pitch in traction and coasts down the next, and half a 1,270 m heavy-haul train (635 m)
forbids it: on a generated 32 km sawtooth line with HXD1 x 2 + 100 x C80 the best plan found with runs of at
least 635 m lay 12 % over E*, with 100 m runs 0.2 %. 100 m is a few seconds of driving at line speed."""


def min_run_m(train) -> float:
    """The general builder's shortest run [m] (``MIN_RUN_M``)."""
    return min(train.length_m / 2.0, MIN_RUN_M)


OPTIMUM_START_SHARE = 0.5
"""E*'s solution the optimum's sequence is read off is E* at T0 + this share of the punctuality window: the
optimiser's plans gather towards the window's slow end, where eq. 10 is least."""


def _drive_start(ctx: StrategyContext):
    """The sequence of the priced-optimal DP drive whose plan runs closest to the planned time
    (``optimize.dp``), with speed holds where even the least energy runs too fast; None where no drive
    reaches the stop."""
    solver = drive_solver(ctx)

    def plan_time(d):  # the drive's plan on the search grid, as ISSA will see it
        q = sequence_from_drive(solver.calc, d)
        res = ctx.search.evaluate(q.conditions, np.array([[*q.nominal_m, np.nan]]))
        return float(res.running_time_s[0]) if res.feasible[0] else math.inf

    drive = solver.for_time(ctx.t0_s, timer=plan_time, close_s=0.25 * (ctx.tolerance_s or 0.0),
                            price_hint=ctx.price_hint_kwh_per_s)
    if drive is None:
        return None
    seq = sequence_from_drive(solver.calc, drive)
    tol = ctx.tolerance_s or 0.0
    if drive.time_s < ctx.t0_s - tol and "C" in seq.conditions:
        slowest = solver.solve(LEAST_PRICE_KWH_PER_S)
        if slowest is not None and plan_time(slowest) < ctx.t0_s - tol:
            seq = with_holds(ctx.search, seq)  # even the least energy is too fast: spend the time holding
    elif drive.time_s < ctx.t0_s - tol and "T" in seq.conditions:
        # traction to the stop (a climb) and still too fast: no drive's sequence came nearer, so hold a
        # lower speed inside the traction run (partial traction), where ISSA places it
        seq = with_holds(ctx.search, seq)
    return seq


def _electric_braking(ctx: StrategyContext, found, common: dict):
    """Where the best plan ``found`` (seq, problem, result, x, fitness) lets the air brake apply to follow a
    limit or a braking curve (its least hold then slows a train well under the limit ahead, or holds it through
    a neutral section on a descent), the same plan with the electric brake alone (E) just before each such
    application (at most ``ELECTRIC_RUNS``): each run's length and end tried on a small batch (``ELECTRIC_TRIES_M``),
    the fastest kept where it saves ``ELECTRIC_MIN_GAIN_S``, then ISSA over all switching points from there; the
    ``_search`` tuple, or None where the model has no separate air brake, the plan makes no such application, or no
    run saves that much time."""
    seq, problem, _, x, _ = found
    calc = ctx.calc
    if calc.air_cycle is None or problem is None:
        return None
    plan = _plan(seq.conditions, x, problem)
    res = calc.evaluate(plan.conditions, plan.switches_m, profile=True, **plan.cycle_kwargs())
    prof = res.profile
    if not res.feasible[0] or prof.air is None:
        return None
    s = calc.s_m
    starts = np.array([v if math.isfinite(v) else np.inf for v in plan.starts_m])
    own = np.searchsorted(starts, s[:-1], side="right") - 1  # each cell's plan condition
    applied = np.flatnonzero((prof.air[0] == AIR_APPLIED) & (np.array(plan.conditions)[own] != "B"))
    if not applied.size:
        return None
    gap = common["min_gap_m"]
    conditions, nominal = list(seq.conditions), list(np.asarray(x, dtype=float)[:len(seq.nominal_m)])
    t_best = float(res.running_time_s[0])
    episodes = [int(k) for i, k in enumerate(applied) if i == 0 or s[k] - s[applied[i - 1]] > ELECTRIC_EPISODE_M]
    for k in episodes[:ELECTRIC_RUNS]:
        x_app = float(s[k])
        groups: dict[tuple, list] = {}
        for end in ELECTRIC_TRIES_M[0]:
            for length in ELECTRIC_TRIES_M[1]:
                b, a = x_app + end, x_app + end - length
                if length < min(E_MIN_RUN_M, gap) or a <= gap or b >= calc.route.length_m - gap:
                    continue
                got = _insert_run(conditions, nominal, "E", a, b)
                if got is not None:
                    groups.setdefault(tuple(got[0]), []).append(got[1])
        for conds, noms in groups.items():  # one batch per sequence
            r = calc.evaluate(conds, np.array([[*nom, np.nan] for nom in noms]), **_batch_margins(plan, len(noms)))
            t_c = np.where(r.feasible, r.running_time_s, np.inf)
            i = int(np.argmin(t_c))
            if t_c[i] < t_best - ELECTRIC_MIN_GAIN_S:
                conditions, nominal, t_best = list(conds), noms[i], float(t_c[i])
    if tuple(conditions) == tuple(seq.conditions):
        return None
    from types import SimpleNamespace

    from .general_builder import _with_windows
    drive = SimpleNamespace(time_s=seq.drive_time_s, energy_kwh=seq.drive_energy_kwh, price_kwh_per_s=seq.price_kwh_per_s)
    new = _with_windows(tuple(conditions), np.array(nominal), gap, calc.route.length_m, False, drive)
    try:
        found = _search(ctx, new, common)
    except InfeasibleError:
        return None
    return _without_idle_electric(ctx, found, common, drive)


def _without_idle_electric(ctx: StrategyContext, found, common: dict, drive):
    """``found`` (``_search``'s tuple) with each E run that saves no time (the search may have moved the switching
    points round it so that coasting there runs as fast) coasted instead: the plan on time and using no more energy
    without it (the last first)."""
    from .general_builder import _with_windows

    seq, problem, _, x, _ = found
    if problem is None:
        return found
    calc = ctx.calc
    n = len(seq.conditions) - 1  # switches (the final B's is NaN)
    conds, sw, margins = list(seq.conditions), list(np.asarray(x, dtype=float)[:problem.n_switches]), \
        np.asarray(x, dtype=float)[problem.n_switches:]
    plan = _plan(conds, x, problem)
    net = ctx.objective == "net"  # (the net energy needs the recovered energy)
    base = calc.evaluate(plan.conditions, plan.switches_m, recovered=net, **plan.cycle_kwargs())
    changed = False
    for j in range(n - 1, 0, -1):
        if conds[j] != "E" or j + 1 >= len(conds) - 1 or conds[j - 1] != conds[j + 1]:
            continue
        c2 = conds[:j] + conds[j + 2:]
        s2 = sw[:j - 1] + sw[j + 1:]
        trial = Plan(tuple(c2), (0.0, *s2, float("nan")), plan.release_margins)
        r = calc.evaluate(trial.conditions, trial.switches_m, recovered=net, **trial.cycle_kwargs())
        t = float(r.running_time_s[0])
        on_time = not ctx.tolerance_s or abs(t - ctx.t0_s) <= ctx.tolerance_s
        if r.feasible[0] and on_time and float(r.energy_kwh(ctx.objective)[0]) <= float(base.energy_kwh(ctx.objective)[0]) + 1e-9:
            conds, sw, base, changed = c2, s2, r, True
    if not changed:
        return found
    gap = common["min_gap_m"]
    new = _with_windows(tuple(conds), np.array(sw), gap, calc.route.length_m, False, drive)
    problem2 = _problem(ctx, calc, new, common)
    x2 = np.concatenate([sw, margins])
    f = float(problem2.fitness(problem2.simulate(np.atleast_2d(x2)))[0])
    return new, problem2, found[2], x2, f


ELECTRIC_RUNS = 6
ELECTRIC_MIN_GAIN_S = 1.0
"""An E run is kept only where it saves at least this much running time [s]: the search after it costs as much as
the first (3 s on the heavy-haul line, where the best E runs saved 0.04 s), and a few hundredths of a second buy
next to no energy."""
ELECTRIC_EPISODE_M = 2000.0
ELECTRIC_TRIES_M = ((-300.0, -150.0, -50.0, 0.0, 50.0), (25.0, 50.0, 100.0, 200.0, 400.0, 800.0))
"""``_electric_braking``: the applications it tries to avoid (the first of each episode, applications more than
``ELECTRIC_EPISODE_M`` apart; at most ``ELECTRIC_RUNS`` episodes), and each E run's end relative to the
application's cell [m] and its length [m] (at least the shortest run)."""


def _insert_run(conditions: list, nominal: list, c: str, a: float, b: float):
    """``conditions`` (the first starting at 0) and their later starts ``nominal`` with condition ``c`` from ``a`` to
    ``b`` [m] inside one run (that run's condition again after ``b``), or None where [a, b] spans a switch."""
    starts = [0.0, *nominal]
    j = int(np.searchsorted(starts, a, side="right") - 1)
    nxt = starts[j + 1] if j + 1 < len(starts) else math.inf
    if b >= nxt or j + 1 >= len(conditions) or conditions[j] in ("B", c):
        return None
    conds = conditions[:j + 1] + [c, conditions[j]] + conditions[j + 1:]
    return conds, nominal[:j] + [a, b] + nominal[j:]


def _batch_margins(plan: Plan, n: int) -> dict:
    """The release margins of ``plan`` as ``evaluate`` takes them, for a batch of ``n`` plans."""
    kw = plan.cycle_kwargs()
    if kw:
        kw["release_margin"] = np.repeat(kw["release_margin"], n, axis=0)
    return kw


def _search(ctx: StrategyContext, seq, common: dict):
    """ISSA (the context's optimiser) over the switching points of ``seq`` from its nominal ones: (seq, problem,
    result, x, fitness of x on the reporting grid); problem and result None for a sequence with nothing to place."""
    if not len(seq.nominal_m):
        res = ctx.calc.evaluate(seq.conditions, np.zeros((1, len(seq.conditions) - 1)) + np.nan)
        f = SwitchingProblem(ctx.calc, seq.conditions, np.zeros(0), np.zeros(0), **common).fitness(res)[0]
        return seq, None, None, np.zeros(0), float(f)
    search = _search_grid_for(ctx, seq)
    problem = _problem(ctx, search, seq, common)
    nominal = problem.center
    jitter = ctx.rng(3).normal(0.0, 0.1, (10, problem.n_var)) * (problem.upper - problem.lower)
    x0 = np.vstack([nominal, nominal + jitter])
    result = _optimise(ctx, problem, salt=1, x0=x0)
    x = _confirmed(ctx, problem, result)
    check = replace(problem, calc=ctx.calc)
    if search is not ctx.calc:
        f_x, f_nominal = check.fitness(check.simulate(np.vstack([x, nominal])))
        if not _punctual(ctx, problem, x) or f_x > f_nominal:
            # the coarser grid misjudged the plans (slow coasting on a long falling line; short runs, whose forces
            # its cells blend): search again on the reporting grid, from the start and from where the first
            # search ended
            problem = check
            again = _optimise(ctx, problem, salt=2, x0=np.vstack([np.atleast_2d(nominal), np.atleast_2d(result.best_x),
                                                                    result.population]))
            result = replace(again, n_evaluations=result.n_evaluations + again.n_evaluations)
            x = _confirmed(ctx, problem, result)
    return seq, problem, result, x, float(check.fitness(check.simulate(np.atleast_2d(x)))[0])


def _problem(ctx: StrategyContext, calc: TractionCalculator, seq, common: dict, centred: bool = True) -> SwitchingProblem:
    """The switching problem of ``seq`` on ``calc`` (its random candidates drawn around the nominal switching
    points where ``centred``), with the proposed plan's releases (``_releases``)."""
    kw = {"lower": seq.lower_m, "upper": seq.upper_m, **({"center": seq.nominal_m} if centred else {})}
    kw.update(_releases(ctx, seq, centred))
    return SwitchingProblem(calc, seq.conditions, **kw, **common)


def _releases(ctx: StrategyContext, seq, centred: bool = True) -> dict:
    """The proposed plan's air-brake releases, as ``SwitchingProblem`` keywords: on every descent where the air
    brake cycles (``TractionCalculator.cycle_regions_m``) the release comes as soon as the brake can recharge
    before it is needed again (``kernel.release_safe``: the least margin, ``EARLIEST_RELEASE``, fixed), so that the
    train loses as little speed, hence time, to the cycle as the rules allow (on the heavy-haul line 14.5 s of the
    run against the rule's margin, at the same traction energy on the descent: the time is saved elsewhere). A
    release margin is then no variable of the search: every margin below the look-ahead's releases the same."""
    regions = ctx.calc.cycle_regions_m
    if not len(regions):
        return {}
    n = len(seq.lower_m)
    fixed = np.full(len(regions), EARLIEST_RELEASE)
    return {"regions_m": regions, "lower": np.concatenate([seq.lower_m, fixed]),
            "upper": np.concatenate([seq.upper_m[:n], fixed]),
            **({"center": np.concatenate([seq.nominal_m, fixed])} if centred else {})}


EARLIEST_RELEASE = MARGIN_MIN
"""The proposed plan's release margin on every descent where the air brake cycles (``_releases``)."""


def _union(a, b):
    """The span of two (lo, hi) time ranges (either may be None)."""
    if a is None or b is None:
        return a or b
    return (min(a[0], b[0]), max(a[1], b[1]))

