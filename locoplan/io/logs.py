"""Drivers' logs, the reading: one log CSV (``read_log_csv``) and whole log sets, manifests or sidecars
with their routes and consists (``load_logs``). The format is described in ``model/logs.py``.

Every problem is reported as ``file:line: column N (name): why`` (CSV) or ``file:line: field: why``
(manifest); a log set with any problem is refused as a whole (exit 2).
"""

from __future__ import annotations

import csv
import difflib
import hashlib
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, Problem
from ..model.logs import (ACTIONS, MANIFEST_NAME, MANIFEST_SCHEMAS, OPTIONAL_COLUMNS, REQUIRED_COLUMNS, DriverRun,
                          LogData, LoggedRun)
from ..model.route import Route
from ..model.train import Train
from .load import _line_for, decode_text, load_route, load_train, read_bytes, read_text, read_yaml, validate_model

MAX_PROBLEMS_PER_FILE = 20
"""After this many problems in one CSV the rest of it is summarised (a wrong file has thousands)."""

COVERAGE_TOLERANCE_M = 50.0
"""A log must start within this distance of the route's start and end within it of the route's end."""

# Units refused in column names, per quantity: what the unit is, and how to convert it.
FOREIGN_UNITS = {
    "speed": {"mph": ("mph", "speed_kmh = speed_mph x 1.609344"), "ms": ("m/s", "speed_kmh = speed_ms x 3.6"),
              "mps": ("m/s", "speed_kmh = speed_mps x 3.6"), "kph": ("km/h under another name", "rename it speed_kmh"),
              "fps": ("ft/s", "speed_kmh = speed_fps x 1.09728"), "kn": ("knots", "speed_kmh = speed_kn x 1.852")},
    "position": {"ft": ("feet", "position_m = position_ft x 0.3048"), "mi": ("miles", "position_m = position_mi x 1609.344"),
                 "km": ("km", "position_m = position_km x 1000"), "yd": ("yards", "position_m = position_yd x 0.9144")},
    "time": {"min": ("minutes", "time_s = time_min x 60"), "h": ("hours", "time_s = time_h x 3600"),
             "ms": ("milliseconds", "time_s = time_ms / 1000")},
    "force": {"lbf": ("pound-force", "force_kn = force_lbf x 0.0044482"), "kip": ("kips", "force_kn = force_kip x 4.44822"),
              "n": ("newtons", "force_kn = force_n / 1000"), "kgf": ("kilogram-force", "force_kn = force_kgf x 0.00980665"),
              "tf": ("tonne-force", "force_kn = force_tf x 9.80665")},
}


def _column_problem(name: str, known: tuple[str, ...]) -> str | None:
    """Why an unexpected column name is refused: a foreign unit, or a likely typo."""
    stem, _, unit = name.partition("_")
    if stem in FOREIGN_UNITS and unit in FOREIGN_UNITS[stem]:
        what, how = FOREIGN_UNITS[stem][unit]
        want = next(c for c in REQUIRED_COLUMNS if c.startswith(stem + "_"))
        return (f"units in {what} are not accepted: locoplan logs are in SI units with the unit in the column "
                f"name; write {want} ({how})")
    close = difflib.get_close_matches(name, known, n=1)
    same_stem = [c for c in known if c.partition("_")[0] == stem]
    hint = f"; did you mean '{(same_stem or close)[0]}'?" if (same_stem or close) else ""
    return f"unknown column{hint} (allowed: {', '.join(known)})"


LOG_BOUNDS = {
    "time_s": (0.0, 604_800.0, "s", "a run's clock (or the time of day) in seconds: no run is planned longer than a week"),
    "position_m": (-2_000_000.0, 2_000_000.0, "m", "the longest route allowed is 2,000 km"),
    "speed_kmh": (0.0, 600.0, "km/h", "no train runs faster (a vehicle's top speed is at most 600 km/h)"),
    "force_kn": (-100_000.0, 100_000.0, "kN", "no train of at most 100,000 t pulls or brakes with more"),
    "notch": (-100.0, 100.0, "", "a driver's handle has a few dozen notches at most"),
}
"""Plausible values of each numeric log column (low, high, unit, why): a value outside is refused at its file and
line (1e308 is no force, and a log of impossible values would be learnt from). A force is held, besides, to what
the run's train can give (:data:`FORCE_MARGIN`)."""

FORCE_MARGIN = 1.25
"""A logged force may exceed the train's largest traction (or braking) force by this factor: a recorder's reading
is not the model's curve, but a force well past it is no reading of that train."""


