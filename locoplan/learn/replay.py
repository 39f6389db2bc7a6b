"""A logged run against E*, the least traction energy at its own running time, and where it lost the difference,
section by section (``locoplan replay``).

The sections are the pattern curves' (``segments.segment_route``: the line split by equivalent gradient into
steep / gentle up and down and level stretches, for the run's train). For section k = [a, b]:

- the run's traction work there, ``E_run,k = sum_i F_i+ |[x_i, x_i+1] & [a, b]|`` (each logged force held from its
  row to the next, as the log's total), and its time there, ``t_run,k = t(b) - t(a)`` (t(x) the time the head first
  reaches x, linear between rows; the first section starts with the log's first row, the last ends with its last);
- the optimum's (E*'s run at the same running time T, ``ocp.bound.optimum_run``): its cells' traction work inside
  [a, b] and its time there (each cell at constant acceleration, ``2 h / (v0 + v1)``, split where a boundary falls
  inside a cell), its section times scaled to add up to T exactly (they do to the solver's tolerance);
- the optimum's prices (the multipliers of E*'s solve, ``ocp.bound.optimum_run``): of time, ``lambda = -dE*/dT``
  at T, the energy one more second saves an optimal drive; and of kinetic energy, ``mu(x)``, the energy one more
  kWh of the train's kinetic energy at x saves the optimum from there on (1 where it holds a speed with part of its
  traction, above 1 under full traction, falling towards 0 while it coasts, 0 where it holds a speed by braking);

and the section's excess

    excess_k = (E_run,k - E*_k) + lambda (t_run,k - t*_k) + mu(a) dK(a) - mu(b) dK(b)

with dK(x) the run's kinetic energy less the optimum's at x (0 at the line's two ends, where both are at rest). The
first term is the energy used there beyond the optimum's. The second prices the time the run spent there beyond
the optimum's: a run slow on one section must be fast elsewhere to arrive at T, and an optimal drive makes that
time good at lambda per second. The last two price the speed the run brings in and carries out: a section left
faster than the optimum leaves it has stored energy the next one will not have to buy (credited to the section
that stored it, charged to the one that spends it). These are the first-order terms of the value function of the
rest of the run (energy still to use from a place, a speed and a time), so a section's excess is, to first order,
what the run's driving on that section cost against driving it optimally from the state it was in. Both the run
and the optimum take T and start and stop at rest, so the time and speed terms add up to zero and the sections'
excesses add up to the run's, ``sum_k excess_k = E_run - E*(T)``, exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import LocoplanError
from ..model.logs import LogData, LoggedRun
from ..physics.units import kmh, kwh, ms
from ..sim.calculator import ModelOptions
from .segments import LEVEL_PERMILLE, Section, segment_route


@dataclass(frozen=True)
class SectionExcess:
    """One section of a run: the run's and the optimum's traction work [kWh] and time [s] there, the value of the
    time it spent beyond the optimum's and of the speed it brought in less what it carried out [kWh], and the
    section's excess [kWh] (module docstring)."""

    index: int
    kind: str
    from_m: float
    to_m: float
    gradient_permille: float
    run_kwh: float
    optimum_kwh: float
    run_s: float
    optimum_s: float
    time_kwh: float
    speed_kwh: float

    @property
    def energy_kwh(self) -> float:
        """The run's traction work beyond the optimum's here [kWh]."""
        return self.run_kwh - self.optimum_kwh

    @property
    def excess_kwh(self) -> float:
        return self.energy_kwh + self.time_kwh + self.speed_kwh

    def to_dict(self) -> dict:
        return {"index": self.index, "type": self.kind, "from_m": round(self.from_m, 1), "to_m": round(self.to_m, 1),
                "gradient_permille": round(self.gradient_permille, 3), "run_kwh": round(self.run_kwh, 3),
                "optimum_kwh": round(self.optimum_kwh, 3), "run_s": round(self.run_s, 2),
                "optimum_s": round(self.optimum_s, 2), "energy_kwh": round(self.energy_kwh, 3),
                "time_kwh": round(self.time_kwh, 3), "speed_kwh": round(self.speed_kwh, 3),
                "excess_kwh": round(self.excess_kwh, 3)}


