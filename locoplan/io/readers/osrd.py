"""OSRD's RailJSON (the open-source railway designer of the OpenRail Association) to locoplan files.

``osrd``: an infrastructure (``track_sections`` joined by ``switches`` and, in older files,
``track_section_links``) and a run through it from one operational point to another, the shortest by
length through the ``--via`` points in order. Each track is run in one direction; a train changes
track only through a switch's port group (or a link) and never reverses. From the path: a route file
(slopes with their sign turned where a track is run backwards, curves, speed limits: the
``--speed-tag`` limit where a section gives one, else its ``speed_limit``, the lowest where sections
overlap; neutral sections; ranges without electrification as sections without traction; every
operational point passed as a station) and a journey file (every operational point passed, a stop
where ``--stop`` names it).

``osrd-train``: a rolling stock (RailJSON rolling stock, version 3) to a vehicle and a consist file.

Units: RailJSON gives metres, m/s, per mille (slopes), metres (signed curve radii), kg, newtons; Davis
A [N], B [N/(m/s)], C [N/(m/s)^2] of the whole train.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from ...errors import InputError, Problem
from ...physics.units import G_MS2, KMH_PER_MS
from ..load import parse_json, read_text
from . import emit
from .base import MAX_SPEED_KMH, Imported, ImportedFile, ImportOptions, SourceChecker, licence_near, path_str
from .network import Network, Segment, merge_ranges, on_path, reachable, search, step_function

MAX_INFRA_BYTES = 512 * 1024 * 1024
"""Largest RailJSON infrastructure read [bytes]: a whole national network is a few hundred MB."""
MIN_RADIUS_M = 100.0
"""The route schema's smallest curve radius [m]."""
ENDPOINTS = ("BEGIN", "END")
DIRECTIONS = {"START_TO_STOP": 1, "STOP_TO_START": -1, "BOTH": 0}
BUILTIN_SWITCH_TYPES: dict[str, tuple[tuple[str, ...], list[tuple[str, str]]]] = {
    # id: (ports, every connection of every group); RailJSON's built-in node types
    "link": (("A", "B"), [("A", "B")]),
    "point_switch": (("A", "B1", "B2"), [("A", "B1"), ("A", "B2")]),
    "crossing": (("A1", "A2", "B1", "B2"), [("A1", "B1"), ("A2", "B2")]),
    "single_slip_switch": (("A1", "A2", "B1", "B2"), [("A1", "B1"), ("A2", "B2"), ("A1", "B2")]),
    "double_slip_switch": (("A1", "A2", "B1", "B2"), [("A1", "B1"), ("A1", "B2"), ("A2", "B1"), ("A2", "B2")]),
}
TOL_M = 1e-3
"""A range end this close beyond its track's end is taken as the end (rounding in the source) [m]."""
MAX_LISTED = 40


def _ref(value: Any) -> Any:
    """A reference to an object: its id (newer files) or ``{"type": ..., "id": ...}`` (older ones)."""
    if isinstance(value, dict) and isinstance(value.get("id"), str):
        return value["id"]
    return value


def _safe(name: str) -> str:
    """A file name from an id: letters, digits, '_', '-', '.' kept, anything else '_'."""
    out = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "x"
    return out[:120]


def _licence(path: Path) -> tuple[Path | None, str]:
    """The licence beside the source: LICENSE, or OSRD's LGPL text (LICENSE-LGPL-3.0.txt)."""
    for folder in (path.parent, path.parent.parent):
        candidate = folder / "LICENSE-LGPL-3.0.txt"
        if candidate.is_file():
            return candidate, ""
    return licence_near(path)


def _more_licences(lic: Path | None) -> list[tuple[str, Path]]:
    """The GPL text beside the LGPL's: the LGPL adds to the GPL, and both travel with the data."""
    if lic is not None and lic.name == "LICENSE-LGPL-3.0.txt" and (lic.parent / "LICENSE-GPL-3.0.txt").is_file():
        return [("LICENSE-osrd-GPL-3.0.txt", lic.parent / "LICENSE-GPL-3.0.txt")]
    return []


def _licence_line(lic: Path | None) -> str:
    return ("Licence: OSRD data, Copyright (c) The OSRD Contributors, LGPL-3.0-only"
            + ("; full text in LICENSE-osrd.txt (with the GPL it adds to, LICENSE-osrd-GPL-3.0.txt, where the source has "
               "it) in the import's output folder." if lic else " (see the source)."))


def _command_line(options: ImportOptions, fmt: str) -> str:
    return f"Converted by: {options.command}" if options.command else f"Converted by locoplan's {fmt} importer."


def load_json_file(path: Path, limit: int) -> Any:
    return parse_json(read_text(path, limit), str(path))