def force_limits_kn(train: Train) -> tuple[float, float]:
    """(largest traction, largest braking) force ``train`` can give [kN]; a log may hold :data:`FORCE_MARGIN` x that."""
    def top(a) -> float:
        return float(np.max(a)) if np.size(a) else 0.0
    return top(train.traction_kn), top(train.electric_brake_kn) + top(train.air_brake_kn)


def _col(j: int, name: str) -> str:
    return f"column {j + 1} ({name})"


def read_log_csv(path: Path, text: str | None = None, train: Train | None = None) -> LogData:
    """Read and check one log CSV. Every problem names the file, the line and the column. Every value is held to
    :data:`LOG_BOUNDS`; with the run's ``train``, each force also to what that train can give."""
    name = str(path)
    if text is None:
        text = read_text(path)  # a regular UTF-8 file of at most 10 MiB (a FIFO or /dev/zero is refused)
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        header = []
    except csv.Error as exc:
        raise InputError(Problem(name, "", f"not valid CSV: {exc}", 1)) from None
    if not header or not any(h.strip() for h in header):
        raise InputError(Problem(name, "", "file is empty: expected a header row "
                                 f"{','.join(REQUIRED_COLUMNS)}[,notch][,action]", 1 if text.strip() else None))
    cols = [h.strip() for h in header]
    known = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
    problems: list[Problem] = []
    seen: dict[str, int] = {}
    for j, c in enumerate(cols):
        if c in seen:
            problems.append(Problem(name, _col(j, c), f"duplicate column (also column {seen[c] + 1})", 1))
        seen.setdefault(c, j)
        if c not in known:
            problems.append(Problem(name, _col(j, c), _column_problem(c, known), 1))
    foreign = {c.partition("_")[0] for c in cols if c not in known and c.partition("_")[0] in FOREIGN_UNITS}
    for c in REQUIRED_COLUMNS:
        if c not in seen and c.partition("_")[0] not in foreign:  # a column in other units is reported already
            problems.append(Problem(name, "header", f"required column '{c}' is missing (columns found: {', '.join(cols)})", 1))
    if problems:
        raise InputError(problems)
    idx = {c: seen[c] for c in known if c in seen}
    values: dict[str, list] = {c: [] for c in idx}
    lines: list[int] = []
    extra = 0

    def add(problem: Problem) -> None:
        nonlocal extra
        if len(problems) < MAX_PROBLEMS_PER_FILE:
            problems.append(problem)
        else:
            extra += 1

    prev: dict[str, float] = {}
    traction_max, brake_max = force_limits_kn(train) if train is not None else (math.inf, math.inf)
    try:
        for row in reader:
            line = reader.line_num
            if not row or not any(x.strip() for x in row):
                continue
            if len(row) != len(cols):
                add(Problem(name, "row", f"{len(row)} fields, the header has {len(cols)}", line))
                continue
            ok = True
            parsed: dict = {}
            for c, j in idx.items():
                raw = row[j].strip()
                if c == "action":
                    if raw.upper() not in ACTIONS:
                        add(Problem(name, _col(j, c), f"{raw!r} is not one of {', '.join(ACTIONS)}", line))
                        ok = False
                    parsed[c] = raw.upper()
                    continue
                try:
                    x = float(raw)
                except ValueError:
                    add(Problem(name, _col(j, c), f"not a number: {raw!r}", line))
                    ok = False
                    continue
                if not math.isfinite(x):
                    add(Problem(name, _col(j, c), f"must be a finite number (got {raw!r})", line))
                    ok = False
                    continue
                if c == "notch" and x != round(x):
                    add(Problem(name, _col(j, c), f"a notch is a whole number (got {raw!r})", line))
                    ok = False
                if c == "speed_kmh" and x < 0:
                    add(Problem(name, _col(j, c), f"speed must be >= 0 km/h (got {raw})", line))
                    ok = False
                elif not LOG_BOUNDS[c][0] <= x <= LOG_BOUNDS[c][1]:
                    lo, hi, unit, why = LOG_BOUNDS[c]
                    add(Problem(name, _col(j, c), f"{raw} is not a plausible value: must be in [{lo:,g}, {hi:,g}]"
                                f"{' ' + unit if unit else ''} ({why})", line))
                    ok = False
                elif c == "force_kn" and (x > FORCE_MARGIN * traction_max + 1.0 or -x > FORCE_MARGIN * brake_max + 1.0):
                    what, top = ("traction", traction_max) if x > 0 else ("braking", brake_max)
                    add(Problem(name, _col(j, c), f"{raw} kN is more {what} than the train '{train.name}' can give (at "
                                f"most {top:,.0f} kN, {FORCE_MARGIN:g} x that allowed for a reading): "
                                "a log of another train, or a column in other units?", line))
                    ok = False
                parsed[c] = x
            if not ok:
                continue
            if "time_s" in prev and parsed["time_s"] <= prev["time_s"]:
                add(Problem(name, _col(idx["time_s"], "time_s"), f"time must rise: {parsed['time_s']:g} s is not after "
                            f"the previous row's {prev['time_s']:g} s (line {prev['line']})", line))
            if "position_m" in prev and parsed["position_m"] < prev["position_m"]:
                add(Problem(name, _col(idx["position_m"], "position_m"), f"positions are not monotone: "
                            f"{parsed['position_m']:g} m is behind the previous row's {prev['position_m']:g} m "
                            f"(line {prev['line']}); a log runs in the running direction", line))
            prev = {"time_s": parsed["time_s"], "position_m": parsed["position_m"], "line": line}
            for c in idx:
                values[c].append(parsed[c])
            lines.append(line)
    except csv.Error as exc:
        add(Problem(name, "", f"not valid CSV: {exc}", reader.line_num))
    if extra:
        problems.append(Problem(name, "", f"... and {extra} more problems in this file"))
    if not problems and len(lines) < 2:
        problems.append(Problem(name, "", f"needs at least two data rows (found {len(lines)})", reader.line_num or 1))
    if problems:
        raise InputError(problems)
    arr = {c: np.asarray(values[c], dtype=float) for c in idx if c != "action"}
    return LogData(arr["time_s"], arr["position_m"], arr["speed_kmh"], arr["force_kn"],
                   arr["notch"].astype(int) if "notch" in arr else None,
                   np.asarray(values["action"]) if "action" in idx else None)


