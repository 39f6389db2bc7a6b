"""A simulator of human freight-train drivers that makes driver logs (the pattern-curve patent needs logs; the
project has none, so it makes them, and labels every one ``synthetic: true``); ``simulate_logs``
returns them as data and ``reporting/logs.py`` writes the log folder.

Human driving, not optimal control. Each driver follows a target speed with a handle of discrete
notches, late by a reaction delay, misjudging the speed by a drifting error; the target comes from
habits that differ between drivers (``DriverParams``):

- ``margin_kmh``: how far below the limit they hold;
- ``anticipation``: 0 = they keep going until the braking curve of a lower limit (or of the stop)
  forces them to brake; 1 = they coast early enough to roll down to it (the coasting curve back from
  it); in between, a blend of the two curves;
- ``coast_down_m`` / ``charge_up_m``: how far before a long down-grade they shut off (letting the
  descent bring the speed back), how far before a long up-grade they speed up to the limit;
- ``brake_over_kmh``: how far above their target they let the speed run before braking instead of
  coasting (small = brakes readily: the waste of braking away energy bought with traction);
- ``notch_step`` (1, 2, 4 of the 8 notches: fine or coarse handling), ``accel_notch`` (the highest
  notch used to accelerate), ``gain_notch_per_kmh``, ``band_kmh`` (dead band when holding);
- ``reaction_s`` (delay between seeing and acting), ``noise_kmh`` (speed misjudged, AR(1) drift);
- ``brake_in``: the share of full braking at which they begin the final stop.

A latent skill per driver (standard normal) pulls these habits together, plus individual noise,
so that some drivers are clearly good and some wasteful; each run jitters them a little.

Physics: the project's model, no second one. The route is the traction calculator's grid: its
speed limit per cell (train-length aware: a limit holds until the tail has cleared it), its
equivalent gradient (strip gradient by default), its neutral sections, and its braking envelope
``calc.e_envelope`` (where braking must begin for every lower limit and for the stop). Forces come
from ``calc.forces_kn`` (traction, braking, resistance + gravity). Time steps of ``DT_S`` with a
midpoint (RK2) force evaluation. A supervision (the train-protection curve of a real locomotive)
brakes fully whenever the train reaches the braking envelope, so no run ever breaks a limit; the
final stop is braked to stop exactly at the end of the route; every run is checked (arrived, never
stalled, never above a limit) before it is returned.

Each driver is given the run's planned time (plus their own punctuality error) and, like a driver
who knows the line, picks the cruise speed that meets it: a bisection on the cruise speed, all runs
of one mass and time at once.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import InputError, Problem
from ..model.consist import Consist, ConsistEntry, Vehicle
from ..model.logs import LogData
from ..model.route import Route
from ..model.train import build_train
from ..physics.units import KMH_PER_MS, kinetic_e, kmh, kmh_from_e, ms_from_e
from ..sim.calculator import ModelOptions, TractionCalculator
from ..strategy.sequence import classify_grades

DT_S = 1.0
"""Time step and log sampling interval [s] (recorders log at about 1 Hz)."""

MIN_ARRIVAL_S = 0.15
"""Shortest last step, the one that closes the last metres to the stop [s]: the logs write time to 0.1 s, and
a train creeping the last metre at a few mm/s would otherwise arrive 0.01 s after the row before, a log with
two rows at one time (which ``learn`` refuses: time must rise). 0.15 s is more than the 0.1 s a rounded time
can lose."""

NOTCHES = 8
"""Traction and braking notches of the handle (force = notch / 8 of the full curve at that speed)."""

BRAKE_IN_KMH = 30.0
"""Below this speed the anticipation curve to the stop is a service brake (half of full braking),
above it a coasting curve: drivers coast towards the station and brake into it."""

COAST_SPAN_KMH = 12.0
"""The anticipation curve lies at most this far below the braking curve: a driver coasts to shed up to
12 km/h before a lower limit or the station, and brakes for the rest."""

CALIBRATION_STEPS = 8
"""At most this many regula-falsi steps on each run's cruise speed (after the bracket's two ends)."""

SIMULATOR = "locoplan drivers simulate"


# ------------------------------------------------------------------------------------------ drivers
@dataclass(frozen=True)
class DriverParams:
    """Per-driver habits, arrays of one value per driver (or per run, after ``take``)."""

    skill: np.ndarray
    margin_kmh: np.ndarray
    anticipation: np.ndarray
    coast_down_m: np.ndarray
    charge_up_m: np.ndarray
    brake_over_kmh: np.ndarray
    notch_step: np.ndarray
    accel_notch: np.ndarray
    gain_notch_per_kmh: np.ndarray
    band_kmh: np.ndarray
    reaction_s: np.ndarray
    noise_kmh: np.ndarray
    brake_in: np.ndarray
    punctuality_bias: np.ndarray  # habitual lateness, in units of the run's tolerance

    def take(self, idx: np.ndarray) -> "DriverParams":
        return DriverParams(**{f.name: getattr(self, f.name)[idx] for f in fields(self)})

    def rows(self) -> list[dict]:
        return [{f.name: (int(getattr(self, f.name)[i]) if f.name in ("notch_step", "accel_notch")
                          else round(float(getattr(self, f.name)[i]), 3)) for f in fields(self)}
                for i in range(len(self.skill))]


def draw_drivers(n: int, rng: np.random.Generator) -> DriverParams:
    """``n`` drivers: a latent skill z ~ N(0, 1) pulls each habit towards good (z > 0) or wasteful
    (z < 0), plus individual noise. Ranges are chosen to give an energy spread of a few tens of per
    cent between the best and the worst driver of a group, as reported for manual freight driving."""
    z = rng.standard_normal(n)

    def trait(weight: float) -> np.ndarray:
        """A value in (0, 1): the skill's pull plus the driver's own, through a logistic."""
        return 1.0 / (1.0 + np.exp(-(weight * z + rng.standard_normal(n) * math.sqrt(max(1.0 - weight ** 2, 0.05)))))

    anticipation = 0.05 + 1.0 * trait(0.85)
    coast_down = 1200.0 * trait(0.8)
    charge_up = 1500.0 * trait(0.7)
    brake_over = 0.5 + 15.0 * trait(0.8)
    fine = trait(0.5)
    notch_step = np.where(fine > 0.66, 1, np.where(fine > 0.33, 2, 4))
    accel_notch = np.clip(np.round(5 + 3.99 * trait(0.4) - 0.5), 5, 8).astype(int)
    gain = 0.6 + 2.0 * trait(0.0)
    band = 3.0 - 2.0 * trait(0.5)
    reaction = 4.0 - 3.0 * trait(0.4)
    noise = 2.0 - 1.6 * trait(0.5)
    margin = 1.5 + 5.0 * (1 - trait(0.2))
    brake_in = 0.35 + 0.35 * trait(0.3)
    bias = 0.3 * rng.standard_normal(n)
    return DriverParams(z, margin, anticipation, coast_down, charge_up, brake_over, notch_step, accel_notch, gain,
                        band, reaction, noise, brake_in, bias)


def jitter(p: DriverParams, rng: np.random.Generator, share: float = 0.08) -> DriverParams:
    """Day-to-day variation of one driver's habits (each continuous habit x (1 + share N(0, 1)))."""
    out = {}
    for f in fields(p):
        x = getattr(p, f.name)
        if f.name in ("skill", "notch_step", "accel_notch", "punctuality_bias"):
            out[f.name] = x
        else:
            out[f.name] = x * np.clip(1.0 + share * rng.standard_normal(x.shape), 0.7, 1.3)
    out["anticipation"] = np.clip(out["anticipation"], 0.0, 1.0)
    return DriverParams(**out)


