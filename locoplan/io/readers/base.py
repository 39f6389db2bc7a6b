"""What every importer shares: the reader interface, the options, the files a reader returns, and the
checks that turn a malformed source value into a ``Problem`` naming the source file, its field (a
JSON path such as ``gradients.values[3][0]``) and why.

A reader is pure: it reads source files and returns the text of each file to write. Writing (all
files or none) and checking every written file against locoplan's schemas is ``importer``'s job.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Protocol

from ...errors import InputError, Problem

MAX_SPEED_KMH = 400.0
"""The route schema's largest speed limit [km/h]."""
MAX_GRADIENT_PERMILLE = 40.0
"""The route schema's steepest gradient [per mille]: steeper than any adhesion railway."""

SAFE_ID = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
"""Identifiers that become file names: letters, digits, '_', '-', '.'; no path separators, no leading dot."""


@dataclass(frozen=True)
class ImportOptions:
    """Options of ``locoplan import``. A reader names the ones it understands in ``Reader.options``.

    ``cap_kmh`` caps every speed limit [km/h]; ``leg`` picks one stop-to-stop leg (1-based) and
    ``all_legs`` asks for every leg explicitly (the default), ``journey`` the whole line as one route and a
    journey file with every stop (``locoplan journey``); ``load_fraction`` is the share of each
    wagon's load limit put on in the consist (1 = fully loaded). Networks (osrd, railml): the path runs
    ``from_station`` .. ``to_station`` through the ``via`` stations in order (railml: or along ``tracks``),
    stopping at ``stops``; ``speed_tag`` (osrd) / ``category`` (railml) pick a train category's speed
    limits; ``thermal``: the train runs on its own power (missing electrification and neutral sections
    cut no traction). ``mode`` (osrd-train): the traction mode whose effort curve is written.
    ``command`` is the command line recorded in each file's header.
    """

    cap_kmh: float | None = None
    leg: int | None = None
    all_legs: bool = False
    journey: bool = False
    load_fraction: float = 1.0
    from_station: str | None = None
    to_station: str | None = None
    via: tuple[str, ...] = ()
    stops: tuple[str, ...] = ()
    speed_tag: str | None = None
    thermal: bool = False
    mode: str | None = None
    tracks: tuple[str, ...] = ()
    category: str | None = None
    command: str = ""


@dataclass(frozen=True)
class ImportedFile:
    """One file to write: ``relpath`` inside the output folder, its kind (route / vehicle / consist),
    its complete text (provenance header + YAML), a one-line summary for the user, and where a
    problem in it came from: ``source_fields`` maps a top-level key of the written file to the source
    field it was converted from (so that a schema violation names the source, not the output)."""

    relpath: str
    kind: str
    text: str
    summary: str
    source_file: str
    source_fields: dict[str, str] = field(default_factory=dict)
    source_lines: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Imported:
    """What a reader returns: the files, the licence file to ship beside them (or None) and notes
    the user should see (e.g. a curve clamped to the schema's minimum radius)."""

    files: list[ImportedFile]
    licence: Path | None = None
    licence_name: str = ""
    notes: list[str] = field(default_factory=list)
    more_licences: list[tuple[str, Path]] = field(default_factory=list)
    """Further licence texts the licence needs beside it (file name written, source), e.g. the GPL under the LGPL."""


class Reader(Protocol):
    """A source format (its description is its line in ``FORMATS``). ``options``: the ``ImportOptions``
    fields it uses (others are refused); ``min_files``/``max_files``: how many source files it takes."""

    name: str
    options: frozenset[str]
    min_files: int
    max_files: int

    def read(self, sources: list[Path], options: ImportOptions) -> Imported: ...