@dataclass(frozen=True)
class LogFile:
    """A log CSV read and checked once, read again whenever its rows are wanted (``LoggedRun.data``): a log
    set is not held in memory (20,000 logs of a 20 km line are 1.7 GB of rows). The content's hash from the
    first read makes sure the rows read again are the ones checked: a log changed since is an input error."""

    path: Path
    sha256: bytes

    @classmethod
    def read_checked(cls, path: Path, train: Train | None = None) -> tuple["LogFile", LogData]:
        """The file and its rows, read and checked (``read_log_csv``; each force against ``train``'s)."""
        raw = read_bytes(path)
        return cls(path, hashlib.sha256(raw).digest()), read_log_csv(path, decode_text(raw, str(path)), train)

    def __call__(self) -> LogData:
        raw = read_bytes(self.path)
        if hashlib.sha256(raw).digest() != self.sha256:
            raise InputError(Problem(str(self.path), "", "changed while locoplan was using it (it was read and checked "
                                     "earlier in this command): run the command again"))
        return read_log_csv(self.path, decode_text(raw, str(self.path)))


MANIFEST_MAX_NODES = 400_000
"""Most values in a manifest: 20,000 runs (what ``drivers simulate`` writes at most) of 15 values each, with room
(a route's 100,000 would stop at about 6,600 runs)."""


def _yaml_entries(path: Path):
    """(model, line map) of a manifest or sidecar file, validated against its schema."""
    data, lines = read_yaml(path, MANIFEST_MAX_NODES)
    schema = data.get("schema")
    if schema not in MANIFEST_SCHEMAS:
        raise InputError(Problem(str(path), "schema", f"expected a driver-log manifest (schema: "
                                 f"{' or '.join(MANIFEST_SCHEMAS)}), got {schema!r}", _line_for(lines, ("schema",))))
    return validate_model(MANIFEST_SCHEMAS[schema], data, str(path), lines), lines


def _manifest_files(path: Path) -> list[Path]:
    """The manifest files a command-line LOGS argument stands for."""
    if not path.exists():
        raise InputError(Problem(str(path), "", "no such file or folder"))
    if path.is_file():
        if path.suffix.lower() == ".csv":
            side = path.with_suffix(".yaml")
            if not side.exists():
                raise InputError(Problem(str(path), "", f"a log needs its manifest: no {side.name} beside it and no "
                                         f"{MANIFEST_NAME} given"))
            return [side]
        return [path]
    if (path / MANIFEST_NAME).exists():
        return [path / MANIFEST_NAME]
    sidecars = sorted(p for p in path.glob("*.yaml") if p.with_suffix(".csv").exists())
    if sidecars:
        return sidecars
    nested = sorted(path.glob(f"*/{MANIFEST_NAME}"))
    if nested:
        return nested
    raise InputError(Problem(str(path), "", f"no {MANIFEST_NAME}, no per-run <log>.yaml beside a <log>.csv, and no "
                             f"sub-folder with a {MANIFEST_NAME}: nothing to read"))


