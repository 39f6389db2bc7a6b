"""Bounds on every value that enters from the command line, and the checks that enforce them.

One table (``LIMITS``) says how far each input may go and why; the checks raise ``InputError`` naming
``<command line>``, the option and the bound, before any work starts. File values are bounded in their
schemas (``model/route.py``, ``model/consist.py``, ``optimize/base.py``); docs/reliability.md lists all.

A bound is never a guess at what is "reasonable" for a study: it is where a value stops meaning
anything physical (a grid finer than a metre, a negative seed) or where the work would take days or the
memory would run out (ten million sweep runs), and each message says so.
"""

from __future__ import annotations

import math
import re

from .errors import InputError, Problem
from .model.common import number

CMDLINE = "<command line>"


def _where(option: str) -> str:
    """Where a value came from: a flag (``--time``) from the command line; an argument name (``time_s``)
    from a Python caller, whose message then names the argument alone (the CLI restates it as its flag)."""
    return CMDLINE if option.startswith("--") else ""

LIMITS = {
    # reporting grid [m]: finer than 0.1 m resolves nothing the train model has; coarser than 1 km skips limits
    "step_m": (0.1, 1000.0),
    # cells of one calculator grid: memory and time grow with them (2,000 km at 10 m is 200,000 cells)
    "cells": 200_000,
    # cells a route needs at least, so that the grid resolves it at all (a 200 m route at the 50 m default)
    "min_cells": 4,
    # optimisation runs of one command (sweep values, study runs x optimisers, drivers x runs x groups):
    # each is an optimisation of seconds to minutes, so 1,000 is already a night's batch
    "runs": 1_000,
    # numpy's generators take seeds 0 .. 2**128 - 1; a seed is a label, so 0 .. 2**63 - 1 is plenty
    "seed": (0, 2**63 - 1),
    # planned running time and tolerance [s]: as a route's schedule (model/route.py)
    "time_s": (1.0, 604_800.0),
    # E_min [kWh]: more than any run's traction energy (a 10,000 t train over 2,000 km uses ~200 MWh)
    "e_min_kwh": (1e-6, 1e7),
}


def finite(value: float, option: str, lo: float | None = None, hi: float | None = None, unit: str = "",
           why: str = "", lo_open: bool = False) -> float:
    """``value`` as a float if it is finite and inside [lo, hi] (``lo_open``: (lo, hi]); else ``InputError``."""
    u = f" {unit}" if unit else ""
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(Problem(_where(option), option, f"must be a finite number{', in ' + unit if unit else ''} (got {value})"))
    low_bad = lo is not None and (value <= lo if lo_open else value < lo)
    if low_bad or (hi is not None and value > hi):
        left = "(" if lo_open else "["
        span = f"{left}{number(lo) if lo is not None else '-inf'}, {number(hi) if hi is not None else 'inf'}]{u}"
        raise InputError(Problem(_where(option), option, f"must be in {span} (got {value:g}){': ' + why if why else ''}"))
    return float(value)


def count(value: int, option: str, lo: int, hi: int, why: str) -> int:
    """An integer option inside [lo, hi]."""
    if not lo <= value <= hi:
        got = f"{value:,}" if abs(value) < 10**30 else f"an integer of {len(str(abs(value)))} digits"
        raise InputError(Problem(_where(option), option, f"must be {number(lo)} .. {number(hi)} (got {got}): {why}"))
    return value


def seed(value: int, option: str = "--seed") -> int:
    """A random seed: an integer 0 .. 2**63 - 1 (numpy refuses negative seeds)."""
    lo, hi = LIMITS["seed"]
    if not lo <= value <= hi:
        got = f"{value:,}" if abs(value) < 10**30 else f"an integer of {len(str(abs(value)))} digits"
        raise InputError(Problem(_where(option), option, f"must be an integer 0 .. 2**63 - 1 (got {got}): numpy's "
                                 "random generators take no negative seeds, and a seed is a label, not a quantity"))
    return value


def runs(n: int, option: str, what: str = "runs") -> int:
    """The number of optimisation runs one command would start, at most ``LIMITS['runs']``."""
    limit = LIMITS["runs"]
    if n > limit:
        raise InputError(Problem(_where(option), option, f"{n:,} {what} is more than the limit of {limit:,} runs per "
                                 "command (each run is an optimisation; split the study into several commands)"))
    return n