# ------------------------------------------------------------------------------------------ field checks
def path_str(loc: tuple) -> str:
    """('gradients', 'values', 3, 0) -> 'gradients.values[3][0]' (JSON-path style, as a user reads it)."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


class SourceChecker:
    """Collects problems of one source file; ``line_of`` maps a key path to its line (YAML) or is None (JSON)."""

    def __init__(self, file: str, line_of: Callable[[tuple], int | None] | None = None):
        self.file = file
        self.line_of = line_of or (lambda loc: None)
        self.problems: list[Problem] = []

    def add(self, loc: tuple, message: str) -> None:
        self.problems.append(Problem(self.file, path_str(loc), message, self.line_of(loc)))

    def fail(self, loc: tuple, message: str):
        """Record and raise at once (for a problem after which nothing further can be checked)."""
        self.add(loc, message)
        self.raise_if_any()

    def raise_if_any(self) -> None:
        if self.problems:
            raise InputError(self.problems)

    def get(self, data: Any, loc: tuple, kind: type | tuple, what: str, required: bool = True) -> Any:
        """``data[loc[-1]]`` checked to be of ``kind``; missing / wrong type is a problem (None returned)."""
        key = loc[-1]
        if not isinstance(data, dict) or key not in data:
            if required:
                self.add(loc, f"required field is missing ({what})")
            return None
        value = data[key]
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            self.add(loc, f"expected {what}, got {type(value).__name__} {value!r}"[:200])
            return None
        return value

    def number(self, value: Any, loc: tuple, what: str) -> float | None:
        """A finite number (not a bool, not a quoted string), else a problem and None."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.add(loc, f"{what} must be a number (got {value!r})"[:200])
            return None
        if not math.isfinite(value):
            self.add(loc, f"{what} must be finite (got {value!r})")
            return None
        return float(value)

    def speed_kmh(self, value: Any, loc: tuple, factor: float = 1.0) -> float | None:
        """A speed limit converted to km/h by ``factor`` and inside the route schema's (0, 400]."""
        v = self.number(value, loc, "speed limit")
        if v is not None and not 0 < v * factor <= MAX_SPEED_KMH:
            self.add(loc, f"speed limit must be > 0 and <= {MAX_SPEED_KMH:g} km/h (got {v * factor:g})")
            return None
        return None if v is None else v * factor

    def gradient_permille(self, value: Any, loc: tuple, factor: float = 1.0, what: str = "gradient") -> float | None:
        """A gradient converted to per mille by ``factor`` and inside the route schema's +-40."""
        g = self.number(value, loc, what)
        if g is not None and abs(g * factor) > MAX_GRADIENT_PERMILLE:
            self.add(loc, f"{what} {g * factor:g} per mille is beyond the route schema's +-{MAX_GRADIENT_PERMILLE:g} "
                          "(steeper than any adhesion railway)")
            return None
        return None if g is None else g * factor

    def unit(self, value: Any, loc: tuple, table: dict[str, float], what: str) -> float | None:
        """The factor that converts a value in unit ``value`` to locoplan's unit; unknown units are a problem."""
        if not isinstance(value, str) or value not in table:
            known = ", ".join(repr(u) for u in table)
            self.add(loc, f"unknown {what} unit {value!r} (known: {known})")
            return None
        return table[value]

    def identifier(self, value: Any, loc: tuple, what: str) -> str | None:
        """An identifier that becomes a file name: a non-empty string of letters, digits, '_', '-', '.'."""
        if value is None:
            self.add(loc, f"required field is missing ({what})")
            return None
        if not isinstance(value, str) or not SAFE_ID.match(value):
            self.add(loc, f"{what} must be letters, digits, '_', '-' or '.' (it names the output file; got {value!r})")
            return None
        return value


def increasing(check: SourceChecker, positions: list[float | None], loc_of: Callable[[int], tuple], what: str) -> None:
    """Positions must strictly increase; name the first entry that does not."""
    prev = None
    for i, s in enumerate(positions):
        if s is None:
            continue
        if prev is not None and s <= prev:
            check.add(loc_of(i), f"{what} must increase strictly ({s:g} m after {prev:g} m)")
            return
        prev = s


def licence_near(source: Path) -> tuple[Path | None, str]:
    """A LICENSE file beside the source or up to two folders above it, and its copyright line."""
    for folder in (source.parent, source.parent.parent, source.parent.parent.parent):
        candidate = folder / "LICENSE"
        if candidate.is_file():
            from ..load import read_text

            try:
                text = read_text(candidate)
            except InputError:
                return None, ""
            line = next((ln.strip() for ln in text.splitlines() if ln.strip().lower().startswith("copyright")), "")
            return candidate, line
    return None, ""

