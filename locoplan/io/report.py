"""Results as JSON objects, CSV profiles and rich tables; files are written whole or not at all."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import InputError, Problem
from ..sim.result import CONDITIONS, Profile


_STAGED: ContextVar[list | None] = ContextVar("locoplan_staged_outputs", default=None)


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place.

    A failure leaves no partial file behind; a missing folder is an input error, not a traceback.
    Inside :func:`all_or_none` the rename waits until every output of the command is written.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(Problem(str(path), "", f"folder {folder} does not exist"))
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=folder)
    os.close(fd)
    staged = _STAGED.get()
    try:
        write(Path(tmp))
        if staged is None:
            os.replace(tmp, path)
        else:
            staged.append((tmp, path))
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


@contextmanager
def all_or_none():
    """A command's outputs appear together or not at all: files written inside the block (through
    :func:`atomic_write`) are renamed into place at its end, and all removed if it raises."""
    staged: list = []
    token = _STAGED.set(staged)
    try:
        yield
    except BaseException:
        for tmp, _ in staged:
            if os.path.exists(tmp):
                os.unlink(tmp)
        raise
    else:
        for tmp, path in staged:
            os.replace(tmp, path)
    finally:
        _STAGED.reset(token)


def check_output_path(path: str | Path | None, field: str, suffixes: tuple[str, ...]) -> None:
    """The one check of an output file before any work: a known suffix and an existing folder.
    ``field`` names the output (``out``, ``plot``...); the command line maps it to its flag."""
    if path is None:
        return
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise InputError(Problem(str(path), field, f"unknown output type {path.suffix.lower() or '(none)'!r}; use a "
                                 + " or ".join(suffixes) + " file name"))
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise InputError(Problem(str(path), "", f"folder {folder} does not exist"))


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


def clean(value: Any) -> Any:
    """JSON-safe copy: numpy scalars to Python, NaN/inf to None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {k: clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [clean(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def to_json(obj: Any) -> str:
    return json.dumps(clean(obj), indent=2, allow_nan=False)


PROFILE_COLUMNS = ("s_m", "t_s", "v_kmh", "limit_kmh", "gradient_permille", "condition", "traction_kn", "brake_kn")


def profile_rows(profile: Profile, plan: int = 0) -> list[dict]:
    """One row per grid node; cell quantities (condition, forces, limit, gradient) are those of the cell
    that starts at the node (the last node, the stop, repeats the last cell's limit and gradient)."""
    rows = []
    n_cells = len(profile.s_m) - 1
    for k, s in enumerate(profile.s_m):
        if np.isnan(profile.v_kmh[plan, k]):  # a failed plan's profile ends where it failed
            break
        c = min(k, n_cells - 1)
        last = k == n_cells or profile.condition[plan, c] < 0
        rows.append({
            "s_m": round(float(s), 3),
            "t_s": round(float(profile.t_s[plan, k]), 4),
            "v_kmh": round(float(profile.v_kmh[plan, k]), 4),
            "limit_kmh": float(profile.limit_kmh[c]),
            "gradient_permille": round(float(profile.gradient_permille[c]), 4),
            "condition": "" if last else CONDITIONS[int(profile.condition[plan, c])],
            "traction_kn": 0.0 if last else round(float(profile.traction_kn[plan, c]), 3),
            "brake_kn": 0.0 if last else round(float(profile.brake_kn[plan, c]), 3),
        })
    return rows


def write_output(path: str | Path, summary: dict, profile: Profile | None) -> None:
    """``--out``: ``.csv`` writes the profile, ``.json`` the summary plus the profile's columns."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        if profile is None:
            raise InputError(Problem(str(path), "out", "this command has no profile to write as CSV; use .json"))
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=PROFILE_COLUMNS, lineterminator="\n")
        writer.writeheader()
        writer.writerows(profile_rows(profile))
        atomic_write_text(path, buf.getvalue())
    elif suffix == ".json":
        data = dict(summary)
        if profile is not None:
            rows = profile_rows(profile)
            data["profile"] = {col: [r[col] for r in rows] for col in PROFILE_COLUMNS}
        atomic_write_text(path, to_json(data) + "\n")
    else:
        raise InputError(Problem(str(path), "out", f"unknown output type {suffix or '(none)'!r}; use .csv or .json"))
