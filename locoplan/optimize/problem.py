"""The ISSA paper's optimisation problem: switching points of a fixed condition sequence (section 3.2).

Decision vector: the positions [m] where conditions 2.. of the sequence begin (Fig. 8), the final
braking point excluded (it comes from the stop's braking curve, as in the paper); on a line where the air
brake cycles, then one release margin per descent (where its cycles release: ``regions_m``). Fitness
(eq. 10-11):

    F = w1 |T - T0| / T0 + w2 |E - E_min| / E_min

Infeasible plans (a limit broken, stalled, stopped short) get an infinite fitness and are replaced by
the optimiser (step 5). Consecutive switching points keep at least half the train's length apart
(the ISSA paper's eq. 3, S >= L/2).

The punctuality window of eq. 3, T in T0 +- eps_t, is a constraint handled by ranking (Deb's rule):
with ``tolerance_s`` set, every plan inside the window ranks before every plan outside it, and plans
outside rank by how far outside they are. Random replacement would be far too costly here (only a
few percent of random plans are on time), and the window is not a traction-calculation failure.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, Problem
from ..physics.units import KJ_PER_KWH
from ..sim.calculator import TractionCalculator
from ..sim.constants import CYCLE_MARGIN
from ..sim.result import BatchResult
from .base import Evaluation


MARGIN_MIN = 0.25
MARGIN_MAX = 4.0
"""The window of a descent's release margin: from a release so high that the train is back at the apply speed
in a quarter of the recharge time (refused unless the least hold takes it lower) to one four recharges deep."""
MARGIN_SPREAD = 0.3
"""The spread of random candidates' release margins around the rule's ``CYCLE_MARGIN``."""

OUTSIDE_WINDOW = 10.0
"""Fitness offset of a plan outside the punctuality window, beyond the largest eq. 10 value an on-time plan
can have (``SwitchingProblem.outside_offset``)."""

E_SCALE_FLOOR_KWH = 0.01
"""Eq. 10's energy term divides by E_min; an E_min that is the least energy of any punctual plan (E*, the
general builder's) is nearly 0 on a line the train can coast from end to end, and may be negative for the net
energy: the term then divides by this much [kWh] instead (it still measures |E - E_min|, and every plan's
E >= E_min, so it still orders plans as their energy does)."""


def energy_scale_kwh(e_min_kwh: float) -> float:
    """The divisor of eq. 10's energy term: |E_min|, at least ``E_SCALE_FLOOR_KWH``."""
    return max(abs(float(e_min_kwh)), E_SCALE_FLOOR_KWH)


def fitness_eq10(time_s, energy_kwh, t0_s: float, e_min_kwh: float, w_time: float, w_energy: float):
    """The ISSA paper's eq. 10-11: w1 |T - T0| / T0 + w2 |E - E_min| / E_min (dimensionless; arrays welcome); the
    divisor is |E_min|, at least ``E_SCALE_FLOOR_KWH`` (:func:`energy_scale_kwh`)."""
    return (w_time * np.abs(time_s - t0_s) / t0_s
            + w_energy * np.abs(energy_kwh - e_min_kwh) / energy_scale_kwh(e_min_kwh))


E_MIN_RUN_M = 50.0
"""The shortest run of the electric brake alone (E) [m]."""


