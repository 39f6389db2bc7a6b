"""Batch traction calculator: integrates many plans at once along distance (the ISSA paper's section 1; DESIGN).

Train dynamics in distance form, with e = v^2 / 2 [m^2/s^2]:

    d e / d s = (F - B - R(v) - G(s)) / (M (1 + gamma))

F traction, B braking, R basic resistance, G gravity on the equivalent gradient [kN]; M mass [t];
gamma the rotating-mass allowance (0 by default). Plans share one condition sequence and differ in
their switching positions; they are the rows of every array, so one step of the loop below advances
the whole batch with a handful of numpy calls.

Why it is accurate on a coarse grid:
- the grid contains every route breakpoint, so each cell has one gradient and one limit, and the
  cell's gravity term is its exact mean (the work of gravity is exact);
- a switching point inside a cell splits the cell by fraction, so time and energy are continuous
  in the switching positions (the optimiser sees a smooth landscape, not 20 m stairs);
- forces are taken at the cell's extrapolated mid-speed (second order), and time uses
  dt = 2 ds / (v0 + v1), exact for constant acceleration, including when the train starts or stops;
- reaching a limit or a braking curve inside a cell is located by intersecting the two straight
  lines in e(s), and the time of both parts is added exactly;
- the braking envelope (backward braking curves from every limit drop and from the stop) is
  plan-independent and integrated once per route with fine sub-steps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from .. import bounds
from ..errors import InputError, Problem
from ..model.conditions import CODE
from ..model.route import Route
from ..model.train import Train, shorter_than_train
from ..physics.braking import full_brake_kn
from ..physics.couplers import (CouplerBound, VehicleLine, coupler_bound, coupler_forces_kn, force_rate_kn_per_s,
                                vehicle_gravity_kn)
from ..physics.energy import recovered_energy_kwh
from ..physics.gradient import equivalent_gradient_permille
from ..physics.resistance import train_resistance_kn
from ..physics.traction import gradient_force_kn, max_force_kn
from ..physics.units import kinetic_e, kmh, kmh_from_e, kwh, ms, ms_from_e
from .constants import ARRIVE_AFTER_S, E_FLOOR, ELECTRIC_CURVE_SHARE
from .defaults import DEFAULT_STEP_M
from .native import kernels
from .records import Cells, Forces, Outputs, Plans, contiguous
from .result import (AIR_HELD, AIR_RECHARGE, CANNOT_HOLD, COUPLER_LIMIT, FORCE_RATE, IMPOSSIBLE, LIMIT_EXCEEDED, NEVER_ARRIVED, OK,
                     STALLED, STOPPED_SHORT, BatchResult, Profile)


ENVELOPE_SUBSTEPS = 20
"""Sub-steps per cell for the braking envelope (computed once per route, so it can afford them)."""

_interp = np.interp  # numpy's public interp (its private compiled core saved a third of it, but is not an API)



@dataclass(frozen=True)
class ModelOptions:
    """Switches of the train model.

    step_m: grid spacing [m].
    point_mass: the papers' point mass at the head. By default the train is a strip of its real
    length: the equivalent gradient is averaged over the train, a speed limit holds until the tail
    has cleared it, and a neutral section cuts traction until the tail has left it.
    air_brake: brake with the wagons' air brakes (at the consist's service coefficient) on top of the
    locomotives' electric brake; False = electric brake alone, as the papers do.
    rotating_mass: gamma, a uniform rotating-mass allowance (inertial mass = M (1 + gamma)); None =
    each vehicle's own ``rotating_mass_factor`` (1 when the file gives none, as in the papers).
    strict_limits: a plan that coasts (or cruises) up to a limit is infeasible, instead of being held
    at the limit by braking as a driver or speed supervision would (the default). Either way a plan is
    infeasible where even full braking cannot hold the limit.
    air_cycle: with the air brake, brake with it as the wagons' direct-release valves do (applied, held,
    released in full, recharged: ``Train.air_cycle``; docs/model.md); False = the air brake as a force the
    plan may modulate at will (the relaxation E* is computed with).
    """

    step_m: float = DEFAULT_STEP_M
    point_mass: bool = False
    air_brake: bool = True
    rotating_mass: float | None = None
    strict_limits: bool = False
    air_cycle: bool = True

    @property
    def strip(self) -> bool:
        """The train-length-aware (strip) model is on."""
        return not self.point_mass

    @classmethod
    def papers(cls, **kw) -> "ModelOptions":
        """The papers' train model (``--point-mass``): point mass, electric brake alone."""
        return cls(point_mass=True, air_brake=False, **kw)


def late_enough(v, d: float, a, t_need: float) -> np.ndarray:
    """``kernel.late_enough`` for arrays of speeds ``v`` [m/s] and decelerations ``a`` [m/s^2] (the same
    arithmetic): whether the electric brake can slow the train enough to cover ``d`` [m] in no less than
    ``t_need`` [s]."""
    v, a = np.broadcast_arrays(np.asarray(v, dtype=float), np.asarray(a, dtype=float))
    with np.errstate(divide="ignore", invalid="ignore"):
        slowest = (v - np.sqrt(np.maximum(v * v - 2.0 * a * d, 0.0))) / a
    return np.where(a <= 0.0, d >= v * t_need - 0.5 * a * t_need * t_need, (v * v <= 2.0 * a * d) | (slowest >= t_need))


def neutral_spans_m(route: Route, train_length_m: float = 0.0) -> list[tuple[float, float]]:
    """Head positions where traction is cut for each neutral section [m]: from ``coast_before_s``
    before the head enters until ``coast_after_s`` after the tail (``train_length_m`` behind the head)
    has left, the times converted to distance at the line's speed limit there (a slower train covers
    less ground in that time, so the span is conservative)."""
    sl = route.speed_limits
    starts = np.array([x.from_m for x in sl])

    def limit_ms(x: float) -> float:
        i = int(np.clip(np.searchsorted(starts, x, side="right") - 1, 0, len(sl) - 1))
        return ms(sl[i].kmh)

    spans = []
    for ns in route.neutral_sections:
        a = ns.from_m - ns.coast_before_s * limit_ms(ns.from_m)
        b = ns.to_m + train_length_m + ns.coast_after_s * limit_ms(min(ns.to_m + train_length_m, route.length_m))
        spans.append((max(a, 0.0), min(b, route.length_m)))
    return spans


