"""What every command module shares: the consoles, the error guard, option parsing and declarations,
and the output-path check. ``cli.py`` and the ``cli_*.py`` command modules import from here, so none of
them imports another (the app lives in ``cli.py``, which registers the others' commands).
"""

from __future__ import annotations

import functools
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape

from . import __version__, bounds
from .errors import InputError, LocoplanError, Problem
from .reporting.files import all_or_none, check_output, check_output_path
from .reporting.writers import to_json, write_output
from .optimize.registry import ALGORITHMS
from .sim.calculator import DEFAULT_STEP_M, ModelOptions

out = Console()
err = Console(stderr=True)

DEFAULT_CONSIST = "configs/consists/HXD1-C80x50.yaml"

FLAGS = {
    "time_s": "--time", "e_min_kwh": "--e-min", "tolerance_s": "--tolerance", "builder": "--builder",
    "strategy": "--strategy", "strategies": "--strategies", "weights": "--weights", "times_s": "--times",
    "runs": "--runs", "algorithm": "--algorithm", "algorithms": "--algorithms", "out": "--out", "plot": "--plot",
    "workers": "--workers", "scheduler": "--scheduler", "where": "--where", "format": "--format", "by": "--by",
    "step_m": "--step", "rotating_mass": "--rotating-mass", "boxplot": "--boxplot", "seed": "--seed",
    "seeds": "--seeds", "factors": "--factors",
}
"""Library argument names -> this command line's flags. The library names its arguments in errors
(``time_s``); the command line shows the flag the user typed (``--time``)."""


BAR_WIDTH = 20
"""Columns of a progress bar's bar: with a short label, the count and the ETA a line fits 80 columns."""


def progress_bar(*extra, transient: bool = True, bar_width: int = BAR_WIDTH):
    """A rich progress display on stderr that reads at 80 columns: short label, count, bar, ETA (then
    ``extra`` columns, e.g. the best fitness). Labels are a few words ("compare runs"); what they count
    is the command's help."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn("{task.description}"), MofNCompleteColumn(), BarColumn(bar_width=bar_width),
                    TextColumn("ETA"), TimeRemainingColumn(), *extra, console=err, transient=transient)


@contextmanager
def run_progress(label: str, total: int, enabled: bool):
    """A progress bar on stderr for a command's runs (``run_many``'s progress events), only when stderr
    is a terminal and never with --json (stdout stays clean either way): ``label`` is short and says what
    is counted ("compare runs"); E_min's energy-saving run, when one is needed, has its own line.
    Yields the callback for ``run_many(progress=...)`` (None when there is no bar)."""
    if not enabled or not err.is_terminal:
        yield None
        return
    with progress_bar() as bar:
        tasks = {"runs": bar.add_task(label, total=total)}

        def callback(ev) -> None:
            if ev.phase not in tasks:
                tasks[ev.phase] = bar.add_task("E_min run", total=ev.total)
            bar.update(tasks[ev.phase], completed=ev.done, total=ev.total)
        yield callback


@contextmanager
def step_progress(label: str, total: int, enabled: bool):
    """A progress bar on stderr over ``total`` steps (terminal only, never with --json). Yields
    ``step(text)``, called as each step starts: the bar counts the steps before it and shows ``text``
    (a few words) after the ETA."""
    if not enabled or not err.is_terminal:
        yield lambda text: None
        return
    from rich.progress import TextColumn

    with progress_bar(TextColumn("{task.fields[now]}"), bar_width=BAR_WIDTH // 2) as bar:  # room for the step's text
        task = bar.add_task(label, total=total, now="")
        started = [0]

        def step(text: str) -> None:
            bar.update(task, completed=started[0], now=text)
            started[0] += 1
        yield step


def as_flags(problem: Problem) -> Problem:
    """A library problem about an argument, restated with the command line's flag."""
    if problem.field in FLAGS and (problem.file in ("", "<command line>") or problem.field in ("out", "plot", "boxplot")):
        return Problem(problem.file or "<command line>", FLAGS[problem.field], problem.message, problem.line)
    if not problem.file:  # an argument's value: on the command line, an option's
        return Problem("<command line>", problem.field, problem.message, problem.line)
    return problem


