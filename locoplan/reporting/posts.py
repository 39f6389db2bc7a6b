"""Positions as people on the line read them: kilometre posts (the route's chainage) and station names.

A route without a chainage has no posts of its own: its positions are counted from its start (0 km), and
tables keep metres as they were. Every position ``X_m`` of a ``--json`` result gets its post beside it as
``X_km_post`` (km, a number: a station's ``at_m`` its ``at_km_post``); the profile CSV gets ``km_post`` and
``station``.
"""

from __future__ import annotations

import numpy as np

from ..model.route import format_post, kilometre_post

POST_DIGITS = 6
"""Kilometre posts in JSON and CSV are rounded to the millimetre."""


def has_chainage(route) -> bool:
    """Whether ``route`` gives kilometre posts of its own."""
    return route is not None and route.chainage is not None


def post_km(route, s_m):
    """The kilometre post [km] at position(s) ``s_m`` [m]: the route's chainage, else the km from its start."""
    post = kilometre_post(route, s_m) if has_chainage(route) else None
    if post is None:
        post = np.asarray(s_m, dtype=float) / 1000.0
        return float(post) if post.ndim == 0 else post
    return post


def post_text(route, s_m: float, form: str = "km", unit: bool = True) -> str:
    """The post at ``s_m`` as people write it (``12.345 km`` or ``12+345``; ``unit`` False: ``12.345``)."""
    km = post_km(route, s_m)
    return format_post(km, form) if unit or form == "plus" else f"{km:.3f}"


def where(route, s_m: float, form: str = "km") -> str:
    """A position for a table: ``2,400 m`` as before on a route without a chainage, ``2,400 m, 102.400 km``
    (or ``102+400``) on one with it."""
    text = f"{s_m:,.0f} m"
    return f"{text}, {post_text(route, s_m, form)}" if has_chainage(route) else text


def station_place(route, st, form: str = "km") -> str:
    """A station with its place: ``B (102.400 km)`` on a route with a chainage, ``B (2,400 m)`` without."""
    place = post_text(route, st.at_m, form) if has_chainage(route) else f"{st.at_m:,.0f} m"
    return f"{st.name} ({place})"


def stations_in(route, from_m: float, to_m: float, last: bool = False) -> list:
    """The route's stations in [from_m, to_m) (with ``last``, to_m included: the run's final section)."""
    if route is None:
        return []
    return [st for st in route.stations
            if from_m - 1e-6 <= st.at_m < to_m - 1e-6 or (last and abs(st.at_m - to_m) <= 1e-6)]


def node_stations(route, s_m) -> dict[int, str]:
    """Each station of ``route`` at the node of the grid ``s_m`` nearest to it: node index -> name (names joined
    with " / " where two stations share a node)."""
    out: dict[int, str] = {}
    if route is None or not route.stations:
        return out
    s = np.asarray(s_m, dtype=float)
    for st in route.stations:
        k = int(np.argmin(np.abs(s - st.at_m)))
        out[k] = f"{out[k]} / {st.name}" if k in out else st.name
    return out


def _km(value) -> float | None:
    return None if value is None else round(float(value), POST_DIGITS)


def stations_json(route) -> list[dict]:
    """The route's stations for ``--json``: ``[{"name", "at_m", "at_km_post"}, ...]``."""
    return [{"name": st.name, "at_m": st.at_m, "at_km_post": _km(post_km(route, st.at_m))} for st in route.stations]


def _posted(obj, route):
    """``obj`` with every ``X_m`` (a number or a list of numbers) followed by ``X_km_post``, in dicts at any depth."""
    if isinstance(obj, list):
        return [_posted(x, route) for x in obj]
    if not isinstance(obj, dict):
        return obj
    out = {}
    for key, value in obj.items():
        out[key] = _posted(value, route)
        if not key.endswith("_m") or key.endswith("_per_m") or "length" in key or key == "step_m":
            continue
        name = key[:-2] + "_km_post"
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            out[name] = _km(post_km(route, value))
        elif isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
            out[name] = [_km(post_km(route, v)) for v in value]
        elif value is None:
            out[name] = None
    return out


def with_posts(result: dict, route) -> dict:
    """A result (one run's summary, or ``{"results": [...]}``) for ``--json`` and ``--out .json``: every position
    ``X_m`` with its kilometre post ``X_km_post``, the route's ``stations`` with theirs, and ``km_posts``: whether
    the posts are the route's chainage (``"chainage"``) or counted from its start (``"from the start"``)."""
    if route is None or not isinstance(result, dict):
        return result
    out = _posted(result, route)
    out["km_posts"] = "chainage" if has_chainage(route) else "from the start"
    if "stations" not in out:
        out["stations"] = stations_json(route)
    return out