def limit_kmh_at(route: Route, s_m, train_length_m: float | None = None) -> np.ndarray:
    """Static speed limit [km/h] at head positions ``s_m``. With ``train_length_m`` (the strip model)
    the lowest limit under the train: a drop counts from where the head reaches it, a rise only once
    the tail has cleared the restriction. ``None``: the point mass at the head."""
    s_m = np.asarray(s_m, dtype=float)
    sl = route.speed_limits
    starts = np.array([x.from_m for x in sl])
    kmh = np.array([x.kmh for x in sl])
    idx = np.clip(np.searchsorted(starts, s_m, side="right") - 1, 0, len(sl) - 1)
    lim = kmh[idx]
    if train_length_m is not None:
        tail = s_m - train_length_m
        for x in sl:  # a rise counts only once the tail has cleared the restriction
            under = (x.from_m < s_m) & (x.to_m > tail)
            lim = np.where(under, np.minimum(lim, x.kmh), lim)
    return lim


DEPARTURE_GRADING_M = 200.0
DEPARTURE_NODES = 14
"""The grid's cells shrink quadratically towards the departure: nodes at (j / n)^2 x ``DEPARTURE_GRADING_M``
(at most a quarter of the line), j = 1 .. ``DEPARTURE_NODES``, the first cell about 1 m. A cell integrates a
plan's conditions as one blend of their forces (``kernel.run_plans``), which is second order in the cell's
length at speed; but from rest the train covers a cell's first metres slowly, and a departure that powers
for a few metres and coasts (a start on a falling line) was timed tens of seconds slow on a 40 m cell (8 m of
traction blended over 40 m: 51 s to 40 m, 31 s when the traction comes first). Near rest the cells are now
as short as the switches there need."""


def departure_nodes_m(length_m: float) -> np.ndarray:
    """The departure's graded nodes [m] (``DEPARTURE_GRADING_M``)."""
    span = min(DEPARTURE_GRADING_M, 0.25 * length_m)
    return (np.arange(1, DEPARTURE_NODES + 1) / DEPARTURE_NODES) ** 2 * span


MERGED_ENDS_PER_CELL = 5
"""Section ends per cell above which they are merged into the cells (``_grid``)."""


def _section_ends_m(route: Route, train: Train, options: ModelOptions) -> np.ndarray:
    """Where the equivalent gradient changes (or, in strip mode, bends): the ends of the gradient sections, curves
    and tunnels, a short curve's spread over one train length, and in strip mode each of these one train length on."""
    points = [x for sections in (route.gradients, route.curves, route.tunnels) for sec in sections
              for x in (sec.from_m, sec.to_m)]
    points += [c.from_m + train.length_m for c in route.curves]  # the pattern-curve patent's claim 6: a short curve is spread
    if options.strip:  # over one train length
        points += [p + train.length_m for p in list(points)]
    return np.unique(np.clip(points, 0.0, route.length_m))


