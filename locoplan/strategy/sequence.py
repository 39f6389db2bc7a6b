"""Condition-sequence builder of the ISSA paper's section 2 (Figs. 2-6).

1. Speed limits are classified (Fig. 2): each change is *rising* or *falling*; a section whose two
   neighbours are both higher is *concave* (a dip), both lower *convex* (a hump); the start and the
   stop count as 0 km/h neighbours.
2. Grades are classified by what the train can do on them at the section's limit speed: *long
   up-grade* when full traction cannot hold the speed (it falls by more than ``threshold_kmh`` over
   the section), *long down-grade* when coasting cannot hold it (it rises by more than
   ``threshold_kmh``), *ordinary* otherwise (Fig. 5, step 2).
3. The sequence (Fig. 6, step 3): the fastest run's conditions on ordinary grades, traction before
   and on long up-grades, coasting before and on long down-grades; braking mid-route is left to the
   braking curves (the energy-saving plans of the ISSA paper's Table 8 brake only at the end), so the
   fastest run's mid-route B becomes C. The switching points into a long grade are free to move
   before its start, which is what the optimiser then decides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.plan import runs_from_profile
from ..physics.units import kinetic_e, kmh_from_e
from ..sim.calculator import TractionCalculator


@dataclass(frozen=True)
class LimitSection:
    from_m: float
    to_m: float
    kmh: float
    kind: str  # concave | convex | rising | falling


@dataclass(frozen=True)
class GradeSection:
    from_m: float
    to_m: float
    permille: float  # mean equivalent gradient over the section
    kind: str  # long-up | long-down | ordinary
    speed_change_kmh: float  # under the deciding condition (T on up-grades, C otherwise), from the limit


@dataclass(frozen=True)
class SequencePlan:
    """A condition sequence with nominal switching points and the window each may move in [m].

    The last condition is always B, placed by the stop's braking curve (not a decision variable).
    """

    conditions: tuple[str, ...]
    nominal_m: np.ndarray  # (n_switches,) where conditions 2.. begin, final B excluded
    lower_m: np.ndarray
    upper_m: np.ndarray
    limits: tuple[LimitSection, ...]
    grades: tuple[GradeSection, ...]

    @property
    def n_switches(self) -> int:
        return len(self.nominal_m)

    def text(self) -> str:
        parts = [f"{c}:{x:.0f}" for c, x in zip(self.conditions, [0.0, *self.nominal_m])]
        return ",".join(parts[: len(self.conditions) - 1] + ["B"])


def classify_limits(calc: TractionCalculator) -> tuple[LimitSection, ...]:
    """The ISSA paper's Fig. 2 types of every speed-limit section (the start and stop are 0 km/h neighbours)."""
    sl = calc.route.speed_limits
    out = []
    for i, sec in enumerate(sl):
        prev = sl[i - 1].kmh if i else 0.0
        nxt = sl[i + 1].kmh if i + 1 < len(sl) else 0.0
        if prev > sec.kmh and nxt > sec.kmh:
            kind = "concave"
        elif prev < sec.kmh and nxt < sec.kmh:
            kind = "convex"
        elif prev <= sec.kmh <= nxt:
            kind = "rising"
        else:
            kind = "falling"
        out.append(LimitSection(sec.from_m, sec.to_m, sec.kmh, kind))
    return tuple(out)


def speed_change_kmh(calc: TractionCalculator, from_m: float, to_m: float, v0_kmh: float, condition: str,
                     n_steps: int = 200) -> float:
    """Speed change [km/h] over [from_m, to_m] under full traction ('T') or coasting ('C'), starting at
    ``v0_kmh``, ignoring limits (RK2 in e = v^2/2 on the calculator's cells; stops at rest)."""
    edges = np.linspace(from_m, to_m, n_steps + 1)
    cells = np.clip(np.searchsorted(calc.s_m, 0.5 * (edges[1:] + edges[:-1]), side="right") - 1, 0, len(calc.h_m) - 1)
    d = (to_m - from_m) / n_steps
    traction = 1.0 if condition == "T" else 0.0

    def slope(e: float, k: int) -> float:
        f_max, _, load = calc.forces_kn(math.sqrt(2 * max(e, 0.0)), k)
        return float(traction * f_max - load) / calc.m_eff_t

    e = kinetic_e(v0_kmh)
    for k in cells:
        e = e + d * slope(e + 0.5 * d * slope(e, k), k)
        if e <= 0:
            return -v0_kmh
    return float(kmh_from_e(e)) - v0_kmh