# ------------------------------------------------------------------------------------------ infrastructure
class Infra:
    """The parts of a RailJSON infrastructure a run needs, checked, with their JSON paths."""

    def __init__(self, data: Any, check: SourceChecker):
        self.check = check
        if not isinstance(data, dict):
            check.fail((), f"expected a RailJSON infrastructure (an object with track_sections, switches, "
                           f"operational_points, ...), got {type(data).__name__}")
        self.version = data.get("version") if isinstance(data.get("version"), str) else None
        self.net = Network()
        self.track_loc: dict[str, tuple] = {}
        self.slopes: dict[str, list] = {}
        self.curves: dict[str, list] = {}
        self._tracks(data)
        check.raise_if_any()
        self._switches(data)
        self._links(data)
        self.ops: dict[str, dict] = {}
        self._operational_points(data)
        self.speeds: dict[str, list] = {}
        self._speed_sections(data)
        self.electrified: dict[str, list] = {}
        self.has_electrification_data = False
        self._electrifications(data)
        self.neutral: dict[str, list] = {}
        self._neutral_sections(data)
        check.raise_if_any()

    # -- helpers
    def _list(self, data: dict, key: str, required: bool = False) -> list:
        value = self.check.get(data, (key,), list, "a list", required)
        return value or []

    def _number(self, item: Any, loc: tuple, what: str) -> float | None:
        if not isinstance(item, dict) or loc[-1] not in item:
            self.check.add(loc, f"required field is missing ({what})")
            return None
        return self.check.number(item[loc[-1]], loc, what)

    def _track_ref(self, item: Any, loc: tuple) -> str | None:
        """A ``track`` field naming an existing track section."""
        if not isinstance(item, dict) or "track" not in item:
            self.check.add(loc + ("track",), "required field is missing (the id of a track section)")
            return None
        track = _ref(item["track"])
        if not isinstance(track, str):
            self.check.add(loc + ("track",), f"expected a track section's id, got {item['track']!r}"[:200])
            return None
        if track not in self.net.lengths:
            self.check.add(loc + ("track",), f"track {track!r} is not among the track_sections: the graph is not "
                                             "well formed (a reference to a missing track)")
            return None
        return track

    def _range(self, item: Any, loc: tuple, track: str) -> tuple[float, float] | None:
        """``begin`` .. ``end`` on ``track``: numbers, begin <= end, inside the track (to 1 mm)."""
        a = self._number(item, loc + ("begin",), "begin [m]")
        b = self._number(item, loc + ("end",), "end [m]")
        if a is None or b is None:
            return None
        length = self.net.lengths[track]
        if a > b:
            self.check.add(loc, f"begin {a:g} m is after end {b:g} m")
            return None
        if a < -TOL_M or b > length + TOL_M:
            self.check.add(loc, f"range {a:g} .. {b:g} m lies outside track {track!r} (0 .. {length:g} m)")
            return None
        return max(a, 0.0), min(b, length)

    def _track_range(self, item: Any, loc: tuple, direction_key: str | None) -> tuple[str, float, float, int] | None:
        track = self._track_ref(item, loc)
        if track is None:
            return None
        r = self._range(item, loc, track)
        if r is None:
            return None
        d = 0
        if direction_key is not None and isinstance(item, dict) and direction_key in item:
            raw = item[direction_key]
            if raw not in DIRECTIONS:
                self.check.add(loc + (direction_key,), f"unknown direction {raw!r} (one of: {', '.join(DIRECTIONS)})")
                return None
            d = DIRECTIONS[raw]
        return track, r[0], r[1], d

    # -- sections of the file
    def _tracks(self, data: dict) -> None:
        tracks = self.check.get(data, ("track_sections",), list, "a list of track sections")
        if tracks is None:
            return
        for i, t in enumerate(tracks):
            loc = ("track_sections", i)
            if not isinstance(t, dict):
                self.check.add(loc, f"expected a track section (id, length, slopes, curves), got {t!r}"[:200])
                continue
            tid = self.check.get(t, loc + ("id",), str, "the track section's id")
            length = self._number(t, loc + ("length",), "length [m]")
            if tid is None or length is None:
                continue
            if length <= 0:
                self.check.add(loc + ("length",), f"length must be > 0 m (got {length:g})")
                continue
            if tid in self.net.lengths:
                self.check.add(loc + ("id",), f"track section {tid!r} is given twice (also {path_str(self.track_loc[tid])})")
                continue
            self.net.lengths[tid] = length
            self.track_loc[tid] = loc
        for i, t in enumerate(tracks):
            if not isinstance(t, dict) or not isinstance(t.get("id"), str) or self.track_loc.get(t["id"]) != ("track_sections", i):
                continue
            tid = t["id"]
            for key, value_key, store in (("slopes", "gradient", self.slopes), ("curves", "radius", self.curves)):
                items = self.check.get(t, ("track_sections", i, key), list, f"a list of {key}", required=False) or []
                for j, item in enumerate(items):
                    loc = ("track_sections", i, key, j)
                    r = self._range(item, loc, tid) if isinstance(item, dict) else None
                    if not isinstance(item, dict):
                        self.check.add(loc, f"expected {{begin, end, {value_key}}}, got {item!r}"[:200])
                    v = self._number(item, loc + (value_key,), value_key) if isinstance(item, dict) else None
                    if r is not None and v is not None and r[1] > r[0]:
                        store.setdefault(tid, []).append((r[0], r[1], (v, loc + (value_key,))))

    def _switch_types(self, data: dict) -> dict[str, tuple[tuple[str, ...], list[tuple[str, str]], tuple]]:
        types = {k: (ports, conns, ()) for k, (ports, conns) in BUILTIN_SWITCH_TYPES.items()}
        for key in ("extended_switch_types", "switch_types"):  # the newer name, and the older one
            for i, st in enumerate(self._list(data, key)):
                loc = (key, i)
                if not isinstance(st, dict):
                    self.check.add(loc, f"expected a switch type (id, ports, groups), got {st!r}"[:200])
                    continue
                sid = self.check.get(st, loc + ("id",), str, "the switch type's id")
                ports = self.check.get(st, loc + ("ports",), list, "a list of port names")
                groups = self.check.get(st, loc + ("groups",), dict, "groups: name -> list of {src, dst}")
                if sid is None or ports is None or groups is None:
                    continue
                conns = []
                for g, group in groups.items():
                    if not isinstance(group, list):
                        group = [group]  # some files give one connection per group as an object
                    for k, c in enumerate(group):
                        cl = loc + ("groups", g, k)
                        if not isinstance(c, dict) or not isinstance(c.get("src"), str) or not isinstance(c.get("dst"), str):
                            self.check.add(cl, f"expected a connection {{src, dst}} between two ports, got {c!r}"[:200])
                            continue
                        for end in ("src", "dst"):
                            if c[end] not in ports:
                                self.check.add(cl + (end,), f"port {c[end]!r} is not among the type's ports ({', '.join(map(str, ports))})")
                        conns.append((c["src"], c["dst"]))
                types[sid] = (tuple(ports), conns, loc)
        return types

    def _switches(self, data: dict) -> None:
        types = self._switch_types(data)
        for i, sw in enumerate(self._list(data, "switches")):
            loc = ("switches", i)
            if not isinstance(sw, dict):
                self.check.add(loc, f"expected a switch (id, switch_type, ports), got {sw!r}"[:200])
                continue
            stype = _ref(sw.get("switch_type"))
            if not isinstance(stype, str) or stype not in types:
                known = ", ".join(sorted(types))
                self.check.add(loc + ("switch_type",), f"unknown switch type {sw.get('switch_type')!r} (known: {known})"[:300])
                continue
            ports = self.check.get(sw, loc + ("ports",), dict, "ports: name -> {endpoint, track}")
            if ports is None:
                continue
            type_ports, conns, _ = types[stype]
            ends: dict[str, tuple[str, str]] = {}
            for port, value in ports.items():
                pl = loc + ("ports", port)
                if port not in type_ports:
                    self.check.add(pl, f"port {port!r} is not a port of a {stype} ({', '.join(type_ports)})")
                    continue
                end = self._endpoint(value, pl)
                if end is not None:
                    ends[port] = end
            for p in type_ports:
                if p not in ports:
                    self.check.add(loc + ("ports",), f"port {p!r} of a {stype} is missing")
            for src, dst in conns:
                if src in ends and dst in ends:
                    (t1, e1), (t2, e2) = ends[src], ends[dst]
                    self.net.link_ends(t1, e1, t2, e2)

    def _endpoint(self, value: Any, loc: tuple) -> tuple[str, str] | None:
        if not isinstance(value, dict):
            self.check.add(loc, f"expected {{endpoint, track}}, got {value!r}"[:200])
            return None
        track = self._track_ref(value, loc)
        end = value.get("endpoint")
        if end not in ENDPOINTS:
            self.check.add(loc + ("endpoint",), f"expected BEGIN or END, got {end!r}"[:200])
            return None
        return None if track is None else (track, end)

    def _links(self, data: dict) -> None:
        for i, link in enumerate(self._list(data, "track_section_links")):  # RailJSON before switch type "link"
            loc = ("track_section_links", i)
            if not isinstance(link, dict):
                self.check.add(loc, f"expected a link {{src, dst}}, got {link!r}"[:200])
                continue
            a = self._endpoint(link.get("src"), loc + ("src",))
            b = self._endpoint(link.get("dst"), loc + ("dst",))
            if a is not None and b is not None:
                self.net.link_ends(a[0], a[1], b[0], b[1])

    def _operational_points(self, data: dict) -> None:
        for i, op in enumerate(self._list(data, "operational_points")):
            loc = ("operational_points", i)
            if not isinstance(op, dict):
                self.check.add(loc, f"expected an operational point (id, parts), got {op!r}"[:200])
                continue
            oid = self.check.get(op, loc + ("id",), str, "the operational point's id")
            parts = self.check.get(op, loc + ("parts",), list, "a list of parts {track, position}")
            if oid is None or parts is None:
                continue
            ext = op.get("extensions") if isinstance(op.get("extensions"), dict) else {}
            ident = ext.get("identifier") if isinstance(ext.get("identifier"), dict) else {}
            name = ident.get("name") if isinstance(ident.get("name"), str) else op.get("name")
            name = name.strip() if isinstance(name, str) and name.strip() else oid
            places = []
            for j, part in enumerate(parts):
                pl = loc + ("parts", j)
                track = self._track_ref(part, pl)
                pos = self._number(part, pl + ("position",), "position [m]") if isinstance(part, dict) else None
                if track is None or pos is None:
                    continue
                if not -TOL_M <= pos <= self.net.lengths[track] + TOL_M:
                    self.check.add(pl + ("position",), f"position {pos:g} m lies outside track {track!r} "
                                   f"(0 .. {self.net.lengths[track]:g} m)")
                    continue
                places.append((track, min(max(pos, 0.0), self.net.lengths[track])))
            if oid in self.ops:
                self.check.add(loc + ("id",), f"operational point {oid!r} is given twice")
                continue
            self.ops[oid] = {"name": name, "places": places, "loc": loc}

    def _speed_sections(self, data: dict) -> None:
        for i, sec in enumerate(self._list(data, "speed_sections")):
            loc = ("speed_sections", i)
            if not isinstance(sec, dict):
                self.check.add(loc, f"expected a speed section, got {sec!r}"[:200])
                continue
            limit = sec.get("speed_limit")
            if limit is not None:
                limit = self.check.number(limit, loc + ("speed_limit",), "speed limit [m/s]")
            tags = sec.get("speed_limit_by_tag") or {}
            if not isinstance(tags, dict):
                self.check.add(loc + ("speed_limit_by_tag",), f"expected tag -> speed [m/s], got {tags!r}"[:200])
                tags = {}
            by_tag = {}
            for tag, v in tags.items():
                if v is not None:
                    x = self.check.number(v, loc + ("speed_limit_by_tag", tag), "speed limit [m/s]")
                    if x is not None:
                        by_tag[tag] = x
            value = {"limit": limit, "by_tag": by_tag, "loc": loc, "on_routes": bool(sec.get("on_routes"))}
            for j, r in enumerate(self.check.get(sec, loc + ("track_ranges",), list, "a list of track ranges") or []):
                tr = self._track_range(r, loc + ("track_ranges", j), "applicable_directions")
                if tr is not None:
                    self.speeds.setdefault(tr[0], []).append((tr[1], tr[2], (value, tr[3])))

    def _electrifications(self, data: dict) -> None:
        key = "electrifications" if "electrifications" in data else "catenaries"  # the older name
        items = self._list(data, key)
        self.has_electrification_data = key in data
        for i, el in enumerate(items):
            loc = (key, i)
            if not isinstance(el, dict):
                self.check.add(loc, f"expected an electrification (voltage, track_ranges), got {el!r}"[:200])
                continue
            voltage = el.get("voltage")
            for j, r in enumerate(self.check.get(el, loc + ("track_ranges",), list, "a list of track ranges") or []):
                tr = self._track_range(r, loc + ("track_ranges", j), "applicable_directions")
                if tr is not None:
                    self.electrified.setdefault(tr[0], []).append((tr[1], tr[2], (str(voltage), tr[3])))

    def _neutral_sections(self, data: dict) -> None:
        for i, ns in enumerate(self._list(data, "neutral_sections")):
            loc = ("neutral_sections", i)
            if not isinstance(ns, dict):
                self.check.add(loc, f"expected a neutral section, got {ns!r}"[:200])
                continue
            lower = ns.get("lower_pantograph", False)
            if not isinstance(lower, bool):
                self.check.add(loc + ("lower_pantograph",), f"expected true or false, got {lower!r}"[:200])
                continue
            nid = ns.get("id") if isinstance(ns.get("id"), str) else f"neutral_sections[{i}]"
            for j, r in enumerate(self.check.get(ns, loc + ("track_ranges",), list, "a list of track ranges") or []):
                tr = self._track_range(r, loc + ("track_ranges", j), "direction")
                if tr is not None:
                    self.neutral.setdefault(tr[0], []).append((tr[1], tr[2], ({"id": nid, "lower": lower}, tr[3])))

    # -- questions
    def find_op(self, wanted: str, flag: str) -> str:
        """The id of the operational point ``wanted`` names (its id or its name)."""
        if wanted in self.ops:
            return wanted
        hits = [oid for oid, op in self.ops.items() if op["name"] == wanted]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            raise InputError(Problem("<command line>", flag, f"{wanted!r} names {len(hits)} operational points "
                                     f"({', '.join(hits[:MAX_LISTED])}): give the id"))
        names = [oid if op["name"] == oid else f"{op['name']} ({oid})" for oid, op in self.ops.items()]
        listed = ", ".join(sorted(names)[:MAX_LISTED]) + (", ..." if len(names) > MAX_LISTED else "")
        raise InputError(Problem(self.check.file, "operational_points", f"no operational point {wanted!r} ({flag}); "
                                 f"the {len(names)} operational points: {listed or 'none'}"))

    def unelectrified_len(self, track: str, a: float, b: float) -> float:
        lo, hi = min(a, b), max(a, b)
        covered = sum(max(0.0, min(e, hi) - max(s, lo)) for s, e in merge_ranges((s, e) for s, e, _ in self.electrified.get(track, ())))
        return (hi - lo) - covered