def _grid(route: Route, train: Train, options: ModelOptions, extra_nodes_m=None,
          graded: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Node positions: a uniform grid merged with every route breakpoint (and +L in strip mode), with ``graded``
    the departure's graded nodes (``DEPARTURE_GRADING_M``), and ``extra_nodes_m`` if given.

    On a line whose gradient, curve and tunnel sections are on average shorter than a fifth of a cell (more
    than ``MERGED_ENDS_PER_CELL`` of their ends per cell: 10 m at the default 50 m step, where validate warns),
    those ends are not made nodes: the cells take the exact mean of the equivalent gradient over them instead
    (returned as the second value, the section ends to integrate over; None: every end is a node), so that the
    grid's size, and every method's cost, stays within a few times the uniform grid's, whatever the number of
    sections."""
    L = route.length_m
    n = max(1, math.ceil(L / options.step_m - 1e-9))
    ends = _section_ends_m(route, train, options)
    # (the line's own sections decide, not the train or the model: the same line is merged for every train)
    own = {x for sections in (route.gradients, route.curves, route.tunnels) for sec in sections for x in (sec.from_m, sec.to_m)}
    dense = len(own) > MERGED_ENDS_PER_CELL * n
    points = [0.0, L, *(departure_nodes_m(L) if graded else ())]
    for sec in route.speed_limits:
        points += [sec.from_m, sec.to_m]
    for a, b in neutral_spans_m(route, train.length_m if options.strip else 0.0):
        points += [a, b]
    if options.strip:
        points += [p + train.length_m for p in list(points)]
    if not dense:
        points += list(ends)
    if extra_nodes_m is not None:
        points += list(np.asarray(extra_nodes_m, dtype=float))
    s = np.union1d(np.linspace(0.0, L, n + 1), np.clip(points, 0.0, L))
    keep = np.concatenate([[True], np.diff(s) > 1e-6])
    s = s[keep]
    s[-1] = L
    return s, (ends if dense else None)


class TractionCalculator:
    """Route + train + model options, with everything plan-independent precomputed.

    ``evaluate(conditions, switches_m)`` runs a batch; see its docstring.
    """

    def __init__(self, route: Route, train: Train, options: ModelOptions | None = None,
                 extra_nodes_m: np.ndarray | None = None, graded_departure: bool = True):
        self.route, self.train = route, train
        self.options = options or ModelOptions()
        if train.length_m >= route.length_m:  # first: a grid message would not say what is wrong
            raise InputError(shorter_than_train(route, train, f"route '{route.name}'"))
        bounds.step(self.options.step_m, route.length_m)
        # braking: the locomotives' electric brake needs the catenary (none in a neutral section's span,
        # where the main breaker is open, as for traction); the wagons' air brake works everywhere
        self.electric_brake_speed_kmh, self.electric_brake_kn = train.brake_curve(air=False)
        self.air_brake_speed_kmh, self.air_brake_kn = ((train.air_brake_speed_kmh, train.air_brake_kn)
                                                       if self.options.air_brake else (np.array([0.0, 1.0]), np.zeros(2)))
        self.air_cycle = (train.air_cycle if self.options.air_brake and self.options.air_cycle
                          and float(np.max(train.air_brake_kn, initial=0.0)) > 0 else None)
        """The air brake's cycle the plans are run with (``Train.air_cycle``), None: none (the electric brake
        alone, or the air brake as a continuous force)."""
        gamma = self.options.rotating_mass
        self.m_eff_t = train.inertial_mass_t if gamma is None else train.mass_t * (1.0 + gamma)
        self.forces = contiguous(Forces(self.m_eff_t, train.traction_speed_kmh, train.traction_kn,
                                        self.electric_brake_speed_kmh, self.electric_brake_kn, self.air_brake_speed_kmh,
                                        self.air_brake_kn, *train.resistance_kn))
        """The train's force model as the compiled loops take it (``records.Forces``)."""
        s, self._merged_ends_m = _grid(route, train, self.options, extra_nodes_m, graded_departure)
        self._build(s)
        kinks = self._braking_curve_entries()
        if kinks.size:  # make every braking-curve entry a node, then rebuild on the finer grid
            s = np.union1d(s, kinks)
            s = s[np.concatenate([[True], np.diff(s) > 1e-6])]
            self._build(s)

    def _build(self, s: np.ndarray) -> None:
        route, train = self.route, self.train
        self.s_m = s
        self.h_m = np.diff(s)
        mid = 0.5 * (s[1:] + s[:-1])
        # Cell means: the point gradient is constant in each cell, the strip gradient linear, so the
        # midpoint value is the exact mean in both modes; where section ends lie inside cells (a line of sections
        # shorter than a cell, ``_grid``), the mean over the pieces between them, exact the same way
        self.gradient_permille = self._cell_mean_gradient(s, self._merged_ends_m)
        self.limit_kmh = np.minimum(self._limit_at(mid), train.max_speed_kmh)
        self.gravity_kn = gradient_force_kn(self.gradient_permille, train.mass_t)
        # the air brake's build-up time of an application made in each cell [s]
        self.t_build_s = (self.air_cycle.build_up_s(self.gradient_permille) if self.air_cycle is not None
                          else np.zeros(len(mid)))
        # 1.0 where traction is allowed, 0.0 in neutral sections and their coasting margins
        self.traction_allowed = np.ones(len(mid))
        for a, b in neutral_spans_m(route, train.length_m if self.options.strip else 0.0):
            self.traction_allowed[(mid > a) & (mid < b)] = 0.0
        # the first cell from each on whose grade the electric brake alone cannot hold the limit (-1: none): an
        # application is not released ahead of one the train would reach within the recharge time
        lim = self.limit_kmh
        short = (max_force_kn(lim, self.electric_brake_speed_kmh, self.electric_brake_kn) * self.traction_allowed
                 + train_resistance_kn(lim, train.resistance_kn) + self.gravity_kn) < 0.0
        self._short_at_limit = short
        idx = np.where(short, np.arange(len(mid)), len(mid))
        nxt = np.minimum.accumulate(idx[::-1])[::-1]
        self.next_short = np.where(nxt < len(mid), nxt, -1).astype(np.int64)
        e_cell = kinetic_e(self.limit_kmh)
        self.e_limit_cell = e_cell
        self.e_limit_node = np.minimum(np.concatenate([[e_cell[0]], e_cell]), np.concatenate([e_cell, [e_cell[-1]]]))
        self.e_limit_node[-1] = 0.0  # the train stops at the end
        # cells where full braking holds the limit (else the envelope below them is the speed from which
        # full braking reaches the limit no earlier than where braking can hold again)
        lim_kmh = kmh_from_e(e_cell)
        cells = np.arange(len(mid))
        self.brake_holds_limit = (self.brake_kn_at(lim_kmh, cells) + train_resistance_kn(lim_kmh, train.resistance_kn)
                                  + self.gravity_kn) >= 0.0
        self.e_envelope, self._entry_m = self._braking_envelope()
        # the electric brake's own braking curves: what a train whose air brake recharges may follow
        self.e_envelope_el = (self._braking_envelope(electric_only=True)[0] if self.air_cycle is not None
                              else np.full(len(s), np.inf))
        self.next_air_curve = self._next_air_curve()
        if self._electric_first():
            self.next_air_curve = self._next_air_curve()
        # cells whose cap is the limit itself (a speed to hold), not a braking curve falling to a drop
        self.holds_limit = (self.e_envelope[1:] >= e_cell * (1 - 1e-9)) & self.brake_holds_limit
        self.impossible = self._impossible_descent()
        self.cells = self._cells(self.e_envelope, self.holds_limit)
        """The grid as the compiled loops take it."""

    def _cell_mean_gradient(self, s: np.ndarray, ends_m: np.ndarray | None) -> np.ndarray:
        """The equivalent gradient's mean over each cell between nodes ``s`` [per mille]: at the cell's midpoint, or,
        with section ends ``ends_m`` inside the cells, summed over the pieces between them (each piece's midpoint
        value is its exact mean: constant in the point model, linear in the strip model)."""
        route, train, strip = self.route, self.train, self.options.strip
        if ends_m is None:
            return equivalent_gradient_permille(route, 0.5 * (s[1:] + s[:-1]), train.length_m, strip)
        cuts = np.union1d(s, ends_m)
        cuts = cuts[np.concatenate([[True], np.diff(cuts) > 1e-9])]
        cuts[-1] = s[-1]
        piece = np.diff(cuts)
        g = equivalent_gradient_permille(route, 0.5 * (cuts[1:] + cuts[:-1]), train.length_m, strip)
        first = np.minimum(np.searchsorted(cuts, s[:-1] - 1e-9), len(piece) - 1)  # each cell's first piece
        return np.add.reduceat(g * piece, first) / np.diff(s)

    def _cells(self, e_env: np.ndarray, holds_limit: np.ndarray, brake_holds: np.ndarray | None = None) -> Cells:
        e_el, nxt = getattr(self, "e_envelope_el", None), getattr(self, "next_air_curve", None)
        return contiguous(Cells(self.s_m, self.h_m, e_env, self.e_limit_node, self.e_limit_cell, self.traction_allowed,
                                self.gravity_kn, holds_limit, self.brake_holds_limit if brake_holds is None else brake_holds,
                                self.t_build_s, self.next_short, np.full(len(self.s_m), np.inf) if e_el is None else e_el,
                                np.full(len(self.h_m), -1, dtype=np.int64) if nxt is None else nxt))

    def _electric_first(self) -> bool:
        """Where a braking curve that needs the air brake (to a lower limit) ends so near the next one (another
        drop, the stop) that the brake could not recharge in between -- the next begins within the distance
        covered at the lower limit in the recharge time, and 90 % of the electric brake cannot slow the train
        enough to reach it after the recharge (``late_enough``) -- the first drop is braked on the electric
        brake's own curve to its lower limit instead (``_electric_curve_to``): the envelope there becomes the lower
        of the two, from where that curve leaves it, so that no release comes just before the next curve. (The
        curve to that drop alone: the electric brake's envelope of everything ahead holds, on a descent it can
        barely hold, the crawl from which it could stop the train by itself, far under the limit the drop
        needs.) Returns whether the envelope changed."""
        if self.air_cycle is None:
            return False
        n = len(self.h_m)
        on = self.next_air_curve == np.arange(n)  # cells on a curve that needs the air brake
        if not on.any():
            return False
        s, env = self.s_m, self.e_envelope
        t_rec = self.air_cycle.recharge_s
        ends = np.flatnonzero(on[:-1] & ~on[1:]) + 1  # the first cell after each run of such cells
        changed = False
        for b in ends:
            j = int(self.next_air_curve[b])
            if j < 0:
                continue
            v = float(ms_from_e(self.e_limit_cell[b]))
            d = float(s[j] - s[b])
            if d >= v * t_rec:
                continue
            if late_enough(v, d, float(self.electric_decel(kmh(v), b)), t_rec + ARRIVE_AFTER_S):
                continue
            curve = self._electric_curve_to(int(b), float(env[b]))
            z = b
            while z > 0 and curve[z - 1] < env[z - 1] * (1 - 1e-9):
                z -= 1
            if z < b:
                env[z:b + 1] = np.minimum(env[z:b + 1], curve[z:b + 1])
                changed = True
        return changed

    def _electric_curve_to(self, b: int, e_b: float) -> np.ndarray:
        """The braking curve (as e per node) that ``ELECTRIC_CURVE_SHARE`` of the electric brake follows to ``e_b`` at
        node ``b`` alone: the electric brake's own envelope (``_braking_envelope``) with no limit after node ``b``
        (inf there, and where no curve is traced back through a grade the electric brake cannot hold)."""
        limit_node, limit_cell = self.e_limit_node.copy(), self.e_limit_cell.copy()
        limit_node[b] = min(limit_node[b], e_b)
        limit_node[b + 1:] = np.inf
        limit_cell[b:] = np.inf
        return self._braking_envelope(electric_only=True, limit_node=limit_node, limit_cell=limit_cell)[0]

    def electric_decel(self, v_kmh, k):
        """-de/ds [m/s^2] at ``v_kmh`` in cell(s) ``k`` under ``ELECTRIC_CURVE_SHARE`` of the electric brake (cut
        in a neutral section's span), with resistance and gravity: how the electric brake's own braking curves
        fall (the compiled loops: (ELECTRIC_CURVE_SHARE x b_el + load) / m)."""
        return (ELECTRIC_CURVE_SHARE * max_force_kn(v_kmh, self.electric_brake_speed_kmh, self.electric_brake_kn)
                * self.traction_allowed[k] + train_resistance_kn(v_kmh, self.train.resistance_kn)
                + self.gravity_kn[k]) / self.m_eff_t

    def _next_air_curve(self) -> np.ndarray:
        """Per cell, the first cell from it on (-1: none) where a braking curve of the envelope falls faster than
        ``ELECTRIC_CURVE_SHARE`` of the electric brake follows (with the air brake's cycle; else all -1): a train
        whose air brake recharges and that would reach it before the recharge is over follows the electric
        brake's own curves instead (``kernel.run_plans``)."""
        n = len(self.h_m)
        if self.air_cycle is None:
            return np.full(n, -1, dtype=np.int64)
        e0, e1 = self.e_envelope[:-1], self.e_envelope[1:]
        falls = (e0 - e1) / self.h_m  # -de/ds along the envelope [m/s^2]
        air = (e1 < e0 * (1 - 1e-9)) & (falls > self.electric_decel(kmh_from_e(0.5 * (e0 + e1)), np.arange(n)))
        idx = np.where(air, np.arange(n), n)
        nxt = np.minimum.accumulate(idx[::-1])[::-1]
        return np.where(nxt < n, nxt, -1).astype(np.int64)

    # ----------------------------------------------------------------- route precomputation
    def _limit_at(self, s_m: np.ndarray) -> np.ndarray:
        """Static speed limit [km/h] at head positions; in strip mode the lowest under the train."""
        return limit_kmh_at(self.route, s_m, self.train.length_m if self.options.strip else None)

    def brake_kn_at(self, v_kmh, k):
        """Max braking force [kN] at ``v_kmh`` in cell ``k``: the electric brake where traction is allowed
        (it needs the catenary) plus the air brake (everywhere, with the air-brake model)."""
        return full_brake_kn(max_force_kn(v_kmh, self.electric_brake_speed_kmh, self.electric_brake_kn),
                             max_force_kn(v_kmh, self.air_brake_speed_kmh, self.air_brake_kn), self.traction_allowed[k])

    def forces_kn(self, v_ms: np.ndarray, k: int | np.ndarray):
        """(max traction, max braking, resistance + gravity) [kN] at speed ``v_ms`` in cell ``k`` (traction
        and the electric brake cut in a neutral section's span)."""
        v_kmh = kmh(v_ms)
        return (max_force_kn(v_kmh, self.train.traction_speed_kmh, self.train.traction_kn) * self.traction_allowed[k],
                self.brake_kn_at(v_kmh, k),
                train_resistance_kn(v_kmh, self.train.resistance_kn) + self.gravity_kn[k])

    def recovered_energy_kwh(self, v_nodes_kmh: np.ndarray, brake_kn: np.ndarray) -> np.ndarray:
        """Energy the electric brake returns to the line [kWh] on runs given by their node speeds and cell
        braking forces ((plans, nodes) and (plans, cells)): the train's ``regen_efficiency`` times the
        electric part of the braking work, the electric brake cut where the catenary is (physics.energy).
        Zero for a train whose locomotives do not regenerate (nothing is computed), NaN for a failed run."""
        if self.train.regen_efficiency <= 0:
            return np.where(np.isnan(brake_kn).any(axis=-1), np.nan, 0.0)
        v_mid = 0.5 * (v_nodes_kmh[:, 1:] + v_nodes_kmh[:, :-1])
        electric = max_force_kn(v_mid, self.electric_brake_speed_kmh, self.electric_brake_kn) * self.traction_allowed
        return recovered_energy_kwh(self.s_m, brake_kn, electric, self.train.regen_efficiency)

    # ----------------------------------------------------------------- couplers
    @cached_property
    def vehicle_line(self) -> VehicleLine | None:
        """The train vehicle by vehicle (``physics.couplers``), None for a train of one vehicle."""
        layout = self.train.layout
        if sum(g.count for g in layout) < 2:
            return None
        return VehicleLine.from_layout(layout, self.options.rotating_mass)

    @cached_property
    def vehicle_gravity_kn(self) -> np.ndarray:
        """Gravity on every vehicle [kN] (cells, vehicles), the head at each cell's middle."""
        return vehicle_gravity_kn(self.route, self.vehicle_line, 0.5 * (self.s_m[1:] + self.s_m[:-1]))

    @cached_property
    def coupler_bound(self) -> CouplerBound:
        """A cheap bound on the largest coupler force in each cell (``physics.couplers.CouplerBound``)."""
        return coupler_bound(self.vehicle_line, self.vehicle_gravity_kn, float(self.train.max_speed_kmh))

    @property
    def checks_forces(self) -> bool:
        """The consist limits its coupler forces or its force rate: every plan is checked against them."""
        return self.vehicle_line is not None and (self.train.coupler_limit_kn is not None
                                                  or self.train.force_rate_limit_kn_per_s is not None)

    def coupler_extremes(self, v_nodes_kmh: np.ndarray, traction_kn: np.ndarray, brake_kn: np.ndarray):
        """(tension, compression) [kN], each (plans, cells) >= 0: the largest tensile and compressive force in
        any coupler in each cell of runs given by their node speeds and cell forces (``physics.couplers``,
        the electric brake cut where the catenary is); NaN where a failed run has no forces."""
        line, gravity = self.vehicle_line, self.vehicle_gravity_kn
        v = np.atleast_2d(v_nodes_kmh)
        tension = np.full(traction_kn.shape, np.nan)
        compression = np.full(traction_kn.shape, np.nan)
        for i in range(traction_kn.shape[0]):
            v_mid = 0.5 * (v[i, 1:] + v[i, :-1])
            ok = np.isfinite(traction_kn[i]) & np.isfinite(brake_kn[i]) & np.isfinite(v_mid)
            c = coupler_forces_kn(line, traction_kn[i, ok], brake_kn[i, ok], v_mid[ok], gravity[ok],
                                  self.traction_allowed[ok])
            tension[i, ok] = np.maximum(c.max(axis=1), 0.0)
            compression[i, ok] = np.maximum(-c.min(axis=1), 0.0)
        return tension, compression

    def _force_failures(self, t_nodes, v_nodes, trac, brk, ok):
        """Plans (where ``ok``) refused by the consist's limits: (reason code, cell, the force or rate) per plan,
        code OK where none is broken. The first cell where a limit is broken decides. The coupler forces are
        computed only for the plans whose cheap bound (``coupler_bound``) reaches the limit somewhere."""
        n, n_cells = trac.shape
        code = np.full(n, OK, dtype=np.int8)
        cell = np.full(n, n_cells, dtype=np.int64)
        value = np.full(n, np.nan)
        lim_c, lim_r = self.train.coupler_limit_kn, self.train.force_rate_limit_kn_per_s
        suspect = np.zeros(n, dtype=bool)
        if lim_c is not None and ok.any():
            v_mid = 0.5 * (v_nodes[:, 1:] + v_nodes[:, :-1])
            electric = np.minimum(brk, max_force_kn(v_mid, self.electric_brake_speed_kmh, self.electric_brake_kn)
                                  * self.traction_allowed)
            with np.errstate(invalid="ignore"):
                suspect = ok & np.any(self.coupler_bound.kn(trac, electric, brk - electric) > lim_c, axis=1)
        for i in np.flatnonzero(ok):
            if suspect[i]:
                tension, compression = self.coupler_extremes(v_nodes[i:i + 1], trac[i:i + 1], brk[i:i + 1])
                tension, compression = tension[0], compression[0]
                over = np.flatnonzero((tension > lim_c) | (compression > lim_c))
                if over.size:
                    k = int(over[0])
                    code[i], cell[i] = COUPLER_LIMIT, k
                    value[i] = tension[k] if tension[k] > lim_c else -compression[k]
            if lim_r is not None:
                rate = force_rate_kn_per_s(t_nodes[i], trac[i] - brk[i])
                over = np.flatnonzero(rate > lim_r)
                if over.size and over[0] + 1 < cell[i]:
                    k = int(over[0]) + 1  # the cell the jump arrives in
                    code[i], cell[i], value[i] = FORCE_RATE, k, rate[k - 1]
        return code, cell, value

    def _braking_envelope(self, electric_only: bool = False, limit_node: np.ndarray | None = None,
                          limit_cell: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Highest e at each node from which max braking still respects every later limit and stops at
        the end: backward integration (RK2, fine sub-steps) from each limit drop and from the stop.

        Also returns the positions where a braking curve rises through its cell's limit inside a cell
        (the braking-curve entry points), so that they can be made grid nodes.

        ``electric_only``: the electric brake's own envelope, the braking curves it follows alone (where
        traction is allowed); inf on the grades it cannot hold at the limit and at their start nodes (there
        the air brake cycles, ``kernel.run_plans``), no curve traced back through them; built on
        ``ELECTRIC_CURVE_SHARE`` of the electric brake's force. ``limit_node``, ``limit_cell``: the limits (as e) to
        brake for instead of the route's (inf: none), e.g. one drop alone (``_electric_curve_to``).
        """
        lim_node = self.e_limit_node if limit_node is None else limit_node
        lim_cell = self.e_limit_cell if limit_cell is None else limit_cell
        n_sub = ENVELOPE_SUBSTEPS
        forces, holds_all = self.forces, self.brake_holds_limit
        reset = np.zeros(len(self.h_m), dtype=np.int64)
        if electric_only:
            forces = forces._replace(af=np.zeros_like(forces.af), ef=ELECTRIC_CURVE_SHARE * forces.ef)
            holds_all = ~self._short_at_limit
            reset = self._short_at_limit.astype(np.int64)
        e_env = np.empty_like(lim_node)
        found = np.empty(len(self.h_m))
        cells = contiguous(self._cells(lim_node, holds_all, holds_all)._replace(  # (e_env, holds_limit not read)
            e_limit_node=lim_node, e_limit_cell=lim_cell))
        count = kernels().braking_envelope(cells, forces, n_sub, e_env, found, reset)
        return e_env, found[:count].copy()

    def _impossible_descent(self) -> str | None:
        """Why no plan can keep the limits, or None: where the envelope falls to rest before the end, even a
        train entering there at 0 km/h passes a limit under full braking further on. The message gives that
        run's worst excess, found by integrating full braking forwards from rest there."""
        e_env = self.e_envelope
        zero = np.flatnonzero(e_env[:-1] <= E_FLOOR)
        if not zero.size:
            return None
        k0 = int(zero[0])
        # the run from rest starts where full braking cannot even hold a train at rest (above it, on the
        # top of the descent, a standing train stays put)
        k = k0
        while k < len(self.h_m) - 1 and e_env[k] <= E_FLOOR and sum(self.forces_kn(np.float64(0.0), k)[1:]) >= 0.0:
            k += 1
        if e_env[k] <= E_FLOOR:
            k0 = k
        self._impossible_cell = int(zero[0])  # where every plan fails
        n_sub = ENVELOPE_SUBSTEPS
        m = self.m_eff_t
        e, worst = 0.0, (0.0, k0, 0.0)  # (excess [km/h], cell, position [m])
        for k in range(k0, len(self.h_m)):
            accel = lambda e_: -float(sum(self.forces_kn(ms_from_e(max(e_, 0.0)), k)[1:])) / m  # noqa: E731
            d = self.h_m[k] / n_sub
            for i in range(n_sub):
                e = max(e + d * accel(e + 0.5 * d * accel(e)), 0.0)
                excess = kmh_from_e(e) - self.limit_kmh[k]
                if excess > worst[0]:
                    worst = (excess, k, self.s_m[k] + (i + 1) * d)
            if worst[0] > 0 and (kmh_from_e(e) < self.limit_kmh[k]
                                 or (k + 1 < len(self.h_m) and self.brake_holds_limit[k + 1])):
                break  # back under the limit, or at the foot of the descent: the excursion is over
        excess, k, at = worst
        if excess <= 0.0:  # no limit is passed: the stop at the end is what full braking cannot reach
            steepest = k0 + int(np.argmin(self.gradient_permille[k0:]))
            return (f"full braking ({self.brake_kn_at(0.0, steepest):,.0f} kN at rest) cannot stop the train on "
                    f"{self.gradient_permille[steepest]:+.1f} per mille: even entering at 0 km/h at {self.s_m[k0]:,.0f} m, "
                    f"full braking reaches the stop at {self.route.length_m:,.0f} m at {kmh_from_e(e):.1f} km/h")
        lim = float(self.limit_kmh[k])
        steepest = k0 + int(np.argmin(self.gradient_permille[k0:k + 1]))  # the descent's steepest cell
        return (f"full braking ({self.brake_kn_at(lim, steepest):,.0f} kN) cannot hold {lim:g} km/h on "
                f"{self.gradient_permille[steepest]:+.1f} per mille: even entering at 0 km/h at {self.s_m[k0]:,.0f} m, "
                f"full braking reaches {lim + excess:.1f} km/h > {lim:g} km/h at {at:,.0f} m")

    def _braking_curve_entries(self) -> np.ndarray:
        """Braking-curve entry points strictly inside cells (nodes already there are left out)."""
        x = self._entry_m
        if not x.size:
            return x
        # distance to the nearest node by bisection (the nodes are sorted): O(n log n) memory-light,
        # where an (entries x nodes) matrix took a gigabyte on a line of thousands of limits
        s = self.s_m
        i = np.clip(np.searchsorted(s, x), 1, len(s) - 1)
        gap = np.minimum(np.abs(x - s[i - 1]), np.abs(x - s[i]))
        return x[gap > 1e-3]

    @cached_property
    def fastest_time_s(self) -> float:
        """Running time of the fastest run (max traction, held at limits, braking as late as allowed)."""
        res = self.evaluate(("T",), np.zeros((1, 0)))
        return float(res.running_time_s[0])

    def fastest_time_for_factor_s(self, asked: str) -> float:
        """:attr:`fastest_time_s` for a planned time written as a factor of it (``asked``, e.g. ``--time 1.1x``). A line
        the train cannot run at all (it stalls on a climb, no brake holds a descent) has no fastest run, so no factor
        of it: InfeasibleError (exit 1, as any planned time on that line) with the physical reason."""
        fastest = self.fastest_time_s
        if math.isfinite(fastest):
            return fastest
        from ..errors import InfeasibleError

        why = self.evaluate(("T",), np.zeros((1, 0))).reason(0)
        raise InfeasibleError(f"{asked}: a factor of the fastest run, but {self.train.name} cannot run {self.route.name} "
                              f"even at full traction: {why}; no planned time can be kept on this line with this train")

    # ----------------------------------------------------------------- plans

    def evaluate(self, conditions, switches_m, profile: bool = False, cruise_kmh=None,
                 recovered: bool = False, release_margin=None, margin_regions_m=None,
                 couplers: bool = True) -> BatchResult:
        """Integrate a batch of plans.

        conditions: sequence of 'T' | 'K' | 'C' | 'B', shared by every plan; the first starts at 0 m.
        switches_m: (n_plans, len(conditions) - 1) positions [m] where conditions 2.. begin, rising.
        cruise_kmh: optional (n_plans,) cruise speed [km/h] (the ISSA paper's four-stage): traction stops at it
        and cruise holds it, braking if need be (below the limits); coasting is not held to it.
        recovered: compute the energy the electric brake recovers (and so the net energy) without the profile.
        release_margin: optional, where the air brake's cycles release (with ``air_cycle``): the release speed lies
        so far below the apply speed that the train, under the full electric brake, regains the apply speed in
        this many recharge times (``kernel.cycle_speeds``); (n_plans,) for every cycle, or (n_plans, n_regions)
        with ``margin_regions_m`` ((n_regions, 2) spans [from, to) [m], e.g. ``cycle_regions_m``: a cell's cycles
        take the margin of the span holding its midpoint, the rule outside them); None or <= 0: the rule's
        ``CYCLE_MARGIN``.
        couplers: with the profile, each cell's largest coupler forces for the report (the consist's vehicle
        line); False leaves them out of a profile only compared by time and speed (the limits of a consist
        that has them are checked either way).
        Returns running time [s], traction energy sum F ds [kWh], feasibility and its reason per plan,
        and on request the per-cell profile. A consist with a coupler or force-rate limit has every plan
        checked against it (on the profile, computed for that even when not returned).
        """
        conditions = tuple(conditions)
        sw = np.atleast_2d(np.asarray(switches_m, dtype=float))
        if sw.shape[1] != len(conditions) - 1:
            raise InputError(Problem("", "switches_m", f"expected {len(conditions) - 1} switching points per plan, got {sw.shape[1]}"))
        bad = [c for c in conditions if c not in CODE]
        if bad:
            raise InputError(Problem("", "conditions", f"unknown condition {bad[0]!r} (use T, K, C, B)"))
        cap = None
        if cruise_kmh is not None:
            cap = np.ascontiguousarray(kinetic_e(np.broadcast_to(np.asarray(cruise_kmh, dtype=float), (sw.shape[0],))))
        want = profile or recovered or self.checks_forces
        margin, region = self._margins(sw.shape[0], release_margin, margin_regions_m)
        res = self._run_kernel(conditions, sw, want, cap, margin, region)
        if not profile:
            return replace(res, profile=None) if want else res
        if self.vehicle_line is not None and couplers:  # the coupler forces of every cell, for the report
            p = res.profile
            tension, compression = self.coupler_extremes(p.v_kmh, p.traction_kn, p.brake_kn)
            res = replace(res, profile=replace(p, coupler_tension_kn=tension, coupler_compression_kn=compression))
        return res

    def _margins(self, n: int, release_margin, regions_m) -> tuple[np.ndarray, np.ndarray]:
        """The release margins as the loops take them: (n, n_regions + 1), column 0 the rule's (0), and each
        cell's column (0 outside every region)."""
        region = np.zeros(len(self.h_m), dtype=np.int64)
        if release_margin is None:
            return np.zeros((n, 1)), region
        given = np.asarray(release_margin, dtype=float)
        if regions_m is None:
            return np.ascontiguousarray(np.column_stack([np.zeros(n), np.broadcast_to(given.reshape(-1), (n,))])), region + 1
        spans = np.asarray(regions_m, dtype=float).reshape(-1, 2)
        mid = 0.5 * (self.s_m[1:] + self.s_m[:-1])
        for r, (a, b) in enumerate(spans):
            region[(mid >= a) & (mid < b)] = r + 1
        given = np.broadcast_to(given.reshape(given.shape[0] if given.ndim == 2 else 1, -1), (n, len(spans)))
        return np.ascontiguousarray(np.column_stack([np.zeros(n), given])), region

    @cached_property
    def cycle_regions_m(self) -> np.ndarray:
        """Where the air brake cycles (with ``air_cycle``): (n_regions, 2) spans [from, to) [m] of the descents
        whose grade the electric brake alone cannot hold at the limit, one span per descent (two such grades
        less than the recharge time apart at the limit are one descent). An optimiser places each span's release
        speeds (``evaluate(release_margin=, margin_regions_m=)``)."""
        if self.air_cycle is None:
            return np.zeros((0, 2))
        short = self.next_short == np.arange(len(self.h_m))
        if not short.any():
            return np.zeros((0, 2))
        s = self.s_m
        idx = np.flatnonzero(short)
        gap_m = kmh_from_e(self.e_limit_cell[idx]) / 3.6 * self.air_cycle.recharge_s
        spans = [[s[idx[0]], s[idx[0] + 1]]]
        for k, g in zip(idx[1:], gap_m[1:]):
            if s[k] - spans[-1][1] <= g:
                spans[-1][1] = s[k + 1]
            else:
                spans.append([s[k], s[k + 1]])
        return np.array(spans)

    def cycle_speeds(self, e_hold: float, k: int, margin: float = 0.0) -> tuple[float, float]:
        """The air brake's cycle under the speed ``e_hold`` (e = v^2/2: a limit, a cruise speed) in cell ``k``, as the
        plans are run (``kernel.cycle_speeds``): (e to apply at, e to release at); ``margin`` the release margin (<= 0:
        the rule's). Needs ``air_cycle``."""
        return kernels().cycle_speeds(float(e_hold), float(self.gravity_kn[k]), float(self.traction_allowed[k]),
                                      float(self.t_build_s[k]), float(self.air_cycle.recharge_s), float(margin),
                                      self.forces)

    def _run_kernel(self, conditions, sw: np.ndarray, want_profile: bool, cruise_e: np.ndarray | None,
                    margin: np.ndarray, region: np.ndarray) -> BatchResult:
        """The compiled loop (``kernel.run_plans``), one plan at a time."""
        n, n_cells = sw.shape[0], len(self.h_m)
        starts = np.concatenate([np.zeros((n, 1)), np.where(np.isnan(sw), np.inf, sw)], axis=1)
        ends = np.concatenate([starts[:, 1:], np.full((n, 1), np.inf)], axis=1)
        # a run that never starts ends nowhere; one after a 'never' start never begins either
        starts = np.ascontiguousarray(np.maximum.accumulate(starts, axis=1))
        ends = np.ascontiguousarray(np.maximum(np.minimum(ends, np.inf), starts))
        codes = np.array([CODE[c] for c in conditions], dtype=np.int64)
        t = np.empty(n)
        work = np.empty(n)
        over_at, stop_at, hold_at, fb_at = (np.empty(n, dtype=np.int64) for _ in range(4))
        shape_nodes, shape_cells = ((n, n_cells + 1), (n, n_cells)) if want_profile else ((1, 1), (1, 1))
        t_nodes, v_nodes = np.zeros(shape_nodes), np.zeros(shape_nodes)
        cond = np.zeros(shape_cells, dtype=np.int8)
        trac, brk, event = np.zeros(shape_cells), np.zeros(shape_cells), np.zeros(shape_cells)
        cyc = self.air_cycle
        plans = Plans(codes, starts, ends, cruise_e if cruise_e is not None else np.zeros(n), cruise_e is not None,
                      bool(self.options.strict_limits), bool(want_profile), cyc is not None,
                      float(cyc.recharge_s) if cyc else 0.0, self._min_hold_s, margin, region)
        air_at, air_apps = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        air_wait, air_margin = np.empty(n), np.empty(n)
        air = np.zeros(shape_cells, dtype=np.int8)
        kernels().run_plans(self.cells, self.forces, plans,
                            Outputs(t, work, over_at, stop_at, hold_at, fb_at, t_nodes, v_nodes, cond, trac, brk, event,
                                    air_at, air_wait, air_apps, air_margin, air))
        never = lambda a: np.where(a < 0, n_cells, a)  # noqa: E731
        prof = (t_nodes, v_nodes, cond, trac, brk, event) if want_profile else None
        airs = (never(air_at), air_wait, air_apps, air_margin, air if want_profile else None) if cyc else None
        return self._verdict(never(over_at), never(stop_at), never(hold_at), fb_at == 1, t, work, prof, sw, airs,
                             held_at_stop=fb_at == 2)

    @property
    def _min_hold_s(self) -> float:
        """The air brake's least hold time [s] as the loops take it (< 0: each application's build-up time)."""
        cyc = self.air_cycle
        return -1.0 if cyc is None or cyc.min_hold_s is None else float(cyc.min_hold_s)

    def _verdict(self, first_over, first_stop, first_hold, braking_at_stop, t, work, prof, switches_m,
                 airs=None, held_at_stop=None) -> BatchResult:
        """Each plan's first failure decides its verdict; assemble the typed result.

        first_*: (n,) the first cell where the plan broke a limit (strict mode), came to rest, or could not
        be held under a limit (n_cells = never); braking_at_stop: it was braking where it came to rest;
        held_at_stop: an application it could not release (kept on) brought it to rest there.
        airs: the air brake's cycle (None without): the first cell where it was applied before its recharge
        was over (n_cells = never), the time since the release there, the applications, the least recharge
        margin and the per-cell state (or None). Refused so before any other failure, a plan keeps its run."""
        n_cells = len(self.h_m)
        last = n_cells - 1
        e_env = self.e_envelope
        want_profile = prof is not None
        if want_profile:
            t_nodes, v_nodes, cond, trac, brk, event = prof
        first = np.minimum(np.minimum(first_over, first_stop), first_hold)
        failed = first < n_cells
        cell = np.minimum(first, last)
        # brought to rest by a braking curve that reaches zero mid-route: no speed is safe there, i.e.
        # full braking cannot slow the train enough for a limit further on
        unholdable = (first_stop == first) & (e_env[cell + 1] <= E_FLOOR) & (cell < last)
        cannot_hold = (first_hold == first) | unholdable
        # at rest inside the last cell, short of the stop (coasting up to it: the crawl's sub-steps)
        short = (first_stop == first) & (cell == last) & ~cannot_hold
        reason = np.where(~failed, OK, np.where(cannot_hold, CANNOT_HOLD,
                          np.where(first_over == first, LIMIT_EXCEEDED,
                                   np.where(braking_at_stop | short, STOPPED_SHORT, STALLED)))).astype(np.int8)
        if held_at_stop is not None:
            reason = np.where((reason == STALLED) & held_at_stop, AIR_HELD, reason).astype(np.int8)
        air_refused = np.zeros(len(first), dtype=bool)
        if airs is not None:
            air_refused = (airs[0] < first) & (self.impossible is None)
            never = np.isin(reason, NEVER_ARRIVED) & failed
            reason = np.where(air_refused, AIR_RECHARGE, reason).astype(np.int8)
            cell = np.where(air_refused, airs[0], cell)
        if self.impossible is not None:  # no plan keeps the limits: every one fails where the route does
            first = np.minimum(first, self._impossible_cell)
            failed = np.ones_like(failed)
            cell = first.copy()
            reason = np.full_like(reason, IMPOSSIBLE)
            cannot_hold = np.zeros_like(cannot_hold)
            unholdable = np.zeros_like(unholdable)
            short = np.zeros_like(short)
        at_node = np.where((cannot_hold & ~unholdable) | short, cell, cell + 1)
        at_node = np.where(air_refused, cell, at_node)  # (the application was made at the cell's start)
        failed_run = failed.copy()  # failed in the run itself (its profile ends there)
        failed = failed | air_refused
        fail_at = np.where(failed, self.s_m[np.minimum(at_node, n_cells)], np.nan)
        profile = recovered = force = None
        if want_profile:
            for j in range(switches_m.shape[1]):  # a plan's own switch is an event of its cell
                x = switches_m[:, j]
                ok = np.isfinite(x) & (x > 0) & (x < self.s_m[-1])
                in_cell = np.clip(np.searchsorted(self.s_m, np.where(ok, x, 0.0), side="right") - 1, 0, n_cells - 1)
                sel = np.nonzero(ok)[0]
                at = in_cell[sel]
                event[sel, at] = np.where(np.isnan(event[sel, at]), x[sel], event[sel, at])
            # a failed plan's profile ends where it failed (at rest where it stalled or stopped short;
            # before the cell where it broke or could not hold a limit): what follows is not a run
            stopped = (reason == STALLED) | (reason == STOPPED_SHORT) | (reason == IMPOSSIBLE) | (reason == AIR_HELD)
            end = np.where(failed, np.where(stopped, cell + 1, np.minimum(first, at_node)), n_cells)
            if airs is not None:  # refused for its recharge: the run up to its own failure, if any
                stopped_run = (first_stop == first) & failed_run
                end = np.where(air_refused, np.where(failed_run, np.where(stopped_run, first + 1, first), n_cells), end)
            air_prof = None if airs is None else airs[4]
            for i in np.flatnonzero(failed & (end < n_cells)):
                t_nodes[i, end[i] + 1:] = np.nan
                v_nodes[i, end[i] + 1:] = np.nan
                trac[i, end[i]:] = np.nan
                brk[i, end[i]:] = np.nan
                cond[i, end[i]:] = -1
                if air_prof is not None:
                    air_prof[i, end[i]:] = -1
            if self.checks_forces:  # refused by the consist's limits, the run itself kept whole
                code, k, value = self._force_failures(t_nodes, v_nodes, trac, brk, ~failed)
                refused = code != OK
                reason = np.where(refused, code, reason).astype(np.int8)
                failed = failed | refused
                cell = np.where(refused, np.minimum(k, last), cell)
                fail_at = np.where(refused, 0.5 * (self.s_m[cell] + self.s_m[cell + 1]), fail_at)
                force = value
            profile = Profile(self.s_m, t_nodes, v_nodes, cond, trac, brk, self.limit_kmh, self.gradient_permille, event,
                              air=air_prof)
            recovered = self.recovered_energy_kwh(v_nodes, brk)
        t = np.where(np.isin(reason, NEVER_ARRIVED), np.nan, t)  # never arrived
        if airs is not None:
            t = np.where(never, np.nan, t)
        lim = self.limit_kmh[cell]
        return BatchResult(running_time_s=t, traction_energy_kwh=kwh(work), feasible=reason == OK,
                           reason_code=reason, failure_m=fail_at, profile=profile,
                           failure_limit_kmh=np.where(failed, lim, np.nan),
                           failure_gradient_permille=np.where(failed, self.gradient_permille[cell], np.nan),
                           failure_brake_kn=np.where(failed, self.brake_kn_at(lim, cell), np.nan),
                           impossible=self.impossible, recovered_energy_kwh=recovered, failure_force=force,
                           force_limits=(self.train.coupler_limit_kn, self.train.force_rate_limit_kn_per_s),
                           **({} if airs is None else dict(
                               air_applications=airs[2], air_margin_s=airs[3],
                               air_wait_s=np.where(air_refused, airs[1], np.nan), recharge_s=self.air_cycle.recharge_s)))