@dataclass
class SwitchingProblem:
    """Box-bounded switching-point problem over one calculator; ``evaluate`` takes the whole population.

    objective: "eq10" (the ISSA paper's fitness) or "energy" (the energy alone [kWh], the energy-saving strategy
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
    regions_m: np.ndarray | None = None
    """The descents where the air brake cycles ((n_regions, 2) [m], ``TractionCalculator.cycle_regions_m``): each
    adds a variable after the switching points, the release margin of its cycles (``kernel.cycle_speeds``: the
    release speed lies so far below the apply speed that the train regains it in this many recharge times), in
    [``MARGIN_MIN``, ``MARGIN_MAX``]; random candidates draw it around the rule's ``CYCLE_MARGIN`` (normal,
    ``MARGIN_SPREAD``)."""
    last: BatchResult | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.n_switches = len(self.conditions) - 2
        self.regions_m = np.zeros((0, 2)) if self.regions_m is None else np.asarray(self.regions_m, dtype=float).reshape(-1, 2)
        self.n_regions = len(self.regions_m)
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        if self.n_regions and len(self.lower) == self.n_switches:  # (a replace() passes them extended already)
            self.lower = np.concatenate([self.lower, np.full(self.n_regions, MARGIN_MIN)])
            self.upper = np.concatenate([self.upper, np.full(self.n_regions, MARGIN_MAX)])
            if self.center is not None:
                self.center = np.concatenate([np.asarray(self.center, dtype=float), np.full(self.n_regions, CYCLE_MARGIN)])
        self.n_var = len(self.lower)
        if self.conditions[-1] != "B" or self.n_var != self.n_switches + self.n_regions:
            raise InputError(Problem("", "sequence", "the sequence must end with B and have one switching point per condition after the first, the final braking point excluded"))
        if np.any(self.upper < self.lower):
            raise InputError(Problem("", "bounds", "a switching point's window is empty (upper < lower)"))
        if self.min_gap_m is None:
            self.min_gap_m = self.calc.train.length_m / 2
        # each run's least length [m] (run j from switching point j - 1 to j: the condition ``conditions[j]``); an
        # electric brake run (E) may be as short as ``E_MIN_RUN_M``
        self.run_gaps_m = np.array([min(E_MIN_RUN_M, self.min_gap_m) if c == "E" else self.min_gap_m
                                    for c in self.conditions[:max(self.n_switches, 1)]], dtype=float)
        if not np.isfinite(self.e_min_kwh):
            raise InputError(Problem("", "e_min_kwh", f"must be a finite number of kWh (got {self.e_min_kwh:g})"))
        # an on-time plan's eq. 10 is at most w1 (|T - T0| < T0) + w2 (E_max + |E_min|) / scale, with E_max the
        # traction work of the largest effort all the way (no plan draws more): a plan outside the window ranks above
        top_kwh = float(np.max(self.calc.train.traction_kn)) * self.calc.route.length_m / KJ_PER_KWH
        self.outside_offset = OUTSIDE_WINDOW + self.weights[0] + self.weights[1] * (
            (top_kwh + abs(self.e_min_kwh)) / energy_scale_kwh(self.e_min_kwh))
        self.n_evaluated = 0
        self.time_range_s: tuple[float, float] | None = None  # shortest / longest feasible time seen [s]

    def switches(self, X: np.ndarray) -> np.ndarray:
        """Every switching point of candidates X (n, n_var), the final braking point appended as 'auto' (NaN)."""
        X = np.atleast_2d(X)[:, :self.n_switches]
        return np.column_stack([X, np.full(len(X), np.nan)])

    def margins(self, X: np.ndarray) -> dict:
        """The release margins of candidates X as ``TractionCalculator.evaluate`` takes them ({}: no cycles)."""
        if not self.n_regions:
            return {}
        return {"release_margin": np.atleast_2d(X)[:, self.n_switches:], "margin_regions_m": self.regions_m}

    def simulate(self, X: np.ndarray, profile: bool = False) -> BatchResult:
        """Traction calculation of candidates X (n, n_var)."""
        return self.calc.evaluate(self.conditions, self.switches(X), profile=profile, recovered=self.energy == "net",
                                  **self.margins(X))

    def fitness(self, res: BatchResult) -> np.ndarray:
        e = res.energy_kwh(self.energy)
        if self.objective == "energy":
            f = e.copy()
        else:
            f = fitness_eq10(res.running_time_s, e, self.t0_s, self.e_min_kwh, *self.weights)
            if self.tolerance_s is not None:
                excess = np.abs(res.running_time_s - self.t0_s) - self.tolerance_s
                f = np.where(excess > 0, self.outside_offset + excess / self.t0_s, f)
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
            n_sw = self.n_switches
            c = np.asarray(self.center, dtype=float)[:n_sw]
            edges = np.concatenate([[self.lower[0] if n_sw else 0.0], c, [self.upper[n_sw - 1] if n_sw else 0.0]])
            spread = np.concatenate([0.1 * np.minimum(c - edges[:-2], edges[2:] - c) + 1.0,
                                     np.full(self.n_regions, MARGIN_SPREAD)])
            return self.repair(rng.normal(self.center, spread, size=(n, self.n_var)))
        return self.repair(rng.uniform(self.lower, self.upper, size=(n, self.n_var)))

    def repair(self, X: np.ndarray) -> np.ndarray:
        """Clip to the windows, sort each row's switching points, and push them apart to the minimum spacing
        (the release margins, after them, are only clipped)."""
        X = np.clip(np.atleast_2d(X).astype(float), self.lower, self.upper)
        n_sw = self.n_switches
        if not n_sw:
            return X
        X[:, :n_sw] = np.sort(X[:, :n_sw], axis=1)
        gap = self.run_gaps_m
        for j in range(1, n_sw):  # forward pass, then a backward pass against the upper bounds
            X[:, j] = np.maximum(X[:, j], X[:, j - 1] + gap[j])
        X[:, n_sw - 1] = np.minimum(X[:, n_sw - 1], self.upper[n_sw - 1])
        for j in range(n_sw - 2, -1, -1):
            X[:, j] = np.minimum(X[:, j], X[:, j + 1] - gap[j + 1])
        return np.clip(X, self.lower, self.upper)
