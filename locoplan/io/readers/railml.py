"""railML 2.x infrastructure (XML) to a locoplan route and journey.

A run is a list of tracks joined end to end (``--track ID ...``, each from its begin to its end, or
backwards where the next track joins its begin), or the shortest path from one operational control
point to another (``--from OCP --to OCP``) through the tracks' connections (track ends and switches).

Read from each track's ``trackElements``: ``speedChange`` (``vMax`` km/h from ``pos`` on, in its
``dir``; a ``trainCategory`` / ``profileRef`` one for ``--category`` only), ``gradientChange`` (``slope``
per mille from ``pos`` on, rising in the track's direction unless ``dir="down"``), ``radiusChange``
(``radius`` m from ``pos`` on, 0 straight), ``tunnel`` (``pos``, ``length``), ``platformEdge`` (a
station's position, with ``ocpRef``); from ``trackTopology``: ``trackBegin`` / ``trackEnd`` (the
track's extent, ``absPos`` its kilometre post), ``mileageChange`` (the kilometre post jumps from
``absPosIn`` to ``absPos``, counting ``absDir`` raising or falling on), ``crossSection`` (``ocpRef`` at
``pos``) and ``connection`` elements. Operational control points (``ocp``) are the stations.

The file is parsed with lxml without resolving entities, loading a DTD or touching the network, and
a document with a DOCTYPE is refused before parsing (railML is defined by its XML schema and needs
none; a DTD can declare entities that expand a small file into gigabytes, or read local files).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from ...errors import InputError, Problem
from ..load import read_bytes
from . import emit
from .base import MAX_GRADIENT_PERMILLE, MAX_SPEED_KMH, Imported, ImportedFile, ImportOptions, licence_near
from .network import Network, Segment, merge_ranges, on_path, search, step_function

MAX_XML_BYTES = 256 * 1024 * 1024
MIN_RADIUS_M = 100.0
TOL_M = 1e-3
_DOCTYPE = re.compile(rb"<!DOCTYPE|<!ENTITY", re.IGNORECASE)


def _local(tag: Any) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


class XmlChecker:
    """Problems of one XML source, each at an element and its line."""

    def __init__(self, file: str):
        self.file = file
        self.problems: list[Problem] = []

    def add(self, el, message: str, attr: str = "") -> None:
        field = _local(el.tag) + (f"@{attr}" if attr else "") + (f"[id={el.get('id')}]" if el.get("id") else "")
        self.problems.append(Problem(self.file, field, message, el.sourceline))

    def raise_if_any(self) -> None:
        if self.problems:
            raise InputError(self.problems)

    def number(self, el, attr: str, what: str, required: bool = True, default: float | None = None) -> float | None:
        raw = el.get(attr)
        if raw is None:
            if required:
                self.add(el, f"required attribute {attr} is missing ({what})", attr)
            return default
        try:
            x = float(raw.strip())
        except ValueError:
            self.add(el, f"{what} must be a number (got {raw[:60]!r})", attr)
            return None
        if not math.isfinite(x):
            self.add(el, f"{what} must be finite (got {raw[:60]!r})", attr)
            return None
        return x


def parse_xml(path: Path):
    """The document's root element, parsed safely (see the module's docstring); a malformed document or one
    with a DOCTYPE raises ``InputError`` with the line."""
    from lxml import etree

    data = read_bytes(path, MAX_XML_BYTES)
    name = str(path)
    m = _DOCTYPE.search(data[:1 << 20])
    if m is not None:
        line = data[:m.start()].count(b"\n") + 1
        raise InputError(Problem(name, "DOCTYPE", "a document type declaration (DTD) is not accepted: railML needs "
                                 "none, and a DTD's entities can expand a small file into gigabytes or read other "
                                 "files; remove the <!DOCTYPE ...> block", line))
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, dtd_validation=False,
                             huge_tree=False, remove_comments=True, remove_pis=True)
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        line = exc.lineno if isinstance(exc.lineno, int) else None
        raise InputError(Problem(name, "", f"not well-formed XML: {exc.msg}"[:300], line)) from None
    tree = root.getroottree()
    if tree.docinfo.doctype or tree.docinfo.internalDTD is not None:
        raise InputError(Problem(name, "DOCTYPE", "a document type declaration (DTD) is not accepted: railML needs none"))
    return root


def _children(el, name: str):
    return [c for c in el if _local(c.tag) == name]


def _child(el, name: str):
    for c in el:
        if _local(c.tag) == name:
            return c
    return None


def _descendants(el, name: str):
    return [c for c in el.iter() if _local(c.tag) == name]


class Track:
    def __init__(self, el, check: XmlChecker):
        self.el = el
        self.id = el.get("id")
        self.name = el.get("name") or self.id
        topo = _child(el, "trackTopology")
        self.begin = _child(topo, "trackBegin") if topo is not None else None
        self.end = _child(topo, "trackEnd") if topo is not None else None
        self.ok = False
        if topo is None or self.begin is None or self.end is None:
            check.add(el, "a track needs trackTopology with trackBegin and trackEnd (its extent)")
            return
        b0 = check.number(self.begin, "pos", "trackBegin position [m]", required=False, default=0.0)
        e0 = check.number(self.end, "pos", "trackEnd position [m]")
        if b0 is None or e0 is None:
            return
        if e0 <= b0:
            check.add(self.end, f"trackEnd pos {e0:g} m is not beyond trackBegin pos {b0:g} m", "pos")
            return
        self.origin, self.length = b0, e0 - b0
        self.topo = topo
        self.elements = _child(el, "trackElements")
        self.ok = True

    def items(self, group: str, name: str) -> list:
        """Elements ``name`` under ``trackElements/group`` (railML 2.x groups them: speedChanges/speedChange)."""
        out = []
        if self.elements is not None:
            for g in _children(self.elements, group):
                out += _children(g, name)
        return out

    def pos(self, el, check: XmlChecker, attr: str = "pos") -> float | None:
        """An element's position on the track [m from trackBegin], inside the track."""
        x = check.number(el, attr, "position [m]")
        if x is None:
            return None
        x -= self.origin
        if not -TOL_M <= x <= self.length + TOL_M:
            check.add(el, f"position {x + self.origin:g} m lies outside track {self.id!r} ({self.origin:g} .. "
                          f"{self.origin + self.length:g} m)", attr)
            return None
        return min(max(x, 0.0), self.length)


