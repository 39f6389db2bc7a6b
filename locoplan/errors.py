"""Exceptions that the CLI turns into a clear message and an exit code (library code never exits), and the
exit codes themselves (:mod:`locoplan.api` re-exports them; here they load without the planner, for ``--help``)."""

from __future__ import annotations

from dataclasses import dataclass

EXIT_OK, EXIT_FAILED, EXIT_INVALID = 0, 1, 2
EXIT_INTERRUPTED = 130
"""Ctrl-C (128 + SIGINT, the shells' convention): the command stopped, nothing written."""
"""Exit codes (SPEC section 3): every result does its job; a valid request whose result does not (no
feasible plan, a timetabled plan outside its window, an optimum not confirmed); invalid input."""

VERDICTS = {EXIT_OK: "ok", EXIT_FAILED: "failed", EXIT_INVALID: "invalid input"}
"""Exit code -> the ``verdict`` of every --json object."""

EXIT_RULE = ("Exit codes, the same for every command: 0 every result does its job; 1 a valid request whose "
             "result does not (no feasible plan, a planned time below the fastest run, or a plan made to keep the "
             "timetable outside T0 +- tolerance; a --sequence, time-saving and energy-saving are measured, their "
             "earliness or lateness reported, never exit 1 for it); 2 invalid input; 130 interrupted (Ctrl-C), nothing "
             "written. With --json, stdout holds one JSON object whatever the outcome (but an interruption), with "
             "verdict, exit_code and errors.")
"""The exit-code rule, as ``locoplan --help`` states it (docs/cli.md, 'Exit codes')."""


class LocoplanError(Exception):
    """Base class of every error a user can cause. ``exit_code`` is what the CLI returns."""

    exit_code = 2


@dataclass(frozen=True)
class Problem:
    """One thing wrong with one input: where (file, line, field) and why."""

    file: str
    field: str
    message: str
    line: int | None = None

    def __str__(self) -> str:
        # a problem with no file is one with an argument's value: from Python it names the argument
        # (``time_s: ...``); the command line restates it as ``<command line>: --time: ...`` (cli_common.as_flags)
        if not self.file:
            return f"{self.field}: {self.message}" if self.field else self.message
        where = f"{self.file}:{self.line}" if self.line else self.file
        return f"{where}: {self.field}: {self.message}" if self.field else f"{where}: {self.message}"


class InputError(LocoplanError):
    """Invalid input (file, field, value): exit code 2. Carries every problem found, not just the first."""

    exit_code = 2

    def __init__(self, problems: list[Problem] | Problem | str):
        if isinstance(problems, str):
            problems = [Problem(file="", field="", message=problems)]
        elif isinstance(problems, Problem):
            problems = [problems]
        self.problems = list(problems)
        super().__init__("\n".join(str(p) for p in self.problems))


class InfeasibleError(LocoplanError):
    """The request is valid but no plan satisfies it (e.g. a running time below the fastest run): exit code 1."""

    exit_code = 1