@dataclass(frozen=True)
class RunReplay:
    """One logged run replayed: its running time [s] and traction energy [kWh] (the log's), E* at that time, the
    price of time lambda = -dE*/dT [kWh/s], the excess and its sections; ``reason`` says why a run has no E* (then
    the optimum's fields are None and there are no sections)."""

    run: LoggedRun
    running_time_s: float
    traction_energy_kwh: float
    optimum_kwh: float | None = None
    accuracy: float | None = None
    price_kwh_per_s: float | None = None
    sections: tuple[SectionExcess, ...] = ()
    reason: str | None = None
    optimum_s_m: np.ndarray | None = field(default=None, repr=False, compare=False)
    optimum_v_kmh: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def compared(self) -> bool:
        return self.optimum_kwh is not None

    @property
    def excess_kwh(self) -> float | None:
        return None if self.optimum_kwh is None else self.traction_energy_kwh - self.optimum_kwh

    @property
    def excess_percent(self) -> float | None:
        """The excess as a share of the run's traction energy [%]: what an optimal drive in the same time would not
        have used."""
        if self.optimum_kwh is None or self.traction_energy_kwh <= 0:
            return None
        return 100.0 * self.excess_kwh / self.traction_energy_kwh

    def to_dict(self) -> dict:
        r = self.run

        def rnd(x, d):
            return None if x is None else round(x, d)
        return {"log": str(r.log_file), "driver_id": r.driver_id, "route": r.route.name, "consist": r.train.name,
                "mass_t": r.mass_t, "scheduled_time_s": r.scheduled_time_s, "date": r.date.isoformat(),
                "synthetic": r.synthetic, "running_time_s": round(self.running_time_s, 2),
                "traction_energy_kwh": round(self.traction_energy_kwh, 3), "optimum_kwh": rnd(self.optimum_kwh, 3),
                "optimum_accuracy_percent": None if self.accuracy is None else float(f"{100 * self.accuracy:.2g}"),
                "price_of_time_kwh_per_s": rnd(self.price_kwh_per_s, 5), "excess_kwh": rnd(self.excess_kwh, 3),
                "excess_percent": rnd(self.excess_percent, 2), "reason": self.reason,
                "sections": [s.to_dict() for s in self.sections]}


# ------------------------------------------------------------------------------------------ the run's side
def _cuts(sections: tuple[Section, ...]) -> np.ndarray:
    """Section boundaries [m], the first and last open (a log may start before 0 or end past the route's end)."""
    x = np.array([s.from_m for s in sections] + [sections[-1].to_m], dtype=float)
    x[0], x[-1] = -math.inf, math.inf
    return x


def work_between(x0: np.ndarray, x1: np.ndarray, force_kn: np.ndarray, cuts: np.ndarray) -> np.ndarray:
    """Traction work [kWh] in each interval [cuts_k, cuts_k+1] of pieces [x0, x1] (positions [m]) under constant
    forces ``force_kn`` (only the traction, F > 0, counts): each piece's work split by the length inside each
    interval."""
    f = np.maximum(force_kn, 0.0)
    out = np.empty(cuts.size - 1)
    for k in range(cuts.size - 1):
        overlap = np.clip(np.minimum(x1, cuts[k + 1]) - np.maximum(x0, cuts[k]), 0.0, None)
        out[k] = kwh(float(np.sum(f * overlap)))
    return out


def log_time_at(data: LogData, x: np.ndarray) -> np.ndarray:
    """The time [s] at which the log's head first reaches each position ``x`` [m] (linear between rows; the first
    row's time before the log's first position, the last row's after its last)."""
    pos, t = data.position_m, data.time_s
    i = np.searchsorted(pos, x, side="left")  # the first row at or past x
    i = np.clip(i, 1, pos.size - 1)
    p0, p1 = pos[i - 1], pos[i]
    w = np.where(p1 > p0, (x - p0) / np.where(p1 > p0, p1 - p0, 1.0), 1.0)
    out = t[i - 1] + np.clip(w, 0.0, 1.0) * (t[i] - t[i - 1])
    out = np.where(x <= pos[0], t[0], out)
    return np.where(x >= pos[-1], t[-1], out)


