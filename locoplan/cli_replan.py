"""``locoplan replan`` (on board: the rest of the run from the train's state, once or as a stream of JSON lines) and
``locoplan drive`` (closed loop: a disturbed run re-planned, against the open-loop plan and E* in hindsight)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from .cli_common import api  # imported when a command runs (cli_common.LazyModule)
from .cli_common import (CONSIST, JSON, MODEL, ROUTE, STOCK, TIME, TOL, _check_outputs, _load, _time, err, fail_on,
                         guarded, json_out, out)
from .errors import InputError, LocoplanError, Problem

if TYPE_CHECKING:
    from .api import ModelRequest

__all__ = ["register"]


def _setup(route: Path, consist: str, stock_dir: Optional[Path], model: ModelRequest, time_s: Optional[str],
           tolerance: Optional[float], quiet: bool):
    from .runner import planned_time

    r, train, opts = _load(route, consist, stock_dir, model)
    t0 = planned_time(r, _time(time_s, (r, train), options=opts, quiet=quiet))
    tol = api.punctuality_tolerance(r, t0, tolerance)
    return r, train, opts, t0, tol


def _is_journey(path: Path) -> bool:
    """Whether a file given as the route is a journey (``schema: locoplan/journey@1``)."""
    from .io.load import read_yaml
    from .model.journey import JOURNEY_SCHEMA

    try:
        data, _ = read_yaml(path)
    except LocoplanError:
        return False  # (the route's loader says what is wrong)
    return isinstance(data, dict) and data.get("schema") == JOURNEY_SCHEMA


def _journey_setup(path: Path, consist: str, stock_dir: Optional[Path], model: ModelRequest, time_s: Optional[str],
                   tolerance: Optional[float]):
    from . import bounds
    from .io.load import load_journey, load_train
    from .runs.journey import journey_fastest_s
    from .runs.replan_journey import JourneyReplanner

    j, line = load_journey(path)
    train = load_train(consist, stock_dir)
    opts = model.options()
    req = bounds.time_request(time_s, "--time")
    total = None
    if req is not None:
        total = req[1] if req[0] == "s" else bounds.time_of(req, journey_fastest_s(j, line, train, opts))
    return JourneyReplanner(j, line, train, opts, time_s=total, tolerance_s=tolerance, source=str(path)), j, train


@guarded
def replan(route: Path = ROUTE,
           at_m: Optional[float] = typer.Option(None, "--at-m", help="The train's head position [m] from the start of the line (required without --stream)."),
           speed_kmh: Optional[float] = typer.Option(None, "--speed-kmh", help="The train's speed [km/h] (required without --stream)."),
           elapsed_s: Optional[float] = typer.Option(None, "--elapsed-s", help="The time since departure [s] (required without --stream)."),
           condition: Optional[str] = typer.Option(None, "--condition", help="The condition in progress (T, K, C or B); default: none known. A change from it costs what the plan charges for a switch."),
           air: Optional[str] = typer.Option(None, "--air", help="The air brake's state where the model has its cycle: charged (released and charged; the default), applied (its least hold over) or recharging (with --recharge-left-s)."),
           recharge_left_s: Optional[float] = typer.Option(None, "--recharge-left-s", help="The time [s] left before the air brake's recharge is over (no application before); required with --air recharging, else none."),
           stream: bool = typer.Option(False, "--stream/--no-stream", help="Read one JSON state per line on stdin (keys s_m, v_kmh, t_s; optionally condition, planned_arrival_s, restriction with from_m, to_m, kmh) and write one JSON advice per line, each at once; a bad line gets an error line and the stream goes on."),
           time_s: Optional[str] = TIME, tolerance: Optional[float] = TOL, consist: str = CONSIST,
           stock_dir: Optional[Path] = STOCK, as_json: bool = JSON, model: ModelRequest = MODEL):
    """The least-energy rest of the run from the train's actual state, arriving at the planned time: the condition
    now, where the next switch is and the speed there, the arrival, the remaining energy. Where the time cannot be
    kept, the fastest remaining run and how late (exit 1). A look-up in the priced DP's cost-to-go, computed once
    at a ladder of prices of time (docs/replan.md)."""
    from .optimize.replan import TrainState
    from .reporting.replan import replan_lines, replan_summary

    if stream:
        if as_json:
            raise InputError(Problem(api.CMDLINE, "--json", "--stream writes one JSON object per line already: leave "
                                                            "out --json"))
        given = [f for f, v in (("--at-m", at_m), ("--speed-kmh", speed_kmh), ("--elapsed-s", elapsed_s),
                                ("--condition", condition), ("--air", air),
                                ("--recharge-left-s", recharge_left_s)) if v is not None]
        if given:
            raise InputError(Problem(api.CMDLINE, given[0], "the states come on stdin with --stream"))
    else:
        missing = [f for f, v in (("--at-m", at_m), ("--speed-kmh", speed_kmh), ("--elapsed-s", elapsed_s)) if v is None]
        if missing:
            raise InputError(Problem(api.CMDLINE, missing[0], "the train's state needs --at-m, --speed-kmh and "
                                                              "--elapsed-s (or --stream)"))
        if condition is not None and condition not in ("T", "K", "C", "B"):
            raise InputError(Problem(api.CMDLINE, "--condition", f"one of T, K, C, B (got {condition!r})"))
        if air is not None and air not in ("charged", "applied", "recharging"):
            raise InputError(Problem(api.CMDLINE, "--air", f"one of charged, applied, recharging (got {air!r})"))
        if (air == "recharging") != (recharge_left_s is not None):
            raise InputError(Problem(api.CMDLINE, "--recharge-left-s" if air == "recharging" or air is None
                                     else "--air", "--air recharging and --recharge-left-s go together (the time "
                                                   "left of the recharge [s])"))
    if _is_journey(route):
        jr, j, train = _journey_setup(route, consist, stock_dir, model, time_s, tolerance)
        if stream:
            _stream(None, j.name, train.name, jr)
            return
        st = TrainState(float(at_m), float(speed_kmh), float(elapsed_s), condition, air, recharge_left_s)
        res, k, rp, from_m, origin = jr.replan(st)
        d = {**jr.summary(st, res, k, rp, from_m, origin, j.name, train.name), "setup_time_s": round(jr.setup_s, 3)}
    else:
        r, train, opts, t0, tol = _setup(route, consist, stock_dir, model, time_s, tolerance, as_json or stream)
        rp = api.replanner(r, train, opts, t0, tol)
        if stream:
            _stream(rp, r.name, train.name)
            return
        res = rp.replan(TrainState(float(at_m), float(speed_kmh), float(elapsed_s), condition, air, recharge_left_s))
        d = {**replan_summary(res, r.name, train.name, tol, rp.cycle_relaxed), "setup_time_s": round(rp.setup_s, 3)}
    if as_json:
        json_out(d)
    else:
        for line in replan_lines(d):
            out.print(line, highlight=False, markup=False)
    fail_on(api.replan_verdict(d))


def _stream(rp, route_name: str, train_name: str, jr=None) -> None:
    """One advice per state line, flushed at once (module docstring of ``optimize.replan``; docs/replan.md)."""
    from .io.load import validate_model
    from .model.disturbance import StreamState
    from .model.route import with_restriction
    from .optimize.replan import Replanner, TrainState
    from .reporting.replan import replan_summary

    bad = 0
    planned = rp.planned_s if rp is not None else None
    for lineno, raw in enumerate(sys.stdin, start=1):
        if not raw.strip():
            continue
        try:
            try:
                data = json.loads(raw)
            except ValueError as exc:
                raise InputError(Problem(f"<stdin>:{lineno}", "", f"not a JSON object ({exc.msg})")) from None
            if not isinstance(data, dict):
                raise InputError(Problem(f"<stdin>:{lineno}", "", "not a JSON object"))
            st = validate_model(StreamState, data, f"<stdin>:{lineno}", {})
            if st.planned_arrival_s is not None:
                if jr is not None:  # (the arrival at the stop of the leg the state is in)
                    jr.override[jr.leg_at(st.s_m)] = float(st.planned_arrival_s)
                else:
                    planned = float(st.planned_arrival_s)
            state = TrainState(st.s_m, st.v_kmh, st.t_s, st.condition, st.air, st.recharge_left_s)
            if jr is not None:
                if st.restriction is not None:
                    raise InputError(Problem(f"<stdin>:{lineno}", "restriction", "a restriction in a journey's "
                                             "stream is not supported: re-plan the leg as a route (locoplan import "
                                             "... --leg N)"))
                res, k, lrp, from_m, origin = jr.replan(state)
                d = jr.summary(state, res, k, lrp, from_m, origin, route_name, train_name)
            else:
                if st.restriction is not None:
                    x = st.restriction
                    rp = Replanner(with_restriction(rp.route, x.from_m, x.to_m, x.kmh), rp.train, rp.options,
                                   planned_s=rp.planned_s, tolerance_s=rp.tolerance_s, prices=rp.prices)
                res = rp.replan(state, planned)
                d = replan_summary(res, route_name, train_name, rp.tolerance_s, rp.cycle_relaxed)
            code = api.replan_verdict(d).exit_code
            line = {"line": lineno, **{k: v for k, v in d.items() if k not in ("route", "consist")},
                    "exit_code": code}
        except LocoplanError as exc:
            problems = getattr(exc, "problems", None)
            texts = [str(p) for p in problems] if problems else [str(exc)]
            code = exc.exit_code
            bad += code == api.EXIT_INVALID
            line = {"line": lineno, "exit_code": code, "verdict": api.VERDICTS.get(code, "failed"), "errors": texts}
        sys.stdout.write(json.dumps(line, allow_nan=False) + "\n")
        sys.stdout.flush()
    if bad:
        err.print(f"error: {bad} line(s) of the stream were not valid states (each answered by an error line)",
                  highlight=False, markup=False, soft_wrap=True)
        raise typer.Exit(api.EXIT_INVALID)


@guarded
def drive(route: Path = ROUTE,
          disturb: Path = typer.Option(..., "--disturb", help="A disturbance file (schema locoplan/disturbance@1): mass_factor, resistance_factor, holds, restrictions, reaction_s, min_hold_s."),
          every: float = typer.Option(30.0, "--every", help="Re-plan every this many seconds [s] (and at once after a hold and when a restriction is announced)."),
          time_s: Optional[str] = TIME, tolerance: Optional[float] = TOL, consist: str = CONSIST,
          stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
          plot: Optional[Path] = typer.Option(None, "--plot", help="The three speed profiles, .png, .svg or .pdf."),
          model: ModelRequest = MODEL):
    """Closed loop: a run of a train that differs from the model (heavier, more resistance, held at a signal,
    restricted on the way, a driver who reacts late), re-planned every --every seconds, beside the departure plan
    followed by position (open loop) and E* in hindsight (the least energy for the real train and its real delays).
    Exit 1 when the closed-loop run arrives outside the window."""
    from .io.load import load_disturbance
    from .reporting.replan import drive_lines, plot_drive
    from .runs.drive import check_disturbance, drive as run_drive

    _check_outputs(None, plot)
    d = load_disturbance(disturb)
    r, train, opts, t0, tol = _setup(route, consist, stock_dir, model, time_s, tolerance, as_json)
    check_disturbance(r, d, str(disturb))
    with err.status("driving: open loop, closed loop, E* in hindsight"):
        res = run_drive(r, train, opts, d, planned_s=t0, tolerance_s=tol, every_s=every)
    s = {"route": r.name, "consist": train.name, "disturbance": d.name or str(disturb), **res.summary()}
    if plot:
        import numpy as np

        from .sim.calculator import limit_kmh_at
        from .runs.drive import real_route

        line = real_route(r, d)
        xs = np.linspace(0.0, line.length_m, 2001)
        plot_drive(plot, [("open loop", res.open_loop.s_m, res.open_loop.v_kmh),
                          ("closed loop", res.closed_loop.s_m, res.closed_loop.v_kmh),
                          ("E* in hindsight", res.hindsight_s_m, res.hindsight_v_kmh)],
                   (xs, np.minimum(limit_kmh_at(line, xs), train.max_speed_kmh)), f"{r.name}: {s['disturbance']}")
    if as_json:
        json_out(s)
    else:
        for text in drive_lines(s):
            out.print(text, highlight=False, markup=False)
    fail_on(api.drive_verdict(s))


def register(app: typer.Typer) -> None:
    """Add ``replan`` and ``drive`` to ``app``."""
    app.command("replan")(replan)
    app.command("drive")(drive)
