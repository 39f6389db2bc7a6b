"""TTOBench track files (JSON, format in TTOBench's ``tracks/README.md``) to locoplan route files.

A track gives stops, and speed limits, gradients and curvatures as lists of [position, value...]
entries, each entry starting a section that runs to the next entry (the last one to the track's
end, its last stop). One route file is written per stop-to-stop leg; positions become metres from
the leg's start.

Curvature: TTOBench gives [position, radius at start, radius at end], signed (+ right, - left),
"infinity" for straight track; unequal radii mean a clothoid, whose curvature 1/R varies linearly
with distance. A constant section becomes a curve of radius |R|. A clothoid becomes one curve whose
radius is the inverse of its mean |curvature|: the curve resistance 600/R [N/kN] is linear in the
curvature, so this keeps the resistance work over the section exact (a point-mass train feels the
average instead of the ramp). Straight sections give no curve. A result sharper than the schema's
100 m minimum is set to 100 m, and the import says so (none of TTOBench's tracks has one).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...errors import InputError, Problem
from ...physics.units import KMH_PER_MS
from ..load import read_text
from . import emit
from .base import Imported, ImportedFile, ImportOptions, SourceChecker, increasing, licence_near

POSITION_UNITS = {"m": 1.0, "km": 1000.0}
VELOCITY_UNITS = {"km/h": 1.0, "m/s": KMH_PER_MS}
SLOPE_UNITS = {"permil": 1.0, "permille": 1.0, "‰": 1.0, "%": 10.0, "percent": 10.0}
RADIUS_UNITS = {"m": 1.0, "km": 1000.0}
STRAIGHT = {"infinity", "+infinity", "-infinity", "inf", "+inf", "-inf"}

MIN_RADIUS_M = 100.0
"""The route schema's smallest curve radius [m]."""


def load_json(path: Path) -> dict:
    """Parse a JSON file; a missing, unreadable or malformed file raises ``InputError`` (with the line)."""
    name = str(path)
    from ..load import parse_json

    data = parse_json(read_text(path), name)
    if not isinstance(data, dict):
        raise InputError(Problem(name, "", f"expected a JSON object with metadata, stops, speed limits, ...; got {type(data).__name__}"))
    return data


def _table(check: SourceChecker, data: dict, key: str, width: int, units: dict[str, dict[str, float]],
           required: bool, length_m: float | None) -> tuple[list[float], list[list[Any]]] | None:
    """A {units, values: [[position, v1, ...], ...]} block: positions [m] (start at 0, strictly increasing,
    inside the track) and the raw value columns; None if absent (and optional) or broken."""
    block = check.get(data, (key,), dict, "an object with 'units' and 'values'", required)
    if block is None:
        return None
    before = len(check.problems)
    unit_key = "unit" if width == 1 else "units"
    factors: dict[str, float | None] = {}
    if width == 1:
        factors["position"] = check.unit(block.get("unit"), (key, "unit"), POSITION_UNITS, "position")
    else:
        unit_block = check.get(block, (key, unit_key), dict, "an object naming the unit of each column")
        if unit_block is None:
            return None
        for col, table in units.items():
            factors[col] = check.unit(unit_block.get(col), (key, unit_key, col), table, col)
    values = check.get(block, (key, "values"), list, "a list")
    if values is None or None in factors.values():
        return None
    if not values:
        check.add((key, "values"), "is empty")
        return None
    positions: list[float | None] = []
    rows: list[list[Any]] = []
    for i, row in enumerate(values):
        if width == 1:
            row = [row]
        elif not isinstance(row, list) or len(row) != width:
            what = "[position, " + ", ".join(c for c in units if c != "position") + "]"
            check.add((key, "values", i), f"expected {what}, got {row!r}"[:200])
            positions.append(None)
            continue
        loc = (key, "values", i) if width == 1 else (key, "values", i, 0)
        s = check.number(row[0], loc, "position")
        positions.append(None if s is None else s * factors["position"])
        rows.append([positions[-1]] + list(row[1:]))
    if len(check.problems) > before:
        return None
    first_loc = (key, "values", 0) if width == 1 else (key, "values", 0, 0)
    if positions[0] != 0:
        check.add(first_loc, f"the first position must be 0 (got {positions[0]:g} m)")
    increasing(check, positions, lambda i: (key, "values", i) if width == 1 else (key, "values", i, 0), "positions")
    if length_m is not None and positions[-1] >= length_m:
        check.add((key, "values", len(positions) - 1, 0),
                  f"position {positions[-1]:g} m is not before the track's end (last stop {length_m:g} m)")
    return positions, rows  # type: ignore[return-value]


