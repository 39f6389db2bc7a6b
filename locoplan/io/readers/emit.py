"""YAML text of route, vehicle and consist files as a person would write them: a provenance header
of comments, one section per line in flow style, numbers without float noise."""

from __future__ import annotations

import json
import textwrap

ROUND_DIGITS = 3
"""Decimals kept in positions and values (1 mm, 0.001 km/h, 0.001 per mille): sources give at most 0.1."""


def num(x: float) -> str:
    """3.0 -> '3', 0.1 + 0.2 -> '0.3', 1e-05 -> '1e-05' (shortest text that reads back to the rounded value)."""
    r = round(float(x), ROUND_DIGITS)
    if r == 0 and x != 0:
        r = float(x)  # a tiny non-zero value (none in real sources) is written as it is, not as 0
    if r == int(r) and abs(r) < 1e15:
        return str(int(r))
    return repr(r)


def coef(x: float) -> str:
    """A derived coefficient to 12 significant digits: exact for sums of decimal inputs (2.2 + 0.225 is
    written 2.425, not 2.4250000000000003), far below any physical meaning."""
    return repr(float(f"{x:.12g}"))


def text(value: str) -> str:
    """A YAML scalar for any string (JSON strings are valid YAML; quotes only where needed)."""
    plain = value and value.strip() == value and all(c.isalnum() or c in " _-.,()+/" for c in value) \
        and value[0].isalpha() and value.lower() not in ("yes", "no", "true", "false", "null", "on", "off")
    return value if plain else json.dumps(value, ensure_ascii=False)


HEADER_WIDTH = 110


def header(lines: list[str]) -> str:
    """Comment lines, wrapped at ``HEADER_WIDTH`` (a command line is kept whole so it can be copied)."""
    out = ""
    for ln in lines:
        parts = [ln] if ln.startswith("Converted by:") else textwrap.wrap(ln, HEADER_WIDTH - 2, break_on_hyphens=False, break_long_words=False) or [""]
        out += "".join(f"# {p}\n" if p else "#\n" for p in parts)
    return out


def sections(key: str, rows: list[tuple[float, float, str, float]], comment: str = "") -> str:
    """``key:`` then one ``{from_m, to_m, <field>: value}`` per line; rows are (from_m, to_m, field, value)."""
    out = f"{key}:{('  # ' + comment) if comment else ''}\n"
    for a, b, name, value in rows:
        out += f"  - {{from_m: {num(a)}, to_m: {num(b)}, {name}: {num(value)}}}\n"
    return out


def route_yaml(head: list[str], name: str, length_m: float, speed_limits, gradients, curves=(), tunnels=(),
               neutral_sections=(), stations=(), chainage=None) -> str:
    """A ``locoplan/route@1`` file; ``speed_limits``/``gradients``/``curves``: (from_m, to_m, value) rows;
    ``tunnels``, ``neutral_sections``: (from_m, to_m) rows; ``stations``: (name, at_m) rows; ``chainage``:
    (at_m, km, descending) rows (kilometre posts), or None."""
    body = header(head)
    body += "schema: locoplan/route@1\n"
    body += f"name: {text(name)}\n"
    body += f"length_m: {num(length_m)}\n"
    body += sections("speed_limits", [(a, b, "kmh", v) for a, b, v in speed_limits], "km/h")
    body += sections("gradients", [(a, b, "permille", v) for a, b, v in gradients], "per mille, + = up-grade")
    if curves:
        body += sections("curves", [(a, b, "radius_m", v) for a, b, v in curves], "additional resistance 600 / R N/kN")
    if tunnels:
        body += "tunnels:\n" + "".join(f"  - {{from_m: {num(a)}, to_m: {num(b)}}}\n" for a, b in tunnels)
    if neutral_sections:
        body += "neutral_sections:  # no traction (nor electric brake) inside\n"
        body += "".join(f"  - {{from_m: {num(a)}, to_m: {num(b)}}}\n" for a, b in neutral_sections)
    if stations:
        body += "stations:\n" + "".join(f"  - {{name: {text(n)}, at_m: {num(s)}}}\n" for n, s in stations)
    if chainage:
        body += "chainage:  # kilometre posts: from at_m on, the post reads km and counts up (or down)\n"
        body += "".join(f"  - {{at_m: {num(s)}, km: {coef(km)}, descending: {'true' if d else 'false'}}}\n"
                        for s, km, d in chainage)
    return body