def _tag_limit(value: dict, tag: str | None) -> tuple[float | None, str]:
    if tag is not None and tag in value["by_tag"]:
        return value["by_tag"][tag], f"speed_limit_by_tag.{tag}"
    return value["limit"], "speed_limit"


def _applies(d_range: int, d_run: int) -> bool:
    return d_range == 0 or d_range == d_run


class OsrdInfraReader:
    name = "osrd"
    options = frozenset({"cap_kmh", "from_station", "to_station", "via", "stops", "speed_tag", "thermal"})
    min_files = 1
    max_files = 1

    def read(self, sources: list[Path], options: ImportOptions) -> Imported:
        path = sources[0]
        if not options.from_station or not options.to_station:
            raise InputError(Problem("<command line>", "--from/--to", "osrd needs the operational points to run "
                                     "between: --from STATION --to STATION"))
        data = load_json_file(path, MAX_INFRA_BYTES)
        check = SourceChecker(str(path))
        infra = Infra(data, check)
        ids = [infra.find_op(options.from_station, "--from")]
        ids += [infra.find_op(v, "--via") for v in options.via]
        ids.append(infra.find_op(options.to_station, "--to"))
        for oid in ids:
            if not infra.ops[oid]["places"]:
                raise InputError(Problem(str(path), path_str(infra.ops[oid]["loc"] + ("parts",)),
                                         f"operational point {oid!r} has no part on a track"))
        if len(set(ids)) < len(ids) and ids[0] == ids[-1] and len(ids) == 2:
            raise InputError(Problem("<command line>", "--to", f"--from and --to name the same operational point {ids[0]!r}"))
        penalty = None if options.thermal else infra.unelectrified_len
        found, _ = search(infra.net, [infra.ops[o]["places"] for o in ids], penalty)
        if found is None:
            raise InputError(self._no_path(path, infra, ids))
        lic, _ = _licence(path)
        route_file, notes, stations = self._route(path, infra, ids, found, options, lic)
        journey_file = self._journey(path, infra, ids, stations, route_file.relpath, options, lic)
        return Imported([route_file, journey_file], lic, "osrd", notes, _more_licences(lic))

    # ------------------------------------------------------------------------------------ no path
    def _no_path(self, path: Path, infra: Infra, ids: list[str]) -> Problem:
        places = {oid: op["places"] for oid, op in infra.ops.items()}
        for k in range(len(ids) - 1):
            a, b = ids[k], ids[k + 1]
            found, _ = search(infra.net, [places[a], places[b]])
            if found is not None:
                continue
            _, settled_a = search(infra.net, [places[a], []])
            from_a = reachable(settled_a, places)
            _, settled_b = search(infra.net, [places[b], []])
            from_b = reachable(settled_b, places)
            name = lambda o: infra.ops[o]["name"]  # noqa: E731
            candidates = [o for o in from_a if o not in (a, b)]
            if not candidates:
                hint = f"no other operational point can be reached from {name(a)!r} either"
            else:
                both = [o for o in candidates if o in from_b]
                best = min(both, key=lambda o: from_b[o]) if both else min(candidates, key=lambda o: from_a[o])
                hint = (f"the nearest that can be reached is {name(best)!r} ({best}, {from_a[best] / 1000:.3f} km from "
                        f"{name(a)!r}" + (f"; {name(b)!r} lies {from_b[best] / 1000:.3f} km beyond it, but a train would "
                                          "have to reverse there)" if best in from_b else ")"))
            leg = f"{name(a)!r} to {name(b)!r}" + ("" if len(ids) == 2 else f" (leg {k + 1} of the run through --via)")
            return Problem(str(path), "track_sections", f"no path from {leg}: no run through the switches joins "
                           f"them without reversing; {hint}")
        return Problem(str(path), "track_sections", "no path through the --via stations in this order without reversing")

    # ------------------------------------------------------------------------------------ route
    def _route(self, path: Path, infra: Infra, ids: list[str], found, options: ImportOptions, lic):
        check = SourceChecker(str(path))
        segs: list[Segment] = found.segments
        length = round(found.length, 3)
        notes: list[str] = []
        # gradients: the sign turned where a track is run backwards
        raw = on_path(segs, infra.slopes, transform=lambda v, d: (v[0] * d, v[1]))
        for _, _, (g, loc) in raw:
            check.gradient_permille(g, loc, what="slope")
        gradients = step_function(length, [(a, b, v[0]) for a, b, v in raw], 0.0, combine=lambda vs: vs[-1])
        # curves: |radius|; 0 is straight
        raw = on_path(segs, infra.curves)
        curve_pieces, clamped = [], 0
        for a, b, (r, _loc) in raw:
            if r == 0:
                continue
            radius = abs(r)
            if radius < MIN_RADIUS_M:
                radius, clamped = MIN_RADIUS_M, clamped + 1
            curve_pieces.append((a, b, radius))
        curves = [(a, b, v) for a, b, v in step_function(length, curve_pieces, None, combine=min) if v is not None]
        if clamped:
            notes.append(f"{path}: {clamped} curve(s) sharper than {MIN_RADIUS_M:g} m set to {MIN_RADIUS_M:g} m "
                         "(the route schema's minimum; their resistance is underestimated)")
        # speed limits: the tag's limit where given, else the section's; the lowest where they overlap
        tag = options.speed_tag
        raw = on_path(segs, infra.speeds, direction_ok=lambda v, d: _applies(v[1], d))
        pieces, tag_used, on_routes = [], False, 0
        for a, b, (value, _) in raw:
            ms, key = _tag_limit(value, tag)
            tag_used |= key != "speed_limit"
            on_routes += value["on_routes"]
            if ms is None:
                continue
            kmh = check.speed_kmh(ms, value["loc"] + tuple(key.split(".")), KMH_PER_MS)
            if kmh is not None:
                pieces.append((a, b, kmh))
        check.raise_if_any()
        if tag is not None and not tag_used:
            tags = sorted({t for rs in infra.speeds.values() for _, _, (v, _) in rs for t in v["by_tag"]})
            notes.append(f"{path}: no speed section on the path gives a limit for --speed-tag {tag!r} "
                         f"(tags in the file: {', '.join(tags) or 'none'}): the sections' own limits are used")
        limits = step_function(length, pieces, None, combine=min)
        uncovered = sum(b - a for a, b, v in limits if v is None)
        if uncovered:
            notes.append(f"{path}: {uncovered / 1000:.3f} km of the path lie in no speed section: written as "
                         f"{MAX_SPEED_KMH:g} km/h (the train's top speed limits it; --cap-kmh caps it)")
        cap = options.cap_kmh
        limits = [(a, b, min(v if v is not None else MAX_SPEED_KMH, cap) if cap else (v if v is not None else MAX_SPEED_KMH))
                  for a, b, v in limits]
        limits = step_function(length, limits, None)
        # traction: neutral sections (every one cuts traction), and ranges without electrification
        neutral_pieces, no_wire = [], []
        if not options.thermal:
            raw = on_path(segs, infra.neutral, direction_ok=lambda v, d: _applies(v[1], d))
            neutral_pieces = [(a, b) for a, b, _ in raw]
            lowered = sorted({v[0]["id"] for _, _, v in raw if v[0]["lower"]})
            kept = sorted({v[0]["id"] for _, _, v in raw if not v[0]["lower"]})
            if infra.has_electrification_data:
                wired = on_path(segs, infra.electrified, direction_ok=lambda v, d: _applies(v[1], d))
                cover = step_function(length, [(a, b, 1.0) for a, b, _ in wired], 0.0, combine=max)
                no_wire = [(a, b) for a, b, v in cover if v == 0.0]
                for a, b in no_wire:
                    tracks = sorted({s.track for s in segs if s.s0 < b and s.s0 + s.length > a})
                    notes.append(f"{path}: no electrification on {a:g} .. {b:g} m of the path (track "
                                 f"{', '.join(tracks)}): written as a neutral section, no traction there "
                                 "(--thermal for a train on its own power)")
        neutral = merge_ranges(neutral_pieces + no_wire)
        if neutral and neutral[0][0] <= 0:
            first = infra.ops[ids[0]]["name"]
            raise InputError(Problem(str(path), path_str(infra.ops[ids[0]]["loc"]),
                                     f"the run starts at {first!r} inside a neutral section or on track without "
                                     f"electrification (0 .. {neutral[0][1]:g} m of the path): an electric train "
                                     "cannot start there; give --thermal for a train on its own power, or start "
                                     "elsewhere"))
        stations = self._stations(infra, ids, found)
        names = [infra.ops[o]["name"] for o in ids]
        rid = _safe(f"{ids[0]}-{ids[-1]}" + "".join(f"-via-{v}" for v in ids[1:-1]))
        relpath = f"{rid}.yaml"
        head = [f"{names[0]} to {names[-1]}" + (f" via {', '.join(names[1:-1])}" if len(ids) > 2 else "")
                + f": the shortest path through the OSRD infrastructure ({length / 1000:.3f} km).",
                f"Source: {path}" + (f" (RailJSON {infra.version})." if infra.version else "."),
                _licence_line(lic),
                _command_line(options, "osrd"),
                "Path (track: from .. to [m], in running order): "
                + "; ".join(f"{s.track}: {emit.num(s.a)} .. {emit.num(s.b)}" for s in segs) + ".",
                "Conversion: positions in metres from the start of the path. Slopes are per mille along each track's "
                "own direction: their sign is turned where a track is run backwards (STOP_TO_START). Curves: |radius|. "
                "Speed limits [m/s x 3.6 = km/h]: "
                + (f"the tag {tag!r}'s limit where a section gives one, else the section's speed_limit; "
                   if tag else "each section's speed_limit (no --speed-tag); ")
                + "the lowest where sections overlap; a section's applicable_directions are respected."]
        if on_routes:
            head.append("Some speed sections apply only on given interlocking routes (on_routes): they are applied "
                        "everywhere on the path (the safe side).")
        if options.thermal:
            head.append("--thermal: the train runs on its own power; neutral sections and missing electrification "
                        "cut no traction.")
        else:
            head.append("Neutral sections: every OSRD neutral section on the path in its direction cuts traction (as in "
                        "OSRD)" + (f"; lower_pantograph: {', '.join(lowered)}" if lowered else "")
                        + (f"; pantograph kept up: {', '.join(kept)}" if kept else "")
                        + ". Announcement ranges are signs only and not carried over."
                        + (f" Ranges without electrification ({len(no_wire)}) are neutral sections too."
                           if no_wire else ""))
        if cap:
            head.append(f"Speed limits capped at {emit.num(cap)} km/h.")
        text = emit.route_yaml(head, f"{names[0]} - {names[-1]} (OSRD)", length, limits, gradients, curves,
                               neutral_sections=neutral, stations=[(n, s) for n, s, _ in stations])
        summary = (f"{relpath}: {length / 1000:.3f} km, {len(limits)} speed-limit, {len(gradients)} gradient section(s), "
                   f"{len(curves)} curve(s), {len(neutral)} neutral section(s), {len(stations)} stations")
        fields = {"speed_limits": "speed_sections", "gradients": "track_sections[].slopes",
                  "curves": "track_sections[].curves", "neutral_sections": "neutral_sections / electrifications",
                  "length_m": "track_sections[].length", "stations": "operational_points"}
        return ImportedFile(relpath, "route", text, summary, str(path), fields), notes, stations

    @staticmethod
    def _stations(infra: Infra, ids: list[str], found) -> list[tuple[str, float, str]]:
        """Every operational point the path passes: (name, at_m, id), in running order, the first at 0 and the
        last at the end; a point passed twice is named "(again)" the second time."""
        hits: list[tuple[float, str]] = []
        for oid, op in infra.ops.items():
            for t, p in op["places"]:
                for seg in found.segments:
                    lo, hi = min(seg.a, seg.b), max(seg.a, seg.b)
                    if seg.track == t and lo - 1e-9 <= p <= hi + 1e-9:
                        hits.append((round(seg.s_of(p), 3), oid))
        length = round(found.length, 3)
        first, last = ids[0], ids[-1]
        hits = [(s, o) for s, o in hits if 0 < s < length]
        hits.sort()
        out: list[tuple[str, float, str]] = [(infra.ops[first]["name"], 0.0, first)]
        seen = {first: 1}
        for s, oid in hits:
            if s <= out[-1][1] or (out[-1][2] == oid and s - out[-1][1] < 1.0):
                continue
            name = infra.ops[oid]["name"]
            n = seen.get(oid, 0)
            seen[oid] = n + 1
            out.append((name if n == 0 else f"{name} (again{'' if n == 1 else ' ' + str(n)})", s, oid))
        n = seen.get(last, 0)
        name = infra.ops[last]["name"]
        out.append((name if n == 0 else f"{name} (again{'' if n == 1 else ' ' + str(n)})", length, last))
        return out

    # ------------------------------------------------------------------------------------ journey
    def _journey(self, path: Path, infra: Infra, ids: list[str], stations, route_rel: str, options: ImportOptions, lic):
        passed = {}
        for name, _, oid in stations:
            passed.setdefault(oid, name)
            passed.setdefault(name, name)
        stop_names = set()
        for wanted in options.stops:
            oid = infra.find_op(wanted, "--stop")
            if oid not in passed:
                listed = ", ".join(n for n, _, _ in stations[1:-1]) or "none"
                raise InputError(Problem("<command line>", "--stop", f"{wanted!r} is not passed by the path from "
                                         f"{stations[0][0]!r} to {stations[-1][0]!r} (the stations passed: {listed})"))
            stop_names.add(passed[oid])
        rows = [(n, s, i in (0, len(stations) - 1) or n in stop_names) for i, (n, s, _) in enumerate(stations)]
        names = [infra.ops[o]["name"] for o in ids]
        relpath = route_rel.replace(".yaml", "-journey.yaml")
        head = [f"{names[0]} to {names[-1]}: a journey over the OSRD path with every operational point it passes "
                f"({len(rows)}), from {path}.",
                _licence_line(lic),
                _command_line(options, "osrd"),
                "Stops: the first and the last station" + (f" and {', '.join(sorted(stop_names))} (--stop)" if stop_names
                                                             else "") + "; the others are passed (stop: false). The "
                "infrastructure gives no timetable: give the running time with locoplan journey --time, and add "
                "dwell_s, time_s, earliest_s, latest_s as the timetable has them."]
        text = emit.journey_yaml(head, f"{names[0]} - {names[-1]}", route_rel, rows)
        stops = sum(1 for r in rows if r[2])
        summary = f"{relpath}: {len(rows)} stations, {stops} stops"
        return ImportedFile(relpath, "journey", text, summary, str(path), {"stations": "operational_points"})