# ------------------------------------------------------------------------------------------ route
@dataclass(frozen=True)
class RouteTables:
    """Per-route, per-train arrays the drivers read (everything from the calculator's grid)."""

    s_m: np.ndarray  # nodes
    limit_kmh: np.ndarray  # per cell
    allowed: np.ndarray  # per cell: 1 traction allowed, 0 neutral section
    e_brake: np.ndarray  # nodes: braking envelope (full braking), e = v^2 / 2 [m^2/s^2]
    e_coast: np.ndarray  # nodes: anticipation envelope (coasting, service braking below BRAKE_IN_KMH)
    to_up_m: np.ndarray  # per cell: distance to the next long up-grade's start (inf if none ahead)
    to_down_m: np.ndarray  # per cell: distance to the next long down-grade's start
    down_gain_kmh: np.ndarray  # per cell: the speed that coasting gains on that down-grade
    on_up: np.ndarray  # per cell: inside a long up-grade


def route_tables(calc: TractionCalculator) -> RouteTables:
    """Envelopes and grade look-ahead for the drivers, from the calculator's route model."""
    s, h = calc.s_m, calc.h_m
    m = calc.m_eff_t
    n = len(h)
    e_coast = calc.e_limit_node.copy()
    e_in = kinetic_e(BRAKE_IN_KMH)
    for k in range(n - 1, -1, -1):  # backward from every lower limit and the stop
        e1 = e_coast[k + 1]
        _, b_max, load = (float(x) for x in calc.forces_kn(ms_from_e(np.float64(e1)), k))
        if e1 >= e_in and load > 0:  # coasting slows the train: start coasting earlier, from lower down
            e0 = e1 + h[k] * load / m
        else:  # into the station, or where coasting does not slow the train: a service brake (half of full)
            e0 = e1 + h[k] * max(0.5 * b_max + load, 0.0) / m
        e_coast[k] = min(e_coast[k], e0)
    # nobody coasts for kilometres to lose a few km/h: the curve stays within COAST_SPAN_KMH of the braking curve
    floor_kmh = np.maximum(kmh_from_e(calc.e_envelope) - COAST_SPAN_KMH, 0.0)
    e_coast = np.minimum(np.maximum(e_coast, kinetic_e(floor_kmh)), calc.e_envelope)
    mid = 0.5 * (s[1:] + s[:-1])
    to_up = np.full(n, np.inf)
    to_down = np.full(n, np.inf)
    gain = np.zeros(n)
    on_up = np.zeros(n, dtype=bool)
    for g in sorted(classify_grades(calc), key=lambda g: -g.from_m):  # nearest grade ahead wins
        ahead = mid < g.from_m
        if g.kind == "long-up":
            to_up = np.where(ahead, np.minimum(to_up, g.from_m - mid), to_up)
            on_up |= (mid >= g.from_m) & (mid < g.to_m)
        elif g.kind == "long-down":
            closer = ahead & (g.from_m - mid < to_down)
            to_down = np.where(closer, g.from_m - mid, to_down)
            gain = np.where(closer, np.clip(g.speed_change_kmh, 0.0, 20.0), gain)
    return RouteTables(s, calc.limit_kmh.copy(), calc.traction_allowed.copy(), calc.e_envelope.copy(), e_coast,
                       to_up, to_down, gain, on_up)


