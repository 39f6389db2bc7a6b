"""Results as JSON objects and CSV rows (run summaries, profiles): the formats of ``--json`` and
``--out``; the files themselves are written through :mod:`locoplan.reporting.files`."""

from __future__ import annotations

import csv
import io
import json
import math
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Any, Optional

import numpy as np

from ..errors import InputError, Problem
from ..io.load import files_read, hash_file, recording_reads
from ..physics.units import kmh_from_e
from ..sim.result import CONDITIONS, Profile
from .files import atomic_write_text


# ------------------------------------------------------------------------------------------ provenance
_PROVENANCE: ContextVar[Optional[dict]] = ContextVar("locoplan_provenance", default=None)

PROVENANCE = ("locoplan_version", "inputs", "input_files")
"""Keys every result JSON of a command has (its --json object and its --out .json files): the version,
the inputs as given on the command line, and every file read with its content hash."""


@contextmanager
def provenance(inputs: dict):
    """A command's run: the ``inputs`` it was given (``{"route": "routes/x.yaml", ...}``) and, recorded
    while it runs, every file it reads; :func:`provenance_fields` says them."""
    with recording_reads():
        token = _PROVENANCE.set(dict(inputs))
        try:
            yield
        finally:
            _PROVENANCE.reset(token)


def provenance_fields() -> dict:
    """``{"locoplan_version", "inputs", "input_files"}`` of the current :func:`provenance` (empty outside
    one). ``input_files`` lists each file read (``{"path", "sha256", "bytes"}``, in the order first read),
    then each file given in ``inputs`` that was read elsewhere (a worker process, SQLite), hashed now."""
    import os

    from .. import __version__

    inputs = _PROVENANCE.get()
    if inputs is None:
        return {}
    files = list(files_read() or [])
    seen = {os.path.realpath(f["path"]) for f in files}
    for value in inputs.values():
        for path in value if isinstance(value, list) else [value]:
            key = os.path.realpath(str(path))
            if key not in seen and (entry := hash_file(path)) is not None:
                files.append(entry)
                seen.add(key)
    return {"locoplan_version": __version__, "inputs": inputs, "input_files": files}


def with_provenance(data: Any) -> Any:
    """``data`` (a result object) with :func:`provenance_fields` added, inside a command's run."""
    if not isinstance(data, dict) or _PROVENANCE.get() is None:
        return data
    return {**data, **provenance_fields()}


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


def csv_cell(value: Any) -> Any:
    """A CSV cell that spreadsheets and ``pandas.read_csv`` read as what it is: numbers as numbers,
    booleans as ``true`` / ``false``, no value (None, NaN) as an empty cell, a list or a dict as JSON
    text (``[0.5, 0.5]`` in JSON, never Python's ``True`` or ``(0.5, 0.5)``)."""
    value = clean(value)
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return value


SPLIT_COLUMNS = {"weights": ("w_time", "w_energy"), "window_s": ("window_from_s", "window_to_s")}
"""Lists of a fixed length that a CSV row gives as columns of their own."""


def csv_row(row: dict) -> dict:
    """A run's fields as CSV cells, :data:`SPLIT_COLUMNS` split into their columns."""
    out = {}
    for key, value in row.items():
        if key in SPLIT_COLUMNS and isinstance(value, (list, tuple)) and len(value) == len(SPLIT_COLUMNS[key]):
            out.update({k: csv_cell(v) for k, v in zip(SPLIT_COLUMNS[key], value)})
        elif key in SPLIT_COLUMNS and value is None:
            out.update(dict.fromkeys(SPLIT_COLUMNS[key], ""))
        else:
            out[key] = csv_cell(value)
    return out


def to_json(obj: Any) -> str:
    return json.dumps(clean(obj), indent=2, allow_nan=False)


