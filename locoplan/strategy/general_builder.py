"""The general condition-sequence builder: the ISSA paper's method (a condition sequence, switching points by
ISSA), with the sequence read off the drive that is optimal at a price of time.

The ISSA paper's section 2 classifies grades at each section's speed limit and copies the fastest run's
conditions elsewhere. On hilly real lines that misjudges the grades (a heavy train runs well below the
limit: on a 5200 t train's climb the optimum lets the speed sag from 80 to 45 km/h and coasts over the
crest) and confines the switching points to windows that miss the optimum's, so the plans were far from
the least energy, or late. Rules judged "at the speed the train will run" were tried first (a cruise
speed V among the decision variables, coasting before steep descents and limit drops, traction before
steep climbs): they reached the optimum on some lines and stayed 10-30 % above it on others, because
which grades deserve a run of their own depends on the timetable and on what follows.

So the sequence comes from the optimum itself, on a coarse grid: ``optimize/dp.py`` finds the drive
that minimises energy + lambda x time over a (position, speed) grid, with lambda bisected to the
planned time; its runs of traction, speed holding (K), coasting and braking are the condition sequence
and its switching points the nominal ones. ISSA then places the switching points on the exact
calculator, minimising eq. 10 inside the punctuality window, each free to move as far as its
neighbours. The energy-saving strategy (E_min of eq. 11) is the same drive at the lowest price: the
least traction energy whatever the time, a true lower bound of every plan's energy, which eq. 11 needs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.conditions import CODE, CONDITIONS
from ..optimize.problem import E_MIN_RUN_M
from ..physics.braking import full_brake_kn
from ..physics.traction import max_force_kn
from ..physics.units import kmh, kmh_from_e
from ..sim.calculator import TractionCalculator


@dataclass(frozen=True)
class DriveSequence:
    """A condition sequence read off a priced-optimal drive, with nominal switching points and windows."""

    conditions: tuple[str, ...]
    nominal_m: np.ndarray
    lower_m: np.ndarray
    upper_m: np.ndarray
    drive_time_s: float
    drive_energy_kwh: float
    price_kwh_per_s: float


def sequence_from_drive(calc: TractionCalculator, drive, min_run_m: float | None = None,
                        keep_force: bool = False) -> DriveSequence:
    """Runs of the drive's per-cell controls as a condition sequence of the ISSA paper: holding the speed is K
    (the calculator's K holds the speed at which it starts); runs shorter than half the train (the ISSA paper's
    eq. 3) join their predecessor; the last run of braking is the stop's (a bare B).
    Each switching point may move as far as its neighbours' nominal positions (less half a train): the
    drive is optimal on a coarse grid, its plan on the exact calculator may want them anywhere between.
    ``keep_force``: a short run of traction, cruise or braking is kept and widened to half a train instead
    (the switching points pushed apart as the optimiser's repair does: an optimum's short burst of traction up
    a climb is what gets a heavy train over it); only short coasting runs join their predecessor."""

    s, L = drive.s_m, calc.route.length_m
    gap = calc.train.length_m / 2 if min_run_m is None else min_run_m
    names = [CONDITIONS[u] for u in drive.controls]
    # the final braking: the last run of B (if any) is the stop's braking curve (a bare B)
    last_b = len(names)
    while last_b > 0 and names[last_b - 1] == "B":
        last_b -= 1
    names = names[:last_b]
    runs: list[list] = []
    for k, c in enumerate(names):
        if runs and runs[-1][2] == c:
            runs[-1][1] = float(s[k + 1])
        else:
            runs.append([float(s[k]), float(s[k + 1]), c])
    merged: list[list] = []
    for r in runs:  # (the departure run may be short; every later run joins its predecessor if it is)
        short = r[1] - r[0] < gap and (not keep_force or r[2] == "C")
        if merged and (short or merged[-1][2] == r[2]):
            merged[-1][1] = r[1]
        else:
            merged.append(r)
    if len(merged) > 1 and merged[-1][1] - merged[-1][0] < gap and merged[-1][2] == "C":
        merged[-2][1] = merged[-1][1]
        merged.pop()
    conditions = tuple(r[2] for r in merged) + ("B",)
    nominal = np.array([r[0] for r in merged[1:]], dtype=float)
    return _with_windows(conditions, nominal, gap, L, keep_force, drive)


def _with_windows(conditions, nominal: np.ndarray, gap: float, L: float, spread: bool, drive) -> DriveSequence:
    """The sequence with its nominal switching points (``spread``: pushed apart to ``gap``, as the optimiser's
    repair does) and each one's window: as far as its neighbours, less ``gap`` (the departure run may be
    shorter)."""
    nominal = np.asarray(nominal, dtype=float).copy()
    if spread and len(nominal):  # the runs at least ``gap`` long (the first may be shorter)
        for j in range(1, len(nominal)):
            nominal[j] = max(nominal[j], nominal[j - 1] + gap)
        nominal[-1] = min(nominal[-1], L - gap)
        for j in range(len(nominal) - 2, -1, -1):
            nominal[j] = min(nominal[j], nominal[j + 1] - gap)
        nominal = np.maximum(nominal, 0.0)
    edges = np.concatenate([[0.0], nominal, [L]])
    # each run's least length: ``gap``, an electric brake run (E) ``E_MIN_RUN_M``
    g = np.array([min(E_MIN_RUN_M, gap) if c == "E" else gap for c in conditions], dtype=float)
    n = len(nominal)
    lower = edges[:-2] + g[:n]
    if n:
        lower[0] = min(gap, 0.5 * nominal[0])  # the departure run may be short
    upper = np.minimum(edges[2:] - g[1:n + 1], L - gap)
    return DriveSequence(tuple(conditions), nominal, lower, np.maximum(upper, lower), drive.time_s, drive.energy_kwh,
                         drive.price_kwh_per_s)


def with_holds(calc: TractionCalculator, seq: DriveSequence) -> DriveSequence:
    """The sequence with a speed hold (K) inside each long coasting run, coasting again after it: for a
    timetable slower than the least energy's own time (a falling line coasts faster than asked), the
    extra time is spent holding a lower speed by braking on a descent, which costs no traction energy;
    ISSA then places where each hold begins and ends (nominally a quarter and three quarters into the
    run; windows as far as the neighbours, less half a train). A sequence without coasting (a climb driven
    in traction to the stop) gets instead a hold inside each traction run, nominally halfway and held to
    the run's end: a lower speed held with partial traction (accelerating again after it would spend more). A hold that ran on to the next condition
    would hold its speed with traction up every rise after the descent (a 40 km falling line asked for
    61 s more than coasting takes: 219.6 kWh with such holds, 4.4 kWh with holds that end)."""
    L = calc.route.length_m
    gap = calc.train.length_m / 2
    starts = np.concatenate([[0.0], seq.nominal_m])
    ends = np.concatenate([seq.nominal_m, [L]])
    body = seq.conditions[:-1]
    run = "C" if "C" in body else "T"  # no coasting at all (a climb): hold inside the traction runs instead
    conditions: list[str] = []
    nominal: list[float] = []
    for j, (c, a, b) in enumerate(zip(body, starts, ends)):
        conditions.append(c)
        if j:
            nominal.append(float(a))
        if c == "C" and b - a > 4 * gap:
            conditions += ["K", "C"]
            nominal += [float(a + 0.25 * (b - a)), float(a + 0.75 * (b - a))]
        elif c == run and b - a > 2 * gap:  # too short to hold and coast again (or traction): hold to its end
            conditions.append("K")
            nominal.append(float(0.5 * (a + b)))
    nominal_m = np.array(nominal)
    edges = np.concatenate([[0.0], nominal_m, [L]])
    lower = edges[:-2] + gap
    if len(nominal_m):
        lower[0] = min(gap, 0.5 * nominal_m[0])
    upper = np.minimum(edges[2:] - gap, L - gap)
    return DriveSequence(tuple(conditions) + ("B",), nominal_m, lower, np.maximum(upper, lower), seq.drive_time_s,
                         seq.drive_energy_kwh, seq.price_kwh_per_s)


FULL_SHARE = 0.97
"""A cell of the optimum whose traction (braking) is at least this share of the most the consist has at its
speed is full traction, T (full braking, B)."""
FORCE_SHARE = 0.02
"""A force under this share of the consist's largest effort is none: the cell coasts (C)."""
CAP_KMH = 0.3
"""A cell whose two nodes are within this of the braking envelope [km/h] is held at a limit or follows a
braking curve: whatever the plan's condition there, the calculator holds the train on the envelope."""
HELD_SHARE = 0.1
"""A cell of the optimum with a partial force holds a speed where its net force is under this share of that
force (or ``FORCE_SHARE`` of the largest effort): the grid's optimum holds a speed to within a few kN."""


