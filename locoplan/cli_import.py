"""``locoplan import FORMAT FILES... --out DIR``: public track and train formats to locoplan files.

Thin command over :func:`locoplan.importer.run_import`; the formats come from
:data:`locoplan.io.readers.FORMATS`. :func:`register` adds the command to a typer app.
"""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Optional

import typer
from rich.markup import escape

from .cli_common import err, guarded, json_out, out, wrote
from .io.readers import FORMATS

__all__ = ["register"]


def _command(fmt: str, sources: list[Path], out_dir: Path, flags: list[str]) -> str:
    """The command line recorded in each written file's header (what reproduces it)."""
    words = ["locoplan", "import", fmt, *[str(s) for s in sources], "--out", str(out_dir), *flags]
    return " ".join(shlex.quote(w) for w in words)


formats = "; ".join(f"{name}: {f.description}" for name, f in FORMATS.items())


@guarded
def import_(fmt: str = typer.Argument(..., metavar="FORMAT", help=f"Source format ({formats})."),
            sources: list[Path] = typer.Argument(..., metavar="FILES...", help="Source files (railtoolkit: running-path and/or rolling-stock files, in any order)."),
            out_dir: Path = typer.Option(..., "--out", metavar="DIR", help="Folder to write into, created with its parents if missing (railtoolkit vehicles go to rolling_stock/, trains to consists/ inside it)."),
            cap_kmh: Optional[float] = typer.Option(None, "--cap-kmh", help="Cap every speed limit at this speed [km/h], e.g. 80 for a freight train on a passenger line (default: no cap)."),
            leg: Optional[int] = typer.Option(None, "--leg", help="ttobench: only this stop-to-stop leg, 1 = first stop to second (default: every leg)."),
            all_legs: bool = typer.Option(False, "--all-legs", help="ttobench: every leg, one route file each (the default)."),
            journey: bool = typer.Option(False, "--journey", help="ttobench: the whole line as one route and a journey file with every stop (for locoplan journey), instead of one route per leg."),
            load_fraction: float = typer.Option(1.0, "--load-fraction", help="railtoolkit: share of each wagon's load_limit put on (1 = fully loaded, as TrainRuns.jl)."),
            from_station: Optional[str] = typer.Option(None, "--from", help="osrd, railml: the station the run starts at (an operational point's id or name)."),
            to_station: Optional[str] = typer.Option(None, "--to", help="osrd, railml: the station the run ends at."),
            via: list[str] = typer.Option([], "--via", help="osrd, railml: a station the path must pass, in the order given (repeat the option for more)."),
            stop: list[str] = typer.Option([], "--stop", help="osrd, railml: a station passed on the way where the journey stops (repeat for more; the first and last stations always are stops)."),
            speed_tag: Optional[str] = typer.Option(None, "--speed-tag", help="osrd: the speed sections' limit for this tag (a train category, e.g. MA100) where a section gives one; else its speed_limit."),
            thermal: bool = typer.Option(False, "--thermal", help="osrd: the train runs on its own power: neutral sections and track without electrification do not cut traction."),
            mode: Optional[str] = typer.Option(None, "--mode", help="osrd-train: the traction mode whose effort curve is written (default: the rolling stock's default_mode)."),
            track: list[str] = typer.Option([], "--track", help="railml: a track (its id) to run along, from its begin to its end; repeat for tracks joined end to end, in running order."),
            category: Optional[str] = typer.Option(None, "--category", help="railml: the train category whose speed limits apply where speedChange elements give one (trainCategory, or a speed profile's id/name)."),
            as_json: bool = typer.Option(False, "--json", help="Machine-readable list of written files on stdout."),
            ):
    """Convert public track / path / train files into route, vehicle and consist files (all written, or none)."""
    from .importer import run_import
    from .io.readers import ImportOptions

    flags = []
    if cap_kmh is not None:
        flags += ["--cap-kmh", f"{cap_kmh:g}"]
    if leg is not None:
        flags += ["--leg", str(leg)]
    if all_legs:
        flags.append("--all-legs")
    if journey:
        flags.append("--journey")
    if load_fraction != 1.0:
        flags += ["--load-fraction", f"{load_fraction:g}"]
    for flag, value in (("--from", from_station), ("--to", to_station), ("--speed-tag", speed_tag), ("--mode", mode),
                        ("--category", category)):
        if value is not None:
            flags += [flag, value]
    for flag, values in (("--via", via), ("--stop", stop), ("--track", track)):
        for value in values:
            flags += [flag, value]
    if thermal:
        flags.append("--thermal")
    options = ImportOptions(cap_kmh=cap_kmh, leg=leg, all_legs=all_legs, journey=journey, load_fraction=load_fraction,
                            from_station=from_station, to_station=to_station, via=tuple(via), stops=tuple(stop),
                            speed_tag=speed_tag, thermal=thermal, mode=mode, tracks=tuple(track), category=category,
                            command=_command(fmt, sources, out_dir, flags))
    report = run_import(fmt, list(sources), out_dir, options)
    wrote([p for p, _, _ in report.written] + ([report.licence] if report.licence else []))
    if as_json:
        json_out({"format": fmt, "files": [{"path": str(p), "kind": k, "summary": s} for p, k, s in report.written],
                       "licence": str(report.licence) if report.licence else None, "notes": report.notes})
    else:
        for path, kind, summary in report.written:
            out.print(f"[green]wrote[/] {escape(str(path))}  ({escape(kind)}: {escape(summary.split(': ', 1)[-1])})", highlight=False)  # wrapped at spaces to the width (80 in a pipe)
        if report.licence:
            out.print(f"[green]wrote[/] {escape(str(report.licence))}  (the source's licence)", highlight=False)  # wrapped at spaces to the width (80 in a pipe)
    for note in report.notes:
        err.print(f"[yellow]note:[/] {escape(note)}", highlight=False, soft_wrap=True)


def register(app: typer.Typer) -> None:
    """Add the ``import`` command to ``app``."""
    app.command("import")(import_)
