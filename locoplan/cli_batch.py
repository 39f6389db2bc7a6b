"""``locoplan batch``, ``locoplan results`` and ``locoplan pareto``: many runs, their store, the front.

Thin commands over :mod:`locoplan.runs`; :func:`register` adds them to a typer app.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from .cli_common import api, bounds  # imported when a command runs (cli_common.LazyModule)
from .cli_common import (ALGO, BUILDER, CONSIST, JSON, MODEL, PLOT_SUFFIXES, STOCK, TOL, WINDOW, _names,
                         _range, _times, all_or_none, check_outputs, err, fail_on, guarded, json_out, out)

if TYPE_CHECKING:
    from .api import ModelRequest

__all__ = ["register"]


def _progress_printer(err, enabled: bool, label: str = "batch runs"):
    """A progress callback for run_many on stderr: a rich bar (counts, rate, ETA) on a terminal, a
    plain line at most every 10 s otherwise (a log file), nothing when disabled. Returns (callback, close)."""
    if not enabled:
        return None, lambda: None
    if err.is_terminal:
        from .cli_common import field_column, progress_bar

        bar = progress_bar(field_column("{task.fields[note]}"), transient=False)
        bar.start()
        tasks: dict = {}

        def cb(ev):
            name = "E_min runs" if ev.phase == "e_min" else label
            if ev.phase not in tasks:
                tasks[ev.phase] = bar.add_task(name, total=ev.total, note="")
            note = "" if ev.phase == "e_min" else f"{ev.reused} stored, {ev.failed} failed"
            bar.update(tasks[ev.phase], completed=ev.done, total=ev.total, note=note)
        return cb, bar.stop
    start, last = time.monotonic(), [0.0]

    def line(ev):
        now = time.monotonic()
        if ev.done != ev.total and now - last[0] < 10:
            return
        last[0] = now
        rate = ev.done / max(now - start, 1e-9)
        eta = (ev.total - ev.done) / rate if rate > 0 else float("nan")
        err.print(f"{ev.phase}: {ev.done}/{ev.total} done, {rate:.2f}/s, ETA {eta:.0f} s"
                  + (f", {ev.reused} from the store, {ev.failed} fail their job" if ev.phase == "runs" else ""),
                  highlight=False)
    return line, lambda: None


def _note_two_contents(err, rows: list[dict]) -> None:
    """Say each name that covered two contents among ``rows`` (``runs.results.two_contents``): the summary shows
    them apart, each as NAME @ HASH."""
    from rich.markup import escape

    from .runs.results import two_contents

    for (field, name), shas in two_contents(rows).items():
        apart = ", ".join(f"'{name} @ {h[:8]}'" for h in shas)
        text = (f"{field} {name!r} names {len(shas)} different contents among these runs (a file edited between "
                f"batches, or two files of one name): summarised apart as {apart}")
        err.print(f"[bold yellow]note:[/] {escape(text)}", highlight=False, markup=True, soft_wrap=True)


def _warn_damaged(err, store, then: str, limit: int = 10) -> None:
    """Name each damaged record of ``store`` (its key, what is wrong) and what was done about it; at most
    ``limit`` lines, then how many more."""
    from rich.markup import escape

    items = list(store.damaged.items()) + [(k, w) for k, w in getattr(store, "replaced", {}).items()]
    for key, why in items[:limit]:
        err.print(f"[bold yellow]warning:[/] {escape(f'{store.name}: run {key}: {why}; {then}')}", highlight=False,
                  markup=True, soft_wrap=True)
    if len(items) > limit:
        err.print(f"[bold yellow]warning:[/] {escape(f'{store.name}: {len(items) - limit:,} more damaged records, {then}')}",
                  highlight=False, markup=True, soft_wrap=True)


@guarded
def batch(study_file: Path = typer.Argument(..., metavar="STUDY.yaml", help="Study file: routes, consists, times, strategies, algorithms, seeds (docs/batch.md)."),
          store_path: Path = typer.Option(..., "--store", help="Result store (SQLite, created if missing); a rerun runs only what it lacks."),
          workers: Optional[int] = typer.Option(None, "--workers", help="Local worker processes (default: the core count; 1 = in this process).", show_default=False),
          scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Dask scheduler address tcp://HOST:PORT (instead of local processes; pip install 'locoplan[dask]')."),
          as_json: bool = JSON,
          quiet: bool = typer.Option(False, "--quiet", help="No progress on stderr (nor with --json)."),
          objective: Optional[str] = typer.Option(None, "--objective", metavar="traction|net", show_default=False,
                                                  help="What the energy terms count, for every run (default: the study file's objective, else traction): traction, or net of what the electric brake recovers.")):
    """Run a study file's product of runs on a process pool or a Dask cluster, into a resumable store."""
    from dataclasses import replace

    from .reporting.tables import show, store_summary_table
    from .runs import Store, make_executor, run_many
    from .runs.results import default_by, rows_of, summarize_rows
    from .runs.study import load_study

    if objective is not None:
        bounds.objective(objective)
    study = load_study(study_file)
    if objective is not None:
        study = replace(study, specs=[s.replace(objective=objective) for s in study.specs])
    with Store(store_path) as store:
        store.check_writer()
        executor = make_executor(workers, scheduler)
        cb, close = _progress_printer(err, not quiet and not as_json)  # stdout is the JSON; a terminal shows no bar
        t = time.perf_counter()
        try:
            result = run_many(study.specs, executor, store=store, progress=cb)
        finally:
            close()
            executor.close()
        wall = time.perf_counter() - t
        _warn_damaged(err, store, "its run was done again and written over it")
        n, ran = len(study.specs), len(result.ran)
        report = {"store": str(store_path), "runs": n, "distinct_runs": len(set(r.key for r in result.records)),
                  "from_store": result.reused, "ran": ran, "workers": executor.workers, "executor": executor.name,
                  "wall_time_s": round(wall, 2), "runs_per_s": round(ran / wall, 3) if ran else None,
                  "fail_their_job": len(result.failures), "ran_keys": result.ran}
        if as_json:
            json_out(report)
            return
        rows = rows_of(result.records)
        by = default_by(rows)
        show(out, store_summary_table(summarize_rows(rows, by), by, f"{study_file}: {n} runs", out.width))
        _note_two_contents(err, rows)
        out.print(f"{n} runs: {result.reused} from the store, {ran} run now on {executor.workers} "
                  f"{executor.name} worker{'s' if executor.workers != 1 else ''} in {wall:.1f} s"
                  + (f" ({ran / wall:.2f} runs/s)" if ran else "") + f"; {len(result.failures)} fail their job "
                  "(infeasible, or outside the window)", highlight=False)  # wrapped at spaces to the width (80 in a pipe)