def step(step_m: float, length_m: float | None = None) -> float:
    """The calculator's grid spacing: finite, within ``LIMITS['step_m']``, and (given the route's length)
    at least ``min_cells`` and at most ``cells`` cells."""
    lo, hi = LIMITS["step_m"]
    finite(step_m, "--step", lo, hi, "m", "the reporting grid spacing")
    if length_m is not None:
        cells = length_m / step_m
        if cells > LIMITS["cells"]:
            raise InputError(Problem(CMDLINE, "--step", f"{step_m:g} m gives {cells:,.0f} cells on this {length_m:,.0f} m "
                                     f"route, more than the limit of {LIMITS['cells']:,} (memory and time grow with "
                                     f"them); use at least {length_m / LIMITS['cells']:.2g} m"))
        if cells < LIMITS["min_cells"]:
            raise InputError(Problem(CMDLINE, "--step", f"{step_m:g} m gives only {cells:.2g} cells on this "
                                     f"{length_m:,.0f} m route (at least {LIMITS['min_cells']} resolve it); use at most "
                                     f"{length_m / LIMITS['min_cells']:.3g} m"))
    return float(step_m)


def objective(value: str, option: str = "--objective") -> str:
    """What the energy terms count (``physics.energy.OBJECTIVES``): ``traction`` or ``net``; else ``InputError``."""
    from .physics.energy import OBJECTIVES

    if value not in OBJECTIVES:
        raise InputError(Problem(_where(option), option, f"unknown objective {value!r}: use one of {', '.join(OBJECTIVES)} "
                                 "(traction: the traction work sum F ds; net: less what the electric brake recovers)"))
    return value


def planned_time(time_s: float, option: str = "--time") -> float:
    lo, hi = LIMITS["time_s"]
    return finite(time_s, option, lo, hi, "s", "a planned running time (no stop-to-stop run is planned longer than a week)")


