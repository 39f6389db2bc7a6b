"""Help that reads well: every option's value named with its unit or kind (``--time S``, ``--e-min KWH``),
arguments named as click names them (``ROUTE``, ``FILES...``), never typer's ``<float>`` / ``{route}``.

:func:`tidy` is called once on the finished app (end of ``cli.py``): it fills in the metavar of every
option that has none, from :data:`METAVARS` (one name per flag, so a flag reads the same in every
command), and of every argument (its name in capitals). The wording of each option stays where it is
declared; this module only names the values.
"""

from __future__ import annotations

import inspect

import typer

METAVARS = {
    "--algorithm": "NAME", "--at-m": "M", "--speed-kmh": "KMH", "--elapsed-s": "S", "--every": "S",
    "--condition": "T|K|C|B", "--air": "STATE", "--recharge-left-s": "S", "--disturb": "FILE", "--algorithms": "NAME,...", "--boxplot": "FILE", "--builder": "NAME", "--by": "FIELD,...",
    "--cap-kmh": "KMH", "--category": "NAME", "--from": "STATION", "--to": "STATION", "--via": "STATION",
    "--stop": "STATION", "--speed-tag": "TAG", "--mode": "MODE", "--track": "ID", "--comfort": "M/S2", "--consist": "FILE|NAME", "--divisions": "N", "--drivers": "N",
    "--e-min": "KWH", "--efficiency": "ETA|KMH:ETA,...", "--factors": "A:B:STEP|X,...", "--folds": "N",
    "--format": "csv|parquet|json", "--holdout": "SHARE", "--leg": "N", "--level": "PERMILLE", "--load-class": "T",
    "--load-fraction": "SHARE", "--logs": "DIR", "--mass": "T", "--masses": "T,...", "--max-order": "N",
    "--max-phase-degree": "N", "--mesh-tol": "REL", "--method": "NAME", "--nodes": "N", "--objective": "time|energy",
    "--out": "FILE", "--params": "FILE", "--params-dir": "DIR", "--patterns": "FILE", "--plot": "FILE",
    "--regen": "SHARE", "--repeats": "N", "--rotating-mass": "GAMMA", "--runs": "N", "--scheduler": "ADDRESS",
    "--seed": "N", "--seeds": "N,...", "--sequence": "PLAN", "--stage2": "MODE", "--state-nodes": "N", "--step": "M",
    "--stock-dir": "DIR", "--store": "FILE", "--strategies": "NAME,...", "--strategy": "NAME", "--time": "TIME", "--depart": "HH:MM", "--arrive": "HH:MM", "--chainage": "km|plus", "--plot-td": "FILE",
    "--times": "A:B:STEP|S,...", "--tolerance": "S", "--weights": "W_TIME,W_ENERGY",
    "--weight-grid": "A:B:STEP|W,...", "--where": "EXPR", "--workers": "N",
}
"""Flag -> the name of its value in help (units in capitals: S seconds, M metres, KWH, KMH, T tonnes)."""


SUMMARIES = {
    "validate": "Check route, vehicle and consist files; list every problem",
    "simulate": "Traction calculation of one plan: a strategy or a sequence",
    "optimize": "The least-energy plan on time (switching points by ISSA)",
    "compare": "Strategies side by side: plans, running times, energies",
    "sweep": "The optimised plan across fitness weights or planned times",
    "study": "Each optimiser over many random seeds: best, worst, mean",
    "ocp": "Optimal control: minimum running time or minimum energy",
    "ocp-study": "Minimum-time collocation methods side by side",
    "learn": "Learn pattern curves from good drivers' logs",
    "advise": "A plan from learned pattern curves, checked by simulation",
    "replay": "Logged runs against E*: where they lost energy, by section",
    "import": "Public track, path and train files to locoplan files",
    "bound": "The least traction energy E* for a running time",
    "batch": "Many runs from a study file on a process pool; resumable",
    "results": "Export, summarise and plot a result store",
    "pareto": "The energy-time front of the strategies' plans",
    "drivers": "Synthetic drivers' logs (labelled synthetic)",
    "replan": "On board: the rest of the run from the train's state",
    "drive": "Closed loop: a disturbed run re-planned, open loop, E*",
}
"""Each command's line in ``locoplan --help``: what it does, short enough for 80 columns (click would
cut the docstring's first sentence with "...")."""


def _flag(info) -> str:
    return info.param_decls[0].split("/")[0] if info.param_decls else ""


def _params(fn):
    # the signature typer reads: a command's own (guarded's wrapper gives the model options' group expanded)
    return inspect.signature(fn).parameters.items()


def _tidy_command(fn) -> None:
    for name, p in _params(fn):
        info = p.default
        if isinstance(info, typer.models.OptionInfo):
            if info.metavar is None and "bool" not in str(p.annotation):  # a flag has no value
                flag = _flag(info)
                if flag not in METAVARS:
                    raise KeyError(f"cli_help.METAVARS has no entry for {flag} (add one)")
                info.metavar = METAVARS[flag]
        elif isinstance(info, typer.models.ArgumentInfo) and info.metavar is None:
            plural = "list" in str(p.annotation)
            info.metavar = name.upper() + ("..." if plural else "")


def _name(info) -> str:
    return info.name or info.callback.__name__.replace("_", "-")


def tidy(app: typer.Typer, top: bool = True) -> None:
    """Name every option's and argument's value in ``app`` (and its sub-apps) that has no metavar yet,
    and give each top-level command its one-line summary from :data:`SUMMARIES`."""
    for cmd in app.registered_commands:
        _tidy_command(cmd.callback)
        if cmd.cls in (None, typer.core.TyperCommand):  # typer's default: ours shows arguments as click does
            cmd.cls = Command
        if top and cmd.short_help is None and _name(cmd) in SUMMARIES:
            cmd.short_help = SUMMARIES[_name(cmd)]
    for group in app.registered_groups:
        tidy(group.typer_instance, top=False)
        name = group.name or group.typer_instance.info.name
        if top and name in SUMMARIES:
            group.short_help = SUMMARIES[name]


class Command(typer.core.TyperCommand):
    """Every command's class (set by :func:`tidy`): an argument with a metavar is shown as that metavar
    alone, in the usage line (``ROUTE``, ``[ROUTE]`` when optional) and in the list, as click shows it
    (typer would write ``{ROUTE}`` and add its type, ``ROUTE <path>``). Public click API only:
    ``collect_usage_pieces`` and ``format_options`` over the parameters' own help records."""

    def collect_usage_pieces(self, ctx) -> list[str]:
        pieces = [self.options_metavar] if self.options_metavar else []
        for param in self.get_params(ctx):
            if param.param_type_name == "argument" and param.metavar:
                pieces.append(param.metavar if param.required else f"[{param.metavar}]")
            else:
                pieces.extend(param.get_usage_pieces(ctx))
        return pieces

    def format_options(self, ctx, formatter) -> None:
        args, opts = [], []
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx)
            if record is None:
                continue
            if param.param_type_name == "argument":
                args.append((param.metavar, record[1]) if param.metavar else record)
            elif param.param_type_name == "option":
                opts.append(record)
        if args:
            with formatter.section("Arguments"):
                formatter.write_dl(args)
        if opts:
            with formatter.section("Options"):
                formatter.write_dl(opts)


__all__ = ["tidy", "METAVARS", "Command"]