VERDICTS = {0: "ok", 1: "failed", 2: "invalid input"}
"""Exit code -> the ``verdict`` of every --json object: 0 every result does its job; 1 a valid request
with no result that does (no feasible plan, or a timetabled plan outside its window); 2 invalid input."""

ENVELOPE = ("verdict", "exit_code", "errors", "locoplan_version", "inputs")
"""Keys every --json object on stdout has besides the result (a --out .json file holds the result alone)."""

_RUN: ContextVar[Optional[dict]] = ContextVar("locoplan_cli_run", default=None)
_OUTPUTS = ("out_file", "plot", "boxplot", "out_dir")


def _inputs(kwargs: dict) -> dict:
    """The files (and catalogue names) a command read, as given: ``{"route": "routes/x.yaml", ...}``."""
    found = {}
    for key, value in kwargs.items():
        if key in _OUTPUTS or value is None:
            continue
        if isinstance(value, Path) or key == "consist":
            found[key] = str(value)
        elif isinstance(value, (list, tuple)) and value and all(isinstance(v, Path) for v in value):
            found[key] = [str(v) for v in value]
    return found


def json_out(obj: dict) -> None:
    """The --json object of a command: printed on stdout when the command ends, with its ``verdict``,
    ``exit_code`` and ``errors`` (the reasons of exit 1 or 2), the ``locoplan_version`` and the ``inputs``
    (see :func:`guarded`). Outside a guarded command it is printed at once."""
    run = _RUN.get()
    if run is None:
        print(to_json(obj))
    else:
        run["json"] = obj


def _finish_json(run: dict, code: int) -> None:
    obj = run["json"]
    if obj is None:  # nothing was computed: the object says why
        obj = {"command": run["command"], "reason": "\n".join(run["errors"]) or None}
        if run.get("problems"):
            obj["problems"] = [{"file": p.file, "line": p.line, "field": p.field, "message": p.message}
                               for p in run["problems"]]
    print(to_json({**obj, "verdict": VERDICTS.get(code, "failed"), "exit_code": code, "errors": run["errors"],
                   "locoplan_version": __version__, "inputs": run["inputs"]}))


def _schedule_line(route: Path) -> str:
    """``routes/x.yaml:9: schedule.run_time_s`` of a route file (its line, when it can be read)."""
    from .io.load import read_yaml

    try:
        _, lines = read_yaml(route)
    except (LocoplanError, OSError):
        return f"{route}: schedule.run_time_s"
    line = lines.get(("schedule", "run_time_s")) or lines.get(("schedule",))
    return f"{route}:{line}: schedule.run_time_s" if line else f"{route}: schedule.run_time_s"


def locate_schedule(text: str) -> str:
    """A "planned running time ... is below the fastest possible run" about the route's own schedule
    (no --time was given) restated with the file and line the time came from."""
    run = _RUN.get()
    if not run or not run.get("schedule_from") or "is below the fastest possible run" not in text:
        return text
    import re

    return re.sub(r"planned running time (\S+ s)", lambda m: f"planned running time {m.group(1)} (the route's schedule, "
                  f"{_schedule_line(run['schedule_from'])})", text, count=1)


def group_reasons(messages: list[str]) -> list[str]:
    """``['four-stage: R', 'proposed: R']`` -> ``['four-stage, proposed: R']``: a reason shared by several
    strategies is said once, naming them all (order kept)."""
    groups: dict[str, list[str]] = {}
    for m in messages:
        name, sep, reason = m.partition(": ")
        if not sep or " " in name:
            name, reason = "", m
        groups.setdefault(reason, []).append(name)
    return [(", ".join(n for n in names if n) + ": " if any(names) else "") + reason for reason, names in groups.items()]