def journey_yaml(head: list[str], name: str, route_file: str, stations: list[tuple[str, float, bool]]) -> str:
    """A ``locoplan/journey@1`` file over ``route_file``; ``stations``: (name, at_m, stop) in running order."""
    body = header(head) + "schema: locoplan/journey@1\n"
    body += f"name: {text(name)}\n"
    body += f"route: {text(route_file)}\n"
    body += "stations:\n"
    body += "".join(f"  - {{name: {text(n)}, at_m: {num(s)}{'' if stop else ', stop: false'}}}\n"
                    for n, s, stop in stations)
    return body


def curve_yaml(points: list[tuple[float, float]], exact: bool = False) -> str:
    """Curve points; ``exact``: to 12 significant digits (converted units), else to the 3 decimals of ``num``."""
    fmt = coef if exact else num
    return "\n".join(f"  - [{fmt(v)}, {fmt(f)}]" for v, f in points) + "\n"


def vehicle_yaml(head: list[str], name: str, kind: str, mass_t: float, length_m: float, max_speed_kmh: float,
                 resistance: tuple[float, float, float], rotating_mass_factor: float, max_load_t: float | None = None,
                 traction_kn: list | None = None, brake_kn: list | None = None, exact_curves: bool = False) -> str:
    """A ``locoplan/vehicle@1`` file. Resistance coefficients keep full precision (they are derived); with
    ``exact_curves`` so do the mass, length, top speed and force curves (converted from other units)."""
    a, b, c = resistance
    body = header(head)
    body += "schema: locoplan/vehicle@1\n"
    body += f"name: {text(name)}\n"
    body += f"kind: {kind}\n"
    fmt = coef if exact_curves else num
    body += f"mass_t: {fmt(mass_t)}\n"
    if max_load_t is not None:
        body += f"max_load_t: {num(max_load_t)}\n"
    body += f"length_m: {fmt(length_m)}\n"
    body += f"max_speed_kmh: {fmt(max_speed_kmh)}\n"
    body += f"resistance_n_per_kn: {{a: {coef(a)}, b: {coef(b)}, c: {coef(c)}}}   # w0 = a + b*v + c*v^2 [N/kN], v in km/h\n"
    body += f"rotating_mass_factor: {num(rotating_mass_factor)}\n"
    if traction_kn is not None:
        body += "traction_kn:   # [speed km/h, max tractive effort kN], linear between points\n" + curve_yaml(traction_kn, exact_curves)
    if brake_kn is not None:
        body += "brake_kn:      # [speed km/h, max electric braking force kN]\n" + curve_yaml(brake_kn, exact_curves)
    return body


def consist_yaml(head: list[str], name: str, entries: list[tuple[str, int, float]],
                 brake_deceleration_ms2: float | None = None) -> str:
    """A ``locoplan/consist@1`` file; ``entries``: (vehicle name, count, load_t per vehicle)."""
    body = header(head)
    body += "schema: locoplan/consist@1\n"
    body += f"name: {text(name)}\n"
    body += "vehicles:\n"
    for vehicle, count, load in entries:
        load_part = f", load_t: {num(load)}" if load else ""
        body += f"  - {{type: {text(vehicle)}, count: {count}{load_part}}}\n"
    if brake_deceleration_ms2 is not None:
        body += f"brake_deceleration_ms2: {num(brake_deceleration_ms2)}\n"
    return body