@dataclass(frozen=True)
class _Drive:
    """A drive in the form ``sequence_from_drive`` reads: nodes [m], per-cell control codes, time, energy."""

    s_m: np.ndarray
    controls: np.ndarray
    time_s: float
    energy_kwh: float
    price_kwh_per_s: float


def optimum_controls(grid: TractionCalculator, sol) -> np.ndarray:
    """Each cell's condition code in E*'s solution ``sol`` (``ocp.cells.CellSolution`` on ``grid``'s cells):
    full traction T, no force C, full braking below the envelope B, a partial force (traction, or braking below
    the envelope) that holds the speed K. A cell on the braking envelope (a limit held, a braking curve
    followed: every condition is held there the same way), and a cell with a partial force whose speed changes
    (a switch inside the cell), take the condition of the cells before them (at the start, after them; T if
    none)."""
    tr = grid.train
    v_kmh = kmh(np.asarray(sol.v_ms, dtype=float))
    vm = np.sqrt(0.5 * (v_kmh[:-1] ** 2 + v_kmh[1:] ** 2))
    allowed = np.asarray(grid.traction_allowed, dtype=float)
    f_max = max_force_kn(vm, tr.traction_speed_kmh, tr.traction_kn) * allowed
    b_max = full_brake_kn(max_force_kn(vm, grid.electric_brake_speed_kmh, grid.electric_brake_kn),
                          max_force_kn(vm, grid.air_brake_speed_kmh, grid.air_brake_kn), allowed)
    small = FORCE_SHARE * float(np.max(tr.traction_kn))
    cap = kmh_from_e(np.maximum(grid.e_envelope, 0.0))
    near = v_kmh >= cap - CAP_KMH
    on_cap = near[:-1] & near[1:]
    e = 0.5 * np.asarray(sol.v_ms, dtype=float) ** 2
    F, B = np.asarray(sol.traction_kn, dtype=float), np.asarray(sol.brake_kn, dtype=float)
    # the net force [kN]: ~0 where a speed is held (against the force applied: a transition nets a good part of it)
    held = np.abs(grid.m_eff_t * np.diff(e) / grid.h_m) < np.maximum(small, HELD_SHARE * np.maximum(F, B))
    full_t = (f_max > small) & ((F >= FULL_SHARE * f_max) | (on_cap & (F > small)))
    full_b = (B > small) & (B >= FULL_SHARE * b_max)
    partial = (F > small) | (B > small)
    code = np.full(len(F), CODE["C"], dtype=np.int64)
    code[partial] = CODE["K"]
    code[full_b] = CODE["B"]
    code[full_t] = CODE["T"]
    inherit = ~full_t & (on_cap | (partial & ~full_b & ~held))
    code[inherit] = -1
    known = np.flatnonzero(code >= 0)
    if not known.size:
        return np.full(len(F), CODE["T"], dtype=np.int64)
    # each inheriting cell: the last known condition before it, else the first one after it
    last = np.maximum.accumulate(np.where(code >= 0, np.arange(len(code)), -1))
    out = np.where(code >= 0, code, code[np.where(last >= 0, last, known[0])])
    # traction inside a cell between coasting (or braking) on both sides is a burst of traction: up a short pitch
    # (a heavy train crawling over a crest) it is what gets the train over, and would be lost to the coasting
    n = len(code)
    nxt = np.minimum.accumulate(np.where(code >= 0, np.arange(n), n)[::-1])[::-1]
    after = code[np.minimum(nxt, known[-1])]
    idle = (CODE["C"], CODE["B"])
    burst = inherit & ~on_cap & (F > small) & np.isin(out, idle) & np.isin(after, idle)
    out[burst] = CODE["T"]
    return out