# ------------------------------------------------------------------------------------------ simulation
@dataclass(frozen=True)
class SimOutcome:
    """Per run: running time [s] (inf if it failed), why it failed ('' if not), and the logs."""

    running_time_s: np.ndarray
    failure: list[str]
    logs: list[LogData] | None


def _quantise(notch: np.ndarray, step: np.ndarray) -> np.ndarray:
    """Round a notch to the driver's step (1, 2 or 4), within 0..NOTCHES."""
    return np.minimum(np.maximum(np.round(notch / step) * step, 0.0), NOTCHES)


def simulate_runs(calc: TractionCalculator, tables: RouteTables, p: DriverParams, cruise_kmh: np.ndarray,
                  noise: np.ndarray, max_time_s: np.ndarray | float, record: bool = False) -> SimOutcome:
    """Drive every run (the rows of ``p``, ``cruise_kmh``, ``noise``) from rest at 0 m to rest at the
    route's end. ``noise`` (n_runs, n_steps) is each run's speed misjudgement [km/h] per step."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return _simulate(calc, tables, p, np.asarray(cruise_kmh, float), noise,
                         np.broadcast_to(np.asarray(max_time_s, float), (len(cruise_kmh),)), record)


def _simulate(calc, tables, p, cruise_kmh, noise, max_time_s, record):
    n = len(cruise_kmh)
    L = float(calc.route.length_m)
    m = calc.m_eff_t
    nodes, limit, allowed = tables.s_m, tables.limit_kmh, tables.allowed
    e_brake = tables.e_brake
    n_cells = len(limit)
    n_steps = noise.shape[1]
    depth = 9
    delay = np.minimum(np.maximum(np.round(p.reaction_s / DT_S).astype(int), 0), depth - 1)
    hist = np.zeros((n, depth))  # commanded notches in a ring (+ traction, - braking)
    hist_label = np.full((n, depth), 2, dtype=np.int8)  # 0 T, 1 K, 2 C, 3 B
    rows = np.arange(n)
    s = np.zeros(n)
    v = np.zeros(n)
    t = np.zeros(n)
    done = np.zeros(n, dtype=bool)
    failed = np.zeros(n, dtype=bool)
    reason = [""] * n
    stopping = np.zeros(n, dtype=bool)
    if record:
        rec_t = np.zeros((n, n_steps + 1))
        rec_s = np.zeros((n, n_steps + 1))
        rec_v = np.zeros((n, n_steps + 1))
        rec_f = np.zeros((n, n_steps + 1))
        rec_notch = np.zeros((n, n_steps + 1), dtype=int)
        rec_label = np.full((n, n_steps + 1), 2, dtype=np.int8)
        length = np.zeros(n, dtype=int)
    live = np.ones(n, dtype=bool)
    for i in range(n_steps):
        k = np.minimum(np.searchsorted(nodes, s, side="right") - 1, n_cells - 1)
        v_kmh = kmh(v)
        f_max, b_max, load = calc.forces_kn(v, k)
        lim = limit[k]
        v_tgt = _target_kmh(tables, p, k, s, v, lim, cruise_kmh)
        slot = i % depth
        hist[:, slot], hist_label[:, slot] = _handle(p, v_tgt, v_kmh + noise[:, i], v_kmh, lim, load, f_max)
        back = (slot - delay) % depth
        notch = hist[rows, back]
        act = hist_label[rows, back]
        # --- the final stop: brake to stop exactly at the end, once it takes a share of full braking
        a_req = v * v / (2 * np.maximum(L - s, 0.05))
        # (not where full braking cannot even slow the train: on a descent it cannot hold, a_req is always
        # "reached", and the final brake would begin kilometres early)
        can_slow = b_max + load > 1e-3 * m
        stopping |= live & (v > 0) & can_slow & (a_req * m >= p.brake_in * (b_max + load))
        # forces: fractions of the curves, evaluated again at the step's mid speed (RK2)
        trac_frac = np.where(stopping | (notch <= 0), 0.0, notch / NOTCHES * allowed[k])
        brake_frac = np.where(stopping, np.minimum(np.maximum(m * a_req - load, 0.0), b_max) / b_max,
                              np.maximum(-notch, 0.0) / NOTCHES)
        # --- supervision (the train-protection curve): where the handle would take the train over the
        # braking envelope within this step, it brakes (or cuts traction) just enough, up to full braking
        trac_frac, brake_frac, guard = _supervise(live, s, v, trac_frac, brake_frac, f_max, b_max, load, m, nodes,
                                                  e_brake)
        act = np.where(stopping | guard, np.where(brake_frac > 0, 3, 2), np.where((act == 0) & (trac_frac == 0), 2, act))
        a0 = (trac_frac * f_max - brake_frac * b_max - load) / m
        v_mid = np.maximum(v + 0.5 * DT_S * a0, 0.0)
        f_mid, b_mid, load_mid = calc.forces_kn(v_mid, k)
        force = trac_frac * f_mid - brake_frac * b_mid
        force_net = force - load_mid
        # at rest the brakes hold the train unless traction overcomes the load (no rolling back)
        acc = np.where((v <= 0) & (force_net <= 0), 0.0, force_net / m)
        v_new = v + acc * DT_S
        # a train coming to rest inside the step: when, and where
        halts = live & (v > 0) & (v_new <= 0)
        t_halt = np.where(halts, v / np.maximum(-acc, 1e-12), DT_S)
        ds = np.where(halts, 0.5 * v * t_halt, 0.5 * (v + np.maximum(v_new, 0.0)) * DT_S)
        dt_step = np.where(halts, t_halt, DT_S)
        v_new = np.maximum(v_new, 0.0)
        # at rest within a few metres of the stop is arriving: the supervision's margin (0.5 m^2/s^2 under
        # the braking envelope) halts a train 0.5 / a_brake short of it, 5 m with the electric brake alone
        a_brake = np.maximum((b_max + load) / m, 1e-3)
        arrive = live & ((s + ds >= L - 0.5) | (halts & stopping & (s + ds >= L - np.maximum(5.0, 0.5 / a_brake + 1.0))))
        if arrive.any():  # the last step ends exactly at the end of the route, at rest
            dt_arrive = 2 * np.maximum(L - s, 0.0) / np.maximum(v, 1e-9)
            dt_step = np.where(arrive, np.maximum(np.minimum(dt_arrive, dt_step * 4), MIN_ARRIVAL_S), dt_step)
            ds = np.where(arrive, L - s, ds)
            overrun = arrive & (v_kmh > 10.0) & (s + 0.5 * (v + v_new) * DT_S > L + 1.0)
        else:
            overrun = arrive
        stall = halts & ~arrive
        if record:
            j = length
            rec_t[rows, j], rec_s[rows, j], rec_v[rows, j] = t, s, v_kmh
            rec_f[rows, j] = np.where(live, force, 0.0)
            shown = np.where(stopping | guard, -np.ceil(brake_frac * NOTCHES - 1e-9), np.where(trac_frac > 0, notch, np.minimum(notch, 0)))
            rec_notch[rows, j] = np.where(live, shown, 0).astype(int)
            rec_label[rows, j] = np.where(live, act, 2)
            length = length + live
        over = live & (v_kmh > lim + 0.1)  # the supervision makes this impossible; checked anyway
        s = np.where(live, s + ds, s)
        v = np.where(live, np.where(arrive, 0.0, v_new), v)
        t = np.where(live, t + dt_step, t)
        done |= arrive & ~overrun
        bad = stall | over | overrun | (live & ~arrive & (t > max_time_s))
        if bad.any():
            for r in np.flatnonzero(bad):
                failed[r] = True
                reason[r] = (f"stalled at {s[r]:,.0f} m" if stall[r] else f"above the limit at {s[r]:,.0f} m" if over[r]
                             else f"ran past the stop at {v_kmh[r]:.1f} km/h" if overrun[r]
                             else f"did not arrive within {max_time_s[r]:,.0f} s")
        live = ~(done | failed)
        if not live.any():
            break
    for r in np.flatnonzero(live):
        failed[r] = True
        reason[r] = f"did not arrive within {n_steps} steps"
    running = np.where(done, t, np.inf)
    logs = _logs(t, s, length, rec_t, rec_s, rec_v, rec_f, rec_notch, rec_label) if record else None
    return SimOutcome(running, reason, logs)


def _target_kmh(tables, p, k, s, v, lim, cruise_kmh):
    """The speed each driver has in mind [km/h]: the cruise speed (the limit up a long up-grade, less before a
    descent), under the limit by the driver's margin, and under what the driver anticipates ahead (a blend of the
    coasting and braking curves, looked ahead by the reaction time)."""
    nodes = tables.s_m
    look = s + v * p.reaction_s
    e_ant = (p.anticipation * np.interp(look, nodes, tables.e_coast)
             + (1.0 - p.anticipation) * np.interp(look, nodes, tables.e_brake))
    base = np.where(tables.on_up[k] | (tables.to_up_m[k] < p.charge_up_m), lim, cruise_kmh)  # power on up a long climb
    base = np.where(tables.to_down_m[k] < p.coast_down_m, np.minimum(base, cruise_kmh - 0.7 * tables.down_gain_kmh[k]),
                    base)
    return np.minimum(np.minimum(base, lim - p.margin_kmh), kmh_from_e(e_ant) - 0.5 * p.margin_kmh)


def _handle(p, v_tgt, v_seen, v_kmh, lim, load, f_max):
    """The handle each driver sets on the speed as judged (``v_seen``): accelerate, hold, coast or brake, as a notch
    (+ traction, - braking) and its label (0 T, 1 K, 2 C, 3 B)."""
    err = v_tgt - v_seen
    brake_at = np.minimum(v_tgt + p.brake_over_kmh, lim - 0.5 * p.margin_kmh)
    accel = err > p.band_kmh
    brake = ~accel & (v_seen > brake_at) & (v_kmh > 1.0)
    hold = ~accel & ~brake & (err > -p.band_kmh)
    n_acc = np.maximum(_quantise(np.minimum(np.ceil(p.gain_notch_per_kmh * err), p.accel_notch), p.notch_step),
                       p.notch_step)
    n_hold = _quantise(np.where(load > 0, NOTCHES * load / f_max, 0.0), p.notch_step)
    n_brk = np.maximum(_quantise(np.ceil(p.gain_notch_per_kmh * (v_seen - brake_at)), p.notch_step), p.notch_step)
    notch = np.where(accel, n_acc, np.where(hold, n_hold, np.where(brake, -n_brk, 0.0)))
    return notch, np.where(accel, 0, np.where(hold, 1, np.where(brake, 3, 2)))


def _supervise(live, s, v, trac_frac, brake_frac, f_max, b_max, load, m, nodes, e_brake):
    """The supervision (the train-protection curve): where the handle would take the train over the braking envelope
    within the step, it brakes (or cuts traction) just enough, up to full braking. Returns the traction and braking
    fractions, and where the supervision brakes."""
    e_now = 0.5 * v * v
    e_cap = np.interp(s + v * DT_S, nodes, e_brake) - 0.5
    reach = np.maximum(v, 0.1) * DT_S
    guard = live & (v > 0) & (e_now + (trac_frac * f_max - brake_frac * b_max - load) / m * reach > e_cap)
    if guard.any():
        f_need = m * (e_cap - e_now) / reach + load  # net force F - B that meets the cap
        trac_frac = np.where(guard, np.minimum(np.maximum(f_need / f_max, 0.0), trac_frac), trac_frac)
        brake_frac = np.where(guard, np.minimum(np.maximum(-f_need / b_max, brake_frac), 1.0), brake_frac)
        guard &= brake_frac > 0
    return trac_frac, brake_frac, guard


def _logs(t, s, length, rec_t, rec_s, rec_v, rec_f, rec_notch, rec_label) -> list:
    """Each run's recorded log, closed by a last row at rest where it ended."""
    logs = []
    names = np.array(["T", "K", "C", "B"])
    for r in range(len(t)):
        j = length[r]
        rec_t[r, j], rec_s[r, j], rec_v[r, j], rec_f[r, j], rec_notch[r, j], rec_label[r, j] = t[r], s[r], 0.0, 0.0, 0, 3
        sl = slice(0, j + 1)
        logs.append(LogData(rec_t[r, sl].copy(), rec_s[r, sl].copy(), rec_v[r, sl].copy(), rec_f[r, sl].copy(),
                            rec_notch[r, sl].copy(), names[rec_label[r, sl]]))
    return logs