def guarded(fn):
    """Turn a user's mistake (LocoplanError) into a red message on stderr and its exit code; with --json
    (an ``as_json`` argument) stdout gets one JSON object whatever the outcome (:func:`json_out`)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        run = {"json": None, "errors": [], "command": fn.__name__.replace("_", "-"), "inputs": _inputs(kwargs),
               "schedule_from": kwargs.get("route") if "time_s" in kwargs and kwargs.get("time_s") is None
               and isinstance(kwargs.get("route"), Path) else None}
        token = _RUN.set(run)
        code = None
        try:
            try:
                # outputs appear all or none: kept on success and on a deliberate exit after them (_fail_if)
                try:
                    with all_or_none(keep=lambda exc: isinstance(exc, typer.Exit)):
                        bounds.check_command(fn, kwargs)  # every option's value, before any work
                        result = fn(*args, **kwargs)
                except typer.Exit:
                    _flush_stdout()
                    raise
                _flush_stdout()
                code = 0
                return result
            except OSError as exc:  # stdout on a full disk or /dev/full, a file that vanished while being read
                raise _os_problem(exc) from None
        except _StdoutClosed:
            raise typer.Exit(0) from None  # the reader of a pipe stopped (`| head`): not an error
        except typer.Exit as exc:
            code = exc.exit_code
            raise
        except LocoplanError as exc:
            problems = getattr(exc, "problems", None)
            # an infeasible request has no file
            texts = [str(as_flags(p)) for p in problems] if problems else [locate_schedule(str(exc))]
            for text in texts[:MAX_PROBLEMS]:
                err.print(f"[bold red]error:[/] {escape(plain(text))}", highlight=False, markup=True, soft_wrap=True)
            if len(texts) > MAX_PROBLEMS:
                err.print(f"[bold red]error:[/] ... and {len(texts) - MAX_PROBLEMS:,} more problems of the same input(s) "
                          f"(the first {MAX_PROBLEMS} are shown)", highlight=False, markup=True, soft_wrap=True)
            run["errors"] += texts
            if problems:
                run["problems"] = [as_flags(p) for p in problems]
            code = exc.exit_code
            raise typer.Exit(exc.exit_code) from None
        finally:
            _RUN.reset(token)
            if code is not None and kwargs.get("as_json"):
                _print_json(run, code)
    return wrapper


def _print_json(run: dict, code: int) -> None:
    """The --json object, as the command ends; stdout on a full disk or /dev/full is a message and exit 2, a
    closed pipe a quiet end, as for every other output."""
    try:
        _finish_json(run, code)
        _flush_stdout()
    except _StdoutClosed:
        raise typer.Exit(0) from None
    except OSError as exc:
        problem = _os_problem(exc)
        if isinstance(problem, _StdoutClosed):
            raise typer.Exit(0) from None
        err.print(f"[bold red]error:[/] {escape(plain(str(problem)))}", highlight=False, markup=True, soft_wrap=True)
        raise typer.Exit(2) from None


MAX_PROBLEMS = 50
"""At most this many problems are printed (a file of 30,000 unknown keys gets 50 lines and a count)."""
MAX_MESSAGE_CHARS = 2_000
"""A message longer than this (a 100 KB value quoted whole) is cut in its middle, saying how much."""


class _StdoutClosed(Exception):
    pass


def plain(text: str) -> str:
    """``text`` as one line of printable text: control characters (a newline in a file name that would start a
    forged ``error:`` line, ANSI escapes that would recolour the terminal) written as escapes, and a huge
    message cut in the middle."""
    out = "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)
    if len(out) > MAX_MESSAGE_CHARS:
        half = MAX_MESSAGE_CHARS // 2
        out = f"{out[:half]} ...[{len(out) - 2 * half:,} characters left out]... {out[-half:]}"
    return out


def _flush_stdout() -> None:
    import sys

    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
        raise _StdoutClosed() from None
    except OSError:
        _silence_stdout()
        raise


def _silence_stdout() -> None:
    """Point fd 1 at /dev/null, so that the interpreter's own flush at exit finds nothing to fail on."""
    import os

    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.close(null)
    except OSError:
        pass


def _os_problem(exc: OSError) -> LocoplanError:
    import errno
    import sys

    if isinstance(exc, BrokenPipeError):
        _silence_stdout()
        return _StdoutClosed()
    why = exc.strerror or str(exc)
    if exc.filename is None and exc.errno in (errno.ENOSPC, errno.EIO, errno.EFBIG, errno.EDQUOT, errno.EBADF, errno.EINVAL):
        _silence_stdout()
        where = "<stdout>"
        try:
            if sys.stdout.isatty():
                where = "<terminal>"
        except (OSError, ValueError):
            pass
        return InputError(Problem(where, "", f"cannot write the output: {why} (nothing else was written)"))
    return InputError(Problem(str(exc.filename or "<command line>"), "", f"cannot read or write: {why}"))
