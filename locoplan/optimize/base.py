"""Optimiser plumbing shared by ISSA, SSA and PSO: the problem protocol, ask/tell loop and infeasible handling.

A *problem* (``Problem``) is a box-bounded minimisation over ``n_var`` decision variables -- for locoplan the
positions of the driving-regime switching points along the route, in metres. It evaluates a whole
population in ONE call (the traction calculation is vectorised over candidates) and says, per candidate,
whether it passed the traction calculation (``feasible``).

Infeasible candidates are handled as in the ISSA paper's section 3.2:

* step 2: the initial population holds only feasible individuals -- random samples are drawn and
  batch-evaluated, feasible ones kept, until the population is full;
* step 5: after every position update, individuals that fail the traction calculation are removed and the
  gap is refilled with freshly sampled feasible individuals.

Both go through the one helper ``sample_feasible`` (step 5 via ``replace_infeasible``), used by every
algorithm. If the feasible region is so small that a bounded number of sample batches cannot fill the
gap, ``NoFeasibleCandidateError`` (an ``InfeasibleError``, CLI exit code 1) is raised.

The optimiser itself is an ask/tell state machine (``Optimizer``): ``ask()`` returns the candidates to
evaluate next (already repaired), ``tell(X, evaluation)`` feeds their evaluation back. ``run()`` drives the
loop against the problem and returns a frozen ``Result``. Library code never prints; a ``callback`` lets
the CLI drive a progress bar. All random numbers come from the ``numpy.random.Generator`` given to
``setup``, so the same seed gives the same result.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from ..model.common import RuleViolations, plausible

from ..errors import InfeasibleError, InputError
from ..errors import Problem as InputProblem

__all__ = [
    "Evaluation",
    "NoFeasibleCandidateError",
    "Optimizer",
    "OptimizerParams",
    "Problem",
    "Result",
    "check_evaluation",
    "replace_infeasible",
    "sample_feasible",
    "validation_problems",
]


@dataclass(frozen=True)
class Evaluation:
    """Evaluation of ``n`` candidates.

    fitness:  (n,) float, dimensionless objective (the ISSA paper's eq. 10: weighted time/energy deviation); lower is better.
    feasible: (n,) bool, True if the candidate passed the traction calculation (speed limits, arrival, ...).
    """

    fitness: np.ndarray
    feasible: np.ndarray


@runtime_checkable
class Problem(Protocol):
    """A box-bounded minimisation problem evaluated a whole population at a time.

    n_var: number of decision variables (e.g. switching points).
    lower, upper: (n_var,) bounds of each variable, in the variable's unit (metres for switching points).
    """

    n_var: int
    lower: np.ndarray  # (n_var,)
    upper: np.ndarray  # (n_var,)

    def evaluate(self, X: np.ndarray) -> Evaluation:
        """Evaluate candidates ``X`` (n_pop, n_var) in ONE call; returns fitness and feasibility per row."""
        ...

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` random candidate rows (n, n_var) inside the bounds, drawn from ``rng``."""
        ...

    def repair(self, X: np.ndarray) -> np.ndarray:
        """Map arbitrary rows (n, n_var) back into the domain (e.g. clip to bounds and sort); returns a new array."""
        ...


@dataclass(frozen=True)
class Result:
    """Outcome of one optimiser run.

    best_x:                (n_var,) best feasible candidate found, in the variables' unit (metres).
    best_fitness:          its fitness (dimensionless, lower is better).
    history:               (n_iterations,) best fitness after each completed iteration (non-increasing).
    n_evaluations:         candidate rows evaluated in total, including the initial fill and replacements.
    n_infeasible_replaced: individuals removed after a position update for failing the traction
                           calculation and replaced by fresh feasible samples (the ISSA paper's sec. 3.2 step 5).
    """

    best_x: np.ndarray
    best_fitness: float
    history: np.ndarray
    n_evaluations: int
    n_infeasible_replaced: int
    population: np.ndarray | None = None  # (pop_size, n_var) the final population, best first


class NoFeasibleCandidateError(InfeasibleError):
    """Random sampling could not find enough candidates that pass the traction calculation.

    Usually the request is too tight (e.g. a running time close to the fastest possible run), so hardly any
    random switching-point set is feasible. Exit code 1 like every ``InfeasibleError``.
    """

    def __init__(self, needed: int, found: int, sampled: int, batches: int):
        self.needed, self.found, self.sampled, self.batches = needed, found, sampled, batches
        super().__init__(
            f"could not find {needed} feasible candidate(s) for the optimiser population: only {found} of "
            f"{sampled} random samples in {batches} batch(es) passed the traction calculation"
        )


def check_evaluation(evaluation: Evaluation, n: int) -> Evaluation:
    """Validate a problem's answer for ``n`` rows and normalise it to (n,) float / (n,) bool arrays.

    A non-finite fitness (NaN, inf) is treated as infeasible, so it can never become the best.
    Wrong shapes are a programming error of the problem and raise ``ValueError``.
    """
    fitness = np.asarray(evaluation.fitness, dtype=float).reshape(-1)
    feasible = np.asarray(evaluation.feasible, dtype=bool).reshape(-1)
    if fitness.shape != (n,) or feasible.shape != (n,):
        raise ValueError(
            f"problem.evaluate returned fitness {fitness.shape} and feasible {feasible.shape} for {n} candidate(s)"
        )
    feasible = feasible & np.isfinite(fitness)
    return Evaluation(fitness=fitness, feasible=feasible)


def _evaluate(problem: Problem, X: np.ndarray) -> Evaluation:
    return check_evaluation(problem.evaluate(X), X.shape[0])


def sample_feasible(
    problem: Problem, rng: np.random.Generator, n: int, max_batches: int = 20
) -> tuple[np.ndarray, Evaluation, int]:
    """Draw ``n`` feasible candidates by rejection sampling in batches (the ISSA paper's sec. 3.2 steps 2 and 5).

    Each batch is sampled with ``problem.sample`` and evaluated in ONE ``problem.evaluate`` call. The batch
    size follows the feasible rate seen so far (so a 10 % feasible region needs few batches), capped at
    10 n rows to bound the cost of one call.

    Returns ``(X, evaluation, n_evaluated)``: X (n, n_var), its evaluation (all feasible), and the number of
    rows evaluated. Raises ``NoFeasibleCandidateError`` if ``max_batches`` batches do not yield ``n``.
    """
    n_var = int(problem.n_var)
    if n <= 0:
        return np.empty((0, n_var)), Evaluation(np.empty(0), np.empty(0, dtype=bool)), 0
    found_x: list[np.ndarray] = []
    found_f: list[np.ndarray] = []
    n_found = n_sampled = 0
    for _ in range(max_batches):
        missing = n - n_found
        if n_sampled == 0:
            size = missing
        elif n_found == 0:
            size = 10 * n  # nothing feasible yet: widen the net as far as the cap allows
        else:
            # expected need plus ~2 binomial standard deviations, so the last few are not chased one by one
            rate = n_found / n_sampled
            size = min(10 * n, math.ceil((missing + 2.0 * math.sqrt(missing) + 2.0) / rate))
        X = np.asarray(problem.sample(size, rng), dtype=float).reshape(size, n_var)
        ev = _evaluate(problem, X)
        n_sampled += size
        ok = np.flatnonzero(ev.feasible)[:missing]
        found_x.append(X[ok])
        found_f.append(ev.fitness[ok])
        n_found += ok.size
        if n_found == n:
            fitness = np.concatenate(found_f)
            return np.concatenate(found_x), Evaluation(fitness, np.ones(n, dtype=bool)), n_sampled
    raise NoFeasibleCandidateError(n, n_found, n_sampled, max_batches)


def replace_infeasible(
    problem: Problem, rng: np.random.Generator, X: np.ndarray, evaluation: Evaluation, max_batches: int = 20
) -> tuple[np.ndarray, Evaluation, np.ndarray, int]:
    """Remove the infeasible rows of an updated population and refill them with fresh feasible samples.

    The ISSA paper's sec. 3.2 step 5. Inputs: X (n, n_var) and its evaluation. Returns ``(X_new, evaluation_new,
    replaced, n_evaluated)``: new arrays (inputs untouched) where every row is feasible, the (n,) bool mask
    of the rows that were replaced, and the number of rows evaluated while sampling.
    """
    replaced = ~np.asarray(evaluation.feasible, dtype=bool)
    k = int(replaced.sum())
    if k == 0:
        return X.copy(), Evaluation(evaluation.fitness.copy(), evaluation.feasible.copy()), replaced, 0
    X_fill, ev_fill, n_eval = sample_feasible(problem, rng, k, max_batches)
    X_new = X.copy()
    fitness = np.asarray(evaluation.fitness, dtype=float).copy()
    X_new[replaced] = X_fill
    fitness[replaced] = ev_fill.fitness
    return X_new, Evaluation(fitness, np.ones(X.shape[0], dtype=bool)), replaced, n_eval


# --------------------------------------------------------------------------------------------- parameters


LIMITS = {
    "pop_size": (2, 1_000),
    "max_iter": (1, 10_000),
    "max_sample_batches": (1, 1_000),
    "evaluations": 1_000_000,  # pop_size x max_iter: 200x the ISSA paper's 5,000
}
"""Bounds of every optimiser's parameter file: generous for studies, finite so that a typo
(``pop_size: 100000000``) is refused at once instead of running for days or filling the memory."""


class OptimizerParams(BaseModel):
    """Parameters common to every algorithm; subclasses add the algorithm's own (the ISSA paper's Table 5).

    Unknown keys are rejected (``extra="forbid"``): a typo in a parameter file never passes silently.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)

    pop_size: Annotated[int, plausible(*LIMITS["pop_size"], "individuals", "the ISSA paper uses 50")] = Field(
        50, ge=2, description="individuals in the population (the ISSA paper: 50)")
    max_iter: Annotated[int, plausible(*LIMITS["max_iter"], "iterations", "the ISSA paper uses 100")] = Field(
        100, ge=1, description="iterations (the ISSA paper: 100)")
    max_sample_batches: Annotated[int, plausible(*LIMITS["max_sample_batches"], "batches",
                                                 "each batch is a population's worth of traction calculations")] = Field(
        20, ge=1, description="sample batches tried when refilling with feasible candidates before giving up"
    )

    @model_validator(mode="after")
    def _budget(self) -> "OptimizerParams":
        n = self.pop_size * self.max_iter
        if n > LIMITS["evaluations"]:
            raise RuleViolations([(("pop_size",), f"pop_size x max_iter = {n:,} evaluations is more than the limit of "
                                   f"{LIMITS['evaluations']:,} (the ISSA paper: 50 x 100 = 5,000; a run of the limit takes "
                                   "about an hour on a 20 km line)")])
        return self


def validation_problems(exc: ValidationError, file: str, lines: dict[str, int] | None = None) -> list[InputProblem]:
    """Turn a pydantic ``ValidationError`` into ``locoplan.errors.Problem`` items naming file, field and line."""
    lines = lines or {}
    problems = []
    for err in exc.errors():
        loc = [str(p) for p in err["loc"]]
        field = ".".join(loc)
        if err["type"] == "extra_forbidden":
            message = "unknown parameter"
        elif err["type"] == "missing":
            message = "required parameter is missing"
        else:
            message = err["msg"] + (f" (got {err['input']!r})" if "input" in err else "")
        problems.append(InputProblem(file=file, field=field, message=message, line=lines.get(loc[0]) if loc else None))
    return problems


# --------------------------------------------------------------------------------------------- optimiser


class Optimizer(ABC):
    """Population optimiser as an ask/tell state machine; subclasses supply the update rules.

    Use::

        opt = ISSA().setup(problem, np.random.default_rng(seed), pop_size=50, max_iter=100, **params)
        result = opt.run(callback=lambda it, best: ...)

    or drive it by hand: ``while not opt.done: X = opt.ask(); opt.tell(X, problem.evaluate(X))``.
    One iteration may take more than one ask/tell round (ISSA evaluates the Levy-perturbed candidates
    separately, the ISSA paper's step 6); ``iteration`` counts completed iterations.

    Subclasses set ``name`` and ``Params`` and implement ``_init_state``, ``_ask`` and ``_tell``; ``_tell``
    calls ``_replace_infeasible`` after a position update and ``_end_iteration`` when an iteration is done.
    """

    name: ClassVar[str] = ""
    Params: ClassVar[type[OptimizerParams]] = OptimizerParams

    def __init__(self) -> None:
        self._ready = False

    # -- setup ------------------------------------------------------------------------------------------

    def setup(
        self, problem: Problem, rng: np.random.Generator, pop_size: int = 50, max_iter: int = 100,
        x0: np.ndarray | None = None, **params: Any
    ) -> Optimizer:
        """Bind a problem and a random generator, validate parameters and build the initial population.

        problem: the ``Problem`` to minimise. rng: source of ALL random numbers (same seed -> same run).
        pop_size, max_iter: population size and number of iterations. params: algorithm parameters
        (see the class's ``Params`` model). Bad parameters raise ``InputError``. The initial population
        holds only feasible individuals (``sample_feasible``; may raise ``NoFeasibleCandidateError``);
        ``x0`` (k, n_var) are candidates known to be good (e.g. a plan built from physics): the feasible
        ones among them join the initial population first. Returns ``self`` so calls chain.
        """
        # numpy scalars (e.g. from a parameter sweep) are plain numbers here; strict pydantic would refuse them
        params = {k: v.item() if isinstance(v, np.generic) else v for k, v in params.items()}
        pop_size = pop_size.item() if isinstance(pop_size, np.generic) else pop_size
        max_iter = max_iter.item() if isinstance(max_iter, np.generic) else max_iter
        try:
            self.params = self.Params(pop_size=pop_size, max_iter=max_iter, **params)
        except ValidationError as exc:
            raise InputError(validation_problems(exc, f"<{self.name or type(self).__name__} parameters>")) from None
        self.problem = problem
        self.rng = rng
        self.lower = np.asarray(problem.lower, dtype=float).reshape(-1)
        self.upper = np.asarray(problem.upper, dtype=float).reshape(-1)
        if self.lower.shape != (problem.n_var,) or self.upper.shape != (problem.n_var,):
            raise ValueError(f"problem bounds must have shape ({problem.n_var},)")
        self.n_evaluations = 0
        self.n_infeasible_replaced = 0
        self.iteration = 0
        self._history: list[float] = []
        self._pending: np.ndarray | None = None
        self.best_x = np.full(problem.n_var, np.nan)
        self.best_fitness = math.inf

        seeded = np.empty((0, problem.n_var))
        seeded_f = np.empty(0)
        if x0 is not None and len(x0):
            x0 = np.asarray(problem.repair(np.atleast_2d(np.asarray(x0, dtype=float))), dtype=float)
            ev0 = _evaluate(problem, x0)
            self.n_evaluations += len(x0)
            keep = np.flatnonzero(ev0.feasible)[: self.params.pop_size]
            seeded, seeded_f = x0[keep], ev0.fitness[keep]
        X, ev, n_eval = sample_feasible(problem, rng, self.params.pop_size - len(seeded), self.params.max_sample_batches)
        X = np.concatenate([seeded, X])
        ev = Evaluation(np.concatenate([seeded_f, ev.fitness]), np.ones(len(X), dtype=bool))
        self.n_evaluations += n_eval
        self.X = X
        self.fitness = ev.fitness
        self._update_best(X, ev)
        self._init_state()
        self._ready = True
        return self

    @property
    def max_iter(self) -> int:
        return self.params.max_iter

    @property
    def done(self) -> bool:
        """True once ``max_iter`` iterations are complete."""
        return self.iteration >= self.params.max_iter

    @property
    def population(self) -> np.ndarray:
        """Current population (pop_size, n_var); every row is feasible between iterations."""
        return self.X.copy()

    # -- ask / tell -------------------------------------------------------------------------------------

    def ask(self) -> np.ndarray:
        """Candidates (k, n_var) to evaluate next, already repaired. Asking twice returns the same candidates."""
        if not self._ready:
            raise RuntimeError("call setup() before ask()")
        if self.done:
            raise RuntimeError("the optimiser has finished (iteration == max_iter)")
        if self._pending is None:
            self._pending = self._ask()
        return self._pending.copy()

    def tell(self, X: np.ndarray, evaluation: Evaluation) -> None:
        """Feed back the evaluation of the candidates returned by the last ``ask()``."""
        if self._pending is None:
            raise RuntimeError("tell() without a preceding ask()")
        X = np.asarray(X, dtype=float)
        if X.shape != self._pending.shape:
            raise ValueError(f"tell() got {X.shape} candidates, ask() returned {self._pending.shape}")
        ev = check_evaluation(evaluation, X.shape[0])
        self.n_evaluations += X.shape[0]
        self._pending = None
        self._tell(X, ev)

    def run(self, callback: Callable[[int, float], Any] | None = None) -> Result:
        """Run the remaining iterations against the problem; returns the ``Result``.

        callback(iteration, best_fitness) is called after each completed iteration (iteration = 1..max_iter)
        so the caller can report progress; its return value is ignored.
        """
        while not self.done:
            before = self.iteration
            X = self.ask()
            self.tell(X, self.problem.evaluate(X))
            if callback is not None and self.iteration > before:
                callback(self.iteration, self.best_fitness)
        return self.result()

    def result(self) -> Result:
        """The best solution and statistics so far."""
        return Result(
            best_x=self.best_x.copy(),
            best_fitness=float(self.best_fitness),
            history=np.asarray(self._history, dtype=float),
            n_evaluations=int(self.n_evaluations),
            n_infeasible_replaced=int(self.n_infeasible_replaced),
            population=self.X[np.argsort(self.fitness, kind="stable")].copy(),
        )

    # -- helpers for subclasses -------------------------------------------------------------------------

    def _repair(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self.problem.repair(X), dtype=float)

    def _replace_infeasible(self, X: np.ndarray, ev: Evaluation) -> tuple[np.ndarray, Evaluation, np.ndarray]:
        """The ISSA paper's step 5 on an evaluated updated population; keeps the counters. Returns (X, ev, replaced)."""
        X, ev, replaced, n_eval = replace_infeasible(self.problem, self.rng, X, ev, self.params.max_sample_batches)
        self.n_evaluations += n_eval
        self.n_infeasible_replaced += int(replaced.sum())
        return X, ev, replaced

    def _update_best(self, X: np.ndarray, ev: Evaluation) -> None:
        """Keep the best feasible candidate ever evaluated (elitist; the population itself may move away)."""
        if not ev.feasible.any():
            return
        score = np.where(ev.feasible, ev.fitness, np.inf)
        i = int(np.argmin(score))
        if score[i] < self.best_fitness:
            self.best_fitness = float(score[i])
            self.best_x = X[i].copy()

    def _end_iteration(self) -> None:
        self.iteration += 1
        self._history.append(self.best_fitness)

    @abstractmethod
    def _init_state(self) -> None:
        """Build algorithm state after the feasible initial population ``self.X``/``self.fitness`` exists."""

    @abstractmethod
    def _ask(self) -> np.ndarray:
        """Next candidates (repaired). Draw every random number from ``self.rng`` here, in a fixed order."""

    @abstractmethod
    def _tell(self, X: np.ndarray, ev: Evaluation) -> None:
        """Consume the evaluation of the last ``_ask`` candidates."""