BLOCK_BYTES = 64 * 2**20
"""Memory for one block of runs [bytes]: the runs are searched and recorded a block at a time, so that
20,000 logs (the limit) take what one block takes (``drive_to_schedule``); the results do not depend on it."""

RECORD_BYTES_PER_STEP = 41
"""Bytes a recorded run holds per time step (time, position, speed, force, notch: 8 each; the action: 1)."""


class SpeedNoise:
    """Each run's speed misjudgement [km/h] per step: AR(1) with stationary standard deviation ``sigma_kmh``
    (one per run), the runs' innovations drawn as one (runs, ``n_steps``) array of standard normals.

    Made a block of runs at a time: the rows of that one draw are consecutive in the generator's stream, so
    drawing the blocks one after another gives the same numbers, and the generator's state at each block's
    start, kept here, draws a block again. Construction advances ``rng`` past the whole draw, as one draw
    would, holding one block at a time."""

    def __init__(self, rng: np.random.Generator, sigma_kmh: np.ndarray, n_steps: int, block_runs: int,
                 rho: float = 0.97):
        self.sigma = np.asarray(sigma_kmh, float)
        self.n_steps, self.rho = int(n_steps), rho
        n = len(self.sigma)
        self.blocks = [(lo, min(lo + max(int(block_runs), 1), n)) for lo in range(0, n, max(int(block_runs), 1))]
        self._states = []
        for lo, hi in self.blocks:
            self._states.append(rng.bit_generator.state)
            rng.standard_normal((hi - lo, self.n_steps))

    def block(self, b: int) -> np.ndarray:
        """Block ``b``'s noise, (its runs, n_steps)."""
        lo, hi = self.blocks[b]
        gen = np.random.Generator(np.random.PCG64())
        gen.bit_generator.state = self._states[b]
        x = gen.standard_normal((hi - lo, self.n_steps))  # the innovations, filtered in place
        sigma = self.sigma[lo:hi]
        x[:, 0] = x[:, 0] * sigma
        c = math.sqrt(1 - self.rho * self.rho)
        for i in range(1, self.n_steps):
            x[:, i] = self.rho * x[:, i - 1] + c * sigma * x[:, i]
        return x