def usage_error_json(exc, args: list[str]) -> None:
    """The --json object of a command line click refused before the command ran (exit 2)."""
    option = next((p.opts[0] for p in [getattr(exc, "param", None)] if p is not None and getattr(p, "opts", None)), "")
    message = exc.format_message()
    command = next((a for a in args if not a.startswith("-")), "")
    print(to_json({"command": command, "reason": f"<command line>: {option + ': ' if option else ''}{message}",
                   "problems": [{"file": "<command line>", "line": None, "field": option, "message": message}],
                   "verdict": VERDICTS[2], "exit_code": 2, "errors": [message], "locoplan_version": __version__,
                   "inputs": {}}))


def _fail_if(messages: list) -> None:
    """After every output is written: name each result that failed its job, exit 1 if any did."""
    messages = group_reasons([locate_schedule(m) for m in messages if m])
    for m in messages:
        err.print(f"[bold red]error:[/] {escape(m)}", highlight=False, soft_wrap=True)
    run = _RUN.get()
    if run is not None:
        run["errors"] += messages
    if messages:
        raise typer.Exit(1)


def _options(step: float, point_mass: bool, rotating_mass: Optional[float], strict_limits: bool = False,
             air_brake: Optional[bool] = None) -> ModelOptions:
    bounds.step(step)
    if rotating_mass is not None and not 0 <= rotating_mass < 1:
        raise InputError(Problem("<command line>", "--rotating-mass", f"must be in [0, 1) (got {rotating_mass:g})"))
    air = (not point_mass) if air_brake is None else air_brake
    return ModelOptions(step_m=step, point_mass=point_mass, air_brake=air, rotating_mass=rotating_mass,
                        strict_limits=strict_limits)


def _weights(text: str) -> tuple[float, float]:
    return bounds.weights(text, "--weights")


def _range(text: str, field: str) -> list[float]:
    """'0.1:0.9:0.1' (start:stop:step, inclusive) or '1470,1500,1530': time weights or running times
    (``pareto --factors``: factors of the fastest run, 1 .. 10)."""
    if field == "--weight-grid":
        return bounds.values(text, field, 0.0, 1.0, why="a time weight (the energy weight is 1 - it)")
    if field == "--factors":
        return bounds.values(text, field, 1.0, 10.0, why="a factor of the fastest run")
    return bounds.values(text, field, *bounds.LIMITS["time_s"], "s", "a planned running time")


def _names(text: str, field: str) -> list[str]:
    names = [x.strip() for x in text.split(",") if x.strip()]
    if not names:
        raise InputError(Problem("", field, "name at least one"))
    return names


def _load(route: Path, consist: str, stock_dir: Optional[Path], step: float, point_mass: bool,
          rotating_mass: Optional[float], strict_limits: bool, air_brake: Optional[bool] = None):
    from .io.load import load_route_and_train

    opts = _options(step, point_mass, rotating_mass, strict_limits, air_brake)
    return (*load_route_and_train(route, consist, stock_dir), opts)


def _time(text: Optional[str], route, consist: str = DEFAULT_CONSIST, stock_dir: Optional[Path] = None,
          options: Optional[ModelOptions] = None, quiet: bool = False, option: str = "--time") -> Optional[float]:
    """``--time`` in seconds: seconds as given; a factor (``1.1x``) or a supplement (``+10%``) of the fastest
    run of this route and train (``route``: a loaded Route, or a file path loaded with ``consist``; then
    ``train`` is loaded too). None stays None (the route's schedule). A note on stderr says what a factor
    came to, unless ``quiet``."""
    req = bounds.time_request(text, option)
    if req is None or req[0] == "s":
        return None if req is None else req[1]
    from .sim.calculator import TractionCalculator

    if isinstance(route, (str, Path)):
        from .io.load import load_route_and_train

        route, train = load_route_and_train(route, consist, stock_dir)
    else:
        route, train = route
    fastest = TractionCalculator(route, train, options or ModelOptions()).fastest_time_s
    t = bounds.time_of(req, fastest)
    if not quiet:
        err.print(f"note: {option} {text}: T0 = {t:g} s ({req[1]:g} x the fastest run, {fastest:.1f} s)",
                  highlight=False, markup=False, soft_wrap=True)
    return t


def _emit(summary_or_results, as_json: bool, out_file: Optional[Path], profile=None, route=None) -> None:
    if out_file:
        write_output(out_file, summary_or_results, profile, route)
    if as_json:
        json_out(summary_or_results)


