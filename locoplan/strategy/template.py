"""The general condition-sequence builder: seed 002's method (a condition sequence, switching points by
ISSA), with the sequence judged at the speed the train will actually run.

Seed 002 section 2 classifies grades at each section's speed limit and copies the fastest run's
conditions elsewhere. On hilly real lines that misjudges the grades (a heavy train runs well below the
limit) and fixes the cruise speed by where each traction run happens to end. The minimum-energy drive
has a simpler structure (Howlett and Pudney's optimal train control; the optimal plans of seed 001,
Fig. 7): regulate at one cruise speed V (full traction below it, hold it, coast above it; hold a lower
limit where one applies), full traction through an up-grade too steep to hold V (starting before it),
coasting through a down-grade steep enough to speed the train up and before a limit drop (starting
before them), coasting before the stop, then the stop's braking curve. This builder writes that
structure as a seed 002 condition sequence:

    K [X K]* [C] B      K = cruise at V (regulate), X = T before steep up-grades, C before steep
                        down-grades and limit drops; the last C before the final B

and the optimiser searches V and where each X (and the final C) begins. Each X ends where its grade
(or limit drop) ends: from there K takes the train back to V by itself (coasting down to it, or
powering up to it), so the end is not worth a decision variable. The windows of the starting points lie
between the previous run's end and the middle of their own grade, so they never overlap.

Steep is judged at u = min(V_ref, limit) cell by cell: up when full traction at u decelerates the train,
down when coasting at u accelerates it; a run of such cells is an event when the speed change it causes
from u exceeds ``threshold_kmh`` (seed 002's 2 km/h). V_ref is the cruise speed at which holding it
(with braking where need be) meets the planned time.

Above V, K coasts up to a braking speed W (V <= W <= the highest limit) and holds W by braking: W = V
is seed 002's cruise (hold the speed), W at the limits lets the train gain time for free on descents;
slow timetables on falling lines need the first, tight ones the second, so W is searched too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sim.calculator import TractionCalculator

THRESHOLD_KMH = 2.0
"""Speed change [km/h] over a grade from which it counts as steep (seed 002 section 2, step 2)."""


@dataclass(frozen=True)
class Event:
    kind: str  # "up" (traction through it) | "down" (coast through it) | "drop" (coast before a limit drop)
    from_m: float
    to_m: float
    speed_change_kmh: float  # from u under the run's condition (full traction up, coasting down)


@dataclass(frozen=True)
class Template:
    """A sequence with its fixed and free switching points, and the cruise-speed window [km/h]."""

    conditions: tuple[str, ...]
    fixed_m: np.ndarray  # (n_switches,) NaN = a decision variable
    lower_m: np.ndarray  # windows and nominal values of the free switching points, in order
    upper_m: np.ndarray
    nominal_m: np.ndarray
    v_ref_kmh: float
    v_lo_kmh: float
    v_hi_kmh: float
    events: tuple[Event, ...]

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Decision-vector bounds: the cruise speed V [km/h], the braking-speed share r (K brakes at
        V + r (v_hi - V)), then the free switching points [m]."""
        return (np.concatenate([[self.v_lo_kmh, 0.0], self.lower_m]), np.concatenate([[self.v_hi_kmh, 1.0], self.upper_m]))

    def candidates(self, speeds_kmh, shares=(0.0, 1.0)) -> np.ndarray:
        """Starting plans: the nominal switching points at each of ``speeds_kmh`` and braking shares, and the
        same with the final coast earlier or later (feasible ones seed the optimiser's population)."""
        rows = []
        lo, hi = self.bounds()
        for v in speeds_kmh:
            for r, shift in [(r, sh) for r in shares for sh in (0.0, -0.25, 0.25)]:
                x = np.concatenate([[v, r], self.nominal_m])
                if self.conditions[-2] == "C" and len(self.nominal_m):
                    j = len(self.nominal_m) - 1
                    x[-1] = self.nominal_m[j] + shift * (self.upper_m[j] - self.lower_m[j])
                rows.append(np.clip(x, lo, hi))
        return np.array(rows)


def speed_bounds_kmh(calc: TractionCalculator) -> tuple[float, float]:
    """Cruise-speed window: from half the fastest run's mean speed (slower plans are not timetabled runs)
    to the highest limit (above every limit, regulating is holding each limit)."""
    v_hi = float(calc.limit_kmh.max())
    v_mean = calc.route.length_m / calc.fastest_time_s * 3.6
    return max(5.0, min(0.5 * v_mean, v_hi - 1.0)), v_hi


def reference_cruise_kmh(calc: TractionCalculator, t0_s: float) -> float:
    """The cruise speed at which holding it (traction or braking as needed, under the limits) takes
    ``t0_s``; clipped to the cruise-speed window."""
    v_lo, v_hi = speed_bounds_kmh(calc)
    v = np.linspace(v_lo, v_hi, max(2, int(round(v_hi - v_lo)) + 1))
    res = calc.evaluate(("K", "B"), np.full((len(v), 1), np.nan), cruise_kmh=v, cruise_mode="regulate",
                        brake_hold_kmh=v)
    ok = res.feasible & np.isfinite(res.running_time_s)
    if not ok.any():
        return v_hi
    t, vv = res.running_time_s[ok], v[ok]
    if t0_s >= t[0]:
        return float(vv[0])
    if t0_s <= t[-1]:
        return float(vv[-1])
    # time falls with the cruise speed: interpolate in the decreasing table
    return float(np.interp(t0_s, t[::-1], vv[::-1]))


