"""``locoplan journey JOURNEY.yaml``: a whole journey of several stops planned at once.

A thin command over :mod:`locoplan.runs.journey` (tables and files in :mod:`locoplan.reporting.journey`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from .cli_common import api, bounds  # imported when a command runs (cli_common.LazyModule)
from .cli_common import (ALGO, CHAINAGE, CONSIST, JSON, MODEL, SEED, STOCK, _check_outputs, err, fail_on, guarded, json_out,
                         departure_s, out, set_departure)

if TYPE_CHECKING:
    from .api import ModelRequest

__all__ = ["register"]


@guarded
def journey(journey_file: Path = typer.Argument(..., metavar="JOURNEY", help="A journey file (locoplan/journey@1)."),
            time_s: Optional[str] = typer.Option(None, "--time", help="Total running time, dwells excluded: seconds (3000, 3000s), minutes (50min), hours and minutes (1h05), h:mm:ss (0:50:00), a factor of the fastest run (1.15x) or a supplement on it (+10%) (default: the journey's run_time_s, else its last station's time_s less the dwells)."),
            depart: Optional[str] = typer.Option(None, "--depart", show_default=False, help="Departure clock time from the first station hh:mm[:ss]: with --arrive, the total running time is the time between them less the dwells; the stations' clocks and the time-distance diagram read this clock."),
            arrive: Optional[str] = typer.Option(None, "--arrive", show_default=False, help="Arrival clock time at the last station hh:mm[:ss] (with --depart, instead of --time; dwells included)."),
            strategies: str = typer.Option("proposed", "--strategies", help="Comma list of strategies that plan each leg at its allocated time."),
            seed: int = SEED, algorithm: str = ALGO, consist: str = CONSIST, stock_dir: Optional[Path] = STOCK,
            as_json: bool = JSON,
            out_file: Optional[Path] = typer.Option(None, "--out", help="The whole run's profile (.csv, the first strategy's plans end to end) or the summary (.json)."),
            plot: Optional[Path] = typer.Option(None, "--plot", help="Speed and clock along the line with stations and windows, and the allocation as bars (.png, .svg or .pdf)."),
            plot_td: Optional[Path] = typer.Option(None, "--plot-td", help="Time-distance diagram of the run: the line (kilometre posts where the route has a chainage) against the clock, stations as lines, stops and dwells, windows (.png, .svg or .pdf)."),
            chainage: str = CHAINAGE,
            model: ModelRequest = MODEL):
    """A run of several stops, the time shared for the least energy.

    The running time goes to the legs so that a second more saves the same on every leg not held by a
    window (equal marginal energy); every leg is planned at its share; the journey's E*, and what the
    allocation saves against equal-percentage supplements and the timetable's own leg times."""
    from .io.load import load_journey, load_train
    from .reporting.files import all_or_none
    from .reporting.journey import (journey_allocations_table, journey_legs_table, journey_stations_table,
                                    journey_summary_table, plot_journey, plot_journey_td, stations_drops,
                                    write_journey_csv)
    from .reporting.posts import with_posts
    from .reporting.tables import fit, show
    from .reporting.writers import with_provenance, write_json
    from .runs.journey import dwell_before, legs_of, plan_journey
    from .settings import RunSettings
    from .strategy.registry import STRATEGIES
    from .errors import InputError, Problem
    from .cli_common import step_progress

    names = tuple(api.names(strategies, "--strategies"))
    for n in names:
        api.check_choice(n, STRATEGIES, "--strategies", "strategy")
    if out_file is not None and out_file.suffix.lower() not in (".csv", ".json"):
        raise InputError(Problem(str(out_file), "--out", "use .csv (the whole run's profile) or .json (the summary)"))
    _check_outputs(None, plot, plot_td=plot_td)
    j, route = load_journey(journey_file)
    train = load_train(consist, stock_dir)
    opts = model.options()
    req = bounds.time_request(time_s, "--time")
    set_departure(depart)
    total = None
    if arrive is not None:  # departure to arrival, dwells included: the running time is that less the dwells
        span = bounds.planned_time(float(bounds.clock_request(time_s, depart, arrive)), "--arrive")
        dwells = dwell_before(j, len(j.stations) - 1)
        total = bounds.planned_time(span - dwells, "--arrive") if span > dwells else None
        if total is None:
            raise InputError(Problem(bounds.CMDLINE, "--arrive", f"{depart} to {arrive} is {span:g} s, no more than the "
                                     f"dwells ({dwells:g} s): no time is left to run"))
        if not as_json:
            err.print(f"note: --depart {depart} --arrive {arrive}: {span:g} s, {total:g} s of running after "
                      f"{dwells:g} s of dwells", highlight=False, markup=False, soft_wrap=True)
    elif req is not None:
        if req[0] == "s":
            total = req[1]
        else:
            fastest = sum(leg.fastest_s for leg in legs_of(j, route, train, opts))
            total = bounds.time_of(req, fastest)
            if not as_json:
                err.print(f"note: --time {time_s}: {total:g} s of running ({req[1]:g} x the fastest run, {fastest:.1f} s)",
                          highlight=False, markup=False, soft_wrap=True)
    n_steps = 3 + len(j.stops) * len(names)
    with step_progress("journey", n_steps, not as_json) as step:
        result = plan_journey(j, route, train, RunSettings(opts, time_s=total, seed=seed, algorithm=algorithm),
                              strategies=names, source=str(journey_file), step=step)
    s = with_posts(result.summary, route)
    with all_or_none():
        if out_file is not None:
            if out_file.suffix.lower() == ".json":
                write_json(out_file, with_provenance(s))
            else:
                write_journey_csv(out_file, result, names[0], j, route)
        if plot is not None:
            plot_journey(plot, result, j, route, names[0], chainage)
        if plot_td is not None:
            plot_journey_td(plot_td, result, j, route, names, chainage, departure_s())
    if as_json:
        json_out(s)
    else:
        tables = [journey_summary_table(s), journey_legs_table(s), journey_allocations_table(s),
                  journey_stations_table(s, route, chainage, departure_s())]
        drops = {1: (2,), 3: stations_drops(route)}
        show(out, [block for k, t in enumerate(tables)
                   for block in fit(t, out.width, drop=drops.get(k, ()), wrap=(1,) if k == 0 else ())])
    fail_on(api.verdict(result.failures))


def register(app: typer.Typer) -> None:
    """Add ``journey`` to ``app``."""
    app.command("journey")(journey)