def _radius_curvature(check: SourceChecker, value: Any, loc: tuple, factor: float) -> float | None:
    """Signed curvature 1/R [1/m] of a radius entry ("infinity" -> 0)."""
    if isinstance(value, str) and value.strip().lower() in STRAIGHT:
        return 0.0
    r = check.number(value, loc, "radius (a number, or \"infinity\" for straight track)")
    if r is None:
        return None
    if r == 0:
        check.add(loc, "radius must not be 0 (use \"infinity\" for straight track)")
        return None
    return 1.0 / (r * factor)


def mean_abs_curvature(k_a: float, k_b: float) -> float:
    """Mean of |k| over a section where curvature k varies linearly from ``k_a`` to ``k_b`` [1/m]."""
    if k_a * k_b >= 0:
        return 0.5 * (abs(k_a) + abs(k_b))
    return (k_a * k_a + k_b * k_b) / (2.0 * (abs(k_a) + abs(k_b)))  # through zero: two triangles


def sections_on_leg(starts: list[float], values: list[float], track_m: float, a: float, b: float,
                    merge: bool = True) -> list[tuple[float, float, float]]:
    """Step function (section i = [starts[i], starts[i+1]), the last to ``track_m``) restricted to the
    leg [a, b], positions relative to ``a`` and rounded to 1 mm; equal neighbours merged."""
    out: list[list[float]] = []
    ends = list(starts[1:]) + [track_m]
    for s0, s1, v in zip(starts, ends, values):
        lo, hi = max(s0, a), min(s1, b)
        if hi <= lo:
            continue
        lo_r, hi_r = round(lo - a, 3), round(hi - a, 3)
        if out:
            lo_r = out[-1][1]  # contiguous by construction, whatever the rounding
        if hi_r <= lo_r:
            continue
        if merge and out and out[-1][2] == v:
            out[-1][1] = hi_r
        else:
            out.append([lo_r, hi_r, v])
    return [tuple(x) for x in out]  # type: ignore[misc]


def curves_on_leg(starts: list[float], k_start: list[float], k_end: list[float], track_m: float, a: float, b: float,
                  ) -> tuple[list[tuple[float, float, float]], int]:
    """Curves (from_m, to_m, radius_m) on the leg [a, b]; clipped clothoids keep the curvature of
    their clipped part. Also returns how many were sharper than ``MIN_RADIUS_M`` and set to it."""
    out: list[tuple[float, float, float]] = []
    clamped = 0
    ends = list(starts[1:]) + [track_m]
    for s0, s1, k0, k1 in zip(starts, ends, k_start, k_end):
        lo, hi = max(s0, a), min(s1, b)
        if hi <= lo or (k0 == 0 and k1 == 0):
            continue
        span = s1 - s0
        ka = k0 + (k1 - k0) * (lo - s0) / span
        kb = k0 + (k1 - k0) * (hi - s0) / span
        k = mean_abs_curvature(ka, kb)
        if k == 0:
            continue
        radius = round(1.0 / k, 1)
        if radius < MIN_RADIUS_M:
            radius, clamped = MIN_RADIUS_M, clamped + 1
        lo_r, hi_r = round(lo - a, 3), round(hi - a, 3)
        if hi_r > lo_r:
            out.append((lo_r, hi_r, radius))
    return out, clamped