def block_runs(n_steps: int, per_step_bytes: int) -> int:
    """How many runs of ``n_steps`` steps fit in ``BLOCK_BYTES`` at ``per_step_bytes`` each (at least one)."""
    return max(1, BLOCK_BYTES // max(per_step_bytes * n_steps, 1))


class _Search:
    """The regula-falsi (Illinois) state of a block of runs on x = 1 / cruise speed (``drive_to_schedule``)."""

    def __init__(self, late, x_fast: np.ndarray, x_slow: np.ndarray):
        self.late = late
        self.x_fast, self.x_slow = x_fast, x_slow
        self.f_fast, self.f_slow = late(x_fast), late(x_slow)
        self.best_x = np.where(np.abs(self.f_fast) < np.abs(self.f_slow), x_fast, x_slow)
        self.best_f = np.minimum(np.abs(self.f_fast), np.abs(self.f_slow))
        self.open_ = (self.f_fast < 0) & (self.f_slow > 0)  # bracketed; otherwise the nearer end is the answer
        self.side = np.zeros(len(x_fast), dtype=int)
        self.steps = 0

    def searching(self) -> bool:
        """Some run of the block is bracketed and not yet within 0.5 s (once within, a run stays within)."""
        return bool((self.open_ & (self.best_f > 0.5)).any())

    def step(self) -> None:
        x_fast, x_slow, f_fast, f_slow = self.x_fast, self.x_slow, self.f_fast, self.f_slow
        open_, side = self.open_, self.side
        x = np.where(open_, x_slow - f_slow * (x_slow - x_fast) / (f_slow - f_fast), self.best_x)
        lo, hi = np.minimum(x_fast, x_slow), np.maximum(x_fast, x_slow)
        x = np.clip(x, lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo))
        f = self.late(x)
        better = np.abs(f) < self.best_f
        self.best_x, self.best_f = np.where(better, x, self.best_x), np.where(better, np.abs(f), self.best_f)
        slow = open_ & (f > 0)
        fast = open_ & (f <= 0)
        # Illinois: halve the stale end's value when the same end moves twice running
        f_fast = np.where(slow & (side == -1), 0.5 * f_fast, f_fast)
        f_slow = np.where(fast & (side == 1), 0.5 * f_slow, f_slow)
        self.x_slow, self.f_slow = np.where(slow, x, x_slow), np.where(slow, f, f_slow)
        self.x_fast, self.f_fast = np.where(fast, x, x_fast), np.where(fast, f, f_fast)
        self.side = np.where(slow, -1, np.where(fast, 1, side))
        self.steps += 1


