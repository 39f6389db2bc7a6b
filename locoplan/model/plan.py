"""A condition sequence with switching points, as users write it: "T:0,K:2200,C:9000,B:19600"."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, Problem
from .conditions import CODE, CONDITIONS


@dataclass(frozen=True)
class Plan:
    """Conditions and where each begins [m]. The first begins at 0; NaN = 'where the braking curve
    begins' (only for a final B: the previous condition runs on until the stop's braking curve)."""

    conditions: tuple[str, ...]
    starts_m: tuple[float, ...]
    release_margins: tuple[tuple[float, float, float], ...] = ()
    """Where the air brake's cycles release, as the optimiser placed them: per descent
    (``TractionCalculator.cycle_regions_m``) (from_m, to_m, margin), the train regaining the apply speed after a
    release in ``margin`` recharge times (``sim.kernel.cycle_speeds``); empty: the calculator's rule."""

    @property
    def switches_m(self) -> np.ndarray:
        """(1, n_conditions - 1) switching positions, the calculator's batch layout for one plan."""
        return np.array([self.starts_m[1:]], dtype=float)

    def cycle_kwargs(self) -> dict:
        """The release margins as ``TractionCalculator.evaluate`` takes them ({} for the rule)."""
        if not self.release_margins:
            return {}
        d = np.array(self.release_margins, dtype=float)
        return {"release_margin": d[None, :, 2], "margin_regions_m": d[:, :2]}

    def text(self) -> str:
        return ",".join(c if math.isnan(s) else f"{c}:{round(s, 1):g}" for c, s in zip(self.conditions, self.starts_m))


def parse_sequence(text: str, length_m: float, field: str = "--sequence") -> Plan:
    """Parse "T:0,K:2200,C:9000,B" (a final bare B brakes where the stop's braking curve begins)."""
    items = [x.strip() for x in text.split(",")]
    if not any(items):
        raise InputError(Problem("", field, "empty sequence; write e.g. T:0,K:2200,C:9000,B"))
    if not all(items):
        raise InputError(Problem("", field, f"item {items.index('') + 1} of {text!r} is empty (a doubled or trailing "
                                 "comma?); write e.g. T:0,K:2200,C:9000,B"))
    conds: list[str] = []
    starts: list[float] = []
    for i, item in enumerate(items):
        cond, _, pos = item.partition(":")
        cond = cond.strip().upper()
        if cond not in CODE:
            raise InputError(Problem("", field, f"item {i + 1} {item!r}: unknown condition {cond!r} (one of {', '.join(CONDITIONS)})"))
        if not pos.strip():
            if i == 0:
                starts.append(0.0)
            elif cond == "B" and i == len(items) - 1:
                starts.append(math.nan)
            else:
                raise InputError(Problem("", field, f"item {i + 1} {item!r}: needs a position in metres (only a final B may omit it)"))
        else:
            try:
                start = float(pos)
            except ValueError:
                raise InputError(Problem("", field, f"item {i + 1} {item!r}: position {pos.strip()!r} is not a number")) from None
            if not math.isfinite(start):
                raise InputError(Problem("", field, f"item {i + 1} {item!r}: position {pos.strip()!r} is not a finite number of metres"))
            starts.append(start)
        conds.append(cond)
    if starts[0] != 0.0:
        raise InputError(Problem("", field, f"the first condition must start at 0 m (got {starts[0]:g})"))
    known = [s for s in starts if not math.isnan(s)]
    for i in range(1, len(known)):
        if known[i] <= known[i - 1]:
            raise InputError(Problem("", field, f"switching points out of order: {known[i]:g} m after {known[i - 1]:g} m (they must rise)"))
    if known[-1] >= length_m:
        raise InputError(Problem("", field, f"switching point {known[-1]:g} m is not before the end of the route ({length_m:g} m)"))
    return Plan(tuple(conds), tuple(starts))


def runs_from_profile(s_m: np.ndarray, condition: np.ndarray, min_run_m: float = 0.0,
                      event_m: np.ndarray | None = None) -> list[dict]:
    """Merge a per-cell condition row into [{condition, from_m, to_m}, ...] runs; runs shorter than
    ``min_run_m`` are absorbed by their predecessor (cells where a switch merely touched).

    ``event_m`` (per cell, NaN = none) places each change at the exact position inside the cell where
    it happened instead of at a cell edge.
    """
    runs: list[dict] = []
    for k, code in enumerate(condition):
        if code < 0:  # a failed plan's profile ends where it failed
            break
        c = CONDITIONS[int(code)]
        a, b = float(s_m[k]), float(s_m[k + 1])
        if runs and runs[-1]["condition"] == c:
            runs[-1]["to_m"] = b
        else:
            if runs and event_m is not None:
                # the change happened inside this cell, or (if this cell shows none) inside the previous one
                inside = event_m[k] if not np.isnan(event_m[k]) else event_m[k - 1]
                if not np.isnan(inside) and runs[-1]["from_m"] < inside < b:
                    a = float(inside)
                    runs[-1]["to_m"] = a
            runs.append({"condition": c, "from_m": a, "to_m": b})
    if min_run_m > 0 and len(runs) > 1:
        merged: list[dict] = [runs[0]]
        for r in runs[1:]:
            if r["to_m"] - r["from_m"] < min_run_m:
                merged[-1]["to_m"] = r["to_m"]
            elif merged[-1]["condition"] == r["condition"]:
                merged[-1]["to_m"] = r["to_m"]
            else:
                merged.append(r)
        runs = merged
    for r in runs:
        r["from_m"], r["to_m"] = round(r["from_m"], 1), round(r["to_m"], 1)
    return runs
