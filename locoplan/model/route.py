"""Route file schema (SPEC section 1): speed limits, gradients, curves, tunnels, neutral sections."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .common import RuleViolations, Strict, plausible

PLAUSIBLE_ROUTE = {
    # a run from stop to stop: shorter than 10 m is no run; 2,000 km is beyond any non-stop freight run
    # (the longest real line shipped is 102 km) and keeps the 50 m grid under 40,000 cells
    "length_m": (10.0, 2_000_000.0),
    # below 1 km/h a train does not run (a closed line is split into two routes, not given 0 km/h)
    "kmh": (1.0, 400.0),
    # no stop-to-stop run is planned longer than a week
    "run_time_s": (1.0, 604_800.0),
    # drivers shut off power for a neutral section some seconds before and after it; ten minutes is the most
    "coast_s": (0.0, 600.0),
}
_L, _V, _T, _C = (PLAUSIBLE_ROUTE[k] for k in ("length_m", "kmh", "run_time_s", "coast_s"))


class Schedule(Strict):
    run_time_s: Annotated[float, plausible(*_T, "s", "no stop-to-stop run is planned longer than a week")] = Field(
        gt=0, description="planned running time [s]")
    tolerance_s: float = Field(default=0.0, ge=0, description="punctuality window +- [s]")

    @model_validator(mode="after")
    def _window(self) -> "Schedule":
        if self.tolerance_s >= self.run_time_s:
            raise RuleViolations([(("tolerance_s",), f"{self.tolerance_s:g} s is not below run_time_s {self.run_time_s:g} s: "
                                   "the window would open at or before departure")])
        return self


class Section(Strict):
    from_m: float = Field(ge=0)
    to_m: float = Field(gt=0)


class SpeedLimit(Section):
    kmh: Annotated[float, plausible(*_V, "km/h", "below 1 km/h a train does not run; above 400 km/h no freight train does")] = Field(
        gt=0, description="speed limit [km/h]")


class Gradient(Section):
    permille: float = Field(ge=-40, le=40, description="gradient [per mille], + = up-grade")


class Curve(Section):
    radius_m: float = Field(ge=100, description="curve radius [m]")


class Tunnel(Section):
    pass


class Station(Strict):
    """A named place along the line (a station, a junction, a block post): shown in outputs."""

    name: str = Field(min_length=1)
    at_m: float = Field(ge=0, description="position [m] from the route's start")


class MileageChange(Strict):
    """From ``at_m`` on, the kilometre post reads ``km`` and counts up (or down, ``descending``) with the distance run."""

    at_m: float = Field(ge=0, description="position [m] from the route's start")
    km: float = Field(description="kilometre post at at_m [km]")
    descending: bool = Field(default=False, description="the posts count down in the running direction")


class NeutralSection(Section):
    coast_before_s: Annotated[float, plausible(*_C, "s", "power is shut off seconds, not hours, around a neutral section")] = 0.0
    coast_after_s: Annotated[float, plausible(*_C, "s", "power is shut off seconds, not hours, around a neutral section")] = 0.0


def _section_problems(name: str, sections, length_m: float, contiguous: bool) -> list[tuple[tuple, str]]:
    """Positive lengths, inside [0, length_m], sorted; contiguous lists must also cover [0, length_m] exactly."""
    out: list[tuple[tuple, str]] = []
    for i, sec in enumerate(sections):
        if sec.to_m < sec.from_m:
            out.append(((name, i), f"from_m > to_m: section reversed ({sec.from_m:g} > {sec.to_m:g}; swap them)"))
        elif sec.to_m == sec.from_m:
            out.append(((name, i), f"zero length: from_m = to_m = {sec.to_m:g} (to_m must be greater than from_m)"))
        if sec.to_m > length_m + 1e-9:
            out.append(((name, i, "to_m"), f"{sec.to_m:g} m lies beyond the route's length_m {length_m:g}"))
    for i in range(1, len(sections)):
        prev, sec = sections[i - 1], sections[i]
        if sec.from_m < prev.to_m - 1e-9:
            out.append(((name, i, "from_m"), f"overlaps the previous section ({sec.from_m:g} < {prev.to_m:g})"))
        elif contiguous and sec.from_m > prev.to_m + 1e-9:
            out.append(((name, i, "from_m"), f"gap after the previous section ({prev.to_m:g} .. {sec.from_m:g} m uncovered)"))
    if contiguous:
        if not sections:
            out.append(((name,), "at least one section is required"))
        else:
            if abs(sections[0].from_m) > 1e-9:
                out.append(((name, 0, "from_m"), f"must start at 0 (got {sections[0].from_m:g})"))
            if abs(sections[-1].to_m - length_m) > 1e-9:
                out.append(((name, len(sections) - 1, "to_m"), f"must end at length_m {length_m:g} (got {sections[-1].to_m:g})"))
    return out


class Route(Strict):
    """A route. Positions in metres from the start, in the running direction."""

    schema_: Literal["locoplan/route@1"] = Field(alias="schema")
    name: str
    length_m: Annotated[float, plausible(*_L, "m", "a route runs from stop to stop, 10 m .. 2,000 km")] = Field(gt=0)
    schedule: Schedule | None = None
    speed_limits: list[SpeedLimit]
    gradients: list[Gradient]
    curves: list[Curve] = []
    tunnels: list[Tunnel] = []
    neutral_sections: list[NeutralSection] = []
    stations: list[Station] = []
    chainage: float | list[MileageChange] | None = Field(
        default=None, description="kilometre post at position 0 [km], or the mileage changes along the line")

    @model_validator(mode="after")
    def _check_sections(self) -> "Route":
        problems: list[tuple[tuple, str]] = []
        problems += _section_problems("speed_limits", self.speed_limits, self.length_m, contiguous=True)
        problems += _section_problems("gradients", self.gradients, self.length_m, contiguous=True)
        for name in ("curves", "tunnels", "neutral_sections"):
            problems += _section_problems(name, getattr(self, name), self.length_m, contiguous=False)
        for i, ns in enumerate(self.neutral_sections):
            if ns.from_m <= 0:
                problems.append((("neutral_sections", i), f"starts at the departure stop ({ns.from_m:g} .. {ns.to_m:g} m): "
                                 "a train standing in a neutral section has no traction and can never start; move "
                                 "the stop, or the section"))
        problems += _place_problems(self)
        if problems:
            raise RuleViolations(problems)
        return self

    def mileage(self) -> list[MileageChange]:
        """The kilometre posts as mileage changes (the first at 0); ``[]`` when the route has no chainage."""
        if self.chainage is None:
            return []
        if isinstance(self.chainage, list):
            return list(self.chainage)
        return [MileageChange(at_m=0.0, km=float(self.chainage))]


def _place_problems(route: "Route") -> list[tuple[tuple, str]]:
    out: list[tuple[tuple, str]] = []
    for i, st in enumerate(route.stations):
        if st.at_m > route.length_m + 1e-9:
            out.append((("stations", i, "at_m"), f"{st.at_m:g} m lies beyond the route's length_m {route.length_m:g}"))
        if i and st.at_m < route.stations[i - 1].at_m:
            out.append((("stations", i, "at_m"), f"not in order: {st.at_m:g} m comes before the previous station "
                        f"({route.stations[i - 1].at_m:g} m); list stations in the running direction"))
    if isinstance(route.chainage, list):
        if not route.chainage:
            out.append((("chainage",), "an empty list: give the kilometre post at position 0, or leave chainage out"))
        elif abs(route.chainage[0].at_m) > 1e-9:
            out.append((("chainage", 0, "at_m"), f"the first mileage change must be at 0 (got {route.chainage[0].at_m:g}), "
                        "so that every position has a kilometre post"))
        for i, mc in enumerate(route.chainage):
            if mc.at_m > route.length_m + 1e-9:
                out.append((("chainage", i, "at_m"), f"{mc.at_m:g} m lies beyond the route's length_m {route.length_m:g}"))
            if i and mc.at_m <= route.chainage[i - 1].at_m:
                out.append((("chainage", i, "at_m"), f"not after the previous mileage change ({mc.at_m:g} <= "
                            f"{route.chainage[i - 1].at_m:g} m)"))
    return out


def kilometre_post(route: Route, s_m):
    """The kilometre post [km] at position(s) ``s_m`` [m]; ``None`` when the route has no chainage."""
    import numpy as np

    changes = route.mileage()
    if not changes:
        return None
    s = np.asarray(s_m, dtype=float)
    at = np.array([c.at_m for c in changes])
    k = np.clip(np.searchsorted(at, s, side="right") - 1, 0, len(changes) - 1)
    km = np.array([c.km for c in changes])[k]
    sign = np.where(np.array([c.descending for c in changes])[k], -1.0, 1.0)
    post = km + sign * (s - at[k]) / 1000.0
    return float(post) if post.ndim == 0 else post


def format_post(km: float, form: str = "km") -> str:
    """A kilometre post as people write it: ``12.345 km`` (form "km") or ``12+345`` (form "plus")."""
    if form == "plus":
        metres = int(round(abs(km) * 1000.0))
        return f"{'-' if km < 0 and metres else ''}{metres // 1000}+{metres % 1000:03d}"
    return f"{km:.3f} km"


def route_slice(route: Route, from_m: float, to_m: float, name: str) -> Route:
    """The part ``from_m`` .. ``to_m`` of ``route`` as a route of its own (positions from its start; a
    section cut by an end keeps its part inside; no schedule)."""
    def cut(sections, key=None, contiguous=False):
        out = []
        for sec in sections:
            a, b = max(sec.from_m, from_m), min(sec.to_m, to_m)
            if b - a > 1e-6:
                d = sec.model_dump()
                d.update(from_m=round(a - from_m, 6), to_m=round(b - from_m, 6))
                out.append(d)
        if contiguous and out:
            out[0]["from_m"] = 0.0
            out[-1]["to_m"] = round(to_m - from_m, 6)
        return out

    data = {"schema": "locoplan/route@1", "name": name, "length_m": round(to_m - from_m, 6),
            "speed_limits": cut(route.speed_limits, contiguous=True), "gradients": cut(route.gradients, contiguous=True),
            "curves": cut(route.curves), "tunnels": cut(route.tunnels),
            "neutral_sections": cut(route.neutral_sections)}
    stations = [{"name": st.name, "at_m": round(st.at_m - from_m, 6)} for st in route.stations
                if from_m - 1e-6 <= st.at_m <= to_m + 1e-6]
    if stations:
        data["stations"] = [dict(d, at_m=min(max(d["at_m"], 0.0), round(to_m - from_m, 6))) for d in stations]
    if route.chainage is not None:
        changes = route.mileage()
        first = {"at_m": 0.0, "km": round(float(kilometre_post(route, from_m)), 9),
                 "descending": [c for c in changes if c.at_m <= from_m + 1e-9][-1].descending}
        later = [{"at_m": round(c.at_m - from_m, 6), "km": c.km, "descending": c.descending}
                 for c in changes if from_m + 1e-9 < c.at_m < to_m - 1e-9]
        data["chainage"] = [first] + later
    return Route.model_validate(data)


def with_restriction(route: Route, from_m: float, to_m: float, kmh: float) -> Route:
    """``route`` with a temporary speed restriction: the limit no higher than ``kmh`` on ``from_m`` .. ``to_m`` (cut
    to the line), every other section as it was (sections split at the restriction's ends)."""
    a, b = max(0.0, float(from_m)), min(route.length_m, float(to_m))
    if b - a <= 1e-6:
        return route
    limits = []
    for sec in route.speed_limits:
        for lo, hi, inside in ((sec.from_m, min(sec.to_m, a), False), (max(sec.from_m, a), min(sec.to_m, b), True),
                               (max(sec.from_m, b), sec.to_m, False)):
            if hi - lo > 1e-6:
                v = min(sec.kmh, float(kmh)) if inside else sec.kmh
                if limits and limits[-1]["kmh"] == v and abs(limits[-1]["to_m"] - lo) < 1e-6:
                    limits[-1]["to_m"] = hi
                else:
                    limits.append({"from_m": lo, "to_m": hi, "kmh": v})
    data = route.model_dump(mode="json", by_alias=True, exclude_none=True)
    data["speed_limits"] = limits
    return Route.model_validate(data)