def sequence_from_optimum(calc: TractionCalculator, grid: TractionCalculator, sol, min_run_m: float | None = None
                          ) -> DriveSequence:
    """The condition sequence of E*'s own solution ``sol`` on ``grid`` (``optimum_controls``), its runs and
    nominal switching points as ``sequence_from_drive`` makes them for a plan on ``calc``: where the optimum
    alternates coasting and holding a speed on a falling line, or holds a speed by braking on a descent, the
    sequence does too."""
    drive = _Drive(np.asarray(grid.s_m, dtype=float), optimum_controls(grid, sol), float(np.sum(2.0 * grid.h_m / np.maximum(
        sol.v_ms[:-1] + sol.v_ms[1:], 1e-9))), float(sol.energy_kwh), -float(sol.slope_kwh_per_s))
    seq = sequence_from_drive(calc, drive, min_run_m, keep_force=True)
    # a hold (K) keeps the speed at which it begins: it begins where the optimum's speed reaches the speed it
    # holds (a cell earlier or later than the cells labelled K: the switch is inside a transition cell)
    s, v = drive.s_m, kmh(np.asarray(sol.v_ms, dtype=float))
    L = calc.route.length_m
    nominal = seq.nominal_m.copy()
    for j, c in enumerate(seq.conditions[1:-1]):
        if c != "K":
            continue
        a, b = nominal[j], (nominal[j + 1] if j + 1 < len(nominal) else L)
        v_hold = float(np.interp(0.5 * (a + b), s, v))
        k = int(np.searchsorted(s, a))
        lo = max(nominal[j - 1] if j else 0.0, s[max(k - HOLD_SEARCH_CELLS, 0)])
        hi = min(b, s[min(k + HOLD_SEARCH_CELLS, len(s) - 1)])
        idx = np.flatnonzero((s >= lo) & (s <= hi))
        d = v[idx] - v_hold
        cross = np.flatnonzero(d[:-1] * d[1:] <= 0.0)
        if cross.size:  # the first crossing (into the hold: within it the speed wavers about it), interpolated
            i = cross[0]
            s0, s1, d0, d1 = s[idx[i]], s[idx[i + 1]], d[i], d[i + 1]
            nominal[j] = s0 if d0 == d1 else s0 + (s1 - s0) * d0 / (d0 - d1)
    gap = calc.train.length_m / 2 if min_run_m is None else min_run_m
    return _with_windows(seq.conditions, nominal, gap, L, True, drive)


HOLD_SEARCH_CELLS = 3
"""Where a hold of the optimum begins is looked for within this many of its cells of where its K cells begin."""
