"""Closed-loop runs and on-board states: the disturbance file (how the real train and its run differ from the model)
and one line of a re-planning stream."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .common import RuleViolations, Strict, plausible


class Restriction(Strict):
    """A temporary speed restriction: the limit no higher than ``kmh`` from ``from_m`` to ``to_m``."""

    from_m: float = Field(ge=0)
    to_m: float
    kmh: Annotated[float, plausible(1.0, 400.0, "km/h", "below 1 km/h a train does not run")]

    @model_validator(mode="after")
    def _order(self) -> "Restriction":
        if self.to_m <= self.from_m:
            raise RuleViolations([(("to_m",), f"must lie after from_m ({self.from_m:g} m)")])
        return self


class AnnouncedRestriction(Restriction):
    """A restriction the driver learns of when the train's head passes ``announced_at_m``."""

    announced_at_m: float = Field(ge=0)

    @model_validator(mode="after")
    def _announced(self) -> "AnnouncedRestriction":
        if self.announced_at_m > self.from_m:
            raise RuleViolations([(("announced_at_m",), f"must come at or before from_m ({self.from_m:g} m): a "
                                   "restriction is announced before the train reaches it")])
        return self


class Hold(Strict):
    """A stop at a signal: the train stands at ``at_m`` for ``s`` seconds."""

    at_m: float = Field(gt=0)
    s: Annotated[float, plausible(0.0, 86_400.0, "s", "a signal holds a train for at most a day")]


class Disturbance(Strict):
    """How a real run differs from the model (``locoplan drive``): the train's mass and resistance by factors, holds
    at signals, restrictions announced on the way, and the driver's reaction time and least time per condition."""

    schema_: Literal["locoplan/disturbance@1"] = Field(alias="schema")
    name: str = ""
    mass_factor: Annotated[float, plausible(0.5, 2.0, "", "the real train's mass as a share of the model's")] = 1.0
    resistance_factor: Annotated[float, plausible(0.2, 5.0, "", "the real running resistance as a share of the model's")] = 1.0
    holds: list[Hold] = []
    restrictions: list[AnnouncedRestriction] = []
    reaction_s: Annotated[float, plausible(0.0, 600.0, "s", "a driver applies advice within minutes")] = 0.0
    min_hold_s: Annotated[float, plausible(0.0, 3600.0, "s", "the least time a condition is held")] = 0.0

    @model_validator(mode="after")
    def _holds_in_order(self) -> "Disturbance":
        at = [h.at_m for h in self.holds]
        if any(b <= a for a, b in zip(at, at[1:])):
            raise RuleViolations([(("holds",), "holds must be sorted by at_m, one per place")])
        return self


class StreamState(Strict):
    """One line of ``locoplan replan --stream``: the train's state, and optionally a new planned arrival (clock since
    departure [s]) or a temporary speed restriction in force from now on."""

    s_m: float
    v_kmh: float
    t_s: float
    condition: Literal["T", "K", "C", "B"] | None = None
    air: Literal["charged", "applied", "recharging"] | None = None
    recharge_left_s: float | None = Field(default=None, ge=0)
    planned_arrival_s: float | None = Field(default=None, gt=0)
    restriction: Restriction | None = None
