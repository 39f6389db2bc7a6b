"""Vehicle and consist file schemas (SPEC section 1).

Plausibility bounds (``PLAUSIBLE``) keep out numbers no real railway vehicle has (a 1e-9 t locomotive,
a billion wagons): they are generous, so that any real train passes, and each message says which
bound was broken and why it exists.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .common import RuleViolations, Strict, plausible

PLAUSIBLE = {
    "vehicle_mass_t": (1.0, 500.0),  # lightest draisine-class vehicle .. heaviest multi-section locomotive
    "load_t": 200.0,  # largest payload per wagon (heavy-haul ore cars carry ~120 t)
    "vehicle_length_m": (2.0, 100.0),
    "speed_kmh": 600.0,  # fastest wheeled train
    "force_kn": 3000.0,  # per vehicle: several times any locomotive's starting effort
    "count": 1000,  # vehicles in one consist entry, and in the whole consist
    "train_mass_t": 100_000.0,  # the heaviest train ever run (BHP Billiton, 2001) weighed 99,734 t
    "train_length_m": 8000.0,  # the same train was 7.35 km long
    "coupler_kn": 10_000.0,  # 2.5 x the static breaking load of a heavy-haul coupler body (No. 16/17: 4,005 kN)
    "force_rate_kn_per_s": 100_000.0,
}


class Resistance(Strict):
    """Davis coefficients of the basic resistance w0 = a + b v + c v^2 [N/kN], v in km/h."""

    a: float = Field(ge=0, le=100)
    b: float = Field(ge=0, le=10)
    c: float = Field(ge=0, le=1)


ForceCurve = list[Annotated[list[float], Field(min_length=2, max_length=2)]]
"""[[speed_kmh, force_kn], ...], linear between points."""


def _curve_problems(field: tuple, curve: ForceCurve | None, what: str = "force_kn",
                    bounds: tuple[float, float] | None = None) -> list[tuple[tuple, str]]:
    """What is wrong with a curve [[speed_kmh, value], ...]: a force [kN] (``what`` = "force_kn"), or another
    quantity within ``bounds`` (e.g. an adhesion coefficient, "mu" in (0, 1])."""
    out: list[tuple[tuple, str]] = []
    if curve is None:
        return out
    if len(curve) < 2:
        out.append((field, f"needs at least two [speed_kmh, {what}] points"))
    for i, (v, f) in enumerate(curve):
        if not (v == v and f == f) or v in (float("inf"), float("-inf")) or f in (float("inf"), float("-inf")):
            out.append((field + (i,), f"speed and {what} must be finite numbers (got [{v:g}, {f:g}])"))
            continue
        if v < 0 or f < 0:
            out.append((field + (i,), f"speed and {what} must be >= 0 (got [{v:g}, {f:g}])"))
        if v > PLAUSIBLE["speed_kmh"]:
            out.append((field + (i,), f"speed {v:g} km/h is implausible (no train runs above {PLAUSIBLE['speed_kmh']:g} km/h)"))
        if bounds is None and f > PLAUSIBLE["force_kn"]:
            out.append((field + (i,), f"force {f:g} kN is implausible for one vehicle (limit {PLAUSIBLE['force_kn']:g} kN)"))
        if bounds is not None and not bounds[0] < f <= bounds[1]:
            out.append((field + (i,), f"{what} {f:g} must lie in ({bounds[0]:g}, {bounds[1]:g}]"))
        if i and v <= curve[i - 1][0]:
            out.append((field + (i,), f"speeds must increase ({v:g} after {curve[i - 1][0]:g})"))
    return out


class AirBrake(Strict):
    """A vehicle's automatic air brake (wagons; locomotives brake electrically, ``brake_kn``).

    Give either ``force_kn``, the vehicle's brake force curve at full brake-cylinder pressure, or
    ``braking_ratio`` with ``shoe``: the converted braking ratio theta_h (converted brake-shoe force
    per kN of the loaded vehicle's weight) and the shoe type whose friction coefficient phi_h(v)
    scales it (TB/T 1407; ``physics.braking``). In service the force is further scaled by the
    consist's ``service_brake_coefficient`` (beta_c).
    """

    braking_ratio: float | None = Field(default=None, gt=0, le=1.5,
                                        description="converted brake-shoe force / loaded weight [-]")
    shoe: Literal["composite"] = "composite"
    force_kn: ForceCurve | None = None

    @model_validator(mode="after")
    def _one_of(self) -> "AirBrake":
        problems = _curve_problems(("force_kn",), self.force_kn)
        if (self.braking_ratio is None) == (self.force_kn is None):
            problems.append(((), "give either braking_ratio (with shoe) or force_kn, not both and not neither"))
        if problems:
            raise RuleViolations(problems)
        return self


class Vehicle(Strict):
    schema_: Literal["locoplan/vehicle@1"] = Field(alias="schema")
    name: str = Field(min_length=1)
    kind: Literal["locomotive", "wagon"]
    mass_t: float = Field(gt=0, description="locomotive mass, or a wagon's tare [t]")
    max_load_t: float | None = Field(default=None, ge=0, description="wagons: largest payload [t]")
    length_m: float = Field(gt=0)
    max_speed_kmh: float = Field(gt=0)
    resistance_n_per_kn: Resistance
    rotating_mass_factor: float = Field(default=1.0, ge=1.0, le=1.5,
                                        description="inertial mass / mass (1 = no rotating-mass allowance)")
    traction_kn: ForceCurve | None = None
    brake_kn: ForceCurve | None = Field(default=None, description="locomotives: max electric brake [kN] vs km/h")
    air_brake: AirBrake | None = None
    regen_efficiency: float | None = Field(default=None, gt=0, le=1, description=(
        "locomotives: share of the electric brake's work at the wheel returned to the line [-]"))
    adhesion_mu: ForceCurve | None = Field(default=None, description=(
        "locomotives: adhesion coefficient against speed [[speed_kmh, mu], ...]; traction and the electric brake "
        "are each at most mu(v) x mass_t x g (every axle driven); without it they are their curves"))

    @model_validator(mode="after")
    def _check(self) -> "Vehicle":
        problems = _curve_problems(("traction_kn",), self.traction_kn) + _curve_problems(("brake_kn",), self.brake_kn)
        problems += _curve_problems(("adhesion_mu",), self.adhesion_mu, "mu", (0.0, 1.0))
        lo, hi = PLAUSIBLE["vehicle_mass_t"]
        if not lo <= self.mass_t <= hi:
            problems.append((("mass_t",), f"{self.mass_t:g} t is implausible for one vehicle (expected {lo:g} .. {hi:g} t)"))
        lo, hi = PLAUSIBLE["vehicle_length_m"]
        if not lo <= self.length_m <= hi:
            problems.append((("length_m",), f"{self.length_m:g} m is implausible for one vehicle (expected {lo:g} .. {hi:g} m)"))
        if self.max_speed_kmh > PLAUSIBLE["speed_kmh"]:
            problems.append((("max_speed_kmh",), f"{self.max_speed_kmh:g} km/h is implausible (no train runs above {PLAUSIBLE['speed_kmh']:g} km/h)"))
        if self.max_load_t is not None and self.max_load_t > PLAUSIBLE["load_t"]:
            problems.append((("max_load_t",), f"{self.max_load_t:g} t is implausible for one wagon (limit {PLAUSIBLE['load_t']:g} t)"))
        if self.kind == "locomotive":
            for field in ("traction_kn", "brake_kn"):
                if getattr(self, field) is None:
                    problems.append(((field,), "a locomotive needs its max force curve [[speed_kmh, force_kn], ...]"))
        else:
            if self.regen_efficiency is not None:
                problems.append((("regen_efficiency",), "a wagon has no electric brake to regenerate with"))
            if self.adhesion_mu is not None:
                problems.append((("adhesion_mu",), "a wagon has no driven wheels (adhesion limits a locomotive's "
                                 "traction and electric brake)"))
            for field in ("traction_kn", "brake_kn"):
                if getattr(self, field) is not None:
                    what = "traction" if field == "traction_kn" else "an electric brake"
                    hint = "" if field == "traction_kn" else "; a wagon's brake is air_brake: {braking_ratio: ...} or {force_kn: [...]}"
                    problems.append(((field,), f"a wagon has no {what}{hint}"))
        if problems:
            raise RuleViolations(problems)
        return self


class ConsistEntry(Strict):
    type: str = Field(min_length=1, description="a vehicle's name")
    count: Annotated[int, plausible(1, PLAUSIBLE["count"], "vehicles", "the longest train ever run had 682 wagons")] = Field(ge=1)
    load_t: Annotated[float, plausible(0, PLAUSIBLE["load_t"], "t", "heavy-haul ore cars carry about 120 t")] = Field(
        default=0.0, ge=0, description="payload per wagon [t]")


class AirBrakeCycle(Strict):
    """How the wagons' direct-release air brake (control valves 120 / 120-1) may be cycled on a long descent.

    An application stays on until a full release; after it the brake pipe and the auxiliary reservoirs must
    recharge before the next application can be relied on. The build-up time of an application is the brake
    idle (propagation) time of TB/T 1407 (《列车牵引计算规程》), t_k = (3.6 + 0.00176 r n)(1 - 0.032 i_j) s, r the
    brake-pipe reduction [kPa], n the vehicles in the train, i_j the gradient [per mille] (docs/files.md).
    """

    reduction_kpa: float = Field(default=50.0, ge=50.0, le=170.0, description=(
        "brake-pipe reduction of a cycle's application [kPa]: a service reduction is at least 50 kPa, a full "
        "service one 140 kPa (500 kPa pipe) or 170 kPa (600 kPa pipe), 《机车操作规程》"))
    build_up_s: float | None = Field(default=None, gt=0, le=300.0, description=(
        "time for an application to reach full force along the train [s]; default TB/T 1407's t_k"))
    recharge_s: float = Field(default=30.0, ge=0, le=3600.0, description=(
        "recharge time after a full release, the part independent of the train's length [s]"))
    recharge_s_per_wagon: float = Field(default=0.6, ge=0, le=60.0, description=(
        "recharge time after a full release per wagon [s]"))
    min_hold_s: float | None = Field(default=None, ge=0, le=3600.0, description=(
        "shortest time an application is held before its release [s]; default its build-up time"))


class Consist(Strict):
    """A train: vehicles in order, and how its brakes are used.

    ``vehicles`` lists the train from the head to the tail: an entry is a group of vehicles standing
    one behind the other, so a locomotive mid-train (distributed power) is an entry between two groups
    of wagons. The whole-train quantities do not depend on the order; the coupler forces do
    (``physics.couplers``).

    ``service_brake_coefficient`` is beta_c of the air brake (TB/T 1407): the share of the full
    brake-cylinder force a service application gives; the planner brakes with the locomotives'
    electric brake plus the wagons' air brake at this coefficient. ``brake_deceleration_ms2``
    replaces all of that by a constant deceleration (railtoolkit's ``a_braking``).

    ``coupler_limit_kn``: the largest quasi-static force a coupler may carry, in tension or in
    compression; ``force_rate_limit_kn_per_s``: how fast the train's applied force (traction less
    braking) may change. The calculator refuses a plan beyond either; without them nothing is checked.

    ``air_brake_cycle``: the wagons' air brake applied, held, released and recharged (:class:`AirBrakeCycle`;
    its defaults when the file gives none). A consist braking at a constant ``brake_deceleration_ms2``, or
    without wagon air brakes, has no cycle.
    """

    schema_: Literal["locoplan/consist@1"] = Field(alias="schema")
    name: str = Field(min_length=1)
    vehicles: list[ConsistEntry] = Field(min_length=1)
    service_brake_coefficient: float = Field(default=0.5, ge=0, le=1)
    brake_deceleration_ms2: float | None = Field(default=None, gt=0, le=3.0)
    coupler_limit_kn: Annotated[float, plausible(100.0, PLAUSIBLE["coupler_kn"], "kN",
                                                 "a coupler limit is hundreds to thousands of kN: a No. 16/17 coupler body breaks at 4,005 kN")] | None = Field(
        default=None, gt=0, description="largest coupler force, tension or compression [kN]")
    force_rate_limit_kn_per_s: Annotated[float, plausible(1.0, PLAUSIBLE["force_rate_kn_per_s"], "kN/s",
                                                          "a rate of change outside this range is a slip of the unit")] | None = Field(
        default=None, gt=0, description="largest rate of change of traction less braking [kN/s]")
    air_brake_cycle: AirBrakeCycle = Field(default_factory=AirBrakeCycle)

    @model_validator(mode="after")
    def _check(self) -> "Consist":
        total = sum(e.count for e in self.vehicles)
        if total > PLAUSIBLE["count"]:
            raise RuleViolations([(("vehicles",), f"{total} vehicles is implausible for one train (limit {PLAUSIBLE['count']})")])
        return self