def drive_to_schedule(calc: TractionCalculator, tables: RouteTables, p: DriverParams, aim_s: np.ndarray,
                      noise: SpeedNoise, steps: int = CALIBRATION_STEPS, keep=None) -> tuple[np.ndarray, SimOutcome]:
    """Each run's cruise speed for its aimed running time, and the runs recorded at those speeds. The
    running time is close to linear in 1 / cruise speed, so the search is regula falsi (Illinois) on
    x = 1 / cruise within a bracket; it stops when every run is within 0.5 s. A run that cannot make its
    time even at the line speed runs at it (and arrives late, as drivers sometimes do).

    The runs are searched and recorded a block at a time (``noise.blocks``), so that memory is one block's,
    whatever the number of runs, with the numbers of one search over all runs at once: the stopping rule
    is shared (every run takes as many steps as the slowest-converging run needs), so the blocks search
    until each is done, then those done early take the steps the slowest block took. Each recorded run's
    log is handed to ``keep(run index, log)`` as it is made (a failed run's is not); without ``keep`` the
    logs are returned in the outcome."""
    n = len(aim_s)
    v_top = float(np.max(tables.limit_kmh))
    mean_kmh = KMH_PER_MS * calc.route.length_m / aim_s
    max_time = 3.0 * aim_s
    x_fast, x_slow = np.full(n, 1.0 / v_top), 1.0 / np.maximum(0.8 * mean_kmh, 10.0)
    kept = [] if keep is None else None
    only = noise.block(0) if len(noise.blocks) == 1 else None  # one block: drawn once

    def block_noise(b):
        return only if only is not None else noise.block(b)

    def late_of(lo, hi, nz):
        pb, aim_b, max_b = p.take(slice(lo, hi)), aim_s[lo:hi], max_time[lo:hi]
        return lambda x: np.minimum(simulate_runs(calc, tables, pb, 1.0 / x, nz, max_b).running_time_s - aim_b, 1e4)

    searches = []
    for b, (lo, hi) in enumerate(noise.blocks):
        s = _Search(late_of(lo, hi, block_noise(b)), x_fast[lo:hi], x_slow[lo:hi])
        while s.steps < steps and s.searching():
            s.step()
        s.late = None  # holds the block's noise
        searches.append(s)
    shared = max((s.steps for s in searches), default=0)
    cruise = np.empty(n)
    running = np.full(n, np.inf)
    failure = [""] * n
    for b, (lo, hi) in enumerate(noise.blocks):
        s, nz = searches[b], block_noise(b)
        s.late = late_of(lo, hi, nz)
        while s.steps < shared:
            s.step()
        s.late = None
        cruise[lo:hi] = 1.0 / s.best_x
        rec = block_runs(noise.n_steps, RECORD_BYTES_PER_STEP)
        for a in range(lo, hi, rec):
            z = min(a + rec, hi)
            out = simulate_runs(calc, tables, p.take(slice(a, z)), cruise[a:z], nz[a - lo:z - lo], max_time[a:z], record=True)
            running[a:z] = out.running_time_s
            failure[a:z] = out.failure
            for j, log in enumerate(out.logs):
                if kept is not None:
                    kept.append(log)
                elif not out.failure[j]:
                    keep(a + j, log)
            del out
        del nz  # before the next block's is made: one block's noise at a time
    return cruise, SimOutcome(running, failure, kept)


