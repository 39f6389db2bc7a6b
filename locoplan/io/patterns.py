"""Learned patterns, the reading: a patterns.json written by ``locoplan learn``, checked against its
format (keys and types) and returned as plain data; ``learn.patterns.Patterns.from_dict`` checks it
against the inputs this locoplan learns from and builds the patterns."""

from __future__ import annotations

from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from ..errors import InputError, Problem
from .load import parse_json, read_text, short_repr, yaml_kind


class PatternLayer(BaseModel):
    """One layer of a patterns.json (``upper`` also has its ``form``)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    features: list[str]
    order: int = Field(ge=1)
    types: list[str]
    mean: list[float]
    std: list[float]
    coef: list[float] | list[list[float]]
    low: list[float] | None = None
    high: list[float] | None = None
    form: str | None = None
    interact: str | None = None


class PatternFile(BaseModel):
    """A patterns.json: the settings and train model it was learned with, both layers, the fit report."""

    model_config = ConfigDict(extra="forbid", strict=True, populate_by_name=True)
    schema_: str = Field(alias="schema")
    locoplan_version: str
    settings: dict
    model: dict
    upper: PatternLayer
    lower: PatternLayer
    report: dict
    inputs: dict | None = None  # the learn command's inputs and the files it read (logs), with their hashes
    input_files: list | None = None


def read_patterns_file(path: str | Path) -> dict:
    """The content of a patterns.json, its keys and types checked (``PatternFile``), as a plain dict
    (``schema``, ``settings``, ``model``, ``upper``, ``lower``, ``report``); a missing or malformed
    file is an input error (exit 2)."""
    path = Path(path)
    name = str(path)
    if not path.exists():
        raise InputError(Problem(name, "--patterns", "no such file"))
    data = parse_json(read_text(path), name)
    if isinstance(data, dict) and "schema" in data and not isinstance(data["schema"], str):
        raise InputError(Problem(name, "schema", f"expected the file's kind as text, 'locoplan/patterns@1', got "
                                 f"{yaml_kind(data['schema'])} ({short_repr(data['schema'])})"))
    try:
        f = PatternFile.model_validate(data)
    except ValidationError as exc:
        raise InputError([Problem(name, ".".join(str(x) for x in e["loc"]), e["msg"]) for e in exc.errors()]) from None
    return f.model_dump(by_alias=True)
