"""A track network as importers of network formats (OSRD RailJSON, railML) see it, and the path of a
train through it.

A network is tracks (an id and a length) and *jumps*: running on track ``t`` in direction ``d`` (+1:
towards increasing positions, -1: towards decreasing) through position ``p``, the train may continue
on track ``t2`` at ``p2`` in direction ``d2`` (a switch's or a link's connection, a track joined to the
next). A train never reverses: it runs each track in one direction and changes track only by a jump.

:func:`shortest_path` finds the shortest run (by length; among equally long ones, the one with the
least ``penalty``, e.g. unelectrified length) from one set of places to another through waypoints in
order. :func:`on_path` and :func:`step_function` turn properties of track ranges into sections of
the path (positions from its start).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field
from typing import Callable, Iterable

Place = tuple[str, float]
"""(track id, position on the track [m])."""


@dataclass(frozen=True)
class Segment:
    """A run along one track from ``a`` to ``b`` (track positions; ``a > b`` when run backwards), starting
    at ``s0`` metres from the path's start."""

    track: str
    a: float
    b: float
    s0: float

    @property
    def direction(self) -> int:
        return 1 if self.b >= self.a else -1

    @property
    def length(self) -> float:
        return abs(self.b - self.a)

    def s_of(self, x: float) -> float:
        """Path position of track position ``x`` (inside the segment)."""
        return self.s0 + (x - self.a) * self.direction


@dataclass
class Network:
    lengths: dict[str, float] = field(default_factory=dict)
    jumps: dict[tuple[str, int], list[tuple[float, str, float, int]]] = field(default_factory=dict)
    """(track, direction) -> [(position, track2, position2, direction2), ...]."""

    def add_jump(self, track: str, pos: float, d: int, track2: str, pos2: float, d2: int) -> None:
        self.jumps.setdefault((track, d), []).append((pos, track2, pos2, d2))

    def link_ends(self, t1: str, end1: str, t2: str, end2: str) -> None:
        """Tracks joined at their ends (``"BEGIN"`` / ``"END"``): a train leaving ``t1`` through ``end1``
        enters ``t2`` through ``end2``, and the other way round."""
        p1, p2 = self.end_pos(t1, end1), self.end_pos(t2, end2)
        leave1, leave2 = (-1 if end1 == "BEGIN" else 1), (-1 if end2 == "BEGIN" else 1)
        self.add_jump(t1, p1, leave1, t2, p2, -leave2)
        self.add_jump(t2, p2, leave2, t1, p1, -leave1)

    def end_pos(self, track: str, end: str) -> float:
        return 0.0 if end == "BEGIN" else self.lengths[track]


@dataclass
class Found:
    """A path: its segments, its length, and the path positions of the waypoints it passed."""

    segments: list[Segment]
    length: float
    waypoint_s: list[float]


def _key(x: float) -> float:
    return round(x, 6)


def search(net: Network, waypoints: list[list[Place]], penalty: Callable[[str, float, float], float] | None = None,
           ) -> tuple[Found | None, dict]:
    """The shortest path through ``waypoints`` (each a list of places: one of them is passed), or None, and
    the settled states (for :func:`reachable`). Dijkstra over states (track, direction, position, stage)."""
    pen = penalty or (lambda t, a, b: 0.0)
    n = len(waypoints)
    by_track: list[dict[str, list[float]]] = []
    for places in waypoints:
        m: dict[str, list[float]] = {}
        for t, p in places:
            m.setdefault(t, []).append(p)
        by_track.append(m)
    heap: list = []
    parent: dict = {}
    best: dict = {}
    counter = 0
    for t, p in waypoints[0]:
        for d in (1, -1):
            st = (t, d, _key(p), 1, False)
            if st not in best:
                best[st] = (0.0, 0.0)
                parent[st] = None
                heapq.heappush(heap, (0.0, 0.0, counter, st, p))
                counter += 1
    settled: dict = {}
    while heap:
        length, cost, _, st, pos = heapq.heappop(heap)
        if st in settled:
            continue
        settled[st] = (length, pos)
        track, d, _, stage, jumped = st
        if stage == n:
            return _build(parent, st, settled, net), settled

        def push(new_st, new_pos, dl, dc, seg):
            nonlocal counter
            cand = (_key(length + dl), cost + dc)
            if new_st in settled:
                return
            old = best.get(new_st)
            if old is None or cand < old:
                best[new_st] = cand
                parent[new_st] = (st, seg)
                heapq.heappush(heap, (cand[0], cand[1], counter, new_st, new_pos))
                counter += 1

        for q in by_track[stage].get(track, ()):
            if (q - pos) * d >= 0:
                push((track, d, _key(q), stage + 1, False), q, abs(q - pos), pen(track, pos, q), (track, pos, q))
        for j, t2, p2, d2 in net.jumps.get((track, d), ()):
            if (j - pos) * d > 0 or (j == pos and not jumped):
                push((t2, d2, _key(p2), stage, True), p2, abs(j - pos), pen(track, pos, j), (track, pos, j))
    return None, settled