class TTOBenchReader:
    name = "ttobench"
    options = frozenset({"cap_kmh", "leg", "all_legs", "journey"})
    min_files = 1
    max_files = 1

    def read(self, sources: list[Path], options: ImportOptions) -> Imported:
        path = sources[0]
        data = load_json(path)
        check = SourceChecker(str(path))
        meta = check.get(data, ("metadata",), dict, "an object with id and library version")
        track_id = None if meta is None else check.identifier(meta.get("id"), ("metadata", "id"), "the track id")
        stops = _table(check, data, "stops", 1, {}, True, None)
        check.raise_if_any()
        stop_m = stops[0]
        if len(stop_m) < 2:
            check.fail(("stops", "values"), "needs at least two stops (the start and the end of the track)")
        track_m = stop_m[-1]
        limits = _table(check, data, "speed limits", 2, {"position": POSITION_UNITS, "velocity": VELOCITY_UNITS},
                        True, track_m)
        grads = _table(check, data, "gradients", 2, {"position": POSITION_UNITS, "slope": SLOPE_UNITS}, False, track_m)
        curv = _table(check, data, "curvatures", 3, {"position": POSITION_UNITS, "radius at start": RADIUS_UNITS,
                                                     "radius at end": RADIUS_UNITS}, False, track_m)
        check.raise_if_any()
        units = lambda key: data[key]["units"]  # noqa: E731  (checked above)
        # values, converted and range-checked against the route schema, naming the source entry
        vf = VELOCITY_UNITS[units("speed limits")["velocity"]]
        limit_kmh = [check.speed_kmh(row[1], ("speed limits", "values", i, 1), vf) for i, row in enumerate(limits[1])]
        grad_permille = [0.0]
        if grads is not None:
            gf = SLOPE_UNITS[units("gradients")["slope"]]
            grad_permille = [check.gradient_permille(row[1], ("gradients", "values", i, 1), gf)
                             for i, row in enumerate(grads[1])]
        k_start: list[float] = []
        k_end: list[float] = []
        if curv is not None:
            cu = units("curvatures")
            for i, row in enumerate(curv[1]):
                k0 = _radius_curvature(check, row[1], ("curvatures", "values", i, 1), RADIUS_UNITS[cu["radius at start"]])
                k1 = _radius_curvature(check, row[2], ("curvatures", "values", i, 2), RADIUS_UNITS[cu["radius at end"]])
                k_start.append(k0 if k0 is not None else 0.0)
                k_end.append(k1 if k1 is not None else 0.0)
        n_legs = len(stop_m) - 1
        if options.leg is not None and not 1 <= options.leg <= n_legs:
            check.add(("stops", "values"), f"--leg {options.leg} is out of range: the track has {len(stop_m)} stops, "
                      f"so legs 1 to {n_legs}")
        check.raise_if_any()

        cap = options.cap_kmh
        capped = [min(v, cap) if cap is not None else v for v in limit_kmh]
        grad_starts = grads[0] if grads is not None else [0.0]
        licence, copyright_line = licence_near(path)
        legs = [options.leg] if options.leg is not None else list(range(1, n_legs + 1))
        files: list[ImportedFile] = []
        notes: list[str] = []
        spans = [(leg, stop_m[leg - 1], stop_m[leg]) for leg in legs]
        if options.journey:  # the whole line, and a journey over it with every stop
            spans = [(0, stop_m[0], stop_m[-1])]
        for leg, a, b in spans:
            sl = sections_on_leg(limits[0], capped, track_m, a, b)
            gr = sections_on_leg(grad_starts, grad_permille, track_m, a, b)
            cv, clamped = curves_on_leg(curv[0], k_start, k_end, track_m, a, b) if curv is not None else ([], 0)
            if clamped:
                notes.append(f"{path}: leg {leg}: {clamped} curve(s) sharper than {MIN_RADIUS_M:g} m set to "
                             f"{MIN_RADIUS_M:g} m (the route schema's minimum; their resistance is underestimated)")
            raw = sections_on_leg(limits[0], limit_kmh, track_m, a, b)
            relpath = f"{track_id}.yaml" if n_legs == 1 or leg == 0 else f"{track_id}-leg{leg}.yaml"
            name = (f"{track_id}, the whole line ({len(stop_m)} stops)" if leg == 0
                    else f"{track_id}, stops {leg}-{leg + 1} ({emit.num(a)}-{emit.num(b)} m)")
            head = self._header(path, meta, track_id, leg, n_legs, a, b, cap, raw, cv, licence, copyright_line,
                                options.command, clamped)
            text = emit.route_yaml(head, name, round(b - a, 3), sl, gr, cv)
            summary = (f"{relpath}: {emit.num((b - a) / 1000)} km, {len(sl)} speed-limit, {len(gr)} gradient "
                       f"section(s), {len(cv)} curve(s)")
            files.append(ImportedFile(relpath, "route", text, summary, str(path),
                                      {"speed_limits": "speed limits.values", "gradients": "gradients.values",
                                       "curves": "curvatures.values", "length_m": "stops.values"}))
        if options.journey:
            files.append(self._journey(path, track_id, stop_m, options.command))
        return Imported(files, licence, "ttobench", notes)

    @staticmethod
    def _journey(path, track_id, stop_m, command) -> ImportedFile:
        """The journey over the whole line: every stop of the track, no timetable (the source has none:
        ``locoplan journey --time`` gives the running time)."""
        head = [f"{track_id}: a journey over the whole track with its {len(stop_m)} stops, from TTOBench.",
                f"Source: {path}. The track gives no timetable: give the running time with locoplan journey --time "
                "(seconds, 1.15x of the fastest run, or +10%), and add dwell_s, time_s, earliest_s, latest_s to the "
                "stations as the timetable has them.",
                f"Converted by: {command}" if command else "Converted by locoplan's ttobench importer."]
        body = emit.header(head) + "schema: locoplan/journey@1\n"
        body += f"name: {emit.text(f'{track_id}, all stops')}\n"
        body += f"route: {emit.text(f'{track_id}.yaml')}\n"
        body += "stations:\n"
        body += "".join(f"  - {{name: {emit.text(f'stop {i + 1}')}, at_m: {emit.num(s - stop_m[0])}}}\n"
                        for i, s in enumerate(stop_m))
        relpath = f"{track_id}-journey.yaml"
        return ImportedFile(relpath, "journey", body, f"{relpath}: {len(stop_m)} stops, {len(stop_m) - 1} legs",
                            str(path), {"stations": "stops.values"})

    @staticmethod
    def _header(path, meta, track_id, leg, n_legs, a, b, cap, raw_limits, curves, licence, copyright_line,
                command, clamped) -> list[str]:
        lo = min(v for _, _, v in raw_limits)
        hi = max(v for _, _, v in raw_limits)
        origin = ", ".join(f"{k} {meta[k]}" for k in ("library version", "created by") if isinstance(meta.get(k), str))
        lic = meta.get("license") if isinstance(meta.get("license"), str) else "see the source"
        part = (f"the whole line, {n_legs} legs" if leg == 0 else f"leg {leg} of {n_legs}")
        lines = [f"{track_id}: {part}, from the stop at {emit.num(a)} m to the stop at {emit.num(b)} m "
                 "of the track, from TTOBench (a public train trajectory optimisation benchmark).",
                 f"Source: {path} (id {track_id}{', ' + origin if origin else ''}).",
                 f"Licence: {lic}" + (f"; {copyright_line}" if copyright_line else "")
                 + ("; full text in LICENSE-ttobench.txt beside this file." if licence else "."),
                 f"Converted by: {command}" if command else "Converted by locoplan's ttobench importer.",
                 f"Conversion: positions in metres from the {'line' if leg == 0 else 'leg'}'s start; each source entry "
                 f"starts a section that runs to the next entry (the last one to the {'line' if leg == 0 else 'leg'}'s end)."]
        if cap is not None:
            lines.append(f"Speed limits capped at {emit.num(cap)} km/h (the source's limits on this leg: "
                         f"{emit.num(lo)} to {emit.num(hi)} km/h).")
        if curves:
            lines.append("Curvature [position, radius at start, radius at end]: a constant section becomes a curve of "
                         "radius |R|; a clothoid (radii differ) one curve of radius 1 / mean |curvature|, which keeps the "
                         "600/R resistance work over it exact. Straight sections give no curve.")
        if clamped:
            lines.append(f"{clamped} curve(s) sharper than {MIN_RADIUS_M:g} m were set to {MIN_RADIUS_M:g} m (schema minimum).")
        return lines
