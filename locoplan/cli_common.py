"""What every command module shares: the consoles, the error guard, option parsing and declarations,
and the output-path check. ``cli.py`` and the ``cli_*.py`` command modules import from here, so none of
them imports another (the app lives in ``cli.py``, which registers the others' commands).
"""

from __future__ import annotations

import functools
import importlib
import inspect
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.console import Console
from rich.markup import escape

from . import __version__
from .catalogue import DEFAULT_CONSIST_FILE
from .errors import EXIT_INTERRUPTED, VERDICTS, InputError, LocoplanError, Problem
from .optimize.names import ALGORITHM_NAMES
from .reporting.files import all_or_none, check_output, check_output_path
from .sim.defaults import DEFAULT_STEP_M

if TYPE_CHECKING:
    from .api import ModelRequest
    from .sim.calculator import ModelOptions


class LazyModule:
    """A module imported when one of its names is first used: the command modules' ``api`` and ``bounds``
    (``from .cli_common import api``), so that importing the command line, and ``locoplan --help``, load
    none of the planner (numpy, pydantic, the calculator); a command loads what it runs."""

    def __init__(self, name: str):
        self._name = name

    def __getattr__(self, attr: str):
        return getattr(importlib.import_module(self._name), attr)

    def __repr__(self) -> str:
        return f"<module {self._name!r}, imported on first use>"


api = LazyModule("locoplan.api")
bounds = LazyModule("locoplan.bounds")

MIN_COLUMNS = 40
"""The least width tables and messages are laid out for: ``COLUMNS=0`` or ``1`` (or a terminal that narrow) would
print nothing, or a character a line."""


class _Console(Console):
    """rich's console at :data:`MIN_COLUMNS` at least, and without emoji codes: a route named ``:x:`` stays ``:x:``
    (user text is escaped for markup where it is printed)."""

    def __init__(self, **kwargs):
        super().__init__(emoji=False, **kwargs)

    @property
    def size(self):
        from rich.console import ConsoleDimensions

        size = Console.size.fget(self)
        return ConsoleDimensions(max(size.width, MIN_COLUMNS), size.height)

    @size.setter
    def size(self, new_size) -> None:
        Console.size.fset(self, new_size)


out = _Console()
err = _Console(stderr=True)

DEFAULT_CONSIST = DEFAULT_CONSIST_FILE

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
    is the command's help. The label, count, bar and ETA keep their width whatever the terminal; an
    ``extra`` column that does not fit is cut with "…" (it never squeezes the count or the ETA)."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
    from rich.table import Column

    def fixed() -> Column:
        return Column(no_wrap=True)

    return Progress(TextColumn("{task.description}", table_column=fixed()), MofNCompleteColumn(table_column=fixed()),
                    BarColumn(bar_width=bar_width, table_column=fixed()), TextColumn("ETA", table_column=fixed()),
                    TimeRemainingColumn(table_column=fixed()), *extra, console=err, transient=transient)