def _build(parent: dict, st, settled: dict, net: Network) -> Found:
    pieces = []
    stages = []
    while parent[st] is not None:
        prev, seg = parent[st]
        pieces.append(seg)
        if st[3] != prev[3]:
            stages.append(len(pieces))
        st = prev
    pieces.reverse()
    marks = {len(pieces) - k for k in stages}  # the indices of the pieces that end at a waypoint
    segments: list[Segment] = []
    waypoint_s = [0.0]
    s = 0.0
    for i, (t, a, b) in enumerate(pieces):
        if b != a:
            last = segments[-1] if segments else None
            if last is not None and last.track == t and last.b == a and (b - a) * last.direction > 0:
                segments[-1] = Segment(t, last.a, b, last.s0)
            else:
                segments.append(Segment(t, a, b, s))
            s += abs(b - a)
        if i in marks:
            waypoint_s.append(s)
    return Found(segments, s, waypoint_s)


def reachable(settled: dict, places: dict[str, list[Place]]) -> dict[str, float]:
    """Name -> the shortest distance at which one of its places was reached (from the settled states of a
    search that ran to exhaustion; places on the start track ahead of the start count too)."""
    out: dict[str, float] = {}
    runs: dict[str, list[tuple[int, float, float]]] = {}
    for (track, d, _, _, _), (length, pos) in settled.items():
        runs.setdefault(track, []).append((d, pos, length))
    for name, plist in places.items():
        for t, p in plist:
            for d, pos, length in runs.get(t, ()):
                if (p - pos) * d >= 0:
                    dist = length + abs(p - pos)
                    if dist < out.get(name, float("inf")):
                        out[name] = dist
    return out


# ------------------------------------------------------------------------------------------ profiles
def on_path(segments: list[Segment], ranges: dict[str, list[tuple[float, float, object]]],
            transform: Callable[[object, int], object] | None = None,
            direction_ok: Callable[[object, int], bool] | None = None) -> list[tuple[float, float, object]]:
    """Track ranges (track -> [(begin, end, value)]) mapped onto the path: (s0, s1, value) pieces, value
    through ``transform(value, direction)`` (e.g. a slope's sign turned when the track is run backwards),
    only where ``direction_ok(value, direction)``."""
    out = []
    for seg in segments:
        lo, hi = min(seg.a, seg.b), max(seg.a, seg.b)
        for begin, end, value in ranges.get(seg.track, ()):
            a, b = max(begin, lo), min(end, hi)
            if b <= a:
                continue
            if direction_ok is not None and not direction_ok(value, seg.direction):
                continue
            s_a, s_b = sorted((seg.s_of(a), seg.s_of(b)))
            out.append((s_a, s_b, transform(value, seg.direction) if transform else value))
    return out


def step_function(length: float, pieces: Iterable[tuple[float, float, float]], default: float | None,
                  combine: Callable[[list[float]], float] = min) -> list[tuple[float, float, float | None]]:
    """Contiguous sections covering [0, length]: where pieces overlap, ``combine`` of their values, where
    none lies ``default``; positions rounded to 1 mm, equal neighbours merged."""
    events: dict[float, list[tuple[int, int]]] = {}
    plist = [(round(a, 3), round(b, 3), v) for a, b, v in pieces]
    plist = [(a, b, v) for a, b, v in plist if b > a]
    for i, (a, b, _) in enumerate(plist):
        events.setdefault(a, []).append((1, i))
        events.setdefault(b, []).append((-1, i))
    cuts = sorted(set(events) | {0.0, round(length, 3)})
    cuts = [c for c in cuts if 0.0 <= c <= round(length, 3)]
    active: set[int] = set()
    for c in sorted(events):
        if c > 0:
            break
        for kind, i in events[c]:
            (active.add if kind == 1 else active.discard)(i)
    out: list[list] = []
    for x0, x1 in zip(cuts, cuts[1:]):
        for kind, i in events.get(x0, ()) if x0 > 0 else ():
            (active.add if kind == 1 else active.discard)(i)
        value = combine([plist[i][2] for i in active]) if active else default
        if out and out[-1][2] == value:
            out[-1][1] = x1
        else:
            out.append([x0, x1, value])
    return [tuple(x) for x in out]  # type: ignore[misc]


def merge_ranges(pieces: Iterable[tuple[float, float]], min_gap: float = 0.0) -> list[tuple[float, float]]:
    """Intervals sorted and joined where they overlap or touch (or lie closer than ``min_gap``)."""
    out: list[list[float]] = []
    for a, b in sorted((round(a, 3), round(b, 3)) for a, b in pieces):
        if b <= a:
            continue
        if out and a <= out[-1][1] + min_gap:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [tuple(x) for x in out]  # type: ignore[misc]