def weights(text: str, option: str = "--weights") -> tuple[float, float]:
    """'w_time,w_energy': two finite, non-negative weights summing to 1 (the ISSA paper's eq. 10)."""
    try:
        parts = [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(Problem(_where(option), option, f"expected two numbers 'w_time,w_energy', got {text!r}")) from None
    if len(parts) != 2 or not all(math.isfinite(x) and x >= 0 for x in parts) or abs(sum(parts) - 1) > 1e-9:
        raise InputError(Problem(_where(option), option, "expected two non-negative weights summing to 1 "
                                 f"(finite numbers: w_time,w_energy), got {text!r}"))
    return parts[0], parts[1]


def items(text: str, option: str) -> list[str]:
    """The items of a comma list, stripped. An empty item (a doubled or trailing comma: ``1500,,1600``)
    is refused, not dropped: it is a value the user meant to write and did not."""
    parts = [x.strip() for x in text.split(",")]
    for i, x in enumerate(parts):
        if not x:
            raise InputError(Problem(_where(option), option, f"item {i + 1} of {text!r} is empty (a doubled or trailing "
                                     "comma?): write every value, e.g. 1500,1600"))
    return parts


def number_list(text: str, option: str, lo: float, hi: float, unit: str = "", why: str = "",
                lo_open: bool = False, integer: bool = False) -> list[float]:
    """'a,b,c' (no start:stop:step): finite numbers in [lo, hi] (``lo_open``: (lo, hi]), at most
    ``LIMITS['runs']`` of them; ``integer``: whole numbers."""
    form = "expected a comma list of whole numbers, e.g. 1,2,3" if integer else "expected a comma list of numbers"
    if not text.strip():
        raise InputError(Problem(_where(option), option, f"{form}, got {text!r}"))
    if text.count(",") >= LIMITS["runs"]:
        raise InputError(Problem(_where(option), option, f"{text.count(',') + 1:,} values: more than the limit of "
                                 f"{LIMITS['runs']:,} runs per command"))
    try:
        out = [int(x) if integer else float(x) for x in items(text, option)]
    except ValueError:
        raise InputError(Problem(_where(option), option, f"{form}, got {text!r}")) from None
    u = f" {unit}" if unit else ""
    for x in out:
        bad = not math.isfinite(x) or x > hi or (x <= lo if lo_open else x < lo)
        if bad:
            span = f"{'(' if lo_open else '['}{number(lo)}, {number(hi)}]{u}"
            got = f"{x:g}" if not integer or abs(x) < 10**30 else f"an integer of {len(str(abs(x)))} digits"
            raise InputError(Problem(_where(option), option, f"value {got}{u} is outside {span}{': ' + why if why else ''}"))
    return out


EFFICIENCY_RANGE = (0.1, 1.0)
"""A traction efficiency (wheel power / power drawn): real drive chains convert 0.8 .. 0.95; below a tenth
of the power drawn reaching the wheel no locomotive runs, and above 1 it would make energy."""


def efficiency(text: str, option: str = "--efficiency") -> float | tuple[tuple[float, float], ...]:
    """A traction efficiency: one number, or a curve of ``speed_kmh:eta`` pairs at rising speeds
    (``0:0.80,40:0.88,120:0.90``), each eta in ``EFFICIENCY_RANGE`` and each speed in 0 .. 600 km/h."""
    lo, hi = EFFICIENCY_RANGE
    form = f"expected a number in [{lo:g}, {hi:g}] or speed_kmh:eta pairs such as 0:0.80,40:0.88,120:0.90, got {text!r}"
    where = _where(option)
    text = text.strip()
    try:
        if ":" in text:
            pts = []
            for item in items(text, option):
                a, b = item.split(":")
                pts.append((float(a), float(b)))
        else:
            pts = [(0.0, float(text))]
    except ValueError:
        raise InputError(Problem(where, option, form)) from None
    if ":" in text:
        if len(pts) < 2 or len(pts) > 100:
            raise InputError(Problem(where, option, f"{form} (a curve has 2 .. 100 points)"))
        if not all(math.isfinite(v) and 0.0 <= v <= 600.0 for v, _ in pts):
            raise InputError(Problem(where, option, f"{form} (speeds in 0 .. 600 km/h)"))
        if any(b <= a for (a, _), (b, _) in zip(pts, pts[1:])):
            raise InputError(Problem(where, option, f"{form} (speeds must rise)"))
    for _, eta in pts:
        if not (math.isfinite(eta) and lo <= eta <= hi):
            raise InputError(Problem(where, option, f"{form} (each efficiency in [{lo:g}, {hi:g}]: real drive chains "
                                     "convert 0.8 .. 0.95 of the power drawn, and no locomotive runs on a tenth)"))
    return tuple(pts) if ":" in text else pts[0][1]


def values(text: str, option: str, lo: float, hi: float, unit: str = "", why: str = "",
           max_values: int | None = None) -> list[float]:
    """'start:stop:step' (inclusive) or 'a,b,c': finite values in [lo, hi], at most ``max_values``
    (default ``LIMITS['runs']``) of them, counted before any list is built."""
    max_values = LIMITS["runs"] if max_values is None else max_values
    form = "expected start:stop:step or a comma list of numbers"
    u = f" {unit}" if unit else ""
    if ":" in text:
        try:
            a, b, c = (float(x) for x in text.split(":"))
        except ValueError:
            raise InputError(Problem(_where(option), option, f"{form}, got {text!r}")) from None
        if not all(math.isfinite(x) for x in (a, b, c)):
            raise InputError(Problem(_where(option), option, f"start, stop and step must be finite numbers, got {text!r}"))
        if c <= 0 or b < a:
            raise InputError(Problem(_where(option), option, f"needs start <= stop and a step > 0, got {text!r}"))
        n = (b - a) / c
        if not n + 1 <= max_values:
            raise InputError(Problem(_where(option), option, f"{text!r} gives {n + 1:,.0f} values: more than the limit of "
                                     f"{max_values:,} runs per command (each is an optimisation); use a larger step"))
        out = [round(a + i * c, 10) for i in range(int(round(n)) + 1)]
    else:
        if not text.strip():
            raise InputError(Problem(_where(option), option, f"{form}, got {text!r}"))
        try:
            out = [float(x) for x in items(text, option)]
        except ValueError:
            raise InputError(Problem(_where(option), option, f"{form}, got {text!r}")) from None
        if len(out) > max_values:
            raise InputError(Problem(_where(option), option, f"{len(out):,} values: more than the limit of {max_values:,} "
                                     "runs per command"))
    for x in out:
        if not math.isfinite(x) or not lo <= x <= hi:
            raise InputError(Problem(_where(option), option, f"value {x:g}{u} is outside [{number(lo)}, {number(hi)}]{u}"
                                     f"{': ' + why if why else ''}"))
    return out


# ------------------------------------------------------------------------------------------ every option
# Every numeric option of every command, checked by ``check_command`` (called by the CLI's error guard before
# a command's body runs, so before any file is read or any work starts). A test walks every command's
# options and fails on a numeric one missing here. An entry: (kind, lo, hi, lo_open, hi_open, unit, why);
# "COMMAND --flag" overrides "--flag" for one command. The commands keep their own, finer checks
# (a step against the route's length, a tolerance against T0), which come after these.
_WEEK = LIMITS["time_s"][1]
OPTIONS: dict[str, tuple] = {
    "--step": ("float", *LIMITS["step_m"], False, False, "m", "the reporting grid spacing"),
    "--time": ("float", *LIMITS["time_s"], False, False, "s",
               "a planned running time (no stop-to-stop run is planned longer than a week)"),
    "--tolerance": ("float", 0.0, _WEEK, False, False, "s", "a punctuality window"),
    "--e-min": ("float", *LIMITS["e_min_kwh"], False, False, "kWh", "more than any run's traction energy"),
    "--seed": ("seed", *LIMITS["seed"], False, False, "", "see seed()"),
    "--rotating-mass": ("float", 0.0, 1.0, False, True, "", "a rotating-mass allowance gamma (real ones are 0.04 .. 0.1)"),
    "--runs": ("int", 1, LIMITS["runs"], False, False, "", "each run is an optimisation"),
    "drivers simulate --runs": ("int", 1, 100, False, False, "", "runs per driver at every mass and time"),
    "--drivers": ("int", 1, 1000, False, False, "", "simulated drivers"),
    "--workers": ("int", 1, 1024, False, False, "", "worker processes (more than the cores do not help: up to 1,024 "
                  "are taken and capped at the cores this process may use)"),
    "--mesh-tol": ("float", 1e-8, 0.1, False, False, "", "the relative discretisation error the mesh refinement "
                   "reaches (default 1e-5): below 1e-8 it chases the NLP's own round-off (IPOPT solves to 1e-6) and "
                   "runs on, above 0.1 is no accuracy at all"),
    "--max-phase-degree": ("int", 3, 40, False, False, "", "LGR points per mesh interval (default 10): 3 is the "
                           "fewest the refinement makes, and more than 40 only grow the NLP (an interval is split instead)"),
    # "own": bounded by the command's own check, which says more (ocp.min_time_run.check_options: 2 .. MAX_NODES,
    # even for two-stage, equal to --nodes for gpm, none for cvp)
    "--nodes": ("own", 2, 1000, False, False, "", "collocation nodes"),
    "--state-nodes": ("own", 2, 1000, False, False, "", "state collocation points"),
    "--regen": ("float", 0.0, 1.0, False, False, "", "the credited share of the electric brake's work"),
    "--comfort": ("float", 0.0, 5.0, True, False, "m/s^2", "an acceleration bound (a freight train manages 0.5)"),
    "--repeats": ("int", 1, 100, False, False, "", "solves per row (each row takes seconds)"),
    "--cap-kmh": ("float", 1.0, 400.0, False, False, "km/h", "a speed limit"),
    "--leg": ("int", 1, 100_000, False, False, "", "a stop-to-stop leg, 1 = first stop to second"),
    "--load-fraction": ("float", 0.0, 1.0, False, False, "", "the share of each wagon's load limit put on"),
    "--divisions": ("int", 1, 100, False, False, "", "equal divisions per section (the patent uses 8)"),
    "--max-order": ("int", 1, 6, False, False, "", "the highest polynomial order tried"),
    "--folds": ("int", 2, 100, False, False, "", "cross-validation folds"),
    "--holdout": ("float", 0.0, 0.9, False, True, "", "the share of the good runs held out of the fit"),
    "--load-class": ("float", 0.0, 100_000.0, True, False, "t", "the width of a load class"),
    "--level": ("float", 0.0, 40.0, False, False, "per mille", "the |equivalent gradient| at or below which a section is level"),
    "--mass": ("float", 0.0, 100_000.0, True, False, "t", "a train's mass (the heaviest ever run is 100,000 t)"),
    "--at-m": ("float", 0.0, 2_000_000.0, False, False, "m", "a position on a line (no line is longer than 2,000 km)"),
    "--speed-kmh": ("float", 0.0, 400.0, False, False, "km/h", "a train's speed"),
    "--elapsed-s": ("float", 0.0, _WEEK, False, False, "s", "the time since departure"),
    "--every": ("float", 1.0, 3600.0, False, False, "s", "the time between two re-plans"),
    "--recharge-left-s": ("float", 0.0, 3600.0, False, False, "s", "the time left of the air brake's recharge"),
}

MAX_OPTION_CHARS = 10_000
"""An option's value longer than this is refused before it is parsed: nothing the commands take comes near
(a 1,000-value list is 8,000 characters), and a message never echoes it whole."""


def check_option(flag: str, value, command: str = "") -> None:
    """``value`` of ``flag`` (of ``command``) inside its entry of ``OPTIONS``; else ``InputError``."""
    entry = OPTIONS.get(f"{command} {flag}") or OPTIONS.get(flag)
    if entry is None or value is None or isinstance(value, bool):
        return
    kind, lo, hi, lo_open, hi_open, unit, why = entry
    if kind == "seed":
        seed(value, flag)
        return
    if kind == "own":
        return
    u = f" {unit}" if unit else ""
    if kind == "int":
        if not isinstance(value, int):
            raise InputError(Problem(CMDLINE, flag, f"must be a whole number (got {value!r})"))
        bad = value < lo or value > hi or (lo_open and value == lo) or (hi_open and value == hi)
        if bad:
            got = f"{value:,}" if abs(value) < 10**30 else f"an integer of {len(str(abs(value)))} digits"
            span = f"{number(lo)} .. {number(hi)}" if not (lo_open or hi_open) else _span(lo, hi, lo_open, hi_open)
            raise InputError(Problem(CMDLINE, flag, f"must be {span}{u} (got {got}): {why}"))
        return
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(Problem(CMDLINE, flag, f"must be a finite number{', in ' + unit if unit else ''} (got {value}): {why}"))
    bad = value < lo or value > hi or (lo_open and value == lo) or (hi_open and value == hi)
    if bad:
        raise InputError(Problem(CMDLINE, flag, f"must be in {_span(lo, hi, lo_open, hi_open)}{u} (got {value:g}): {why}"))


def _span(lo, hi, lo_open: bool, hi_open: bool) -> str:
    return f"{'(' if lo_open else '['}{number(lo)}, {number(hi)}{')' if hi_open else ']'}"


def check_text(flag: str, value: str) -> None:
    """A text option: not empty (an empty value never means the default: leave the option out) and not
    longer than ``MAX_OPTION_CHARS``."""
    if not value.strip():
        raise InputError(Problem(CMDLINE, flag, f"is empty ({value!r}): give a value, or leave the option out for "
                                 "its default"))
    if len(value) > MAX_OPTION_CHARS:
        raise InputError(Problem(CMDLINE, flag, f"a value of {len(value):,} characters is longer than the limit of "
                                 f"{MAX_OPTION_CHARS:,} (starts {value[:40]!r})"))


def _masses(text: str, option: str) -> list[float]:
    from .model.consist import PLAUSIBLE

    return number_list(text, option, 0.0, PLAUSIBLE["train_mass_t"], "t", "a train's mass (the heaviest train ever "
                       "run weighed 99,734 t)", lo_open=True)


def seed_list(text: str, option: str = "--seeds") -> list[int]:
    """A comma list of seeds, each 0 .. 2**63 - 1."""
    if not text.strip():
        raise InputError(Problem(_where(option), option, "name at least one seed"))
    try:
        out = [int(x) for x in items(text, option)]
    except ValueError:
        raise InputError(Problem(_where(option), option, f"expected whole numbers, e.g. 1,2,3 (got {text!r})")) from None
    for x in out:
        seed(x, option)
    return out


def _given_empty(flag: str, given: list[str]) -> bool:
    """Whether the command line gives ``flag`` an empty value (``--out ''`` or ``--out=``)."""
    return any(a == f"{flag}=" or (a == flag and i + 1 < len(given) and given[i + 1] == "") for i, a in enumerate(given))


def check_command(fn, kwargs: dict, given: list[str] | None = None) -> None:
    """Every option value a command function ``fn`` was called with (``kwargs``), against ``OPTIONS`` and
    ``check_text``: numeric ones inside their bounds, text ones not empty or huge. ``given``: the command
    line as typed, where a path option given as ``''`` (which arrives as the folder ``.``) is told apart."""
    import inspect
    from pathlib import PurePath

    command = fn.__name__.rstrip("_").replace("_", "-")
    if fn.__module__.endswith("cli_learn") and command == "simulate":
        command = "drivers simulate"
    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return
    for name, value in kwargs.items():
        p = params.get(name)
        decls = getattr(p.default, "param_decls", None) if p is not None else None
        flags = [d for d in (decls or ()) if d.startswith("--")]
        if not flags:
            continue
        flag = flags[0].split("/")[0]
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            if isinstance(v, str):
                check_text(flag, v)
                parse = TEXT_NUMBERS.get(f"{command} {flag}") or TEXT_NUMBERS.get(flag)
                if parse is not None:
                    parse(v, flag)
            elif isinstance(v, PurePath):
                check_text(flag, "" if str(v) == "." and _given_empty(flag, given or []) else str(v))
            else:
                check_option(flag, v, command)
DURATION_FORMS = "seconds (1500, 1500s), minutes (25min), hours and minutes (1h05) or h:mm:ss (0:25:00)"
"""The forms of a running time written as a duration."""
TIME_FORMS = f"{DURATION_FORMS}, a factor of the fastest run (1.1x) or a supplement on it (+10%)"
"""The forms a planned running time takes on the command line (``--time``, each item of ``--times``)."""
CLOCK_FORMS = "a clock time hh:mm or hh:mm:ss (08:25, 08:25:30)"
"""The forms of a clock time (``--depart``, ``--arrive``)."""

_UNITS = {"h": 3600.0, "min": 60.0, "m": 60.0, "s": 1.0}
_DURATION = re.compile(r"(\d+(?:\.\d*)?|\.\d+)(h|min|m|s)?")
_HMS = re.compile(r"(\d+):([0-5]\d):([0-5]\d(?:\.\d*)?)")


def duration_s(text: str) -> float | None:
    """A duration as people write it, in seconds: ``1500``, ``1500s``, ``25min`` (or ``25m``), ``1h05``
    (1 h 5 min: a bare number after ``h`` is minutes, after ``min`` seconds), ``1h05m30s``, ``1.5h``,
    ``0:25:00`` (h:mm:ss); spaces are ignored. None when ``text`` is none of these forms."""
    t = str(text).strip().lower().replace(" ", "")
    m = _HMS.fullmatch(t)
    if m:
        return int(m.group(1)) * 3600.0 + int(m.group(2)) * 60.0 + float(m.group(3))
    if not t:
        return None
    total, pos, last, order = 0.0, 0, None, ("h", "min", "s")
    while pos < len(t):
        m = _DURATION.match(t, pos)
        if m is None:
            return None
        number, unit = float(m.group(1)), m.group(2)
        if unit is None:  # a bare number: seconds alone, or the next unit down after h (minutes) or min (seconds)
            if m.end() != len(t):
                return None
            unit = {None: "s", "h": "min", "min": "s"}.get(last)
            if unit is None:
                return None
        unit = "min" if unit == "m" else unit
        if last is not None and order.index(unit) <= order.index(last):
            return None  # each unit once, from hours down
        total += number * _UNITS[unit]
        last, pos = unit, m.end()
    return total


def time_request(text: str | float | None, option: str = "--time") -> tuple[str, float] | None:
    """A planned running time as typed: ``('s', seconds)`` for a duration (:func:`duration_s`: ``1500``,
    ``25min``, ``1h05``, ``0:25:00``), ``('x', factor of the fastest run)`` for ``1.1x``; ``+10%`` (a
    running-time supplement on the fastest run, as timetables state it) is the factor 1.1.
    None stays None (the route's schedule). Raises ``InputError`` naming ``option`` and the forms."""
    if text is None:
        return None
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return "s", planned_time(float(text), option)
    raw = str(text).strip()
    t = raw.lower().replace(" ", "")
    try:
        if t.endswith("x"):
            kind, value = "x", float(t[:-1])
        elif t.endswith("%"):
            if not t.startswith("+"):
                raise ValueError
            kind, value = "x", 1.0 + float(t[1:-1]) / 100.0
        else:
            seconds = duration_s(t)
            if seconds is None:  # a number of seconds out of bounds (-5, nan) is told its bound, as it was
                seconds = float(t[:-1] if t.endswith("s") else t)
            kind, value = "s", seconds
    except ValueError:
        hint = (" (a clock time belongs in --depart / --arrive; a running time as h:mm:ss is 0:25:00)"
                if re.fullmatch(r"\d+:\d+", t) else "")
        raise InputError(Problem(_where(option), option, f"expected {TIME_FORMS}, got {raw!r}{hint}")) from None
    if kind == "s":
        return "s", planned_time(value, option)
    if not math.isfinite(value) or value < 1.0 or value > 10.0:
        raise InputError(Problem(_where(option), option, f"{raw!r} is not a factor of the fastest run in 1 .. 10 (no train runs "
                                 "faster than its fastest run; +0% .. +900% is the same range as a supplement)"))
    return "x", value


POST_FORMS = ("km", "plus")
"""How a kilometre post is written (``--chainage``): ``12.345 km`` or ``12+345``."""


def post_form(text: str, option: str = "--chainage") -> str:
    """``km`` or ``plus`` (:data:`POST_FORMS`); else ``InputError`` naming ``option`` and both."""
    if text not in POST_FORMS:
        raise InputError(Problem(_where(option), option, f"expected km (kilometre posts as 12.345 km) or plus (as "
                                 f"12+345), got {text!r}"))
    return text


DAY_S = 86_400.0


def clock_s(text: str, option: str = "--depart") -> float:
    """A clock time ``hh:mm`` or ``hh:mm:ss`` (00:00 .. 23:59:59) in seconds since midnight; else
    ``InputError`` naming ``option`` and the forms."""
    raw = str(text).strip()
    m = re.fullmatch(r"(\d{1,2}):([0-5]\d)(?::([0-5]\d(?:\.\d*)?))?", raw)
    if m is None or int(m.group(1)) > 23:
        raise InputError(Problem(_where(option), option, f"expected {CLOCK_FORMS}, got {raw!r}"))
    return int(m.group(1)) * 3600.0 + int(m.group(2)) * 60.0 + float(m.group(3) or 0.0)


def clock_text(seconds: float, with_seconds: bool | None = None) -> str:
    """Seconds since midnight as a clock ``hh:mm`` (``hh:mm:ss`` where the seconds are not 0, or with
    ``with_seconds``); past midnight the clock starts again (a run overnight)."""
    s = int(round(seconds)) % int(DAY_S)
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    if with_seconds or (with_seconds is None and sec):
        return f"{h:02d}:{m:02d}:{sec:02d}"
    return f"{h:02d}:{m:02d}"


def clock_span_s(depart: str, arrive: str) -> float:
    """The running time from a departure clock to an arrival clock [s] (``--depart 08:00 --arrive 08:25`` is
    1500 s); an arrival before the departure is the next day's (a run over midnight). ``InputError`` naming
    the option at fault."""
    a, b = clock_s(depart, "--depart"), clock_s(arrive, "--arrive")
    span = (b - a) % DAY_S
    if span <= 0:
        raise InputError(Problem(CMDLINE, "--arrive", f"{arrive.strip()} is the departure's own clock time: give a later "
                                 "arrival (an earlier one is read as the next day's)"))
    return planned_time(span, "--arrive")


def clock_request(time: str | None, depart: str | None, arrive: str | None) -> str | None:
    """``--time`` as the command reads it, given ``--depart`` / ``--arrive``: the running time from the
    departure to the arrival in seconds (as text) when both are given, else ``time`` as given. ``--arrive``
    needs ``--depart`` and excludes ``--time`` (two running times)."""
    if arrive is None:
        return time
    if depart is None:
        raise InputError(Problem(CMDLINE, "--arrive", "needs --depart: the running time is the arrival less the departure "
                                 "(--depart 08:00 --arrive 08:25)"))
    if time is not None:
        raise InputError(Problem(CMDLINE, "--arrive", f"give --time or --arrive, not both (--time {time} and --depart "
                                 f"{depart} --arrive {arrive} are two running times)"))
    return f"{clock_span_s(depart, arrive):g}"


TIMES_FORMS = ("start:stop:step in seconds (1400:1600:100), or a comma list of planned running times, each "
               f"{TIME_FORMS}")
"""The forms of a list of planned running times on the command line (``--times``)."""


def times_request(text: str, option: str = "--times") -> list[tuple[str, float]]:
    """A list of planned running times as typed (``--times``): ``'1400:1600:100'`` (start:stop:step, seconds,
    inclusive) or a comma list whose items each take a :func:`time_request` form (``1400,1.1x,+20%``).
    Raises ``InputError`` naming ``option`` and the forms."""
    if ":" in text and "," not in text and not _HMS.fullmatch(text.strip()):
        return [("s", v) for v in values(text, option, *LIMITS["time_s"], "s", "a planned running time")]
    items = text.split(",")
    if not text.strip():
        raise InputError(Problem(_where(option), option, f"expected {TIMES_FORMS}, got {text!r}"))
    for i, x in enumerate(items):
        if not x.strip():
            raise InputError(Problem(_where(option), option, f"item {i + 1} of {text!r} is empty (a doubled or trailing "
                                     f"comma?): expected {TIMES_FORMS}"))
    if len(items) > LIMITS["runs"]:
        raise InputError(Problem(_where(option), option, f"{len(items):,} values: more than the limit of "
                                 f"{LIMITS['runs']:,} runs per command"))
    return [time_request(x, option) for x in items]


def time_of(request: tuple[str, float], fastest_s: float) -> float:
    """Seconds of a :func:`time_request`, given the fastest run [s]: a factor's time is rounded up to 0.1 s
    (so that 1x is never below the fastest run by a rounding)."""
    kind, value = request
    if kind == "s":
        return value
    if fastest_s is None or not math.isfinite(fastest_s):  # a line the train cannot run: no factor of its fastest run
        from .errors import InfeasibleError

        raise InfeasibleError(f"{value:g}x is a factor of the fastest run, but the train has no run to the stop on "
                              "this line (it stalls, or cannot hold a speed limit); give seconds, or a line and train "
                              "that can run")
    return math.ceil(value * fastest_s * 10 - 1e-9) / 10


_TIMES = (*LIMITS["time_s"], "s", "a planned running time")
TEXT_NUMBERS = {
    "--time": time_request,
    "--times": times_request,
    "--depart": clock_s,
    "--chainage": post_form,
    "--arrive": lambda text, flag: clock_s(text, flag),
    "drivers simulate --times": lambda text, flag: number_list(text, flag, *_TIMES),
    "--weights": weights,
    # sweep's --weights is the old name of --weight-grid: named as the grid, as the command reads it
    "sweep --weights": lambda text, flag: values(text, "--weight-grid", 0.0, 1.0,
                                                 why="a time weight (the energy weight is 1 - it)"),
    "--weight-grid": lambda text, flag: values(text, flag, 0.0, 1.0, why="a time weight (the energy weight is 1 - it)"),
    "--factors": lambda text, flag: values(text, flag, 1.0, 10.0, why="a factor of the fastest run"),
    "--seeds": seed_list,
    "--masses": _masses,
    "--efficiency": efficiency,
}
"""Text options that hold numbers (a time form, a list, a grid, a curve): each parsed by its function here,
every number inside its bound, before the command's body runs. "COMMAND --flag" overrides "--flag"; the
commands parse the same text with the same function."""