def load_logs(paths: list[Path] | Path, stock_dir: str | Path | None = None) -> list[LoggedRun]:
    """Every run of the given log folders / manifests, checked. All problems are collected and raised
    together (``InputError``, exit 2): a log set is used whole or not at all. Each log is read and checked
    here, and its rows dropped: ``LoggedRun.data`` reads them again (``LogFile``)."""
    paths = [paths] if isinstance(paths, (str, Path)) else list(paths)
    problems: list[Problem] = []
    runs: list[LoggedRun] = []
    routes: dict[Path, Route] = {}
    trains: dict[tuple, Train] = {}
    manifests: list[Path] = []
    for p in paths:
        try:
            manifests += _manifest_files(Path(p))
        except InputError as exc:
            problems += exc.problems
    for mf in manifests:
        try:
            model, lines = _yaml_entries(mf)
        except InputError as exc:
            problems += exc.problems
            continue
        if isinstance(model, DriverRun):
            entries = [(model, (), model.route, model.consist)]
            synthetic = model.synthetic
        else:
            entries = [(r, ("runs", i), r.route or model.route, r.consist or model.consist) for i, r in enumerate(model.runs)]
            synthetic = model.synthetic
        base = mf.parent
        for entry, loc, route_ref, consist_ref in entries:
            where = lambda key: (".".join([f"runs[{loc[1]}]"] if loc else []) + ("." if loc else "") + key)  # noqa: E731
            line = lambda key: _line_for(lines, loc + (key,))  # noqa: E731
            bad = False
            for key, ref in (("route", route_ref), ("consist", consist_ref)):
                if ref is None:
                    problems.append(Problem(str(mf), where(key), f"no {key}: give it for the run or for the whole manifest",
                                            line(key) or _line_for(lines, loc)))
                    bad = True
            if bad:
                continue
            route_path = (base / route_ref).resolve()
            if not route_path.exists():
                own = getattr(entry, "route", None) is not None and loc  # given for the run, or for the manifest
                problems.append(Problem(str(mf), where("route") if own else "route", f"no such route file: {route_ref} "
                                        f"(looked for {route_path})", line("route") if own else _line_for(lines, ("route",))))
                continue
            log_path = base / entry.log
            if not log_path.exists():
                problems.append(Problem(str(mf), where("log"), f"no such log file: {entry.log} (looked for {log_path})",
                                        line("log")))
                continue
            consist_path = base / consist_ref
            consist_spec = str(consist_path) if consist_path.exists() else consist_ref
            try:
                if route_path not in routes:
                    routes[route_path] = load_route(route_path)
                key = (consist_spec, str(stock_dir))
                if key not in trains:
                    trains[key] = load_train(consist_spec, stock_dir)
                log_file, data = LogFile.read_checked(log_path, trains[key])
            except InputError as exc:
                problems += exc.problems
                continue
            route, train = routes[route_path], trains[key]
            n_before = len(problems)
            if abs(entry.mass_t - train.mass_t) > 0.01 * train.mass_t:
                problems.append(Problem(str(mf), where("mass_t"), f"{entry.mass_t:g} t disagrees with the consist "
                                        f"'{train.name}' ({train.mass_t:g} t) by more than 1 %", line("mass_t")))
            if abs(entry.actual_time_s - data.running_time_s) > max(2.0, 0.002 * data.running_time_s):
                problems.append(Problem(str(mf), where("actual_time_s"), f"{entry.actual_time_s:g} s, but the log "
                                        f"{entry.log} runs {data.running_time_s:g} s", line("actual_time_s")))
            last_line = data.time_s.size + 1
            if data.position_m[0] > COVERAGE_TOLERANCE_M:
                problems.append(Problem(str(log_path), _col(1, "position_m"), f"the log starts at {data.position_m[0]:,.1f} m: "
                                        f"a run must start at the route's start (within {COVERAGE_TOLERANCE_M:g} m)", 2))
            if abs(data.position_m[-1] - route.length_m) > COVERAGE_TOLERANCE_M:
                problems.append(Problem(str(log_path), _col(1, "position_m"), f"the log ends at {data.position_m[-1]:,.1f} m, "
                                        f"the route '{route.name}' is {route.length_m:,.0f} m long: a run must cover it "
                                        f"(within {COVERAGE_TOLERANCE_M:g} m)", last_line))
            if len(problems) > n_before:
                continue
            runs.append(LoggedRun(log_path, mf, _line_for(lines, loc) if loc else None, entry.driver_id, route_path,
                                  route, Path(consist_spec), train, entry.mass_t, entry.scheduled_time_s,
                                  entry.actual_time_s, entry.date, synthetic, data.running_time_s,
                                  data.traction_energy_kwh, log_file))
    if problems:
        raise InputError(problems)
    if not runs:
        raise InputError(Problem(", ".join(str(p) for p in paths), "", "no runs found"))
    return runs