@guarded
def results(store_path: Path = typer.Argument(..., metavar="STORE", help="Result store written by locoplan batch."),
            fmt: Optional[str] = typer.Option(None, "--format", help="Export one row per run: csv, parquet or json (stdout, or --out). Default: the summary table."),
            out_file: Optional[Path] = typer.Option(None, "--out", help="Write the export (or, without --format, the summary as .json/.csv) here."),
            where: Optional[list[str]] = typer.Option(None, "--where", help="Keep runs with FIELD OP VALUE (OP: = != < <= > >=, ~ contains), e.g. --where 'algorithm=issa' --where 'planned_time_s>2000'; repeat to AND."),
            by: Optional[str] = typer.Option(None, "--by", help="Fields the summary groups by (default: route,consist,planned_time_s,strategy,algorithm; with journey runs in the store, kind,journey first).", show_default=False),
            plot: Optional[Path] = typer.Option(None, "--plot", help="Energy against running time per strategy and optimiser, one panel per route and consist (.png, .svg or .pdf)."),
            boxplot: Optional[Path] = typer.Option(None, "--boxplot", help="Box plots per optimiser of the energy above each group's best run (.png, .svg or .pdf)."),
            as_json: bool = JSON):
    """Export, summarise and plot a result store (from the stored runs, no re-run)."""
    import sys

    from .reporting.plot_runs import plot_boxes, plot_energy_time
    from .reporting.tables import show, store_summary_table
    from .runs import Store
    from .runs.results import (DEFAULT_BY, FORMATS, JOURNEY_BY, PLOT_FIELDS, SUMMARY_FIELDS, ExportShape, check_format,
                               default_by, export, export_to_file, iter_rows, stream_rows, summarize_rows, write_export)

    api.check_choice(fmt, FORMATS, "format", "format")
    check_outputs(out=(out_file, (f".{fmt}",) if fmt is not None else (".json", ".csv")),
                  plot=(plot, PLOT_SUFFIXES), boxplot=(boxplot, PLOT_SUFFIXES))
    if fmt is not None:
        check_format(fmt, out_file)
    asked = _names(by, "--by") if by is not None else None
    group = asked or [*JOURNEY_BY, *DEFAULT_BY]  # the fields kept; without --by the groups follow the rows
    # streamed, a chunk of records at a time: a first pass keeps of each row only the fields the summary or the
    # plots read; an export (--format) is written in a second pass, a row at a time, over the same rows
    keep = (*group, *SUMMARY_FIELDS) if fmt is None else ()
    keep = tuple(dict.fromkeys([*keep, *(PLOT_FIELDS if plot or boxplot else ())]))
    shape = ExportShape(fmt, str(store_path)) if fmt is not None else None
    with Store(store_path, create=False) as store:
        rows, fields = stream_rows(store.iter_records(), where, keep, on_row=shape.add if shape else None)
        _warn_damaged(err, store, "left out (the other runs are used; the store file is damaged, so batch does not "
                      "write into it: run the batch into a new store to run them again)" if store.file_damaged else
                      "left out (the other runs are used; locoplan batch on the store runs it again)")
        group = asked or default_by(rows)
        if rows:
            api.check_fields(group, fields, "by")
        summary = summarize_rows(rows, group) if fmt is None else []
        if fmt is None:
            _note_two_contents(err, rows)

        def again():  # the second pass: the rows of the first (up to its last row id), a row at a time
            return iter_rows(store.iter_records(upto=store.last_rowid), where)

        with all_or_none():
            if fmt is not None and out_file is not None:
                export_to_file(again(), shape, out_file)
            elif out_file is not None:
                export(summary, out_file, out_file.suffix.lower().lstrip("."))
            if plot:
                plot_energy_time(rows, plot)
            if boxplot:
                plot_boxes(rows, boxplot)
        if fmt is not None and out_file is None:
            write_export(again(), shape, sys.stdout)
    if fmt is None:
        if as_json:
            json_out({"store": str(store_path), "runs": len(rows), "summary": summary})
        else:
            show(out, store_summary_table(summary, group, f"{store_path}: {len(rows)} runs", out.width))
    if store.damaged:  # the result is of the runs that could be read: said, and exit 1 (never a silent success)
        n = len(store.damaged)
        where = (f"{n:,} damaged part{'s' if n > 1 else ''} of the file" if store.file_damaged else
                 f"{n:,} damaged record{'s' if n > 1 else ''}")
        fail_on(api.Verdict([f"{store_path}: the store is damaged ({where}, named above): this "
                             "result leaves out the runs there"
                             + ("; run the batch into a new store to run them again" if store.file_damaged else
                                "; locoplan batch on the store runs them again")]))