# ------------------------------------------------------------------------------------------ consists
def consist_for_mass(base: Consist, vehicles: dict[str, Vehicle], mass_t: float) -> Consist:
    """The base consist with its wagon entry resized to reach ``mass_t``: as few wagons as carry it
    fully loaded (heavy haul runs full), the load per wagon then trimmed to hit the mass exactly."""
    check_train_mass(mass_t, "--masses")
    wagons = [i for i, e in enumerate(base.vehicles) if vehicles[e.type].kind == "wagon"]
    if len(wagons) != 1:
        raise InputError(Problem(base.name, "vehicles", "the base consist for --masses needs exactly one wagon entry "
                                 f"(found {len(wagons)})"))
    w = wagons[0]
    entry = base.vehicles[w]
    wagon = vehicles[entry.type]
    fixed = sum(vehicles[e.type].mass_t * e.count + e.load_t * e.count for i, e in enumerate(base.vehicles) if i != w)
    payload_max = wagon.max_load_t if wagon.max_load_t is not None else entry.load_t
    per_wagon = wagon.mass_t + payload_max
    if payload_max <= 0 and abs(mass_t - fixed - round((mass_t - fixed) / wagon.mass_t) * wagon.mass_t) > 1e-6:
        raise InputError(Problem("<command line>", "--masses", f"{mass_t:g} t cannot be reached: {wagon.name} declares no "
                                 "max_load_t and its entry no load_t, so only whole wagons of "
                                 f"{wagon.mass_t:g} t can be added (use a consist whose wagon has max_load_t)"))
    rest = mass_t - fixed
    if rest < wagon.mass_t:
        raise InputError(Problem("<command line>", "--masses", f"{mass_t:g} t is lighter than the locomotives plus one "
                                 f"empty {wagon.name} ({fixed + wagon.mass_t:g} t)"))
    count = max(1, math.ceil(rest / per_wagon - 1e-9))
    load = rest / count - wagon.mass_t
    entries = list(base.vehicles)
    entries[w] = ConsistEntry(type=entry.type, count=count, load_t=round(load, 6))
    names = " + ".join(f"{e.count} x {e.type}" if e.count > 1 else e.type for e in entries)
    return base.model_copy(update={"vehicles": entries, "name": f"{names} ({mass_t:g} t)"})


# ------------------------------------------------------------------------------------------ the command
@dataclass(frozen=True)
class SimulationSpec:
    route_file: Path
    route: Route
    base_consist: Consist
    vehicles: dict[str, Vehicle]
    vehicle_files: dict[str, Path]
    masses_t: tuple[float, ...]
    times_s: tuple[float, ...]
    n_drivers: int = 40
    n_runs: int = 5
    seed: int = 1
    options: ModelOptions = ModelOptions()
    tolerance_s: float | None = None
    start_date: dt.date = dt.date(2024, 1, 1)

    def check(self) -> None:
        """Every count and value inside its bound (``locoplan.bounds``), before any run is simulated."""
        from .. import bounds

        bounds.count(self.n_drivers, "--drivers", 1, 1_000, "simulated drivers")
        bounds.count(self.n_runs, "--runs", 1, 100, "runs per driver at every mass and time")
        logs = self.n_drivers * self.n_runs * len(self.masses_t) * len(self.times_s)
        if logs > MAX_LOGS:
            raise InputError(Problem("<command line>", "--runs", f"drivers x runs x masses x times = {logs:,} logs, more "
                                     f"than the limit of {MAX_LOGS:,} (each is a CSV file)"))
        for m in self.masses_t:
            check_train_mass(m, "--masses")
        for t in self.times_s:
            bounds.planned_time(t, "--times")
        bounds.seed(self.seed)
        if self.tolerance_s is not None:
            bounds.finite(self.tolerance_s, "--tolerance", 0.0, bounds.LIMITS["time_s"][1], "s", "the punctuality window +-")


AIM_SPREAD = 0.9
"""Simulated drivers aim anywhere in T0 +- AIM_SPREAD x the punctuality window (``simulate_logs``)."""


def _check_window(spec: "SimulationSpec", t0: float, fastest_s: float) -> None:
    """The window a planned time ``t0`` is simulated with: below ``t0`` (as a route file's tolerance must be),
    and narrow enough that the earliest aim, t0 - AIM_SPREAD x tolerance, is at least half the fastest run
    (a run is given 3 x its aim to arrive: aims earlier than that are never simulated)."""
    if spec.tolerance_s is not None:
        tol, where, field = spec.tolerance_s, "<command line>", "--tolerance"
    elif spec.route.schedule is not None:
        tol, where, field = spec.route.schedule.tolerance_s, str(spec.route_file), "schedule.tolerance_s"
    else:
        return
    if tol >= t0:
        raise InputError(Problem(where, field, f"a punctuality window of +-{tol:g} s is not below the planned running "
                                 f"time {t0:g} s: the window would open at or before departure"))
    earliest = t0 - AIM_SPREAD * tol
    if earliest < 0.5 * fastest_s:
        most = math.floor((t0 - 0.5 * fastest_s) / AIM_SPREAD * 10) / 10
        raise InputError(Problem(where, field, f"a punctuality window of +-{tol:g} s at {t0:g} s: the simulated drivers aim "
                                 f"as early as {t0:g} - {AIM_SPREAD:g} x {tol:g} = {earliest:.1f} s, less than half the "
                                 f"fastest possible run ({fastest_s:.1f} s), and no run that early is simulated; "
                                 f"give a window of at most {most:g} s"))


MAX_LOGS = 20_000
"""Logs one ``drivers simulate`` writes at most (40 drivers x 5 runs x 100 groups)."""


def check_train_mass(mass_t: float, option: str) -> float:
    """A whole train's mass from the command line: finite and no heavier than the heaviest train ever run."""
    from .. import bounds
    from ..model.consist import PLAUSIBLE

    return bounds.finite(mass_t, option, 0.0, PLAUSIBLE["train_mass_t"], "t",
                         "the heaviest train ever run weighed 99,734 t", lo_open=True)


@dataclass(frozen=True)
class SimulatedLogs:
    """What ``simulate_logs`` made, as data (``reporting/logs.py`` writes it as a log folder)."""

    logs: dict[str, LogData]  # relative path of each log CSV -> its columns
    consists: dict[str, Consist]  # relative path of each consist file -> the consist resized to that mass
    manifest: dict  # manifest.yaml's content (schema locoplan/driver-logs@1)
    driver_ids: list[str]
    driver_rows: list[dict]  # each driver's habits (DriverParams.rows)
    groups: list[dict]  # per mass and time: drivers' mean / min / max energy and time, late runs

    @property
    def n_runs(self) -> int:
        return len(self.manifest["runs"])


