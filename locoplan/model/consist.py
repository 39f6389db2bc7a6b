"""Vehicle and consist file schemas (SPEC section 1)."""

from __future__ import annotations

from typing import Literal

from typing import Annotated

from pydantic import Field, model_validator

from .common import RuleViolations, Strict


class Resistance(Strict):
    """Davis coefficients of the basic resistance w0 = a + b v + c v^2 [N/kN], v in km/h."""

    a: float = Field(ge=0)
    b: float = Field(ge=0)
    c: float = Field(ge=0)


ForceCurve = list[Annotated[list[float], Field(min_length=2, max_length=2)]]
"""[[speed_kmh, force_kn], ...], linear between points."""


def _curve_problems(field: str, curve: ForceCurve | None) -> list[tuple[tuple, str]]:
    out: list[tuple[tuple, str]] = []
    if curve is None:
        return out
    if len(curve) < 2:
        out.append(((field,), "needs at least two [speed_kmh, force_kn] points"))
    for i, (v, f) in enumerate(curve):
        if v < 0 or f < 0:
            out.append(((field, i), f"speed and force must be >= 0 (got [{v:g}, {f:g}])"))
        if i and v <= curve[i - 1][0]:
            out.append(((field, i), f"speeds must increase ({v:g} after {curve[i - 1][0]:g})"))
    return out


class Vehicle(Strict):
    schema_: Literal["locoplan/vehicle@1"] = Field(alias="schema")
    name: str
    kind: Literal["locomotive", "wagon"]
    mass_t: float = Field(gt=0, description="locomotive mass, or a wagon's tare [t]")
    max_load_t: float | None = Field(default=None, ge=0, description="wagons: largest payload [t]")
    length_m: float = Field(gt=0)
    max_speed_kmh: float = Field(gt=0)
    resistance_n_per_kn: Resistance
    traction_kn: ForceCurve | None = None
    brake_kn: ForceCurve | None = None

    @model_validator(mode="after")
    def _check(self) -> "Vehicle":
        problems = _curve_problems("traction_kn", self.traction_kn) + _curve_problems("brake_kn", self.brake_kn)
        if self.kind == "locomotive":
            for field in ("traction_kn", "brake_kn"):
                if getattr(self, field) is None:
                    problems.append(((field,), "a locomotive needs its max force curve [[speed_kmh, force_kn], ...]"))
        if problems:
            raise RuleViolations(problems)
        return self


class ConsistEntry(Strict):
    type: str = Field(min_length=1, description="a vehicle's name")
    count: int = Field(ge=1)
    load_t: float = Field(default=0.0, ge=0, description="payload per wagon [t]")


class Consist(Strict):
    schema_: Literal["locoplan/consist@1"] = Field(alias="schema")
    name: str
    vehicles: list[ConsistEntry] = Field(min_length=1)
