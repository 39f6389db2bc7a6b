"""TTOBench tracks as locoplan routes, for the benchmarks (until ``locoplan import ttobench`` lands).

A track file (../shared/data/external/ttobench/tracks, see its README.md) gives ``stops`` [m],
``speed limits`` [[position_m, kmh], ...] and ``gradients`` [[position_m, permille], ...] as the starts
of sections. A route is one leg from stop to stop (positions from the leg's start); the speed limits
are capped at ``cap_kmh`` (80 km/h: the freight trains of the study). Curvatures are left out (these
tracks give them as clothoid transitions; their 600/R term is small at these radii). ``join`` puts
legs one after the other (a longer line for the solver's scaling benchmark).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.model.route import Route

TRACKS = Path(__file__).resolve().parents[1].parent / "shared/data/external/ttobench/tracks"
if not TRACKS.is_dir():  # run from a worktree one level down, or from the main checkout
    TRACKS = Path("/work/shared/data/external/ttobench/tracks")

LINES = {  # name -> (track file, leg index)
    "CH_Fribourg_Bern": ("CH_Fribourg_Bern", 0),
    "CH_StGallen_Wil": ("CH_StGallen_Wil", 0),
    "CH_Stadelhofen_Altstetten-leg1": ("CH_Stadelhofen_Altstetten", 0),
    "CN_Songjiazhuang_Yizhuang-leg1": ("CN_Songjiazhuang_Yizhuang", 0),
    "SE_Vasteras_Kolback": ("SE_Vasteras_Kolback", 0),
    "00_var_speed_limit_100": ("00_var_speed_limit_100", 0),
}


def _sections(points, a: float, b: float, key: str, cap: float | None = None) -> list[dict]:
    """``[[position, value], ...]`` section starts -> contiguous sections over [a, b], shifted to start at 0."""
    pts = sorted((float(p), float(v)) for p, v in points)
    out = []
    for i, (p, v) in enumerate(pts):
        end = pts[i + 1][0] if i + 1 < len(pts) else np.inf
        lo, hi = max(p, a), min(end, b)
        if hi <= lo:
            continue
        val = min(v, cap) if cap is not None else v
        if out and out[-1][key] == val:
            out[-1]["to_m"] = round(hi - a, 3)
        else:
            out.append({"from_m": round(lo - a, 3), "to_m": round(hi - a, 3), key: val})
    return out


def track_leg(track: str, leg: int = 0, cap_kmh: float | None = 80.0) -> Route:
    """Leg ``leg`` (stop ``leg`` to stop ``leg + 1``) of a TTOBench track as a route."""
    data = json.loads((TRACKS / f"{track}.json").read_text())
    stops = data["stops"]["values"]
    a, b = float(stops[leg]), float(stops[leg + 1])
    limits = _sections(data["speed limits"]["values"], a, b, "kmh", cap_kmh)
    grads = data.get("gradients", {"values": [[0.0, 0.0]]})["values"]
    gradients = _sections([[p, max(-40.0, min(40.0, g))] for p, g in grads], a, b, "permille")
    length = round(b - a, 3)
    limits[-1]["to_m"] = gradients[-1]["to_m"] = length
    return Route.model_validate({"schema": "locoplan/route@1", "name": f"{track} leg {leg + 1} (TTOBench, <= {cap_kmh:g} km/h)",
                                 "length_m": length, "speed_limits": limits, "gradients": gradients})


def line(name: str, cap_kmh: float | None = 80.0) -> Route:
    track, leg = LINES[name]
    return track_leg(track, leg, cap_kmh)


def join(routes: list[Route], name: str) -> Route:
    """The routes one after the other (no stop in between)."""
    limits, grads, off = [], [], 0.0
    for r in routes:
        for sec in r.speed_limits:
            limits.append({"from_m": sec.from_m + off, "to_m": sec.to_m + off, "kmh": sec.kmh})
        for sec in r.gradients:
            grads.append({"from_m": sec.from_m + off, "to_m": sec.to_m + off, "permille": sec.permille})
        off += r.length_m
    return Route.model_validate({"schema": "locoplan/route@1", "name": name, "length_m": off,
                                 "speed_limits": limits, "gradients": grads})