@guarded
def pareto(route: Path = typer.Argument(..., metavar="ROUTE|JOURNEY", help="Route YAML file, or a journey file (the front over its total running time, dwells excluded)."),
           factors: Optional[str] = typer.Option(None, "--factors", help="Planned times as factors of the fastest run, start:stop:step or list (default 1.05:1.6:0.05)."),
           times: Optional[str] = typer.Option(None, "--times", help="Planned times instead of --factors: start:stop:step in seconds, or a comma list of seconds, factors (1.1x) and supplements (+10%), e.g. 1300,1400,1500."),
           strategies: str = typer.Option("four-stage,proposed", "--strategies", help="Timetabled strategies planned at each time."),
           seeds: str = typer.Option("1", "--seeds", help="Seeds of the proposed strategy at each time, comma list."),
           algorithm: str = ALGO, consist: str = CONSIST, stock_dir: Optional[Path] = STOCK, as_json: bool = JSON,
           out_file: Optional[Path] = typer.Option(None, "--out", help="The front as .json."),
           plot: Optional[Path] = typer.Option(None, "--plot", help="Energy against running time: every plan, the front, E* when known (.png, .svg or .pdf)."),
           model: ModelRequest = MODEL, tolerance: Optional[float] = TOL,
           window: bool = WINDOW, builder: Optional[str] = BUILDER,
           optimum: bool = typer.Option(True, "--optimum/--no-optimum", help="E*, the least energy, at each planned time (a few seconds per time)."),
           workers: Optional[int] = typer.Option(None, "--workers", help="Local worker processes (default: the core count).", show_default=False)):
    """The energy-time front: the best on-time plan at a grid of running times, and the least energy E*.

    On a journey the running time is its total (dwells excluded), every plan a journey run (each leg planned
    at its share) and E* the journey's (the least-energy allocation of the time)."""
    from .io.load import file_schema
    from .model.journey import JOURNEY_SCHEMA
    from .reporting.plot_runs import plot_pareto
    from .reporting.tables import pareto_table, show
    from .reporting.writers import with_provenance, write_json
    from .runs import make_executor
    from .runs.pareto import pareto as run_pareto
    from .runs.spec import RunSpec

    api.one_of(factors, times, "--factors", "give --factors or --times, not both")
    check_outputs(out=(out_file, (".json",)), plot=(plot, PLOT_SUFFIXES))
    f = _range(factors, "--factors") if factors else None
    asked = bounds.times_request(times, "--times") if times else None
    seed_list = api.seed_list(seeds, "--seeds")
    opts = model.options()
    journey = route if file_schema(route) == JOURNEY_SCHEMA else None
    ts = _times(asked, route, consist, stock_dir, opts, quiet=as_json, journey=journey)
    from .settings import RunSettings

    settings = RunSettings(opts, algorithm=algorithm, tolerance_s=tolerance, window=window, builder=builder)
    base = RunSpec(None if journey else str(route), str(consist), settings=settings,
                   stock_dir=None if stock_dir is None else str(stock_dir),
                   journey=None if journey is None else str(journey))
    executor = make_executor(workers)
    cb, close = _progress_printer(err, not as_json and err.is_terminal, "pareto runs")
    try:
        front = run_pareto(base, factors=f, times_s=ts, strategies=_names(strategies, "--strategies"),
                           seeds=seed_list, executor=executor, progress=cb, optimum=optimum)
    finally:
        close()
        executor.close()
    with all_or_none():
        if out_file:
            write_json(out_file, with_provenance(front))
        if plot:
            plot_pareto(front, plot)
    if as_json:
        json_out(front)
    else:
        show(out, pareto_table(front, out.width))
        out.print(f"front: {front['front_kind']}", highlight=False)  # wrapped at spaces to the width (80 in a pipe)


def register(app: typer.Typer) -> None:
    """Add ``batch``, ``results`` and ``pareto`` to ``app``."""
    app.command("batch")(batch)
    app.command("results")(results)
    app.command("pareto")(pareto)