PROFILE_COLUMNS = ("s_m", "t_s", "v_kmh", "limit_kmh", "gradient_permille", "condition", "traction_kn", "brake_kn")
COUPLER_COLUMNS = ("coupler_tension_kn", "coupler_compression_kn")
"""The largest tensile and the largest compressive force in any coupler of the train in the cell that starts
at the node [kN] (``physics.couplers``; both >= 0); written for a train of more than one vehicle."""
AIR_COLUMNS = ("air_brake", "air_event")
"""The wagons' air brake in the cell that starts at the node (with its cycle): ``applied`` or ``released``, and
``apply`` where an application begins in that cell, ``release`` where it is released at the node."""
FILE_COLUMNS = ("limit_file_kmh", "gradient_file_permille")
"""The route file's own limit and gradient at each node, beside ``limit_kmh`` / ``gradient_permille``,
which are what the train meets: the lowest of the limits under its length (held until the tail clears
a lower one) and its top speed, and the equivalent gradient (averaged over the train, with curves and
tunnels). Written when the route is known (simulate, optimize, advise, ocp --objective energy)."""


PLACE_COLUMNS = ("km_post", "station")
"""Where each node is as people on the line read it (written when the route is known, after every other
column): its kilometre post [km] (the route's chainage, else the km from the start) and, at the node nearest
each of the route's stations, the station's name (empty elsewhere)."""


def section_values(sections, attr: str, s_m) -> np.ndarray:
    """The value ``attr`` of the contiguous ``sections`` (from_m, to_m) at each position ``s_m`` [m]
    (the section that starts at or before it; the last one holds at the end of the line)."""
    starts = np.array([x.from_m for x in sections], dtype=float)
    values = np.array([getattr(x, attr) for x in sections], dtype=float)
    k = np.clip(np.searchsorted(starts, np.asarray(s_m, dtype=float), side="right") - 1, 0, len(values) - 1)
    return values[k]


def profile_columns(profile: Profile, route=None) -> tuple[str, ...]:
    """The columns of a profile's CSV: :data:`PROFILE_COLUMNS`, the coupler forces where the profile has them,
    the route file's own values where the route is known."""
    return (PROFILE_COLUMNS + (COUPLER_COLUMNS if profile.coupler_tension_kn is not None else ())
            + (AIR_COLUMNS if profile.air is not None else ()) + (FILE_COLUMNS + PLACE_COLUMNS if route is not None else ()))


def profile_rows(profile: Profile, plan: int = 0, route=None) -> list[dict]:
    """One row per grid node; cell quantities (condition, forces, limit, gradient) are those of the cell
    that starts at the node (the last node, the stop, repeats the last cell's limit and gradient). With
    ``route``, also the file's own limit and gradient (:data:`FILE_COLUMNS`)."""
    rows = []
    n_cells = len(profile.s_m) - 1
    if route is not None:
        starts = profile.s_m[np.minimum(np.arange(len(profile.s_m)), n_cells - 1)]
        file_limit = section_values(route.speed_limits, "kmh", starts)
        file_grade = section_values(route.gradients, "permille", starts)
        from .posts import POST_DIGITS, node_stations, post_km

        posts = np.round(np.atleast_1d(post_km(route, profile.s_m)), POST_DIGITS)
        stations = node_stations(route, profile.s_m)
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
            **({} if profile.coupler_tension_kn is None else {
                "coupler_tension_kn": 0.0 if last else round(float(profile.coupler_tension_kn[plan, c]), 1),
                "coupler_compression_kn": 0.0 if last else round(float(profile.coupler_compression_kn[plan, c]), 1)}),
            **({} if profile.air is None else _air_cells(profile.air[plan, c], last)),
            **({} if route is None else {"limit_file_kmh": float(file_limit[k]),
                                         "gradient_file_permille": round(float(file_grade[k]), 4),
                                         "km_post": float(posts[k]), "station": stations.get(k, "")}),
        })
    return rows


def _air_cells(code: int, last: bool) -> dict:
    """The :data:`AIR_COLUMNS` of a cell from its ``Profile.air`` code."""
    from ..sim.result import AIR_APPLIED, AIR_ON, AIR_RELEASED

    if last:
        return {"air_brake": "", "air_event": ""}
    return {"air_brake": "applied" if code in (AIR_ON, AIR_APPLIED) else "released",
            "air_event": {AIR_APPLIED: "apply", AIR_RELEASED: "release"}.get(int(code), "")}