def field_column(template: str):
    """A progress column of a command's own field (``template`` as TextColumn's, e.g.
    ``"best {task.fields[best]}"``) on one line, cut with "…" where the terminal has no room for it."""
    from rich.progress import ProgressColumn
    from rich.text import Text

    class FieldColumn(ProgressColumn):
        def render(self, task) -> Text:
            return Text(template.format(task=task), no_wrap=True, overflow="ellipsis")

    return FieldColumn()


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
    with progress_bar(field_column("{task.fields[now]}"), bar_width=BAR_WIDTH // 2) as bar:  # room for the step's text
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


ENVELOPE = ("verdict", "exit_code", "errors")
"""Keys every --json object on stdout has besides what a --out .json file holds (the result and its
:data:`~locoplan.reporting.writers.PROVENANCE`: version, inputs, input files with their hashes)."""

_RUN: ContextVar[Optional[dict]] = ContextVar("locoplan_cli_run", default=None)
_OUTPUTS = ("out_file", "plot", "plot_td", "boxplot", "out_dir")


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
        from .reporting.writers import to_json

        print(to_json(obj))
    else:
        run["json"] = obj


def _finish_json(run: dict, code: int) -> None:
    from .reporting.writers import provenance_fields, to_json

    obj = run["json"]
    if obj is None:  # nothing was computed: the object says why
        obj = {"command": run["command"], "reason": "\n".join(run["errors"]) or None}
        if run.get("problems"):
            obj["problems"] = [{"file": p.file, "line": p.line, "field": p.field, "message": p.message}
                               for p in run["problems"]]
    if "reason" not in obj:  # a result of many runs (compare, sweep ...): its failures' reasons, once, at the top
        obj = {**obj, "reason": "\n".join(run["errors"]) or None}
    print(to_json({**obj, "verdict": VERDICTS.get(code, "failed"), "exit_code": code, "errors": run["errors"],
                   **(provenance_fields() or {"locoplan_version": __version__, "inputs": run["inputs"], "input_files": []})}))


def _schedule_line(route: Path) -> tuple[Optional[float], str]:
    """The schedule's running time of a route file and where it is written, ``routes/x.yaml:9:
    schedule.run_time_s`` (its line, when it can be read)."""
    from .io.load import read_yaml

    try:
        data, lines = read_yaml(route)
    except (LocoplanError, OSError):
        return None, f"{route}: schedule.run_time_s"
    schedule = data.get("schedule") if isinstance(data, dict) else None
    value = schedule.get("run_time_s") if isinstance(schedule, dict) else None
    line = lines.get(("schedule", "run_time_s")) or lines.get(("schedule",))
    where = f"{route}:{line}: schedule.run_time_s" if line else f"{route}: schedule.run_time_s"
    return (float(value) if isinstance(value, (int, float)) else None), where


def locate_schedule(text: str) -> str:
    """A "planned running time ... is below the fastest possible run" about the route's own schedule
    (no --time was given) restated with the file and line the time came from."""
    run = _RUN.get()
    if not run or not run.get("schedule_from") or "is below the fastest possible run" not in text:
        return text
    import re

    value, where = _schedule_line(run["schedule_from"])

    def said(m) -> str:  # only the schedule's own time is said to come from it (not a --times value)
        if value is None or m.group(1) != f"{value:g}":
            return m.group(0)
        return f"planned running time {m.group(1)} s (the route's schedule, {where})"
    return re.sub(r"planned running time (\S+) s", said, text, count=1)


COMMAND_LINE: ContextVar[tuple[str, ...]] = ContextVar("locoplan_command_line", default=())
"""The command line as typed, set by the command group while it runs a command (empty when a command runs on
its own)."""


COMMAND_PARAMS: ContextVar[tuple] = ContextVar("locoplan_command_params", default=())
"""The running command's parameters (click's ``Parameter`` objects: names, options, metavars), set by the command
group while it runs a command (empty when a command runs on its own)."""


def _given() -> list[str]:
    """The command line as typed (``COMMAND_LINE``)."""
    return list(COMMAND_LINE.get())


_LATER = {"ModelRequest": "ModelRequest"}
"""Annotations :func:`guarded` leaves as written: a model group's type (``model: ModelRequest = MODEL``) is in
:mod:`locoplan.api`, imported when a command runs; typer never reads it (the group's options stand in its place)."""


def guarded(fn):
    """Turn a user's mistake (LocoplanError) into a red message on stderr and its exit code; with --json
    (an ``as_json`` argument) stdout gets one JSON object whatever the outcome (:func:`json_out`).

    A parameter whose default is a :class:`ModelGroup` (``model: ModelRequest = MODEL``) stands for the
    model options: the command line shows the group's options in its place, and ``fn`` gets them as one
    :class:`~locoplan.api.ModelRequest`."""
    signature = inspect.signature(fn, eval_str=True, locals=_LATER)
    groups = {name: p.default for name, p in signature.parameters.items() if isinstance(p.default, ModelGroup)}
    shown = [q for p in signature.parameters.values()
             for q in (p.default.parameters() if isinstance(p.default, ModelGroup) else [p])]
    clocks = "depart" not in signature.parameters and _takes_time(signature)
    if clocks:  # --depart / --arrive beside --time: the running time from two clock times
        at = next(i for i, q in enumerate(shown) if q.name == "time_s") + 1
        shown[at:at] = [inspect.Parameter(name, inspect.Parameter.POSITIONAL_OR_KEYWORD, default=info,
                                          annotation=Optional[str]) for name, info in (("depart", DEPART), ("arrive", ARRIVE))]

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from .reporting.writers import provenance

        run = {"json": None, "errors": [], "command": fn.__name__.replace("_", "-"), "inputs": _inputs(kwargs),
               "schedule_from": kwargs.get("route") if "time_s" in kwargs and kwargs.get("time_s") is None
               and kwargs.get("times") is None and isinstance(kwargs.get("route"), Path) else None}
        token = _RUN.set(run)
        departure = _DEPARTURE.set(None)
        code = None
        streams = std_streams()
        streams.__enter__()  # stdout's errors named as stdout's, stderr's dropped (std_streams)
        recording = provenance(run["inputs"])
        recording.__enter__()  # every file the command reads, hashed, for --json and the --out .json files
        try:
            try:
                # outputs appear all or none: kept on success and on a deliberate exit after them (_fail_if)
                try:
                    with all_or_none(keep=lambda exc: isinstance(exc, typer.Exit)):
                        bounds.check_command(wrapper, kwargs, _given())  # every option's value, before any work
                        _check_outputs_not_inputs(run["command"], kwargs)
                        call = _grouped(kwargs, groups)
                        if clocks:
                            call = _clocked(call, run)
                        with _out_to_stdout(run["command"], call):
                            result = fn(*args, **call)
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
        except KeyboardInterrupt:  # Ctrl-C: every output left unwritten (all_or_none), no --json object
            try:
                err.print("[bold red]interrupted:[/] nothing written", highlight=False, markup=True, soft_wrap=True)
            except OSError:
                pass
            raise typer.Exit(EXIT_INTERRUPTED) from None
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
            _DEPARTURE.reset(departure)
            try:
                if code is not None and kwargs.get("as_json"):
                    _print_json(run, code)
            finally:
                recording.__exit__(None, None, None)
                streams.__exit__(None, None, None)
    wrapper.__signature__ = signature.replace(parameters=shown)  # what typer reads (inspect's public protocol)
    wrapper.__annotations__ = {p.name: p.annotation for p in shown}
    return wrapper


_JSON_OUT = {"learn", "pareto"}
"""Commands whose ``--out`` is a .json file only: ``--out -`` writes that JSON (every other command's is CSV)."""


@contextmanager
def _out_to_stdout(command: str, call: dict):
    """``--out -``: the command's output file on stdout, in its ``--format`` where it has one, else CSV (JSON where
    ``--out`` takes .json alone); the tables it prints go to stderr, so that stdout holds the output alone.
    With ``--json`` (its object on stdout too) the combination is refused: exit 2."""
    from .reporting.files import STDOUT as DASH, stdout_output

    path = call.get("out_file")
    if path is None or str(path) != DASH:
        yield
        return
    if call.get("as_json"):
        raise InputError(Problem("<command line>", "--out", "- writes the output to stdout, where --json writes its "
                                 "object: give --out - or --json, not both (or --out FILE with --json)"))
    suffix = f".{call['fmt']}" if call.get("fmt") else ".json" if command in _JSON_OUT else ".csv"
    with stdout_output(suffix) as name:
        call["out_file"] = name
        was = out.stderr
        out.stderr = True
        try:
            yield
        finally:
            out.stderr = was


_WRITTEN = {"out_file": "--out", "plot": "--plot", "plot_td": "--plot-td", "boxplot": "--boxplot"}
"""The parameters that name a file a command writes (besides the store of a command in :data:`_WRITES_STORE`)."""
_WRITES_STORE = {"batch": ("store_path", "--store")}
"""Commands that write into a store they are given (the store is their output, not an input)."""


def _param_names() -> dict[str, str]:
    """Parameter name -> how the command line shows it (``--consist``, ``ROUTE``), for the running command."""
    names = {}
    for param in COMMAND_PARAMS.get():
        opts = getattr(param, "opts", None) or []
        long = [o for o in opts if o.startswith("--")]
        names[param.name] = long[0] if long and param.param_type_name == "option" else (param.metavar or param.name.upper())
    return names


def _check_outputs_not_inputs(command: str, kwargs: dict) -> None:
    """Before any work: no output file of the command (``--out``, ``--plot``, ``--boxplot``, batch's ``--store``) is a
    file it reads (its route, study, store, consist, ...), nor are two outputs one file (by real path, through links,
    or by inode). Files named inside an input (a study's routes) are checked when the outputs are moved into place
    (:func:`~locoplan.reporting.files.all_or_none`)."""
    from .reporting.files import check_distinct, check_not_inputs

    shown = _param_names()
    outputs = {flag: kwargs.get(name) for name, flag in _WRITTEN.items() if kwargs.get(name) is not None}
    store = _WRITES_STORE.get(command)
    if store and kwargs.get(store[0]) is not None:
        outputs[store[1]] = kwargs[store[0]]
    inputs: dict[str, list[Path]] = {}
    for name, value in kwargs.items():
        if name in _WRITTEN or name in _OUTPUTS or (store and name == store[0]) or value is None:
            continue
        paths = [value] if isinstance(value, (Path, str)) else list(value) if isinstance(value, (list, tuple)) else []
        paths = [Path(p) for p in paths if isinstance(p, Path) or (name == "consist" and isinstance(p, str))]
        if paths:
            inputs[shown.get(name, name)] = paths
    check_distinct(outputs)
    check_not_inputs(outputs, inputs)


def _takes_time(signature: inspect.Signature) -> bool:
    """Whether a command takes ``--time`` (a parameter ``time_s`` declared as that option)."""
    p = signature.parameters.get("time_s")
    return p is not None and "--time" in (getattr(p.default, "param_decls", None) or ())


_DEPARTURE: ContextVar[Optional[float]] = ContextVar("locoplan_departure", default=None)


def departure_s() -> Optional[float]:
    """The running command's ``--depart`` in seconds since midnight (None when not given): the clock its
    time-distance diagram reads."""
    return _DEPARTURE.get()


def _clocked(call: dict, run: dict) -> dict:
    """A command's arguments with ``--depart`` / ``--arrive`` turned into its ``--time`` (the running time between
    them, :func:`locoplan.bounds.clock_request`) and the departure kept for the clock (:func:`departure_s`)."""
    call = dict(call)
    depart, arrive = call.pop("depart", None), call.pop("arrive", None)
    call["time_s"] = bounds.clock_request(call.get("time_s"), depart, arrive)
    if arrive is not None:
        run["schedule_from"] = None  # the time is the clocks', not the route's schedule
    set_departure(depart)
    return call


def set_departure(depart: Optional[str]) -> None:
    """Keep ``--depart`` (hh:mm[:ss], checked) for the running command's clock (:func:`departure_s`)."""
    if depart is not None:
        _DEPARTURE.set(bounds.clock_s(depart, "--depart"))


def _grouped(kwargs: dict, groups: dict) -> dict:
    """The command's own arguments: each group's options gathered into its one value."""
    if not groups:
        return kwargs
    call = dict(kwargs)
    for name, group in groups.items():
        call[name] = group.request(call)
    return call


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


STDOUT = "<stdout>"


class _Stdout:
    """``sys.stdout`` while a command runs: an OSError from writing it names it (its filename is ``<stdout>``), so
    that a full stdout is told apart from a file the system did not name (``_os_problem``)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except OSError as exc:
            raise _named_stdout(exc) from exc

    def flush(self):
        try:
            return self._stream.flush()
        except OSError as exc:
            raise _named_stdout(exc) from exc

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _named_stdout(exc: OSError) -> OSError:
    if exc.filename is None:
        exc.filename = STDOUT
    return exc


class _Stderr:
    """``sys.stderr`` while a command runs: when it cannot be written (stderr on a full device), the messages are
    dropped and file descriptor 2 is pointed at /dev/null, so that the command writes its outputs and ends with
    the exit code it would have had: the code is all a caller can still learn."""

    def __init__(self, stream):
        self._stream = stream
        self.failed = False

    def write(self, text):
        if not self.failed:
            try:
                return self._stream.write(text)
            except OSError:
                self._fail()
        return len(text)

    def flush(self):
        if not self.failed:
            try:
                self._stream.flush()
            except OSError:
                self._fail()

    def _fail(self) -> None:
        import os

        self.failed = True
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 2)
            os.close(null)
            self._stream.flush()  # what is left in its buffer goes to /dev/null now, not into the exit
        except (OSError, ValueError):
            pass

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextmanager
def std_streams():
    """Run with ``sys.stdout`` and ``sys.stderr`` wrapped (``_Stdout``, ``_Stderr``; not twice)."""
    import sys

    stdout, stderr = sys.stdout, sys.stderr
    if stdout is not None and not isinstance(stdout, _Stdout):
        sys.stdout = _Stdout(stdout)
    if stderr is not None and not isinstance(stderr, _Stderr):
        sys.stderr = _Stderr(stderr)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = stdout, stderr


def sane_std_streams() -> None:
    """At the start of a process: a standard stream that is closed (``locoplan ... >&-``, a daemon) is pointed at
    /dev/null, so that no file the command opens takes its descriptor (a store opened as descriptor 1 would receive
    the report) and nothing prints into ``None``; stdout and stderr replace what their encoding cannot write (an
    ASCII terminal, a route named in another script) instead of failing."""
    import os
    import sys

    for fd, mode in ((0, os.O_RDONLY), (1, os.O_WRONLY), (2, os.O_WRONLY)):
        try:
            os.fstat(fd)
        except OSError:
            try:
                null = os.open(os.devnull, mode)
                if null != fd:
                    os.dup2(null, fd)
                    os.close(null)
            except OSError:
                continue
            stream = open(fd, "r" if fd == 0 else "w", encoding="utf-8", errors="replace", closefd=False)
            setattr(sys, ("stdin", "stdout", "stderr")[fd], stream)
    for name in ("stdout", "stderr"):
        stream = getattr(sys, name)
        if stream is None:
            continue
        try:
            if getattr(stream, "errors", "strict") == "strict":
                stream.reconfigure(errors="replace")
        except (AttributeError, ValueError, OSError):
            pass


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


def wrote(paths) -> None:
    """Name files a command has written whole outside ``all_or_none`` (a folder moved into place), so that a
    report it cannot print afterwards (stdout on a full disk) says they are there."""
    run = _RUN.get()
    if run is not None:
        run.setdefault("written", []).extend(paths)


def _os_problem(exc: OSError) -> LocoplanError:
    import sys

    if isinstance(exc, BrokenPipeError):
        _silence_stdout()
        return _StdoutClosed()
    why = exc.strerror or str(exc)
    if exc.filename is None and "shared object" in why:  # a library that did not load: most often no memory for it
        return LocoplanError(f"could not load a compiled library: {why.split('. ')[0]} (out of memory, e.g. under an "
                      "address-space limit (ulimit -v), or a broken install)")
    if exc.filename is None:  # a write whose file the system does not name (a file object's write, a library's)
        return InputError(Problem("<unnamed file>", "", f"cannot read or write a file: {why} (the system did not say "
                                  "which file; a full disk, a file-size limit (ulimit -f)?)"))
    if exc.filename == STDOUT:
        _silence_stdout()
        where = STDOUT
        try:
            if sys.stdout.isatty():
                where = "<terminal>"
        except (OSError, ValueError):
            pass
        run = _RUN.get()
        kept = (run or {}).get("written") or []
        if kept:  # files a command wrote whole before it printed its report (import, drivers simulate)
            shown = ", ".join(str(p) for p in kept[:3]) + (f" and {len(kept) - 3:,} more" if len(kept) > 3 else "")
            return InputError(Problem(where, "", f"cannot write the output: {why} (the files were written whole, "
                                      f"{shown}; only the report printed here was lost)"))
        return InputError(Problem(where, "", f"cannot write the output: {why} (nothing else was written)"))
    return InputError(Problem(str(exc.filename or "<command line>"), "", f"cannot read or write: {why}"))
def usage_error_json(exc, args: list[str]) -> None:
    """The --json object of a command line click refused before the command ran (exit 2)."""
    from .reporting.writers import to_json

    option = next((p.opts[0] for p in [getattr(exc, "param", None)] if p is not None and getattr(p, "opts", None)), "")
    message = exc.format_message()
    command = next((a for a in args if not a.startswith("-")), "")
    print(to_json({"command": command, "reason": f"<command line>: {option + ': ' if option else ''}{message}",
                   "problems": [{"file": "<command line>", "line": None, "field": option, "message": message}],
                   "verdict": VERDICTS[2], "exit_code": 2, "errors": [message], "locoplan_version": __version__,
                   "inputs": {}, "input_files": []}))


def _fail_if(messages: list) -> None:
    """After every output is written: name each result that failed its job, exit 1 if any did."""
    fail_on(api.verdict(messages, locate_schedule))


def _names(text: str, field: str) -> list[str]:
    return api.names(text, field)


def _range(text: str, field: str) -> list[float]:
    return api.value_grid(text, field)


def _load(route: Path, consist: str, stock_dir: Optional[Path], model: ModelRequest):
    """The route, the train and the checked model options of a command."""
    from .io.load import load_route_and_train

    opts = model.options()
    return (*load_route_and_train(route, consist, stock_dir), opts)


def _time(text: Optional[str], route, consist: str = DEFAULT_CONSIST, stock_dir: Optional[Path] = None,
          options: Optional[ModelOptions] = None, quiet: bool = False, option: str = "--time") -> Optional[float]:
    """``--time`` in seconds (:func:`locoplan.api.planned_time`; ``route``: a loaded (Route, Train), or a
    route file loaded with ``consist`` when the time is a factor of the fastest run). A note on stderr
    says what a factor came to, unless ``quiet``."""
    req = bounds.time_request(text, option)
    if req is None or req[0] == "s":
        return None if req is None else req[1]
    if isinstance(route, (str, Path)):
        from .io.load import load_route_and_train

        route = load_route_and_train(route, consist, stock_dir)
    planned = api.planned_time(text, *route, options=options, option=option)
    if planned.note and not quiet:
        err.print(f"note: {planned.note}", highlight=False, markup=False, soft_wrap=True)
    return planned.time_s


def _times(requests: Optional[list], route, consist: str = DEFAULT_CONSIST, stock_dir: Optional[Path] = None,
           options: Optional[ModelOptions] = None, quiet: bool = False, option: str = "--times",
           journey: Optional[Path] = None) -> Optional[list[float]]:
    """``--times`` in seconds (``requests`` from :func:`locoplan.bounds.times_request`; ``route`` as for
    :func:`_time`, loaded only when a time is a factor of the fastest run; with ``journey``, the factors are of
    that journey file's fastest total running time); a note on stderr says what the factors came to, unless
    ``quiet``."""
    if requests is None:
        return None
    def journey_fastest() -> float:
        from .io.load import load_journey, load_train
        from .runs.journey import journey_fastest_s
        from .sim.calculator import ModelOptions

        j, line = load_journey(journey)
        return journey_fastest_s(j, line, load_train(consist, stock_dir), options or ModelOptions())

    if journey is None and any(kind != "s" for kind, _ in requests) and isinstance(route, (str, Path)):
        from .io.load import load_route_and_train

        route = load_route_and_train(route, consist, stock_dir)
    planned = api.planned_times(requests, *(route if isinstance(route, tuple) else (None, None)), options=options,
                                option=option, fastest_s=None if journey is None else journey_fastest)
    if planned.note and not quiet:
        err.print(f"note: {planned.note}", highlight=False, markup=False, soft_wrap=True)
    return planned.times_s


def record_error(text: str) -> None:
    """A failure the command has printed itself, kept for its ``--json`` document's ``errors`` (every exit-1 document
    says why)."""
    run = _RUN.get()
    if run is not None:
        run["errors"].append(text)


def fail_on(verdict: api.Verdict, notes: bool = False) -> None:
    """After every output is written: name each result that failed its job, exit 1 if any did (with
    ``notes``, first say the verdict's notes)."""
    for m in verdict.notes if notes else ():
        err.print(f"note: {escape(m)}", highlight=False, soft_wrap=True)
    for m in verdict.failures:
        err.print(f"[bold red]error:[/] {escape(m)}", highlight=False, soft_wrap=True)
    run = _RUN.get()
    if run is not None:
        run["errors"] += verdict.failures
    if verdict.failures:
        raise typer.Exit(verdict.exit_code)


def _emit(summary_or_results, as_json: bool, out_file: Optional[Path], profile=None, route=None) -> None:
    """``--out`` and ``--json`` of a result; with ``route``, every position with its kilometre post and the
    route's stations (:func:`locoplan.reporting.posts.with_posts`)."""
    from .reporting.posts import with_posts
    from .reporting.writers import write_output

    summary_or_results = with_posts(summary_or_results, route)
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


def _check_outputs(out_file: Optional[Path], plot: Optional[Path], csv_ok: bool = True,
                   plot_td: Optional[Path] = None) -> None:
    """Refuse bad output names (type, folder, writable) before any long computation."""
    from .reporting.plot import check_plot_path

    from .reporting.files import check_distinct

    check_output(out_file, "--out", (".csv", ".json") if csv_ok else (".json",))
    check_output(plot and check_plot_path(plot), "--plot")
    check_output(plot_td, "--plot-td", PLOT_SUFFIXES)
    check_distinct({"--out": out_file, "--plot": plot, "--plot-td": plot_td})


def plot_runs_td(path: Path, profiles: list, title: str, route, form: str) -> None:
    """``--plot-td``: the time-distance diagram of plans (label, a calculator ``Profile``) on ``route``, on the
    clock of ``--depart`` when given."""
    from .reporting.plot_td import plot_time_distance, series_of

    series = [(label, *series_of(profile)) for label, profile in profiles]
    dep = departure_s()
    plot_time_distance(path, series, title, route, form, dep)


# Options shared by the commands (typer has no option groups; these keep them identical)
ROUTE = typer.Argument(..., help="Route YAML file.")
CONSIST = typer.Option(DEFAULT_CONSIST, "--consist", help="Consist YAML file or catalogue name.")
STOCK = typer.Option(None, "--stock-dir", help="Folder of vehicle files searched first.")
JSON = typer.Option(False, "--json", help="Machine-readable result on stdout (nothing else there).")


class ModelGroup:
    """The train-model options (``--step``, ``--point-mass``, ``--air-brake``, ``--rotating-mass``,
    ``--strict-limits``), declared once. A command names the group as one parameter,
    ``model: ModelRequest = MODEL``; :func:`guarded` shows the group's options in its place (in this order)
    and hands the command one :class:`~locoplan.api.ModelRequest`. ``helps`` words the options for a
    command whose model options mean something narrower (``ocp``: the energy objective's); ``strict``
    False leaves ``--strict-limits`` out (the drivers' simulation and learning never use it)."""

    HELP = {
        "step": "Reporting grid spacing [m] (optimisers search on 100 m).",
        "point_mass": "The papers' train model (to reproduce their tables): a point mass at the head, braked by its locomotives alone. Default: the train's real length (gradient averaged over it, a limit held until the tail clears it) and the wagons' air brakes.",
        "air_brake": "Brake with the wagons' air brakes as well as the electric brake (default: on, off with --point-mass).",
        "rotating_mass": "Uniform rotating-mass allowance gamma, inertial mass M(1+gamma) (default: each vehicle's own factor, 1 if none).",
        "strict_limits": "Coasting up to a limit makes a plan infeasible (default: held there by braking).",
    }

    def __init__(self, helps: Optional[dict] = None, step_m: float = DEFAULT_STEP_M, strict: bool = True):
        h = {**self.HELP, **(helps or {})}
        self.options = {
            "step": (float, typer.Option(step_m, "--step", help=h["step"])),
            "point_mass": (bool, typer.Option(False, "--point-mass/--no-point-mass", help=h["point_mass"])),
            "air_brake": (Optional[bool], typer.Option(None, "--air-brake/--no-air-brake", help=h["air_brake"], show_default=False)),
            "rotating_mass": (Optional[float], typer.Option(None, "--rotating-mass", help=h["rotating_mass"], show_default=False)),
        }
        if strict:
            self.options["strict_limits"] = (bool, typer.Option(False, "--strict-limits/--no-strict-limits", help=h["strict_limits"]))

    def parameters(self) -> list[inspect.Parameter]:
        """The group's options as the parameters typer reads."""
        return [inspect.Parameter(name, inspect.Parameter.POSITIONAL_OR_KEYWORD, default=info, annotation=kind)
                for name, (kind, info) in self.options.items()]

    def request(self, kwargs: dict) -> ModelRequest:
        """The group's values, taken out of a command's ``kwargs``, as one request."""
        from .api import ModelRequest

        values = {name: kwargs.pop(name) for name in self.options}
        return ModelRequest(step_m=values["step"], point_mass=values["point_mass"], air_brake=values["air_brake"],
                            rotating_mass=values["rotating_mass"], strict_limits=values.get("strict_limits", False))


MODEL = ModelGroup()
"""The model options of every planning command."""
MODEL_NO_STRICT = ModelGroup(strict=False)
"""The model options of the drivers' simulation and of learning (no --strict-limits)."""
TIME = typer.Option(None, "--time", help="Planned running time T0: seconds [s] (1500, 1500s), minutes (25min), hours and minutes (1h05), h:mm:ss (0:25:00), a factor of the fastest run (1.1x) or a supplement on it (+10%) (default: the route's schedule; or --depart with --arrive).")
CHAINAGE = typer.Option("km", "--chainage", help="How kilometre posts are written where the route has a chainage: km (12.345 km) or plus (12+345).")
PLOT_TD = typer.Option(None, "--plot-td", help="Time-distance diagram of the run: the line (kilometre posts where the route has a chainage) against the clock (--depart's, else since the departure), stations as lines; .png, .svg or .pdf.")
DEPART = typer.Option(None, "--depart", help="Departure clock time hh:mm[:ss]: with --arrive, the planned running time is the time between them; the time-distance diagram reads this clock.", show_default=False)
ARRIVE = typer.Option(None, "--arrive", help="Arrival clock time hh:mm[:ss] (with --depart, instead of --time; an arrival before the departure is the next day's).", show_default=False)
WEIGHTS = typer.Option("0.5,0.5", "--weights", help="Fitness weights w_time,w_energy: fitness = w_time |T - T0| / T0 + w_energy |E - E_min| / E_min.")
EMIN = typer.Option(None, "--e-min", help="E_min, the energy the fitness measures against [kWh] (default: the energy-saving strategy's energy, computed only when needed; deterministic: the same for every --seed and --algorithm, since its search (--builder issa-paper) always starts from its own fixed seed, and the general builder's comes from the deterministic least-price drive).")
SEED = typer.Option(1, "--seed", help="Random seed: the same seed gives the same result.")
ALGO = typer.Option("issa", "--algorithm", help=f"Optimiser: {', '.join(ALGORITHM_NAMES)}.")
TOL = typer.Option(None, "--tolerance", help="Punctuality window +- [s] (default: the route's schedule tolerance).")
BUILDER = typer.Option(None, "--builder", help="Sequence builder: general (the default, in every train model; any line) or issa-paper (the ISSA paper's own rules to the letter: with --point-mass it reproduces the paper's tables).", show_default=False)
WINDOW = typer.Option(True, "--window/--no-window", help="Keep plans inside T0 +- tolerance; --no-window ranks by the fitness alone.")
PARAMS = typer.Option(None, "--params", help="Optimiser parameter YAML (default: configs/optimizers/<algorithm>.yaml).")
GAP = typer.Option(True, "--gap/--no-gap", help="Report each plan's gap to the least energy E* at its own running time (a minimum-energy optimal control; a few seconds per plan).")
WORKERS = typer.Option(1, "--workers", help="Runs in parallel on this many processes (1: in this process).")
OBJECTIVE = typer.Option("traction", "--objective", metavar="traction|net", help="What the energy terms count: traction (the traction work sum F ds) or net (the traction work less what the electric brake returns to the line, the locomotives' regen_efficiency): the optimisers' fitness, E_min, E* and the gap to it.")

__all__ = ["out", "err", "guarded", "all_or_none", "check_outputs", "json_out"]