def classify_grades(calc: TractionCalculator, threshold_kmh: float = 2.0) -> tuple[GradeSection, ...]:
    """The ISSA paper's step 2: long up-grade / long down-grade / ordinary for every gradient section.

    The reference speed is the lowest limit on the section: a long up-grade is one where full
    traction from that speed loses more than ``threshold_kmh`` by the end, a long down-grade one where
    coasting from it gains more than ``threshold_kmh``. Curves and tunnels count through the
    equivalent gradient.
    """
    out = []
    for sec in calc.route.gradients:
        inside = (calc.s_m[:-1] >= sec.from_m - 1e-9) & (calc.s_m[1:] <= sec.to_m + 1e-9)
        v_ref = float(calc.limit_kmh[inside].min())
        mean_grad = float(np.sum(calc.gradient_permille[inside] * calc.h_m[inside]) / np.sum(calc.h_m[inside]))
        dv_t = speed_change_kmh(calc, sec.from_m, sec.to_m, v_ref, "T")
        dv_c = speed_change_kmh(calc, sec.from_m, sec.to_m, v_ref, "C")
        if dv_t < -threshold_kmh:
            kind, dv = "long-up", dv_t
        elif dv_c > threshold_kmh:
            kind, dv = "long-down", dv_c
        else:
            kind, dv = "ordinary", dv_c if mean_grad < 0 else dv_t
        out.append(GradeSection(sec.from_m, sec.to_m, mean_grad, kind, dv))
    return tuple(out)


def fastest_runs(calc: TractionCalculator) -> list[dict]:
    """The fastest run's condition runs (the ISSA paper's step 1)."""
    prof = calc.evaluate(("T",), np.zeros((1, 0)), profile=True).profile
    return runs_from_profile(prof.s_m, prof.condition[0], 1.0, prof.event_m[0])


def build_sequence(calc: TractionCalculator, threshold_kmh: float = 2.0, min_run_m: float | None = None) -> SequencePlan:
    """The ISSA paper's section 2: the energy-saving, on-time condition sequence with nominal switching points.

    Runs shorter than ``min_run_m`` (default half the train's length, the ISSA paper's eq. 3) are absorbed.
    Each switching point may move between the midpoints to its neighbours; a switch into a long grade
    may move back as far as the previous switch may, and not past the grade's start (the
    pre-positioning of Fig. 5: traction before long up-grades, coasting before long down-grades); the
    traction on a long up-grade lasts at least over its first half (coasting over the crest is allowed).
    """
    L = calc.route.length_m
    min_run = calc.train.length_m / 2 if min_run_m is None else min_run_m
    limits = classify_limits(calc)
    grades = classify_grades(calc, threshold_kmh)
    # condition as a function of position: fastest run, mid-route braking left to the braking curves
    pieces = [(r["from_m"], r["to_m"], "C" if r["condition"] == "B" else r["condition"]) for r in fastest_runs(calc)]
    for g in grades:
        if g.kind == "ordinary":
            continue
        cond = "T" if g.kind == "long-up" else "C"
        clipped = []
        for a, b, c in pieces:
            if b <= g.from_m or a >= g.to_m:
                clipped.append((a, b, c))
                continue
            if a < g.from_m:
                clipped.append((a, g.from_m, c))
            if b > g.to_m:
                clipped.append((g.to_m, b, c))
        clipped.append((g.from_m, g.to_m, cond))
        pieces = sorted(clipped)
    # merge, absorb short runs, end with the braking run
    runs: list[list] = []
    for a, b, c in pieces:
        if runs and (runs[-1][2] == c or b - a < min_run):
            runs[-1][1] = b
        else:
            runs.append([a, b, c])
    if runs[-1][2] == "C" and len(runs) > 1 and runs[-1][1] - runs[-1][0] < min_run:
        runs.pop()
    conditions = tuple(r[2] for r in runs) + ("B",)
    nominal = np.array([r[0] for r in runs[1:]], dtype=float)
    # windows: halfway to the neighbouring nominal switches; a switch into a long grade may move back
    # to the previous switch (pre-positioning before the grade)
    grade_starts = {g.from_m for g in grades if g.kind != "ordinary"}
    up_ends = {g.to_m: g for g in grades if g.kind == "long-up"}
    edges = np.concatenate([[0.0], nominal, [L]])
    lower = 0.5 * (edges[:-2] + edges[1:-1])
    upper = 0.5 * (edges[1:-1] + edges[2:])
    for j, x in enumerate(nominal):
        if x in grade_starts:  # before the grade (Fig. 5), as far back as the previous switch may go
            lower[j] = (lower[j - 1] if j else 0.0) + min_run
            upper[j] = x
        if x in up_ends:  # traction covers at least the first half of a long up-grade (no stall)
            g = up_ends[x]
            lower[j] = max(lower[j], 0.5 * (g.from_m + g.to_m))
    lower = np.maximum(lower, min_run)
    upper = np.minimum(upper, L - min_run)
    return SequencePlan(conditions, nominal, lower, upper, limits, grades)
