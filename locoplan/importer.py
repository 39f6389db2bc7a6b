"""``locoplan import``: run a reader, check every file it produced against locoplan's schemas, and
write them all or none (into a hidden temporary folder inside the output folder, then moved).

A problem in a produced file is reported at the source field it was converted from (the reader's
``source_fields``), so a user fixes the file they have, not one they have never seen.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import tempfile
from dataclasses import dataclass, fields
from pathlib import Path


from .errors import InputError, Problem
from .io.load import load_journey, load_train, parse_yaml, validate_data
from .io.readers import READERS, ImportedFile, ImportOptions
from .reporting.files import existing_folder, make_folder, put_back

CLI = "<command line>"
OPTION_FLAGS = {"cap_kmh": "--cap-kmh", "leg": "--leg", "all_legs": "--all-legs", "journey": "--journey",
                "load_fraction": "--load-fraction", "from_station": "--from", "to_station": "--to", "via": "--via",
                "stops": "--stop", "speed_tag": "--speed-tag", "thermal": "--thermal", "mode": "--mode",
                "tracks": "--track", "category": "--category"}


@dataclass(frozen=True)
class ImportReport:
    """What was written: (path, kind, summary) per file, the licence file (or None), notes for the user."""

    written: list[tuple[Path, str, str]]
    licence: Path | None
    notes: list[str]


def check_options(fmt: str, n_sources: int, options: ImportOptions) -> None:
    """The format exists, gets a number of files it takes, and no option it does not use."""
    if fmt not in READERS:
        raise InputError(Problem(CLI, "FORMAT", f"unknown format {fmt!r} (one of: {', '.join(READERS)})"))
    reader = READERS[fmt]
    problems = []
    defaults = ImportOptions()
    for f in fields(ImportOptions):
        if f.name in OPTION_FLAGS and getattr(options, f.name) != getattr(defaults, f.name) and f.name not in reader.options:
            users = [name for name, r in READERS.items() if f.name in r.options]
            problems.append(Problem(CLI, OPTION_FLAGS[f.name], f"does not apply to {fmt} (only to: {', '.join(users)})"))
    if options.leg is not None and options.all_legs:
        problems.append(Problem(CLI, "--leg", "give --leg N or --all-legs, not both"))
    if options.journey and (options.leg is not None or options.all_legs):
        problems.append(Problem(CLI, "--journey", "writes the whole line and its stops: give it without --leg or --all-legs"))
    if options.leg is not None and options.leg < 1:
        problems.append(Problem(CLI, "--leg", f"legs are numbered from 1 (got {options.leg})"))
    if options.cap_kmh is not None and not (math.isfinite(options.cap_kmh) and options.cap_kmh > 0):
        problems.append(Problem(CLI, "--cap-kmh", f"must be a speed > 0 km/h (got {options.cap_kmh:g})"))
    if not (math.isfinite(options.load_fraction) and 0 <= options.load_fraction <= 1):
        problems.append(Problem(CLI, "--load-fraction", f"must be in [0, 1] (share of each wagon's load_limit; "
                                f"got {options.load_fraction:g})"))
    if not reader.min_files <= n_sources <= reader.max_files:
        problems.append(Problem(CLI, "FILES", f"{fmt} takes {reader.min_files} to {reader.max_files} file(s), got {n_sources}"))
    if problems:
        raise InputError(problems)


def _writable(folder: Path) -> bool:
    return os.access(folder, os.W_OK | os.X_OK)


def check_out_dir(out_dir: Path) -> None:
    """The output folder is a writable folder, or is missing and can be created (the one rule for output
    folders: created when the files are written)."""
    where = str(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(Problem(where, "--out", "is a file, not a folder"))
    folder = existing_folder(out_dir, where, "--out")
    if not _writable(folder):
        raise InputError(Problem(where, "--out", "folder is not writable" if folder == out_dir
                                 else f"folder {folder} is not writable"))


def _top_key(field: str) -> str:
    return re.split(r"[.\[]", field, maxsplit=1)[0] if field else ""


def _to_source(item: ImportedFile, problems: list[Problem]) -> list[Problem]:
    """Problems of a produced file, restated at the source field it came from."""
    out = []
    for p in problems:
        key = _top_key(p.field)
        source = item.source_fields.get(key, "")
        line = item.source_lines.get(key) or None
        out.append(Problem(item.source_file, source or p.field,
                           f"{p.message} (as {p.field or 'the file'} of the imported {item.kind} {item.relpath})", line))
    return out


def _validate(tmp: Path, items: list[ImportedFile]) -> None:
    """Routes and vehicles against their schemas; then consists (which load their vehicles), only if
    every vehicle passed, so that one bad vehicle is reported once, at its source field."""
    for stage in (("route", "vehicle"), ("consist", "journey")):
        problems: list[Problem] = []
        for item in (i for i in items if i.kind in stage):
            try:
                if item.kind == "consist":
                    load_train(tmp / item.relpath)
                elif item.kind == "journey":
                    load_journey(tmp / item.relpath)
                else:
                    validate_data(parse_yaml(item.text, item.relpath)[0], item.relpath, {})
            except InputError as exc:
                problems += _to_source(item, exc.problems)
        if problems:
            raise InputError(problems)


def run_import(fmt: str, sources: list[Path], out_dir: Path, options: ImportOptions) -> ImportReport:
    """Import ``sources`` of format ``fmt`` into ``out_dir``: every file written, or none (``InputError``)."""
    check_options(fmt, len(sources), options)
    check_out_dir(out_dir)
    imported = READERS[fmt].read(sources, options)
    seen: dict[str, str] = {}
    for item in imported.files:
        if item.relpath in seen:
            raise InputError(Problem(item.source_file, "id", f"two inputs would both be written to {item.relpath} "
                                     f"(also from {seen[item.relpath]}): ids must differ"))
        seen[item.relpath] = item.source_file
        _check_target(out_dir, item)
    licence_name = f"LICENSE-{imported.licence_name}.txt" if imported.licence else None
    if licence_name:
        _check_target(out_dir, ImportedFile(licence_name, "licence", "", "", str(imported.licence)))
    for name, source in imported.more_licences:
        _check_target(out_dir, ImportedFile(name, "licence", "", "", str(source)))
    make_folder(out_dir, str(out_dir), "--out")  # a missing output folder is made (nothing was refused)
    try:
        return _write_all(out_dir, imported, licence_name)
    except OSError as exc:  # a full disk, a folder that turned read-only: nothing is left written
        raise InputError(Problem(str(exc.filename or out_dir), "--out", f"cannot write the imported files: "
                                 f"{exc.strerror or exc} (none was written)")) from None


NAME_MAX_BYTES = 255
"""The longest file name (one path component) Linux, macOS and Windows file systems take."""


def _check_target(out_dir: Path, item: ImportedFile) -> None:
    """Before anything is written: the file's name is one the file system takes, every folder on its way is a
    folder (or can be made), and what stands at its place, if anything, is a regular file to replace."""
    rel = Path(item.relpath)
    for part in rel.parts:
        size = len(part.encode("utf-8", "surrogateescape"))
        if size > NAME_MAX_BYTES:
            raise InputError(Problem(item.source_file, "id", f"gives the file name {part[:40]!r}... of {size:,} bytes, "
                                     f"longer than the {NAME_MAX_BYTES} a file system takes: shorten the id"))
    folder = out_dir
    for part in rel.parts[:-1]:
        folder = folder / part
        if os.path.lexists(folder) and not folder.is_dir():
            raise InputError(Problem(str(folder), "--out", f"is a file where the folder {part}/ is to hold the imported "
                                     f"{item.kind} {rel.name}: move it away (nothing was written)"))
    target = out_dir / rel
    if target.is_dir():
        raise InputError(Problem(str(target), "--out", "a folder stands where this file is to be written"))
    if os.path.lexists(target):
        try:
            mode = os.stat(target).st_mode
        except OSError as exc:
            raise InputError(Problem(str(target), "--out", f"cannot replace it: {exc.strerror or exc}")) from None
        import stat

        if not stat.S_ISREG(mode):
            raise InputError(Problem(str(target), "--out", "exists and is not a regular file (a pipe, a device or a "
                                     "socket is never written over): move it away (nothing was written)"))


def _write_all(out_dir: Path, imported, licence_name: str | None) -> ImportReport:
    """Write into a hidden folder, validate, then move every file into place; if a move fails, the files
    moved so far are put back as they were (old contents restored, new ones removed), and so are the folders."""
    tmp = Path(tempfile.mkdtemp(prefix=".locoplan-import-", dir=out_dir))
    made: list[Path] = []  # folders made inside out_dir
    moved: list[tuple[Path, Path | None]] = []  # (target, backup of what stood there, or None)
    try:
        for item in imported.files:
            (tmp / item.relpath).parent.mkdir(parents=True, exist_ok=True)
            (tmp / item.relpath).write_text(item.text, encoding="utf-8")
        _validate(tmp, imported.files)
        extra = [name for name, _ in imported.more_licences] if licence_name else []
        if licence_name:
            shutil.copyfile(imported.licence, tmp / licence_name)
            for name, source in imported.more_licences:
                shutil.copyfile(source, tmp / name)
        pairs = [(tmp / item.relpath, out_dir / item.relpath) for item in imported.files]
        if licence_name:
            pairs.append((tmp / licence_name, out_dir / licence_name))
            pairs += [(tmp / name, out_dir / name) for name in extra]
        backups = tmp / ".backup"
        backups.mkdir()
        try:
            for n, (new, target) in enumerate(pairs):
                folder = target.parent
                missing = []
                while not folder.exists():
                    missing.append(folder)
                    folder = folder.parent
                for f in reversed(missing):
                    f.mkdir()
                    made.append(f)
                backup = None
                if target.exists():
                    backup = backups / str(n)
                    os.link(target, backup) if _same_device(target, backups) else shutil.copy2(target, backup)
                os.replace(new, target)
                moved.append((target, backup))
        except BaseException:
            put_back(moved)
            for f in reversed(made):
                try:
                    f.rmdir()
                except OSError:
                    pass
            raise
        written = [(out_dir / item.relpath, item.kind, item.summary) for item in imported.files]
        licence = out_dir / licence_name if licence_name else None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return ImportReport(written, licence, imported.notes)


def _same_device(a: Path, b: Path) -> bool:
    try:
        return os.stat(a).st_dev == os.stat(b).st_dev
    except OSError:
        return False