def run_sections(data: LogData, sections: tuple[Section, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(traction work [kWh], time [s]) of a log in each section; they add up to the log's traction energy and
    running time."""
    cuts = _cuts(sections)
    work = work_between(data.position_m[:-1], data.position_m[1:], data.force_kn[:-1], cuts)
    inner = cuts[1:-1]
    t = np.concatenate([[data.time_s[0]], log_time_at(data, inner), [data.time_s[-1]]])
    return work, np.diff(t)


# ------------------------------------------------------------------------------------------ the optimum's side
def optimum_sections(s_m: np.ndarray, v_ms: np.ndarray, traction_kn: np.ndarray,
                     sections: tuple[Section, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(traction work [kWh], time [s]) of a cell solution (node positions and speeds, each cell's constant traction)
    in each section: a cell a boundary cuts is split there, its time at constant acceleration."""
    cuts = _cuts(sections)
    work = work_between(s_m[:-1], s_m[1:], traction_kn, cuts)
    h = np.diff(s_m)
    t_node = np.concatenate([[0.0], np.cumsum(2.0 * h / np.maximum(v_ms[:-1] + v_ms[1:], 1e-12))])

    def time_to(x: float) -> float:
        """Time from the start to position x: the cell's start, then constant acceleration inside it."""
        k = int(np.clip(np.searchsorted(s_m, x, side="right") - 1, 0, h.size - 1))
        f = (x - s_m[k]) / h[k]
        vx = math.sqrt(max(v_ms[k] ** 2 + f * (v_ms[k + 1] ** 2 - v_ms[k] ** 2), 0.0))
        return float(t_node[k]) + (2.0 * f * h[k] / max(v_ms[k] + vx, 1e-12) if f > 0 else 0.0)

    t = np.array([0.0] + [time_to(float(x)) for x in cuts[1:-1]] + [float(t_node[-1])])
    return work, np.diff(t)


def log_speed_at(data: LogData, x: np.ndarray) -> np.ndarray:
    """The log's speed [km/h] where the head first reaches each position ``x`` [m] (linear between rows)."""
    pos, v = data.position_m, data.speed_kmh
    i = np.clip(np.searchsorted(pos, x, side="left"), 1, pos.size - 1)
    p0, p1 = pos[i - 1], pos[i]
    w = np.clip(np.where(p1 > p0, (x - p0) / np.where(p1 > p0, p1 - p0, 1.0), 1.0), 0.0, 1.0)
    out = v[i - 1] + w * (v[i] - v[i - 1])
    return np.where(x <= pos[0], v[0], np.where(x >= pos[-1], v[-1], out))


def boundary_values(data: LogData, opt, sections: tuple[Section, ...]) -> np.ndarray:
    """At each inner boundary of the sections, the value of the kinetic energy the run carries over the optimum's
    there [kWh]: ``mu(x) (K_run(x) - K*(x))``, with ``mu`` the optimum's price of kinetic energy at x (its cells'
    prices, linear between their middles) and K the train's kinetic energy."""
    x = np.array([s.from_m for s in sections[1:]], dtype=float)
    if not x.size:
        return x
    mid = 0.5 * (opt.s_m[1:] + opt.s_m[:-1])
    mu = np.interp(x, mid, opt.kinetic_price)
    v_run = ms(log_speed_at(data, x))
    v_opt = np.interp(x, opt.s_m, opt.v_ms)
    return mu * kwh(0.5 * opt.mass_t * (v_run ** 2 - v_opt ** 2))


# ------------------------------------------------------------------------------------------ a run, many runs
def replay_run(run: LoggedRun, options: ModelOptions | None = None, level_permille: float = LEVEL_PERMILLE,
               keep_profile: bool = False) -> RunReplay:
    """One logged run against E* at its own running time, section by section (module docstring). A run without
    an E* (faster than the model's train can run the line, a consist that cannot run it, a solve that did not
    converge) has its ``reason`` and no sections. ``keep_profile``: keep the optimum's speed along the line
    (for a plot)."""
    from ..ocp.bound import optimum_run

    data = run.data
    T, energy = data.running_time_s, data.traction_energy_kwh
    try:
        opt = optimum_run(run.route, run.train, options, T)
    except LocoplanError as exc:
        return RunReplay(run, T, energy, reason=f"no optimum at the log's running time {T:g} s: {exc}")
    sections = segment_route(run.route, run.train, level_permille)
    run_kwh, run_s = run_sections(data, sections)
    opt_kwh, opt_s = optimum_sections(opt.s_m, opt.v_ms, opt.traction_kn, sections)
    opt_s = opt_s * (T / float(np.sum(opt_s)))  # the optimum takes T, to the solver's tolerance: exactly T
    price = -float(opt.bound.slope_kwh_per_s)
    carried = np.concatenate([[0.0], boundary_values(data, opt, sections), [0.0]])  # at rest at both ends
    rows = tuple(SectionExcess(s.index, s.kind, s.from_m, s.to_m, s.gradient_permille, float(run_kwh[k]),
                               float(opt_kwh[k]), float(run_s[k]), float(opt_s[k]), price * float(run_s[k] - opt_s[k]),
                               float(carried[k] - carried[k + 1]))
                 for k, s in enumerate(sections))
    return RunReplay(run, T, energy, float(opt.bound.energy_kwh), opt.bound.accuracy, price, rows,
                     optimum_s_m=opt.s_m if keep_profile else None,
                     optimum_v_kmh=kmh(opt.v_ms) if keep_profile else None)


def replay_logs(runs: list[LoggedRun], options: ModelOptions | None = None, level_permille: float = LEVEL_PERMILLE,
                progress=lambda run: None) -> list[RunReplay]:
    """Every logged run replayed (:func:`replay_run`), in the order given; ``progress(run)`` as each begins."""
    out = []
    for r in runs:
        progress(r)
        out.append(replay_run(r, options, level_permille))
    return out


def summary(replays: list[RunReplay]) -> dict:
    """Over the runs with an E*: their traction energy, E* and excess [kWh] and the excess as a share of the energy
    [%] (what driving at the optimum in the same running times would have saved), and per line (route and
    sections) the runs' excess section by section (total and mean per run)."""
    done = [r for r in replays if r.compared]
    used = sum(r.traction_energy_kwh for r in done)
    best = sum(r.optimum_kwh for r in done)
    groups: dict[tuple, list[RunReplay]] = {}
    for r in done:
        key = (r.run.route.name, tuple((s.from_m, s.to_m, s.kind) for s in r.sections))
        groups.setdefault(key, []).append(r)
    lines = []
    for (route, _), rs in groups.items():
        secs = []
        for k, s in enumerate(rs[0].sections):
            tot = sum(r.sections[k].excess_kwh for r in rs)
            secs.append({"index": s.index, "type": s.kind, "from_m": round(s.from_m, 1), "to_m": round(s.to_m, 1),
                         "gradient_permille": round(s.gradient_permille, 3),
                         "energy_kwh": round(sum(r.sections[k].energy_kwh for r in rs), 3),
                         "time_kwh": round(sum(r.sections[k].time_kwh for r in rs), 3),
                         "speed_kwh": round(sum(r.sections[k].speed_kwh for r in rs), 3),
                         "excess_kwh": round(tot, 3), "mean_excess_kwh": round(tot / len(rs), 3)})
        e = sum(r.traction_energy_kwh for r in rs)
        x = sum(r.excess_kwh for r in rs)
        lines.append({"route": route, "runs": len(rs), "traction_energy_kwh": round(e, 3), "excess_kwh": round(x, 3),
                      "excess_percent": round(100 * x / e, 2) if e > 0 else None, "sections": secs})
    return {"runs": len(replays), "compared": len(done), "traction_energy_kwh": round(used, 3),
            "optimum_kwh": round(best, 3), "excess_kwh": round(used - best, 3),
            "excess_percent": round(100 * (used - best) / used, 2) if used > 0 else None, "lines": lines}
