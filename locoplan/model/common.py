"""Shared pieces of the file schemas: strict base model and rule violations that carry a field location."""

from __future__ import annotations

from pydantic import AfterValidator, BaseModel, ConfigDict


class Strict(BaseModel):
    """Frozen, unknown keys forbidden (a typo is never silently ignored), strict types (a quoted "55" is not a number),
    numbers finite (YAML's .inf and .nan are never a length, a speed or a force)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False, defer_build=True)


class RuleViolations(ValueError):
    """Raised by model validators for cross-field rules; carries ``(loc, message)`` pairs.

    pydantic wraps it into a ``ValidationError`` and keeps the instance in ``ctx["error"]``, so the
    loader can report each violation at its own field (and YAML line) instead of at the file root.
    """

    def __init__(self, problems: list[tuple[tuple, str]]):
        self.problems = problems
        super().__init__("; ".join(f"{'.'.join(map(str, loc))}: {msg}" for loc, msg in problems))


def plausible(lo: float, hi: float, unit: str, why: str) -> AfterValidator:
    """A field check ``lo <= value <= hi`` whose message says the bound and why it exists, e.g.
    ``length_m: 1e-06 m is implausible: ... (expected 10 .. 2,000,000 m)``. Use as
    ``Annotated[float, plausible(...)]`` after the type's own checks (finite, > 0)."""

    def check(value: float) -> float:
        if not lo <= value <= hi:
            raise RuleViolations([((), f"{number(value) if isinstance(value, int) else format(value, 'g')} {unit} is implausible: {why} (expected {number(lo)} .. {number(hi)} {unit})")])
        return value

    return AfterValidator(check)


def number(x: float) -> str:
    """A bound as people write it: 2,000,000 rather than 2e+06; 0.001 as is."""
    return f"{int(x):,}" if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"