def _dir(el) -> int:
    """+1 up (the track's direction), -1 down, 0 both / none / not given."""
    d = (el.get("dir") or "").strip().lower()
    return 1 if d == "up" else -1 if d == "down" else 0


class RailmlReader:
    name = "railml"
    options = frozenset({"cap_kmh", "from_station", "to_station", "via", "stops", "tracks", "category"})
    min_files = 1
    max_files = 1

    def read(self, sources: list[Path], options: ImportOptions) -> Imported:
        path = sources[0]
        by_tracks = bool(options.tracks)
        by_ocp = bool(options.from_station or options.to_station)
        if by_tracks == by_ocp or (by_ocp and not (options.from_station and options.to_station)):
            raise InputError(Problem("<command line>", "--track/--from", "give the tracks to run along (--track ID, "
                                     "repeated in running order) or the stations (--from OCP --to OCP), one of the two"))
        if by_tracks and options.via:
            raise InputError(Problem("<command line>", "--via", "applies to --from/--to, not to --track"))
        root = parse_xml(path)
        check = XmlChecker(str(path))
        if _local(root.tag) != "railml":
            raise InputError(Problem(str(path), _local(root.tag), f"not a railML document: the root element is "
                                     f"<{_local(root.tag)}>, expected <railml>", root.sourceline))
        version = root.get("version") or ""
        ns = root.nsmap.get(None) or ""
        if version.startswith("3") or "/3" in ns[-4:]:
            raise InputError(Problem(str(path), "railml@version", f"railML {version or ns} is not railML 2.x (2.0 .. 2.5): "
                                     "railML 3 describes topology and positions differently", root.sourceline))
        infra = _child(root, "infrastructure")
        if infra is None:
            raise InputError(Problem(str(path), "railml", "no <infrastructure> element", root.sourceline))
        tracks: dict[str, Track] = {}
        for el in _descendants(infra, "track"):
            if not el.get("id"):
                check.add(el, "a track needs an id")
                continue
            t = Track(el, check)
            if t.ok:
                if t.id in tracks:
                    check.add(el, f"track id {t.id!r} is given twice (also line {tracks[t.id].el.sourceline})")
                tracks[t.id] = t
        check.raise_if_any()
        ocps = self._ocps(infra, tracks, check)
        net = self._network(tracks, check)
        check.raise_if_any()
        if by_tracks:
            segments = self._along(tracks, net, options.tracks, path)
            names = [tracks[options.tracks[0]].name, tracks[options.tracks[-1]].name]
            wp_ids: list[str] = []
        else:
            wp_ids = [self._find(ocps, w, flag, path) for w, flag in
                      [(options.from_station, "--from")] + [(v, "--via") for v in options.via] + [(options.to_station, "--to")]]
            for oid in wp_ids:
                if not ocps[oid]["places"]:
                    raise InputError(Problem(str(path), f"ocp[id={oid}]", "the operational control point has no position on "
                                             "a track (no crossSection, platformEdge or macroscopicNode refers to it)",
                                             ocps[oid]["line"]))
            found, _ = search(net, [ocps[o]["places"] for o in wp_ids])
            if found is None:
                raise InputError(Problem(str(path), "connections", f"no path from {ocps[wp_ids[0]]['name']!r} to "
                                         f"{ocps[wp_ids[-1]]['name']!r} through the tracks' connections without "
                                         "reversing"))
            segments = found.segments
            names = [ocps[wp_ids[0]]["name"], ocps[wp_ids[-1]]["name"]]
        return self._files(path, root, tracks, ocps, segments, names, wp_ids, options, check)

    # ------------------------------------------------------------------------------------ topology
    def _ocps(self, infra, tracks: dict[str, Track], check: XmlChecker) -> dict[str, dict]:
        ocps: dict[str, dict] = {}
        for el in _descendants(infra, "ocp"):
            oid = el.get("id")
            if not oid:
                continue
            name = el.get("name") or oid
            ocps[oid] = {"name": name, "places": [], "line": el.sourceline}
        for t in tracks.values():
            refs = [(cs, t.pos(cs, check)) for cs in _descendants(t.topo, "crossSection") if cs.get("ocpRef")]
            for pe in t.items("platformEdges", "platformEdge"):
                if pe.get("ocpRef"):
                    p = t.pos(pe, check)
                    length = check.number(pe, "length", "platform length [m]", required=False, default=0.0) or 0.0
                    if p is not None:  # the middle of the platform (pos is its start in the track's direction)
                        p = min(max(p + (length / 2 if _dir(pe) >= 0 else -length / 2), 0.0), t.length)
                    refs.append((pe, p))
            for end, p in ((t.begin, 0.0), (t.end, t.length)):
                for node in _children(end, "macroscopicNode"):
                    if node.get("ocpRef"):
                        refs.append((node, p))
            for el, p in refs:
                ref = el.get("ocpRef")
                if p is None:
                    continue
                if ref not in ocps:
                    check.add(el, f"ocpRef {ref!r} names no ocp of the file", "ocpRef")
                    continue
                ocps[ref]["places"].append((t.id, p))
        return ocps

    def _network(self, tracks: dict[str, Track], check: XmlChecker) -> Network:
        net = Network()
        for t in tracks.values():
            net.lengths[t.id] = t.length
        owner: dict[str, tuple] = {}  # connection id -> ("end", track, BEGIN/END) or ("switch", track, pos, orientation)
        conns = []
        for t in tracks.values():
            for end_el, end in ((t.begin, "BEGIN"), (t.end, "END")):
                for c in _children(end_el, "connection"):
                    if c.get("id"):
                        owner[c.get("id")] = ("end", t.id, end)
                        conns.append(c)
            holder = _child(t.topo, "connections")
            for sw in (list(holder) if holder is not None else []):
                if _local(sw.tag) not in ("switch", "crossing"):
                    continue
                p = t.pos(sw, check)
                for c in _children(sw, "connection"):
                    if c.get("id") and p is not None:
                        owner[c.get("id")] = ("switch", t.id, p, (c.get("orientation") or "").lower())
                        conns.append(c)
        done = set()
        for c in conns:
            a, ref = c.get("id"), c.get("ref")
            if not ref:
                continue
            if ref not in owner:
                check.add(c, f"connection {a!r} refers to {ref!r}, which is no connection of the file: the topology is "
                             "not well formed", "ref")
                continue
            if (ref, a) in done:
                continue
            done.add((a, ref))
            oa, ob = owner[a], owner[ref]
            if oa[0] == "end" and ob[0] == "end":
                net.link_ends(oa[1], oa[2], ob[1], ob[2])
            elif oa[0] == "end" or ob[0] == "end":
                end, sw = (oa, ob) if oa[0] == "end" else (ob, oa)
                _, t2, e2 = end
                _, t3, p, orient = sw
                p2 = 0.0 if e2 == "BEGIN" else net.lengths[t2]
                into = 1 if e2 == "BEGIN" else -1
                dirs = [1] if orient == "outgoing" else [-1] if orient == "incoming" else [1, -1]
                for d in dirs:
                    net.add_jump(t3, p, d, t2, p2, into)
                    net.add_jump(t2, p2, -into, t3, p, -d)
        return net

    def _along(self, tracks: dict[str, Track], net: Network, ids: tuple[str, ...], path: Path) -> list[Segment]:
        for tid in ids:
            if tid not in tracks:
                listed = ", ".join(sorted(tracks)[:40])
                raise InputError(Problem(str(path), "track", f"no track {tid!r} (--track); the tracks: {listed}"))
        dirs = [1] * len(ids)
        for k in range(len(ids) - 1):
            a, b = ids[k], ids[k + 1]
            options = []
            for d in (1, -1):
                pos = net.lengths[a] if d == 1 else 0.0
                for j, t2, p2, d2 in net.jumps.get((a, d), ()):
                    if t2 == b and j == pos and p2 in (0.0, net.lengths[b]):
                        options.append((d, d2))
            if not options:
                raise InputError(Problem(str(path), "connection", f"tracks {a!r} and {b!r} (--track) are not joined end "
                                         "to end by a connection: give the tracks in running order"))
            if k == 0:
                dirs[0] = options[0][0]
            match = [o for o in options if o[0] == dirs[k]]
            if not match:
                raise InputError(Problem(str(path), "connection", f"track {b!r} joins {a!r} at the end the run enters "
                                         f"{a!r} by: the run would reverse"))
            dirs[k + 1] = match[0][1]
        segs, s = [], 0.0
        for tid, d in zip(ids, dirs):
            length = net.lengths[tid]
            segs.append(Segment(tid, 0.0 if d == 1 else length, length if d == 1 else 0.0, s))
            s += length
        return segs

    @staticmethod
    def _find(ocps: dict, wanted: str, flag: str, path: Path) -> str:
        if wanted in ocps:
            return wanted
        hits = [o for o, v in ocps.items() if v["name"] == wanted]
        if len(hits) == 1:
            return hits[0]
        listed = ", ".join(sorted(f"{v['name']} ({o})" if v["name"] != o else o for o, v in ocps.items())[:40])
        why = f"names {len(hits)} ocps: give the id" if hits else "is no ocp of the file"
        raise InputError(Problem(str(path), "ocp", f"{wanted!r} ({flag}) {why}; the ocps: {listed or 'none'}"))

    # ------------------------------------------------------------------------------------ profiles
    def _files(self, path: Path, root, tracks, ocps, segments: list[Segment], names, wp_ids, options, check):
        length = round(sum(s.length for s in segments), 3)
        notes: list[str] = []
        limits = self._speeds(tracks, segments, length, options, check, notes, path)
        grads = self._steps(tracks, segments, length, "gradientChanges", "gradientChange", "slope", check, signed=True)
        curves_raw = self._steps(tracks, segments, length, "radiusChanges", "radiusChange", "radius", check, signed=False)
        check.raise_if_any()
        gradients = step_function(length, [(a, b, v[0] if v else 0.0) for a, b, v in grads], 0.0, combine=lambda vs: vs[-1])
        for _a, _b, v in grads:
            if v and abs(v[0]) > MAX_GRADIENT_PERMILLE:
                check.add(v[1], f"slope {v[0]:g} per mille is beyond the route schema's +-{MAX_GRADIENT_PERMILLE:g}", "slope")
        curves, clamped = [], 0
        for a, b, v in curves_raw:
            if not v or v[0] == 0:
                continue
            r = abs(v[0])
            if r < MIN_RADIUS_M:
                r, clamped = MIN_RADIUS_M, clamped + 1
            curves.append((a, b, r))
        curves = [(a, b, r) for a, b, r in step_function(length, curves, None) if r is not None]
        if clamped:
            notes.append(f"{path}: {clamped} curve(s) sharper than {MIN_RADIUS_M:g} m set to {MIN_RADIUS_M:g} m")
        tunnels = self._tunnels(tracks, segments, check)
        chainage = self._chainage(tracks, segments, check)
        check.raise_if_any()
        stations = self._stations(ocps, segments, length, wp_ids)
        lic, copyright_line = licence_near(path)
        rid = _safe("-".join(wp_ids) if wp_ids else "-".join(options.tracks))
        relpath = f"{rid}.yaml"
        version = root.get("version") or "2.x"
        head = [f"{names[0]} to {names[-1]}: a run through a railML {version} infrastructure ({length / 1000:.3f} km).",
                f"Source: {path}.",
                ("Licence: see the source" + (f"; {copyright_line}" if copyright_line else "")
                 + ("; full text in LICENSE-railml.txt in the import's output folder." if lic else ".")),
                f"Converted by: {options.command}" if options.command else "Converted by locoplan's railml importer.",
                "Path (track: from .. to [m], in running order): "
                + "; ".join(f"{s.track}: {emit.num(s.a)} .. {emit.num(s.b)}" for s in segments) + ".",
                "Conversion: positions in metres from the start of the run; speedChange vMax [km/h] from its pos on in "
                "its dir" + (f" (category {options.category!r} where given)" if options.category else "")
                + "; gradientChange slope [per mille] rising in the track's direction (its sign turned where a track is "
                "run down); radiusChange |radius| [m] (0 straight); tunnel pos .. pos + length; kilometre posts from "
                "trackBegin/absPos and mileageChange."]
        if options.cap_kmh:
            head.append(f"Speed limits capped at {emit.num(options.cap_kmh)} km/h.")
        text = emit.route_yaml(head, f"{names[0]} - {names[-1]} (railML)", length, limits, gradients, curves,
                               tunnels=tunnels, stations=[(n, s) for n, s in stations], chainage=chainage)
        summary = (f"{relpath}: {length / 1000:.3f} km, {len(limits)} speed-limit, {len(gradients)} gradient section(s), "
                   f"{len(curves)} curve(s), {len(tunnels)} tunnel(s), {len(stations)} station(s)")
        files = [ImportedFile(relpath, "route", text, summary, str(path),
                              {"speed_limits": "speedChange", "gradients": "gradientChange", "curves": "radiusChange",
                               "tunnels": "tunnel", "chainage": "mileageChange", "stations": "ocp"})]
        if len(stations) >= 2 and stations[0][1] == 0 and stations[-1][1] == length:
            files.append(self._journey(path, stations, relpath, options, names, ocps))
        else:
            notes.append(f"{path}: no journey file: the run does not start and end at operational control points")
        return Imported(files, lic, "railml", notes)

    def _speeds(self, tracks, segments, length, options, check, notes, path):
        """The speed limits along the run: each speedChange (in the run's direction; a category's only for
        ``--category``) applies from its position on, across track ends, until the next one is passed (the last
        sign passed governs; at the same position the category's wins)."""
        cat = options.category
        series: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
        initial: dict[bool, tuple[float, float] | None] = {False: None, True: None}
        categories: set[str] = set()
        for k, seg in enumerate(segments):
            t = tracks[seg.track]
            for el in t.items("speedChanges", "speedChange"):
                if _dir(el) not in (0, seg.direction):
                    continue
                label = [el.get(a) for a in ("trainCategory", "etcsTrainCategory", "profileRef") if el.get(a)]
                categories.update(label)
                if label and (cat is None or cat not in label):
                    continue
                if (el.get("vMax") or "").strip().lower() in ("", "none"):
                    continue  # a marker, or the end of another category's restriction
                p = t.pos(el, check)
                v = check.number(el, "vMax", "speed limit vMax [km/h]")
                if p is None or v is None:
                    continue
                if not 0 < v <= MAX_SPEED_KMH:
                    check.add(el, f"vMax {v:g} km/h is outside (0, {MAX_SPEED_KMH:g}]", "vMax")
                    continue
                sp = bool(label)
                s = seg.s_of(p)
                if seg.s0 - 1e-9 <= s <= seg.s0 + seg.length + 1e-9:
                    series[sp].append((max(s, 0.0), v))
                elif k == 0 and s < seg.s0 and (initial[sp] is None or s > initial[sp][0]):
                    initial[sp] = (s, v)  # behind the start: the limit the run starts under
        if cat is not None and cat not in categories:
            notes.append(f"{path}: no speedChange on the run names the category {cat!r} (categories: "
                         f"{', '.join(sorted(categories)) or 'none'}): the general limits are used")
        if cat is None and categories:
            notes.append(f"{path}: speedChange elements for the categories {', '.join(sorted(categories))} are left "
                         "out (--category NAME picks one)")
        starts: list[tuple[float, int, float]] = []
        for sp in (False, True):
            ev = sorted(series[sp], key=lambda e: e[0])
            if initial[sp] is not None and not (ev and ev[0][0] <= 1e-6):
                ev = [(0.0, initial[sp][1])] + ev
            starts += [(a, int(sp), v) for a, v in ev]
        starts.sort(key=lambda e: (e[0], e[1]))  # the last sign passed governs; the category's at the same place
        if not starts:
            raise InputError(Problem(str(path), "speedChange", "no speedChange applies on the run: its speed limits "
                                     "are unknown"))
        if starts[0][0] > 1e-6:
            notes.append(f"{path}: no speedChange at or before the start of the run (in its direction): the first one "
                         f"met, {starts[0][2]:g} km/h, is taken from the start")
            starts[0] = (0.0, starts[0][1], starts[0][2])
        pieces = [(a, b, v) for (a, _, v), (b, _, _) in zip(starts, starts[1:] + [(length, 0, 0.0)])]
        cap = options.cap_kmh
        return step_function(length, [(a, b, min(v, cap) if cap else v) for a, b, v in pieces], None,
                             combine=lambda vs: vs[0])

    def _steps(self, tracks, segments, length, group, name, attr, check, signed: bool):
        """A track property that changes at elements (gradient, radius): (s0, s1, (value, element)) on the path."""
        ranges: dict[str, list] = {}
        for tid in {s.track for s in segments}:
            t = tracks[tid]
            items = []
            for el in t.items(group, name):
                p = t.pos(el, check)
                v = check.number(el, attr, f"{name} {attr}")
                if p is None or v is None:
                    continue
                items.append((p, v, el, _dir(el)))
            ups = [(p, v, el) for p, v, el, d in items if d >= 0]
            downs = [(p, -v if signed else v, el) for p, v, el, d in items if d < 0]
            rows = []
            if ups or not downs:
                ups.sort(key=lambda r: r[0])
                for i, (p, v, el) in enumerate(ups):
                    end = ups[i + 1][0] if i + 1 < len(ups) else t.length
                    rows.append((p, end, (v, el)))
            else:  # only down-direction changes: each applies from its pos down to the previous one
                downs.sort(key=lambda r: r[0])
                for i, (p, v, el) in enumerate(downs):
                    start = downs[i - 1][0] if i else 0.0
                    rows.append((start, p, (v, el)))
                if downs:
                    rows.append((downs[-1][0], t.length, (0.0, downs[-1][2])))
            ranges[tid] = [r for r in rows if r[1] > r[0]]
        transform = (lambda v, d: (v[0] * d, v[1])) if signed else None
        return on_path(segments, ranges, transform=transform)

    def _tunnels(self, tracks, segments, check):
        ranges: dict[str, list] = {}
        for tid in {s.track for s in segments}:
            t = tracks[tid]
            for el in t.items("tunnels", "tunnel"):
                p = t.pos(el, check)
                n = check.number(el, "length", "tunnel length [m]")
                if p is None or n is None:
                    continue
                if n <= 0:
                    check.add(el, f"tunnel length must be > 0 m (got {n:g})", "length")
                    continue
                a, b = (p, p + n) if _dir(el) >= 0 else (p - n, p)
                ranges.setdefault(tid, []).append((max(a, 0.0), min(b, t.length), el))
        return merge_ranges((a, b) for a, b, _ in on_path(segments, ranges))

    def _chainage(self, tracks, segments, check):
        """Kilometre posts along the run: (at_m, km, descending) at the run's start and wherever the posts jump."""
        out: list[tuple[float, float, bool]] = []
        for seg in segments:
            t = tracks[seg.track]
            pieces = self._mileage(t, check)
            if pieces is None:
                return None
            for x0, x1, km0, slope in (pieces if seg.direction == 1 else reversed(pieces)):  # km = km0 + slope (x - x0) / 1000
                lo, hi = max(x0, min(seg.a, seg.b)), min(x1, max(seg.a, seg.b))
                if hi <= lo and not (seg.length == 0):
                    continue
                entry_x = lo if seg.direction == 1 else hi
                s = round(seg.s_of(entry_x), 6)
                km = km0 + slope * (entry_x - x0) / 1000.0
                desc = slope * seg.direction < 0
                if out:
                    ps, pkm, pdesc = out[-1]
                    expected = pkm + (-1 if pdesc else 1) * (s - ps) / 1000.0
                    if pdesc == desc and abs(expected - km) < 1e-9:
                        continue
                out.append((s, round(km, 9), desc))
        return out or None

    def _mileage(self, t: Track, check):
        """The track's kilometre posts: [(x0, x1, km at x0, +1/-1)] over [0, length], or None without absPos."""
        start = check.number(t.begin, "absPos", "kilometre post absPos [m]", required=False)
        changes = []
        for mc in _descendants(t.topo, "mileageChange"):
            p = t.pos(mc, check)
            abs_in = check.number(mc, "absPosIn", "kilometre post before the change [m]", required=False)
            abs_out = check.number(mc, "absPos", "kilometre post after the change [m]")
            d = (mc.get("absDir") or "").lower()
            if d not in ("raising", "rising", "falling", ""):
                check.add(mc, f"absDir must be raising or falling (got {mc.get('absDir')!r})", "absDir")
                continue
            if p is None or abs_out is None:
                continue
            changes.append((p, abs_in, abs_out, -1 if d == "falling" else 1 if d else None))
        if start is None:
            if changes:
                check.add(t.begin, "the track has mileageChange elements but its trackBegin gives no absPos: the "
                                   "kilometre post at its start is unknown", "absPos")
            return None
        changes.sort(key=lambda c: c[0])
        slope = 1
        if changes and changes[0][1] is not None and changes[0][0] > 0:
            slope = 1 if changes[0][1] >= start else -1
        elif not changes:
            end = check.number(t.end, "absPos", "kilometre post absPos [m]", required=False)
            if end is not None and end < start:
                slope = -1
        pieces = []
        x, km = 0.0, start / 1000.0
        for p, _, abs_out, d in changes:
            if p > x:
                pieces.append((x, p, km, slope))
            x, km = p, abs_out / 1000.0
            slope = d if d is not None else slope
        pieces.append((x, t.length, km, slope))
        return pieces

    @staticmethod
    def _stations(ocps, segments, length, wp_ids) -> list[tuple[str, float]]:
        hits = []
        for oid, v in ocps.items():
            for tid, p in v["places"]:
                for seg in segments:
                    lo, hi = min(seg.a, seg.b), max(seg.a, seg.b)
                    if seg.track == tid and lo - 1e-6 <= p <= hi + 1e-6:
                        hits.append((round(seg.s_of(p), 3), oid))
        hits.sort()
        out: list[tuple[str, float]] = []
        used: dict[str, int] = {}
        taken: set[str] = set()
        for s, oid in hits:
            if oid in taken and wp_ids and oid not in (wp_ids[-1],):
                continue
            if out and s <= out[-1][1]:
                continue
            name = ocps[oid]["name"]
            n = used.get(name, 0)
            used[name] = n + 1
            out.append((name if n == 0 else f"{name} ({n + 1})", s))
            taken.add(oid)
        if wp_ids:
            first, last = ocps[wp_ids[0]]["name"], ocps[wp_ids[-1]]["name"]
            out = [x for x in out if 0 < x[1] < length and x[0] not in (first, last)]
            out = [(first, 0.0)] + out + [(last, length)]
        return out

    def _journey(self, path, stations, route_rel, options, names, ocps) -> ImportedFile:
        wanted = set()
        for w in options.stops:
            name = ocps[w]["name"] if w in ocps else w
            if name not in [n for n, _ in stations[1:-1]]:
                listed = ", ".join(n for n, _ in stations[1:-1]) or "none"
                raise InputError(Problem("<command line>", "--stop", f"{w!r} is not passed by the run (the stations "
                                         f"passed: {listed})"))
            wanted.add(name)
        rows = [(n, s, i in (0, len(stations) - 1) or n in wanted) for i, (n, s) in enumerate(stations)]
        relpath = route_rel.replace(".yaml", "-journey.yaml")
        head = [f"{names[0]} to {names[-1]}: a journey over the railML run with every operational control point it "
                f"passes ({len(rows)}), from {path}.",
                f"Converted by: {options.command}" if options.command else "Converted by locoplan's railml importer.",
                "Stops: the first and the last station" + (f" and {', '.join(sorted(wanted))} (--stop)" if wanted else "")
                + "; give the running time with locoplan journey --time."]
        text = emit.journey_yaml(head, f"{names[0]} - {names[-1]}", route_rel, rows)
        return ImportedFile(relpath, "journey", text, f"{relpath}: {len(rows)} stations, {sum(r[2] for r in rows)} stops",
                            str(path), {"stations": "ocp"})


def _safe(name: str) -> str:
    return (re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "x")[:120]
