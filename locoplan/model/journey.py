"""Journey file schema: a whole line (a route file), its stations (stops and timing points) and a timetable.

Times are clock times in seconds since the departure from the first station; a stop's times are its
arrival (its dwell follows), a timing point's the moment the train passes it. The running time of the
journey is the clock time at the last station less the dwells.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .common import RuleViolations, Strict, plausible
from .route import PLAUSIBLE_ROUTE

JOURNEY_SCHEMA = "locoplan/journey@1"

_DAY_S = 86_400.0
_WEEK_S = 604_800.0


class Station(Strict):
    """A station on the line: a stop (``stop: true``, the default: the train stands there ``dwell_s``) or a
    timing point the train passes (``stop: false``), with its scheduled time ``time_s`` and a window
    ``earliest_s`` .. ``latest_s`` (each optional)."""

    name: str = Field(min_length=1)
    at_m: float = Field(ge=0, description="position along the route [m]")
    stop: bool = True
    dwell_s: Annotated[float, plausible(0.0, _DAY_S, "s", "a freight train dwells minutes or hours at a stop, not days")] = Field(
        default=0.0, ge=0, description="time standing at the stop [s]")
    time_s: Annotated[float, plausible(0.0, _WEEK_S, "s", "no journey is planned longer than a week")] | None = Field(
        default=None, ge=0, description="scheduled arrival (a stop) or passing (a timing point) [s since departure]")
    earliest_s: Annotated[float, plausible(0.0, _WEEK_S, "s", "no journey is planned longer than a week")] | None = Field(
        default=None, ge=0, description="earliest arrival or passing [s since departure]")
    latest_s: Annotated[float, plausible(0.0, _WEEK_S, "s", "no journey is planned longer than a week")] | None = Field(
        default=None, ge=0, description="latest arrival or passing [s since departure]")

    @model_validator(mode="after")
    def _window(self) -> "Station":
        problems = []
        if self.earliest_s is not None and self.latest_s is not None and self.earliest_s > self.latest_s:
            problems.append((("latest_s",), f"{self.latest_s:g} s is before earliest_s {self.earliest_s:g} s: the window is empty"))
        if self.time_s is not None:
            if self.earliest_s is not None and self.time_s < self.earliest_s:
                problems.append((("time_s",), f"{self.time_s:g} s is before earliest_s {self.earliest_s:g} s"))
            if self.latest_s is not None and self.time_s > self.latest_s:
                problems.append((("time_s",), f"{self.time_s:g} s is after latest_s {self.latest_s:g} s"))
        if not self.stop and self.dwell_s > 0:
            problems.append((("dwell_s",), "a timing point the train passes has no dwell (set stop: true to stop there)"))
        if problems:
            raise RuleViolations(problems)
        return self

    def window_s(self) -> tuple[float | None, float | None]:
        """(earliest, latest) clock times, each None where open."""
        return self.earliest_s, self.latest_s


class Journey(Strict):
    """A journey over one line (``route``: a route file, its path relative to this file's folder)."""

    schema_: Literal["locoplan/journey@1"] = Field(alias="schema")
    name: str
    route: str = Field(min_length=1, description="the whole line: a route file, relative to this file")
    run_time_s: Annotated[float, plausible(1.0, _WEEK_S, "s", "no journey is planned longer than a week")] | None = Field(
        default=None, gt=0, description="total running time, dwells excluded [s]")
    stations: list[Station] = Field(min_length=2)

    @model_validator(mode="after")
    def _stations(self) -> "Journey":
        problems = []
        st = self.stations
        if st[0].at_m != 0.0:
            problems.append((("stations", 0, "at_m"), f"the first station is the departure: it must be at 0 m (got {st[0].at_m:g})"))
        if not st[0].stop:
            problems.append((("stations", 0, "stop"), "the first station is where the train departs: it must be a stop"))
        if any(x is not None for x in (st[0].time_s, st[0].earliest_s, st[0].latest_s)):
            problems.append((("stations", 0), "the clock starts at the departure from the first station: give it no "
                             "time_s, earliest_s or latest_s"))
        if not st[-1].stop:
            problems.append((("stations", len(st) - 1, "stop"), "the last station is where the journey ends: it must be a stop"))
        for i in range(1, len(st)):
            if st[i].at_m <= st[i - 1].at_m:
                problems.append((("stations", i, "at_m"), f"{st[i].at_m:g} m is not beyond the previous station "
                                 f"({st[i - 1].name}, {st[i - 1].at_m:g} m): list the stations in running order"))
        stops = [i for i, s in enumerate(st) if s.stop]
        shortest = PLAUSIBLE_ROUTE["length_m"][0]
        for a, b in zip(stops, stops[1:]):  # each leg runs as a route of its own: at least a route's shortest length
            if 0 < st[b].at_m - st[a].at_m < shortest:
                problems.append((("stations", b, "at_m"), f"the leg {st[a].name} - {st[b].name} is "
                                 f"{st[b].at_m - st[a].at_m:g} m long: a run between two stops is at least "
                                 f"{shortest:g} m (the shortest route); make one of them a passing station (stop: false) "
                                 "or drop it"))
        seen: dict[str, int] = {}
        for i, s in enumerate(st):
            if s.name in seen:
                problems.append((("stations", i, "name"), f"{s.name!r} is also station {seen[s.name] + 1}: names must differ"))
            seen.setdefault(s.name, i)
        if problems:
            raise RuleViolations(problems)
        return self

    @property
    def stops(self) -> list[int]:
        """Indices of the stations where the train stops (the first and the last among them)."""
        return [i for i, s in enumerate(self.stations) if s.stop]