PLOT_SUFFIXES = (".png", ".svg", ".pdf")  # as reporting.plot.FIGURE_SUFFIXES


def check_outputs(**outputs: tuple[Optional[Path], tuple[str, ...]]) -> None:
    """Check every output path of a command before any work (name -> (path or None, suffixes)); no two may
    name the same file."""
    from .reporting.files import check_distinct

    for name, (path, suffixes) in outputs.items():
        check_output_path(path, name, suffixes)
    check_distinct({FLAGS.get(name, name): path for name, (path, _) in outputs.items()})


def _check_outputs(out_file: Optional[Path], plot: Optional[Path], csv_ok: bool = True) -> None:
    """Refuse bad output names (type, folder, writable) before any long computation."""
    from .reporting.plot import check_plot_path

    from .reporting.files import check_distinct

    check_output(out_file, "--out", (".csv", ".json") if csv_ok else (".json",))
    check_output(plot and check_plot_path(plot), "--plot")
    check_distinct({"--out": out_file, "--plot": plot})


# Options shared by the commands (typer has no option groups; these keep them identical)
ROUTE = typer.Argument(..., help="Route YAML file.")
CONSIST = typer.Option(DEFAULT_CONSIST, "--consist", help="Consist YAML file or catalogue name.")
STOCK = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first.")
JSON = typer.Option(False, "--json", help="Machine-readable result on stdout (nothing else there).")
STEP = typer.Option(DEFAULT_STEP_M, "--step", help="Reporting grid spacing [m] (optimisers search on 100 m).")
POINT_MASS = typer.Option(False, "--point-mass/--no-point-mass", help="The papers' train model (to reproduce their tables): a point mass at the head, braked by its locomotives alone. Default: the train's real length (gradient averaged over it, a limit held until the tail clears it) and the wagons' air brakes.")
AIR = typer.Option(None, "--air-brake/--no-air-brake", help="Brake with the wagons' air brakes as well as the electric brake (default: on, off with --point-mass).", show_default=False)
ROT = typer.Option(None, "--rotating-mass", help="Uniform rotating-mass allowance gamma, inertial mass M(1+gamma) (default: each vehicle's own factor, 1 if none).", show_default=False)
STRICT = typer.Option(False, "--strict-limits/--no-strict-limits", help="Coasting up to a limit makes a plan infeasible (default: held there by braking).")
TIME = typer.Option(None, "--time", help="Planned running time T0 [s]: seconds (1500), a factor of the fastest run (1.1x) or a supplement on it (+10%) (default: the route's schedule).")
WEIGHTS = typer.Option("0.5,0.5", "--weights", help="Fitness weights w_time,w_energy: fitness = w_time |T - T0| / T0 + w_energy |E - E_min| / E_min.")
EMIN = typer.Option(None, "--e-min", help="E_min, the energy the fitness measures against [kWh] (default: the energy-saving strategy's energy, computed only when needed; deterministic: the same for every --seed and --algorithm, since its search (--builder seed002) always starts from its own fixed seed, and the general builder's comes from the deterministic least-price drive).")
SEED = typer.Option(1, "--seed", help="Random seed: the same seed gives the same result.")
ALGO = typer.Option("issa", "--algorithm", help=f"Optimiser: {', '.join(ALGORITHMS)}.")
TOL = typer.Option(None, "--tolerance", help="Punctuality window +- [s] (default: the route's schedule tolerance).")
BUILDER = typer.Option(None, "--builder", help="Sequence builder: general (the default, in every train model; any line) or seed002 (the ISSA paper's own rules to the letter: with --point-mass it reproduces the paper's tables).", show_default=False)
WINDOW = typer.Option(True, "--window/--no-window", help="Keep plans inside T0 +- tolerance; --no-window ranks by the fitness alone.")
PARAMS = typer.Option(None, "--params", help="Optimiser parameter YAML (default: configs/optimizers/<algorithm>.yaml).")
GAP = typer.Option(True, "--gap/--no-gap", help="Report each plan's gap to the least energy E* at its own running time (a minimum-energy optimal control; a few seconds per plan).")
WORKERS = typer.Option(1, "--workers", help="Runs in parallel on this many processes (1: in this process).")

__all__ = ["out", "err", "guarded", "all_or_none", "check_outputs", "json_out"]
