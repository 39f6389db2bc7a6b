"""``locoplan drivers simulate``, ``locoplan learn`` and ``locoplan advise``: the pattern-curve patent on the command line.

Thin commands over :mod:`locoplan.learn`; :func:`register` adds them (and the ``drivers`` / ``advice``
strategies of ``compare``) to a typer app.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from . import learn as _pattern_curves  # noqa: F401  (its import registers compare's 'drivers' and 'advice')
from .cli_common import api  # imported when a command runs (cli_common.LazyModule)
from .cli_common import (CHAINAGE, CONSIST, JSON, MODEL, MODEL_NO_STRICT, ROUTE, STOCK, TIME, _check_outputs, departure_s, err,
                         fail_on, guarded, json_out, out, plain, step_progress, wrote)

if TYPE_CHECKING:
    from .api import ModelRequest

__all__ = ["register"]


@guarded
def simulate(route: Path = ROUTE,
             out_dir: Path = typer.Option(..., "--out", metavar="DIR", help="Folder for the logs: a new one (created with its parents) or an empty one; never written over."),
             drivers: int = typer.Option(40, "--drivers", help="Number of simulated drivers."),
             runs: int = typer.Option(5, "--runs", help="Runs per driver at every mass and time."),
             masses: str = typer.Option("5200", "--masses", help="Train masses [t], comma list: the consist's wagons resized."),
             times: Optional[str] = typer.Option(None, "--times", help="Planned running times [s], comma list (default: the route's schedule)."),
             seed: int = typer.Option(1, "--seed", help="Random seed: the same seed gives the same logs."),
             tolerance: Optional[float] = typer.Option(None, "--tolerance", help="Punctuality window +- [s] the drivers aim within (default: the route's)."),
             consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
             model: ModelRequest = MODEL_NO_STRICT):
    """Simulate human drivers on ROUTE and write their logs, every one marked synthetic."""
    from .errors import InputError, Problem
    from .io.load import load_consist, load_route
    from .learn.drivers import SimulationSpec
    from .reporting.learn_tables import groups_table
    from .reporting.logs import check_out_dir, simulate_drivers

    api.check_counts(drivers=drivers, runs=runs)
    check_out_dir(out_dir)
    opts = model.options()
    r = load_route(route)
    if times is None and r.schedule is None:
        raise InputError(Problem("<command line>", "--times", f"route '{r.name}' has no schedule: give the planned running times "
                                 "the drivers aim at as seconds, e.g. --times 1500 or --times 1500,1600 (a factor "
                                 "of the fastest run would differ with each of --masses)"))
    base, vehicles, files, _, _ = load_consist(consist, stock_dir)
    spec = SimulationSpec(route, r, base, vehicles, files, api.positive_numbers(masses, "--masses"),
                          api.positive_numbers(times, "--times") if times else (r.schedule.run_time_s,), drivers, runs, seed,
                          opts, tolerance)
    with step_progress("mass batches", len(spec.masses_t), not as_json) as step:  # one batch per mass
        summary = simulate_drivers(spec, out_dir, progress=step)
    wrote([summary.out_dir])
    for stale in summary.removed:
        err.print(f"note: removed {plain(str(stale))}, left by a drivers simulate stopped before it finished",
                  highlight=False, markup=False, soft_wrap=True)
    if as_json:
        json_out({"out": str(summary.out_dir), "runs": summary.n_runs, "synthetic": True, "seed": seed,
                       "groups": summary.groups, "drivers": summary.drivers})
    else:
        out.print(groups_table(f"{r.name}: {summary.n_runs} synthetic runs written to {summary.out_dir}", summary.groups))

@guarded
def learn(logs: list[Path] = typer.Argument(..., help="Log folders (manifest.yaml) or manifests."),
          out_file: Path = typer.Option(..., "--out", help="The learned patterns, .json."),
          plot: Optional[Path] = typer.Option(None, "--plot", help="Learned curves against the good drivers' data, .png, .svg or .pdf."),
          seed: int = typer.Option(1, "--seed", help="Random seed (folds, held-out runs): the same seed gives the same patterns."),
          divisions: int = typer.Option(8, "--divisions", help="p: equal divisions per section (speed points of the lower layer)."),
          max_order: int = typer.Option(4, "--max-order", help="Highest polynomial order tried (chosen by cross-validation)."),
          folds: int = typer.Option(5, "--folds", help="Cross-validation folds (of whole runs)."),
          holdout: float = typer.Option(0.2, "--holdout", help="Share of the good runs held out of the fit, for the fit report."),
          load_class: float = typer.Option(500.0, "--load-class", help="Width of a load class [t]: good drivers are picked among the runs of one route, planned time and load class."),
          level: float = typer.Option(2.0, "--level", help="|equivalent gradient| [per mille] at or below which a section is level."),
          stock_dir: Optional[Path] = STOCK, as_json: bool = JSON, model: ModelRequest = MODEL_NO_STRICT):
    """Learn pattern curves (time shares per section, speeds inside them) from the good drivers' logs.
    Method: the patent on locomotive operation sequences from double-layer pattern curves."""
    from .io.logs import load_logs
    from .reporting.learn_tables import fit_tables
    from .reporting.tables import fit, show
    from .reporting.writers import with_provenance, write_json
    from .learn.patterns import LearnSettings
    from .learn.patterns import learn as run_learn

    _check_outputs(out_file, plot, csv_ok=False)
    settings = LearnSettings(divisions=divisions, level_permille=level, max_order=max_order, folds=folds,
                             holdout_share=holdout, load_class_t=load_class, seed=seed)
    settings.check()
    opts = model.options()
    runs = load_logs(logs, stock_dir)
    learned = run_learn(runs, settings, opts)
    data = learned.patterns.to_dict()
    if plot:
        from .reporting.plot_learn import plot_fit

        plot_fit(plot, learned)
    write_json(out_file, with_provenance(data))
    if as_json:
        json_out({"out": str(out_file), **data["report"], "upper": {k: v for k, v in data["upper"].items() if k not in ("coef",)},
                       "lower": {k: v for k, v in data["lower"].items() if k not in ("coef",)}})
    else:
        for table in fit_tables(data["report"]):  # numbers whole, headers at their spaces, at any width
            show(out, fit(table, out.width, wrap=(0,)))
        out.print(f"patterns written to {out_file}", highlight=False, markup=False)

@guarded
def advise(route: Path = ROUTE,
           patterns: Path = typer.Option(..., "--patterns", help="Learned patterns.json (locoplan learn)."),
           time_s: Optional[str] = TIME,
           mass: Optional[float] = typer.Option(None, "--mass", help="Resize the consist's wagons to this mass [t] (default: the consist as it is)."),
           consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
           out_file: Optional[Path] = typer.Option(None, "--out", help="Profile as .csv, or summary + sections + profile as .json."),
           plot: Optional[Path] = typer.Option(None, "--plot", help="Advice over the limits with the learned pattern, .png, .svg or .pdf."),
           tolerance: Optional[float] = typer.Option(None, "--tolerance", help="Punctuality window +- [s] (default: the route's schedule tolerance)."),
           model: ModelRequest = MODEL, chainage: str = CHAINAGE):
    """A plan from learned pattern curves (time shares, speed curve, operation sequence), checked by the
    calculator. Method: the patent on locomotive operation sequences from double-layer pattern curves."""
    from .cli_common import _emit, _fail_if
    from .io.load import build_train, load_consist, load_route, load_train
    from .learn.advise import advise as run_advise
    from .learn.advise import check_model
    from .learn.drivers import check_train_mass, consist_for_mass
    from .io.patterns import read_patterns_file
    from .learn.patterns import Patterns
    from .runner import make_context, schedule_verdict, summarize, RunResult
    from .settings import RunSettings
    from .reporting.learn_tables import sections_table
    from .reporting.tables import fit, sequence_table, show, summary_table
    from .strategy.strategies import StrategyOutcome

    _check_outputs(out_file, plot)
    opts = model.options()
    if mass is not None:
        check_train_mass(mass, "--mass")
    pat = Patterns.from_dict(read_patterns_file(patterns), str(patterns))
    check_model(pat, opts, str(patterns))
    r = load_route(route)
    if mass is None:
        train = load_train(consist, stock_dir)
    else:
        base, vehicles, *_ = load_consist(consist, stock_dir)
        train = build_train(consist_for_mass(base, vehicles, mass), vehicles, "--mass")
    from .cli_common import _time

    ctx = make_context(r, train, RunSettings(opts, time_s=_time(time_s, (r, train), options=opts, quiet=as_json),
                                             tolerance_s=tolerance))
    a = run_advise(pat, r, train, ctx.t0_s, opts, calc=ctx.calc)
    outcome = StrategyOutcome(a.plan, solve_time_s=a.solve_time_s)
    summary = summarize(ctx, "advice", outcome, a.result, with_fitness=False)
    summary.update(speed_scale=round(a.scale, 4), patterns=str(patterns), sections=a.sections())
    _emit(summary, as_json, out_file, a.result.profile, r)
    if plot:
        from .reporting.plot_learn import plot_advice

        from .reporting.plot import run_title

        plot_advice(plot, a, run_title(r.name, train.name, f"advice from {patterns.name}", summary), chainage)
    if not as_json:
        show(out, summary_table(summary, out.width, r, chainage, departure_s())
             + fit(sections_table(summary["sections"]), out.width, drop=(7, 6, 5), wrap=(8,))
             + sequence_table(summary["sequence"], out.width, r, chainage))
    _fail_if([schedule_verdict(ctx, RunResult("advice", outcome, a.result, summary), strict=True)])


@guarded
def replay(logs: list[Path] = typer.Argument(..., help="Log folders (manifest.yaml), manifests, or logs with their sidecar <log>.yaml."),
           plot: Optional[Path] = typer.Option(None, "--plot", help="The run with the largest excess against E*'s run, and the excess by section, .png, .svg or .pdf."),
           out_file: Optional[Path] = typer.Option(None, "--out", help="Every run and section: .json (the --json document) or .csv (one row per run and section)."),
           level: float = typer.Option(2.0, "--level", help="|equivalent gradient| [per mille] at or below which a section is level."),
           stock_dir: Optional[Path] = STOCK, as_json: bool = JSON, model: ModelRequest = MODEL_NO_STRICT):
    """Each logged run against E*, the least traction energy at its own running time, and where it lost the
    difference, section by section (the sections of the pattern curves); the total over the logs is what driving
    at the optimum would have saved."""
    from .io.logs import load_logs
    from .reporting.learn_tables import replay_tables
    from .reporting.tables import show
    from .reporting.writers import rows_csv, with_provenance, write_json
    from .reporting.files import atomic_write_text

    _check_outputs(out_file, plot)
    opts = model.options()
    runs = load_logs(logs, stock_dir)
    with step_progress("runs", len(runs), not as_json) as step:
        result = api.replay(runs, opts, level, progress=lambda run: step(run.log_file.stem))
    doc = result.document
    if out_file is not None and out_file.suffix.lower() == ".csv":
        atomic_write_text(out_file, rows_csv(*replay_rows(doc)))
    elif out_file is not None:
        write_json(out_file, with_provenance(doc))
    if plot:
        from .reporting.plot_learn import plot_replay

        plot_replay(plot, result.replays, opts)
    if as_json:
        json_out(doc)
    else:
        show(out, replay_tables(doc, out.width))
    fail_on(result.verdict)


REPLAY_RUN_COLUMNS = ("log", "driver_id", "mass_t", "running_time_s", "traction_energy_kwh", "optimum_kwh", "excess_kwh",
                      "price_of_time_kwh_per_s")
REPLAY_SECTION_COLUMNS = ("index", "type", "from_m", "to_m", "run_kwh", "optimum_kwh", "run_s", "optimum_s", "energy_kwh",
                          "time_kwh", "speed_kwh", "excess_kwh")


def replay_rows(doc: dict) -> tuple[list[dict], list[str]]:
    """``replay --out FILE.csv``: one row per run and section, the run's fields then the section's (``section_``)."""
    columns = list(REPLAY_RUN_COLUMNS) + [f"section_{c}" for c in REPLAY_SECTION_COLUMNS]
    rows = []
    for r in doc["runs"]:
        head = {c: r[c] for c in REPLAY_RUN_COLUMNS}
        for s in r["sections"] or [{}]:
            rows.append({**head, **{f"section_{c}": s.get(c) for c in REPLAY_SECTION_COLUMNS}})
    return rows, columns


def register(app: typer.Typer) -> None:
    """Add ``drivers simulate``, ``learn``, ``advise`` and ``replay`` to ``app``, and the compare strategies."""
    drivers_app = typer.Typer(no_args_is_help=True, help="Synthetic drivers' logs (labelled synthetic), to learn pattern curves from.")
    drivers_app.command("simulate")(simulate)
    app.add_typer(drivers_app, name="drivers")
    app.command("learn")(learn)
    app.command("advise")(advise)
    app.command("replay")(replay)