RUN_COLUMNS = ("route", "consist", "strategy", "algorithm", "seed", "planned_time_s", "w_time", "w_energy", "feasible",
               "reason", "running_time_s", "traction_energy_kwh", "recovered_energy_kwh", "net_energy_kwh", "energy_at_t0_kwh", "punctuality_error_s", "punctual", "fitness",
               "e_min_kwh", "e_min_source", "optimum_kwh", "gap_to_optimum_kwh", "gap_to_optimum_percent", "optimum_accuracy_percent", "cruise_kmh",
               "switches", "coasts", "energy_reduction_percent", "max_coupler_tension_kn", "max_coupler_compression_kn",
               "air_applications", "min_recharge_margin_s", "objective", "n_evaluations", "solve_time_s", "plan")
"""Columns of ``--out FILE.csv`` of the commands with several runs (compare, sweep, study): one row per
run, the ``--json`` summary's fields of the same names (weights split into w_time, w_energy; empty when
a run has no value, e.g. no running time for a plan that stalls)."""


def rows_csv(rows: list[dict], columns) -> str:
    """Rows (dicts) as CSV text with ``columns`` in this order (other keys left out)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(columns), lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    writer.writerows({k: csv_cell(v) for k, v in r.items()} for r in rows)
    return buf.getvalue()


def run_rows_csv(rows: list[dict]) -> str:
    """Run summaries as CSV text in :data:`RUN_COLUMNS` order."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=RUN_COLUMNS, lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    for r in rows:
        w = r.get("weights") or (None, None)
        row = {k: r.get(k) for k in RUN_COLUMNS}
        row.update(w_time=w[0], w_energy=w[1])
        writer.writerow({k: csv_cell(v) for k, v in row.items()})
    return buf.getvalue()


def write_output(path: str | Path, summary: dict, profile: Profile | None, route=None) -> None:
    """``--out``: ``.csv`` writes the profile (or, for several runs ``{"results": [...]}``, one row per
    run, :data:`RUN_COLUMNS`), ``.json`` the summary plus the profile's columns."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv" and profile is None and isinstance(summary.get("results"), list):
        atomic_write_text(path, run_rows_csv(summary["results"]))
    elif suffix == ".csv":
        if profile is None:
            raise InputError(Problem(str(path), "--out", "this command has no profile to write as CSV; use .json"))
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=profile_columns(profile, route), lineterminator="\n")
        writer.writeheader()
        writer.writerows({k: csv_cell(v) for k, v in r.items()} for r in profile_rows(profile, route=route))
        atomic_write_text(path, buf.getvalue())
    elif suffix == ".json":
        data = dict(summary)
        if profile is not None:
            rows = profile_rows(profile, route=route)
            data["profile"] = {col: [r[col] for r in rows] for col in profile_columns(profile, route)}
        atomic_write_text(path, to_json(with_provenance(data)) + "\n")
    else:
        raise InputError(Problem(str(path), "--out", f"unknown output type {suffix or '(none)'!r}; use .csv or .json"))


def write_json(path: str | Path, data: Any) -> None:
    """``data`` as a ``.json`` file (JSON-safe, indented, one final newline)."""
    atomic_write_text(path, to_json(data) + "\n")


def write_rows(path: str | Path, data: dict) -> None:
    """``{"results": [rows], ...}`` as ``.json`` (the whole object) or ``.csv`` (the rows, their own
    columns in their order)."""
    path = Path(path)
    if path.suffix.lower() == ".json":
        write_json(path, with_provenance(data))
        return
    rows = data["results"]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    w.writeheader()
    w.writerows({k: csv_cell(v) for k, v in r.items()} for r in rows)  # true/false, empty cells, as every CSV
    atomic_write_text(path, buf.getvalue())


def optimum_columns(run) -> dict:
    """The optimum at its collocation points (for ``--out .json``)."""
    sol = run.solution.solution
    n = sol.grid.n_col
    v = kmh_from_e(np.maximum(sol.X[0, :n], 0.0))
    cols = {"s_m": np.round(sol.grid.s_col, 3).tolist(), "v_kmh": np.round(v, 4).tolist(),
            "t_s": np.round(sol.X[1, :n], 4).tolist()}
    for name, row in zip(sol.problem.model.controls, sol.U):
        cols[f"{name}_kn"] = np.round(row, 3).tolist()
    return cols