# ------------------------------------------------------------------------------------------ rolling stock
MAX_UNIT_LENGTH_M = 100.0
MAX_UNIT_MASS_T = 500.0
"""A vehicle file holds at most 100 m and 500 t (the vehicle schema's plausible bounds): a longer or heavier
OSRD rolling stock (a whole trainset) becomes that many equal units."""


class OsrdTrainReader:
    name = "osrd-train"
    options = frozenset({"mode"})
    min_files = 1
    max_files = 50

    def read(self, sources: list[Path], options: ImportOptions) -> Imported:
        files: list[ImportedFile] = []
        lic = None
        for path in sources:
            data = load_json_file(path, 64 * 1024 * 1024)
            check = SourceChecker(str(path))
            files += self._stock(path, data, check, options)
            lic = lic or _licence(path)[0]
        return Imported(files, lic, "osrd", [], _more_licences(lic))

    def _stock(self, path: Path, data: Any, check: SourceChecker, options: ImportOptions) -> list[ImportedFile]:
        if not isinstance(data, dict):
            check.fail((), f"expected a RailJSON rolling stock (an object with name, mass, effort_curves, ...), "
                           f"got {type(data).__name__}")
        name = check.get(data, ("name",), str, "the rolling stock's name")

        def positive(key: str, what: str) -> float | None:
            x = check.number(data[key], (key,), what) if key in data else None
            if key not in data:
                check.add((key,), f"required field is missing ({what})")
            elif x is not None and x <= 0:
                check.add((key,), f"{what} must be > 0 (got {x:g})")
                return None
            return x

        mass_kg = positive("mass", "mass [kg]")
        length = positive("length", "length [m]")
        vmax = positive("max_speed", "max speed [m/s]")
        inertia = positive("inertia_coefficient", "inertia coefficient (rotating-mass factor)")
        rr = check.get(data, ("rolling_resistance",), dict, "{type: davis, A, B, C}")
        davis = None
        if rr is not None:
            if rr.get("type", "davis") != "davis":
                check.add(("rolling_resistance", "type"), f"only the Davis form is known (got {rr.get('type')!r})")
            coeffs = []
            for k in ("A", "B", "C"):
                v = check.number(rr.get(k), ("rolling_resistance", k), f"Davis {k}") if k in rr else None
                if k not in rr:
                    check.add(("rolling_resistance", k), f"required field is missing (Davis {k})")
                elif v is not None and v < 0:
                    check.add(("rolling_resistance", k), f"Davis {k} must be >= 0 (got {v:g})")
                coeffs.append(v)
            davis = coeffs if None not in coeffs else None
        gamma, gamma_kind, gamma_loc = self._gamma(data, check)
        curve, mode, others, mode_loc = self._effort(data, check, options.mode)
        check.raise_if_any()
        mass_t = mass_kg / 1000.0
        n = max(1, math.ceil(length / MAX_UNIT_LENGTH_M - 1e-9), math.ceil(mass_t / MAX_UNIT_MASS_T - 1e-9))
        weight_kn = mass_t * G_MS2  # the whole train's weight [kN]
        a_n, b_n, c_n = davis
        a = a_n / weight_kn
        b = b_n / KMH_PER_MS / weight_kn
        c = c_n / KMH_PER_MS ** 2 / weight_kn
        vid = _safe(name)
        vmax_kmh = vmax * KMH_PER_MS
        traction = [(v * KMH_PER_MS, f / 1000.0 / n) for v, f in curve]
        src = f"Source: {path} (RailJSON rolling stock {data.get('railjson_version', '?')})."
        unit = (f"The rolling stock is {emit.coef(length)} m and {emit.coef(mass_t)} t; a vehicle file holds at most "
                f"{MAX_UNIT_LENGTH_M:g} m and {MAX_UNIT_MASS_T:g} t, so it is {n} equal units of "
                f"{emit.coef(length / n)} m and {emit.coef(mass_t / n)} t, each with 1/{n} of the tractive effort "
                "(the train's totals are the source's)." if n > 1 else "")
        head = [f"{name}: an OSRD rolling stock" + (f", as {n} equal units (consists/{vid}.yaml)." if n > 1 else "."),
                src, _licence_line(_licence(path)[0]), _command_line(options, "osrd-train"),
                "Units converted exactly: mass kg / 1000 = t; max_speed m/s x 3.6 = km/h; effort N / 1000 = kN at "
                "speed m/s x 3.6 = km/h; inertia_coefficient = rotating_mass_factor (inertial mass / mass, as in OSRD).",
                f"Resistance: OSRD's Davis R = A + B v + C v^2 [N], v in m/s, of the whole train (A = {emit.coef(a_n)} N, "
                f"B = {emit.coef(b_n)} N/(m/s), C = {emit.coef(c_n)} N/(m/s)^2). locoplan's w0 = a + b v + c v^2 [N/kN] "
                f"per kN of weight, v in km/h: a = A / W, b = B / 3.6 / W, c = C / 3.6^2 / W with the train's weight "
                f"W = {emit.coef(mass_t)} t x {G_MS2:g} m/s^2 = {emit.coef(weight_kn)} kN (locoplan's g), so that "
                "w0 x W is R at every speed.",
                f"Effort curve: mode {mode!r}'s default curve" + (f"; the other modes, not written: {', '.join(others)} "
                                                                  "(--mode NAME writes one of them)" if others else "")
                + ". Conditional curves (comfort, electrical profile, power restriction) are not carried over.",
                "No electric brake in RailJSON: brake_kn is zero; the consist brakes at gamma (brake_deceleration_ms2)."]
        if unit:
            head.append(unit)
        text = emit.vehicle_yaml(head, vid, "locomotive", mass_t / n, length / n, vmax_kmh, (a, b, c), inertia,
                                 traction_kn=traction, brake_kn=[(0.0, 0.0), (vmax_kmh, 0.0)], exact_curves=True)
        fields = {"mass_t": "mass", "length_m": "length", "max_speed_kmh": "max_speed",
                  "rotating_mass_factor": "inertia_coefficient", "resistance_n_per_kn": "rolling_resistance",
                  "traction_kn": path_str(mode_loc), "brake_kn": "max_speed", "name": "name"}
        summary = f"rolling_stock/{vid}.yaml: locomotive '{vid}', {emit.coef(mass_t / n)} t, {emit.coef(length / n)} m"
        vehicle = ImportedFile(f"rolling_stock/{vid}.yaml", "vehicle", text, summary, str(path), fields)
        chead = [f"{name}: an OSRD rolling stock as a train" + (f" of {n} equal units." if n > 1 else "."),
                 src, _licence_line(_licence(path)[0]), _command_line(options, "osrd-train"),
                 f"brake_deceleration_ms2: gamma ({gamma_kind}) = {emit.coef(gamma)} m/s^2. locoplan brakes with the force "
                 "inertial mass x gamma, to which running resistance adds and from which a down-grade takes; OSRD's "
                 "CONST gamma is the deceleration itself, its MAX gamma the same force as here."]
        ctext = emit.consist_yaml(chead, name, [(vid, n, 0.0)], None) + f"brake_deceleration_ms2: {emit.coef(gamma)}\n"
        consist = ImportedFile(f"consists/{vid}.yaml", "consist", ctext, f"consists/{vid}.yaml: '{name}', {n} vehicle(s)",
                               str(path), {"brake_deceleration_ms2": path_str(gamma_loc), "vehicles": "name"})
        return [vehicle, consist]

    @staticmethod
    def _gamma(data: dict, check: SourceChecker) -> tuple[float | None, str, tuple]:
        """The braking deceleration: ``gamma: {type, value}`` (RailJSON 3), ``const_gamma`` (newer files) or
        ``gamma`` with ``gamma_type`` (older ones)."""
        if "const_gamma" in data:
            g = check.number(data["const_gamma"], ("const_gamma",), "braking deceleration const_gamma [m/s^2]")
            kind, loc = "CONST", ("const_gamma",)
        elif isinstance(data.get("gamma"), dict):
            gd = data["gamma"]
            kind = gd.get("type", "CONST")
            if kind not in ("CONST", "MAX"):
                check.add(("gamma", "type"), f"unknown gamma type {kind!r} (CONST or MAX)")
            g = check.number(gd.get("value"), ("gamma", "value"), "braking deceleration gamma.value [m/s^2]")
            loc = ("gamma", "value")
        elif "gamma" in data:
            g = check.number(data["gamma"], ("gamma",), "braking deceleration gamma [m/s^2]")
            kind, loc = str(data.get("gamma_type", "CONST")), ("gamma",)
        else:
            check.add(("gamma",), "required field is missing (the braking deceleration: gamma {type, value} or const_gamma)")
            return None, "", ("gamma",)
        if g is not None:
            g = abs(g)
            if g == 0:
                check.add(loc, "braking deceleration must not be 0")
        return g, str(kind), loc

    @staticmethod
    def _effort(data: dict, check: SourceChecker, wanted: str | None):
        ec = check.get(data, ("effort_curves",), dict, "{default_mode, modes: {mode: {default_curve, ...}}}")
        if ec is None:
            return None, None, [], ("effort_curves",)
        modes = check.get(ec, ("effort_curves", "modes"), dict, "mode -> {default_curve, curves, is_electric}")
        if not modes:
            if modes is not None:
                check.add(("effort_curves", "modes"), "is empty")
            return None, None, [], ("effort_curves",)
        mode = wanted if wanted is not None else ec.get("default_mode")
        if mode not in modes:
            where = "--mode" if wanted is not None else "effort_curves.default_mode"
            if wanted is not None:
                raise InputError(Problem(check.file, "effort_curves.modes", f"no mode {wanted!r} ({where}); the modes: "
                                         f"{', '.join(map(str, modes))}"))
            check.add(("effort_curves", "default_mode"), f"{mode!r} is not among the modes ({', '.join(map(str, modes))})")
            return None, None, [], ("effort_curves",)
        loc = ("effort_curves", "modes", mode, "default_curve")
        curve = check.get(modes[mode], loc[:-1] + ("default_curve",), dict, "{speeds, max_efforts}")
        others = [f"{m} ({'electric' if isinstance(v, dict) and v.get('is_electric') else 'thermal'})"
                  for m, v in modes.items() if m != mode]
        if curve is None:
            return None, mode, others, loc
        speeds = check.get(curve, loc + ("speeds",), list, "a list of speeds [m/s]")
        efforts = check.get(curve, loc + ("max_efforts",), list, "a list of efforts [N]")
        if speeds is None or efforts is None:
            return None, mode, others, loc
        if len(speeds) != len(efforts) or len(speeds) < 2:
            check.add(loc, f"speeds and max_efforts must be lists of the same length, at least 2 (got {len(speeds)} and "
                           f"{len(efforts)})")
            return None, mode, others, loc
        points = []
        for i, (v, f) in enumerate(zip(speeds, efforts)):
            vv = check.number(v, loc + ("speeds", i), "speed [m/s]")
            ff = check.number(f, loc + ("max_efforts", i), "effort [N]")
            if vv is None or ff is None:
                return None, mode, others, loc
            if vv < 0 or ff < 0:
                check.add(loc + ("speeds" if vv < 0 else "max_efforts", i), f"must be >= 0 (got {vv if vv < 0 else ff:g})")
                return None, mode, others, loc
            if points and vv <= points[-1][0]:
                check.add(loc + ("speeds", i), f"speeds must increase strictly ({vv:g} after {points[-1][0]:g} m/s)")
                return None, mode, others, loc
            points.append((vv, ff))
        return points, mode, others, loc