def _cell_accelerations(calc: TractionCalculator, u_kmh: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell, at speed u: deceleration-free test values (d(v^2/2)/ds) under full traction and coasting."""
    forces = calc.forces_kn(u_kmh / 3.6, np.arange(len(calc.h_m)))
    f_max, _, load = forces
    return (f_max * calc.traction_allowed - load) / calc.m_eff_t, -load / calc.m_eff_t


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """[first, last] cell indices of each run of True."""
    out, start = [], None
    for k, f in enumerate(flags):
        if f and start is None:
            start = k
        elif not f and start is not None:
            out.append((start, k - 1))
            start = None
    if start is not None:
        out.append((start, len(flags) - 1))
    return out


def find_events(calc: TractionCalculator, v_ref_kmh: float, threshold_kmh: float = THRESHOLD_KMH) -> list[Event]:
    """Steep grades and limit drops at the reference speed, in route order."""
    s, h = calc.s_m, calc.h_m
    u = np.minimum(v_ref_kmh, calc.limit_kmh)
    a_t, a_c = _cell_accelerations(calc, u)
    merge = calc.train.length_m / 2
    events: list[Event] = []
    for kind, flags, acc in (("up", a_t < 0, a_t), ("down", a_c > 0, a_c)):
        runs = _runs(flags)
        merged: list[list[int]] = []
        for a, b in runs:  # join runs of the same kind separated by less than half a train
            if merged and s[a] - s[merged[-1][1] + 1] < merge:
                merged[-1][1] = b
            else:
                merged.append([a, b])
        for a, b in merged:
            u0 = u[a] / 3.6
            e_end = 0.5 * u0 * u0 + float(np.sum(acc[a:b + 1] * h[a:b + 1]))
            dv = (np.sqrt(2 * max(e_end, 0.0)) - u0) * 3.6
            if abs(dv) >= threshold_kmh:
                events.append(Event(kind, float(s[a]), float(s[b + 1]), float(dv)))
    # limit drops below the reference speed (a drop counts at the head)
    lim = calc.limit_kmh
    for k in np.flatnonzero(np.diff(lim) < 0) + 1:
        if lim[k] < min(v_ref_kmh, lim[k - 1]) - 1e-9:
            events.append(Event("drop", float(s[k]), float(s[k]), float(lim[k] - min(v_ref_kmh, lim[k - 1]))))
    return sorted(events, key=lambda e: (e.from_m, e.to_m))


def build_template(calc: TractionCalculator, t0_s: float, threshold_kmh: float = THRESHOLD_KMH,
                   v_ref_kmh: float | None = None) -> Template:
    """The sequence ``K [X K]* [C] B`` for ``calc``'s route and train at the planned time ``t0_s``."""
    L = calc.route.length_m
    gap = calc.train.length_m / 2
    v_lo, v_hi = speed_bounds_kmh(calc)
    v_ref = reference_cruise_kmh(calc, t0_s) if v_ref_kmh is None else float(v_ref_kmh)
    events = find_events(calc, v_ref, threshold_kmh)
    conditions = ["K"]
    fixed: list[float] = []
    lower: list[float] = []
    upper: list[float] = []
    nominal: list[float] = []
    pos = 0.0  # where the previous run ends
    for ev in events:
        cond = "T" if ev.kind == "up" else "C"
        end = ev.to_m
        if ev.kind == "drop":  # coast up to the drop; the braking curve does the rest
            end = ev.from_m
        if end <= pos:  # inside the previous run: covered
            continue
        if ev.from_m < pos + gap and len(conditions) > 1 and conditions[-2] == cond:
            fixed[-1] = end  # overlaps the previous run of the same kind: extend it
            pos = end
            continue
        lo = pos + gap
        hi = min(0.5 * (ev.from_m + ev.to_m), end - gap) if ev.kind != "drop" else end - gap
        if hi <= lo:  # no room to start a run of its own: the previous run or K covers it
            continue
        lead = min(500.0, 0.5 * (ev.from_m - pos)) if ev.kind != "drop" else 0.5 * (hi - lo)
        conditions += [cond, "K"]
        fixed += [np.nan, end]
        lower.append(lo)
        upper.append(hi)
        nominal.append(float(np.clip(ev.from_m - lead, lo, hi)))
        pos = end
    # coasting before the stop: from anywhere after the last run to half a train before the end
    lo, hi = pos + gap, L - gap
    if hi > lo:
        conditions.append("C")
        fixed.append(np.nan)
        lower.append(lo)
        upper.append(hi)
        nominal.append(lo + 0.6 * (hi - lo))
    conditions.append("B")
    return Template(tuple(conditions), np.array(fixed, dtype=float), np.array(lower), np.array(upper),
                    np.array(nominal), v_ref, v_lo, v_hi, tuple(events))