def simulate_logs(spec: SimulationSpec, progress=None, sink=None) -> SimulatedLogs:
    """Simulate ``n_drivers`` drivers x ``n_runs`` runs for every mass and planned time: the logs, the
    consists and the manifest as data (nothing is written here). With ``sink``, each log is handed to
    ``sink(relative path, log)`` as soon as it is made and not kept (``SimulatedLogs.logs`` is then empty):
    memory stays one block of runs' (``drive_to_schedule``) whatever the number of logs."""
    spec.check()
    rng = np.random.default_rng(spec.seed)
    drivers = draw_drivers(spec.n_drivers, rng)
    ids = [f"D{i + 1:02d}" for i in range(spec.n_drivers)]
    tol = spec.tolerance_s
    logs: dict[str, LogData] = {}
    consists: dict[str, Consist] = {}
    runs_meta: list[dict] = []
    groups: list[dict] = []
    day = 0
    for mass in spec.masses_t:
        consist = consist_for_mass(spec.base_consist, spec.vehicles, mass)
        train = build_train(consist, spec.vehicles, "--masses")
        calc = TractionCalculator(spec.route, train, spec.options)
        tables = route_tables(calc)
        cname = f"consists/m{mass:g}.yaml"
        consists[cname] = consist
        for t0 in spec.times_s:
            if t0 < calc.fastest_time_s:
                raise InputError(Problem("<command line>", "--times", f"{t0:g} s is below the fastest possible run of "
                                         f"{train.name} on '{spec.route.name}', {calc.fastest_time_s:.1f} s"))
            _check_window(spec, t0, calc.fastest_time_s)
        # every driver's runs at every planned time of this mass, as one search (made a block at a time)
        per_time = spec.n_drivers * spec.n_runs
        idx = np.tile(np.repeat(np.arange(spec.n_drivers), spec.n_runs), len(spec.times_s))
        planned = np.repeat(np.asarray(spec.times_s, float), per_time)
        tol_s = np.array([tol if tol is not None else (spec.route.schedule.tolerance_s if spec.route.schedule else 0.01 * x)
                          for x in planned])
        p = jitter(drivers.take(idx), rng)
        aim = planned + tol_s * np.clip(p.punctuality_bias + 0.3 * rng.standard_normal(len(idx)), -AIM_SPREAD, AIM_SPREAD)
        n_steps = int(math.ceil(3.0 * float(aim.max()) / DT_S))
        noise = SpeedNoise(rng, p.noise_kmh, n_steps, block_runs(n_steps, 8))
        if progress:
            progress(f"{mass:g} t, {len(idx)} runs")  # one batch per mass: all its drivers, runs and times
        energy, times = np.zeros(len(idx)), np.zeros(len(idx))

        def keep(r: int, log: LogData) -> None:
            nonlocal day
            d, t0, rep = idx[r], planned[r], r % spec.n_runs + 1
            name = f"logs/{ids[d]}-m{mass:g}-t{t0:g}-r{rep}.csv"
            energy[r], times[r] = log.traction_energy_kwh, log.running_time_s
            if sink is None:
                logs[name] = log
            else:
                sink(name, log)
            runs_meta.append({"log": name, "driver_id": ids[d], "consist": cname, "mass_t": float(mass),
                              "scheduled_time_s": float(t0), "actual_time_s": round(float(log.running_time_s), 1),
                              "date": spec.start_date + dt.timedelta(days=day)})
            day += 1

        _, out = drive_to_schedule(calc, tables, p, aim, noise, keep=keep)
        bad = [(ids[idx[r]], out.failure[r]) for r in range(len(idx)) if out.failure[r]]
        if bad:  # a simulator defect, never a user's mistake: say which run and why
            raise RuntimeError(f"driver simulator: {len(bad)} run(s) failed on '{spec.route.name}' at {mass:g} t, "
                               f"e.g. driver {bad[0][0]}: {bad[0][1]}")
        for j, t0 in enumerate(spec.times_s):
            sel = slice(j * per_time, (j + 1) * per_time)
            e, tj = energy[sel], times[sel]
            tol_j = tol_s[j * per_time]
            groups.append({"mass_t": float(mass), "scheduled_time_s": float(t0), "runs": per_time,
                           "mean_energy_kwh": round(float(e.mean()), 2), "min_energy_kwh": round(float(e.min()), 2),
                           "max_energy_kwh": round(float(e.max()), 2), "mean_time_s": round(float(tj.mean()), 1),
                           "late_runs": int(np.sum(tj > t0 + tol_j)), "early_runs": int(np.sum(tj < t0 - tol_j))})
    manifest = {"schema": "locoplan/driver-logs@1", "route": "route.yaml", "synthetic": True,
                "generator": {"name": SIMULATOR, "version": __version__, "seed": int(spec.seed)},
                "notes": (f"SYNTHETIC: {spec.n_drivers} simulated drivers x {spec.n_runs} runs per mass and time, "
                          f"made by {SIMULATOR} (locoplan {__version__}), not recorded on a real train"),
                "runs": runs_meta}
    return SimulatedLogs(logs, consists, manifest, ids, drivers.rows(), groups)
