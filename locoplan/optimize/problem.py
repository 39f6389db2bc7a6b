"""Seed 002's optimisation problem: switching points of a fixed condition sequence (section 3.2).

Decision vector: the positions [m] where conditions 2.. of the sequence begin (Fig. 8), the final
braking point excluded (it comes from the stop's braking curve, as in the seed). Fitness (eq. 10-11):

    F = w1 |T - T0| / T0 + w2 |E - E_min| / E_min

Infeasible plans (a limit broken, stalled, stopped short) get an infinite fitness and are replaced by
the optimiser (step 5). Consecutive switching points keep at least half the train's length apart
(seed 002 eq. 3, S >= L/2).

The punctuality window of eq. 3, T in T0 +- eps_t, is a constraint handled by ranking (Deb's rule):
with ``tolerance_s`` set, every plan inside the window ranks before every plan outside it, and plans
outside rank by how far outside they are. Random replacement would be far too costly here (only a
few percent of random plans are on time), and the window is not a traction-calculation failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, Problem
from ..sim.calculator import TractionCalculator
from ..sim.result import BatchResult
from .base import Evaluation


OUTSIDE_WINDOW = 10.0
"""Fitness offset of a plan outside the punctuality window: above any on-time plan's eq. 10 value."""


def fitness_eq10(time_s, energy_kwh, t0_s: float, e_min_kwh: float, w_time: float, w_energy: float):
    """Seed 002 eq. 10-11: w1 |T - T0| / T0 + w2 |E - E_min| / E_min (dimensionless; arrays welcome)."""
    return w_time * np.abs(time_s - t0_s) / t0_s + w_energy * np.abs(energy_kwh - e_min_kwh) / e_min_kwh


@dataclass
class SwitchingProblem:
    """Box-bounded switching-point problem over one calculator; ``evaluate`` takes the whole population.

    objective: "eq10" (seed 002 fitness) or "energy" (the energy alone [kWh], the energy-saving strategy
    that ignores the timetable). energy: what E counts in either (``physics.energy.OBJECTIVES``): the
    traction work (default) or the net energy, traction less what the electric brake recovers.
    """

    calc: TractionCalculator
    conditions: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    t0_s: float = 1500.0
    e_min_kwh: float = 1.0
    weights: tuple[float, float] = (0.5, 0.5)
    objective: str = "eq10"
    energy: str = "traction"
    tolerance_s: float | None = None
    min_gap_m: float | None = None
    center: np.ndarray | None = None
    """A known good candidate (the general builder's nominal plan): random candidates are then drawn
    around it (normal, a tenth of the distance to the nearer neighbouring switching point) instead of
    uniformly, which keeps most of them feasible on long lines where a uniform draw of 20+ switching
    points almost never is."""
    last: BatchResult | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        self.n_var = len(self.lower)
        if self.conditions[-1] != "B" or len(self.conditions) - 2 != self.n_var:
            raise InputError(Problem("", "sequence", "the sequence must end with B and have one switching point per condition after the first, the final braking point excluded"))
        if np.any(self.upper < self.lower):
            raise InputError(Problem("", "bounds", "a switching point's window is empty (upper < lower)"))
        if self.min_gap_m is None:
            self.min_gap_m = self.calc.train.length_m / 2
        if self.e_min_kwh <= 0:
            raise InputError(Problem("", "e_min_kwh", f"must be > 0 kWh (got {self.e_min_kwh:g})"))
        self.n_evaluated = 0
        self.time_range_s: tuple[float, float] | None = None  # shortest / longest feasible time seen [s]

    def switches(self, X: np.ndarray) -> np.ndarray:
        """Every switching point of candidates X (n, n_var), the final braking point appended as 'auto' (NaN)."""
        X = np.atleast_2d(X)
        return np.column_stack([X, np.full(len(X), np.nan)])

    def simulate(self, X: np.ndarray, profile: bool = False) -> BatchResult:
        """Traction calculation of candidates X (n, n_var)."""
        return self.calc.evaluate(self.conditions, self.switches(X), profile=profile, recovered=self.energy == "net")

    def fitness(self, res: BatchResult) -> np.ndarray:
        e = res.energy_kwh(self.energy)
        if self.objective == "energy":
            f = e.copy()
        else:
            f = fitness_eq10(res.running_time_s, e, self.t0_s, self.e_min_kwh, *self.weights)
            if self.tolerance_s is not None:
                excess = np.abs(res.running_time_s - self.t0_s) - self.tolerance_s
                f = np.where(excess > 0, OUTSIDE_WINDOW + excess / self.t0_s, f)
        return np.where(res.feasible, f, np.inf)

    def evaluate(self, X: np.ndarray) -> Evaluation:
        res = self.simulate(X)
        self.n_evaluated += len(res.feasible)
        self.last = res
        if res.feasible.any():
            t = res.running_time_s[res.feasible]
            lo, hi = float(t.min()), float(t.max())
            if self.time_range_s is not None:
                lo, hi = min(lo, self.time_range_s[0]), max(hi, self.time_range_s[1])
            self.time_range_s = (lo, hi)
        return Evaluation(fitness=self.fitness(res), feasible=res.feasible.copy())

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Uniform inside each switching point's window (or around ``center``), then repaired (sorted, spaced)."""
        if self.center is not None:
            c = np.asarray(self.center, dtype=float)
            edges = np.concatenate([[self.lower[0]], c, [self.upper[-1]]])
            spread = 0.1 * np.minimum(c - edges[:-2], edges[2:] - c) + 1.0
            return self.repair(rng.normal(c, spread, size=(n, self.n_var)))
        return self.repair(rng.uniform(self.lower, self.upper, size=(n, self.n_var)))

    def repair(self, X: np.ndarray) -> np.ndarray:
        """Clip to the windows, sort each row, and push points apart to the minimum spacing."""
        X = np.clip(np.atleast_2d(X).astype(float), self.lower, self.upper)
        X = np.sort(X, axis=1)
        gap = self.min_gap_m
        for j in range(1, self.n_var):  # forward pass, then a backward pass against the upper bounds
            X[:, j] = np.maximum(X[:, j], X[:, j - 1] + gap)
        X[:, -1] = np.minimum(X[:, -1], self.upper[-1])
        for j in range(self.n_var - 2, -1, -1):
            X[:, j] = np.minimum(X[:, j], X[:, j + 1] - gap)
        return np.clip(X, self.lower, self.upper)
