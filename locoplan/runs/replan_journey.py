"""Re-planning on board inside a journey (``locoplan replan JOURNEY``): the state's leg re-planned to its stop.

A journey's legs run stop to stop, each at the running time the journey's plan gives it (``runs.journey.allocate``:
the least-energy allocation of the journey's running time, inside every station's window). A state (position along
the whole line, clock since the departure from the first station, dwells included) lies inside one leg, between
its two stops; the re-plan is that leg's (``optimize.replan.Replanner`` on the leg's route), arriving at its stop at
the clock the plan has there, inside the window. The stops after it keep their planned clock: the rest of the
journey runs as planned (each later leg departs at its planned time after its stop's dwell).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..runner import punctuality_tolerance
from ..errors import InputError, Problem
from ..model.journey import Journey
from ..model.route import Route
from ..model.train import Train
from ..optimize.replan import Replan, Replanner, TrainState
from ..sim.calculator import ModelOptions
from .journey import Leg, allocate, check_windows, dwell_before, fastest_clock, legs_of, total_running_time


@dataclass(frozen=True)
class PlannedLeg:
    """A leg of the journey's plan: the leg, its planned departure and arrival at its stop (clock since the departure
    from the first station [s]) and the stop's window (clock [s], each None where open)."""

    leg: Leg
    depart_s: float
    arrive_s: float
    window: tuple[float | None, float | None]


class JourneyReplanner:
    """The journey's plan (its legs' running times) and, per leg, a ``Replanner`` made when a state first falls in it."""

    def __init__(self, journey: Journey, route: Route, train: Train, options: ModelOptions, *, time_s: float | None,
                 tolerance_s: float | None, source: str):
        self.journey, self.route, self.train, self.options = journey, route, train, options
        self.tolerance_arg = tolerance_s
        legs = legs_of(journey, route, train, options)
        total = total_running_time(journey, time_s, source)
        check_windows(journey, legs, total, fastest_clock(journey, legs, train, options), source)
        times, _ = allocate(journey, legs, train, options, total)
        self.legs: list[PlannedLeg] = []
        run = 0.0
        for leg, t in zip(legs, times):
            dep = run + dwell_before(journey, leg.first + 1)  # (the dwells up to and including its first stop's)
            st = journey.stations[leg.last]
            self.legs.append(PlannedLeg(leg, dep, dep + float(t), st.window_s()))
            run += float(t)
        self._rp: dict[int, Replanner] = {}
        self.override: dict[int, float] = {}
        """A new planned arrival at a leg's stop (clock [s]), by leg (``replan --stream``'s ``planned_arrival_s``)."""
        self.setup_s = 0.0

    def leg_at(self, s_m: float) -> int:
        """The leg whose run a position lies on (a stop's position: the leg departing from it; the last stop: the
        last leg's end)."""
        starts = np.array([p.leg.from_m for p in self.legs])
        return int(min(max(np.searchsorted(starts, s_m, side="right") - 1, 0), len(self.legs) - 1))

    def replanner(self, k: int) -> Replanner:
        if k not in self._rp:
            p = self.legs[k]
            t_leg = p.arrive_s - p.depart_s
            tol = punctuality_tolerance(p.leg.route, t_leg, self.tolerance_arg)
            rp = Replanner(p.leg.route, self.train, self.options, planned_s=t_leg, tolerance_s=tol)
            self._rp[k] = rp
            self.setup_s += rp.setup_s
        return self._rp[k]

    def replan(self, st: TrainState, planned_arrival_s: float | None = None) -> tuple[Replan, int, Replanner, float,
                                                                                       float]:
        """The state's leg re-planned (``planned_arrival_s``: a new planned arrival at its stop, clock [s]; default
        the plan's). Returns (the leg's re-plan in the leg's own frame, the leg's index, its replanner, the leg's
        start along the line [m], the clock the leg's frame starts at [s])."""
        L = self.route.length_m
        where = f"state at {st.s_m:g} m, {st.v_kmh:g} km/h, {st.t_s:g} s"
        if not -1e-6 <= st.s_m <= L + 1e-6:
            raise InputError(Problem(where, "s_m", f"off the line (0 .. {L:g} m)"))
        k = self.leg_at(st.s_m)
        p = self.legs[k]
        rp = self.replanner(k)
        if planned_arrival_s is None:
            planned_arrival_s = self.override.get(k)
        arrive = p.arrive_s if planned_arrival_s is None else float(planned_arrival_s)
        origin = min(p.depart_s, st.t_s)  # (a train that left its stop early: the leg's clock from its departure)
        local = TrainState(min(max(st.s_m - p.leg.from_m, 0.0), p.leg.route.length_m), st.v_kmh, st.t_s - origin,
                           st.condition, st.air, st.recharge_left_s)
        return rp.replan(local, arrive - origin), k, rp, p.leg.from_m, origin

    def summary(self, st: TrainState, res: Replan, k: int, rp: Replanner, from_m: float, origin: float,
                route_name: str, train_name: str) -> dict:
        """The --json object of a re-plan inside a leg, on the whole line's positions and the journey's clock."""
        from ..reporting.replan import replan_summary

        d = replan_summary(res, route_name, train_name, rp.tolerance_s, rp.cycle_relaxed)
        d["state"] = {**d["state"], "s_m": st.s_m, "t_s": st.t_s}
        if d["next_switch_m"] is not None:
            d["next_switch_m"] = round(d["next_switch_m"] + from_m, 1)
        for key in ("arrival_s", "planned_arrival_s"):
            d[key] = round(d[key] + origin, 2)
        d["window_s"] = [round(x + origin, 2) for x in d["window_s"]]
        d["plan"] = _shift_plan(d["plan"], from_m)
        for ev in d.get("air_events") or []:
            ev["at_m"] = round(ev["at_m"] + from_m, 1)
            ev["t_s"] = round(ev["t_s"] + origin, 2)
        p = self.legs[k]
        j = self.journey
        stop = j.stations[p.leg.last]
        lo, hi = p.window
        d["leg"] = {"leg": k + 1, "from": j.stations[p.leg.first].name, "to": stop.name,
                    "from_m": round(p.leg.from_m, 1), "stop_m": round(stop.at_m, 1),
                    "planned_departure_s": round(p.depart_s, 2), "arrival_s": d["arrival_s"],
                    "planned_arrival_s": d["planned_arrival_s"], "stop_window_s": [lo, hi],
                    "inside_stop_window": bool((lo is None or d["arrival_s"] >= lo - 1e-6)
                                               and (hi is None or d["arrival_s"] <= hi + 1e-6))}
        d["next_stops"] = [{"name": j.stations[q.leg.last].name, "at_m": round(j.stations[q.leg.last].at_m, 1),
                            "planned_arrival_s": round(q.arrive_s, 2), "planned_departure_s": round(q.depart_s, 2),
                            "kept": True} for q in self.legs[k + 1:]]
        return d


def _shift_plan(plan: str, from_m: float) -> str:
    out = []
    for item in plan.split(",") if plan else []:
        c, _, at = item.partition(":")
        out.append(f"{c}:{float(at) + from_m:.1f}" if at else c)
    return ",".join(out)
