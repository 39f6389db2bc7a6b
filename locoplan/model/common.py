"""Shared pieces of the file schemas: strict base model and rule violations that carry a field location."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Strict(BaseModel):
    """Frozen, unknown keys forbidden (a typo is never silently ignored), strict types (a quoted "55" is not a number)."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class RuleViolations(ValueError):
    """Raised by model validators for cross-field rules; carries ``(loc, message)`` pairs.

    pydantic wraps it into a ``ValidationError`` and keeps the instance in ``ctx["error"]``, so the
    loader can report each violation at its own field (and YAML line) instead of at the file root.
    """

    def __init__(self, problems: list[tuple[tuple, str]]):
        self.problems = problems
        super().__init__("; ".join(f"{'.'.join(map(str, loc))}: {msg}" for loc, msg in problems))
