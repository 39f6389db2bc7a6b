"""Output files written whole or not at all (temporary file + rename), and the checks of an output's
path made before any work: the one place a command's files are written from."""

from __future__ import annotations

import os
import stat
import sys
import tempfile
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import Callable

from ..errors import InputError, Problem


_PENDING: ContextVar[list[tuple[str, Path]] | None] = ContextVar("locoplan_pending_outputs", default=None)

STDOUT = "-"
"""The output name that means stdout (``--out -``)."""

_STDOUT: ContextVar[frozenset[str]] = ContextVar("locoplan_stdout_outputs", default=frozenset())


@contextmanager
def stdout_output(suffix: str):
    """An output that goes to stdout: yields the name to write it under, ``-`` with ``suffix`` (the writers choose
    the format by the suffix, ``.csv``, ``.json``...). What :func:`atomic_write` writes under that name is staged
    in a temporary file and written to stdout where a file would be moved into place (so, inside
    :func:`all_or_none`, only when the command's outputs are complete); no file of that name is made."""
    name = STDOUT + suffix
    token = _STDOUT.set(_STDOUT.get() | {name})
    try:
        yield Path(name)
    finally:
        _STDOUT.reset(token)


def is_stdout(path: str | Path | None) -> bool:
    """True when ``path`` is the name :func:`stdout_output` gave: written to stdout, not to a file."""
    return path is not None and str(Path(path)) in _STDOUT.get()


def existing_folder(folder: Path, name: str, option: str) -> Path:
    """The nearest folder of ``folder`` (itself or an ancestor) that exists: the one rule for output
    folders is that missing ones are created when the output is written, so a check before the work
    looks at the folder they will be created in. A file standing in the way is an input error."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise InputError(Problem(name, option, f"{probe} is not a folder"))
    return probe


def make_folder(folder: Path, name: str, option: str = "") -> None:
    """Create an output's folder (and its parents) if missing; an OSError becomes an input error."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(Problem(name, option, f"cannot create folder {folder}: {exc.strerror or exc}")) from None


def check_output(path: str | Path | None, option: str, suffixes: tuple[str, ...] = ()) -> Path | None:
    """Before any work: ``path`` has one of ``suffixes``, is not a folder or a device, and its folder (or,
    where that is still to be created, the folder it will be created in) takes a new file (tried by
    creating and removing an empty temporary file there)."""
    if path is None:
        return None
    path = Path(path)
    if is_stdout(path):  # no file: only its format is checked
        if suffixes and path.suffix.lower() not in suffixes:
            raise InputError(Problem("<command line>", option, f"-: stdout takes {path.suffix} here, and this output "
                                     "is " + " or ".join(suffixes)))
        return path
    try:
        return _check_output(path, option, suffixes)
    except OSError as exc:  # a name too long, a loop of links, ...
        raise InputError(Problem(str(path), option, f"cannot write: {exc.strerror or exc}")) from None


def _check_output(path: Path, option: str, suffixes: tuple[str, ...]) -> Path:
    name = str(path)
    if path.is_dir():  # before the suffix: a folder has none, and 'unknown output type' would not say what is wrong
        raise InputError(Problem(name, option, f"is a folder: name a file inside it, e.g. {path / ('result' + (suffixes[0] if suffixes else ''))}"))
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(Problem(name, option, f"unknown output type {path.suffix or '(none)'!r}; use " + " or ".join(suffixes)))
    if path.exists() and not path.is_file():
        raise InputError(Problem(name, option, "exists and is not a regular file (a device or a pipe is never written over)"))
    folder = existing_folder(path.parent if str(path.parent) else Path("."), name, option)
    try:
        fd, probe = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=".probe", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise InputError(Problem(name, option, f"cannot write into {folder}: {exc.strerror or exc}")) from None
    return path


def same_file(a: str | Path, b: str | Path) -> bool:
    """True when ``a`` and ``b`` name one file: the same real path (every link resolved, also a link to a folder
    above a file still to be made) or, for two existing files, the same inode (a hard link)."""
    try:
        if os.path.realpath(a) == os.path.realpath(b):
            return True
        return os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b)
    except (OSError, ValueError):  # a name too long, a loop of links: not provably one file
        return False



def check_distinct(outputs: dict[str, Path | None]) -> None:
    """Before any work: no two of a command's outputs (option -> path) name the same file."""
    seen: list[tuple[str, Path]] = []
    for option, path in outputs.items():
        if path is None:
            continue
        for other, p in seen:
            if same_file(Path(path), p):
                raise InputError(Problem(str(path), option, f"names the same file as {other} ({p}): one output would be "
                                         "lost; name each output differently"))
        seen.append((option, Path(path)))


def check_not_inputs(outputs: dict[str, Path | None], inputs: dict[str, list[Path]]) -> None:
    """Before any work: no output (option -> path) names a file the command reads (option -> paths), by its path,
    through links or by its inode; writing it would replace the input with the command's own result."""
    for option, path in outputs.items():
        if path is None:
            continue
        for source, paths in inputs.items():
            for given in paths:
                if os.path.isfile(given) and same_file(path, given):
                    raise InputError(Problem(str(path), option, f"is the input {source} ({given}): writing it would "
                                             "replace what this command reads; name another output file"))


def _temp_prefix(path: Path) -> str:
    """A hidden temporary name beside ``path``: short enough for any name the folder takes."""
    return f".{path.name[:40]}."


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _mode_for(path: Path) -> int:
    """The mode ``path`` gets: an existing file keeps its own (as when written in place), a new one
    0666 less the umask (as ``open`` gives); never mkstemp's 0600."""
    try:
        st = os.stat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return 0o666 & ~_umask()


def atomic_write(path: str | Path, write: Callable[[Path], None]) -> None:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it into place (inside
    ``all_or_none()``: when the whole command has succeeded).

    A failure leaves no partial file behind; a missing folder is created (with its parents).
    """
    path = Path(path)
    if is_stdout(path):
        return _stage_stdout(path, write)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        existing_folder(folder, str(path), "")
        make_folder(folder, str(path))
    pending = _PENDING.get()
    if pending is not None and any(same_file(path, target) for _, target in pending):
        raise InputError(Problem(str(path), "", "two outputs of this command name the same file: one would be lost; "
                                 "name each output differently"))
    try:
        fd, tmp = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=path.suffix[:16], dir=folder)
        os.close(fd)
    except OSError as exc:
        raise InputError(Problem(str(path), "", f"cannot write into {folder}: {exc.strerror or exc}")) from None
    try:
        write(Path(tmp))
        os.chmod(tmp, _mode_for(path))
        pending = _PENDING.get()
        if pending is None:
            _commit([(tmp, path)])
        else:
            pending.append((tmp, path))
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise InputError(Problem(str(path), "", f"cannot write: {exc.strerror or exc}")) from None
        raise


def _stage_stdout(path: Path, write: Callable[[Path], None]) -> None:
    """:func:`atomic_write` of an output that goes to stdout: staged in the system's temporary folder."""
    fd, tmp = tempfile.mkstemp(prefix="locoplan-stdout.", suffix=path.suffix[:16])
    os.close(fd)
    try:
        write(Path(tmp))
    except BaseException:
        _discard([tmp])
        raise
    pending = _PENDING.get()
    if pending is None:
        _commit([(tmp, path)])
    else:
        pending.append((tmp, path))


def _to_stdout(tmp: str) -> None:
    """A staged output, written to stdout as it is (text, or bytes: a parquet export), then removed."""
    try:
        with open(tmp, "rb") as fh:
            data = fh.read()
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            text = None
        sys.stdout.flush()
        if text is not None:
            sys.stdout.write(text)
        else:
            sys.stdout.buffer.write(data)
        sys.stdout.flush()
    finally:
        _discard([tmp])


@contextmanager
def all_or_none(keep: Callable[[BaseException], bool] = lambda exc: False):
    """Every output written inside (by ``atomic_write``) appears when the block ends normally, or
    when it ends with an exception ``keep`` accepts (a deliberate exit after the outputs); otherwise
    none does: a command writes all its outputs or none."""
    pending: list[tuple[str, Path]] = []
    token = _PENDING.set(pending)
    commit = False
    try:
        yield
        commit = True
    except BaseException as exc:
        commit = keep(exc)
        raise
    finally:
        _PENDING.reset(token)
        if commit:
            _commit(pending)
        else:
            _discard(tmp for tmp, _ in pending)


def _discard(paths) -> None:
    for tmp in paths:
        try:
            os.unlink(tmp)
        except OSError:  # already gone, or not ours to remove any more
            pass


def _read_by_this_command(path: Path) -> str | None:
    """The input file (as named when read) that ``path`` is, when this command read it (``io.load`` records every
    file it reads, so also a route named inside a study or a journey file); else None."""
    from ..io.load import files_read

    for entry in files_read() or ():
        if same_file(path, entry["path"]):
            return entry["path"]
    return None


def _commit(pending: list[tuple[str, Path]]) -> None:
    """Move every staged output into place together: none replaces a file the command read, and when one move
    fails the ones before it are undone (each replaced file is kept as a hard link until every move is done), so
    the outputs appear all or none. An output to stdout (:func:`stdout_output`) is written there once the files
    are in place."""
    to_stdout = [tmp for tmp, path in pending if is_stdout(path)]
    pending = [(tmp, path) for tmp, path in pending if not is_stdout(path)]
    try:
        _commit_files(pending)
    except BaseException:
        _discard(to_stdout)
        raise
    for tmp in to_stdout:
        _to_stdout(tmp)


def _commit_files(pending: list[tuple[str, Path]]) -> None:
    for _tmp, path in pending:
        source = _read_by_this_command(path)
        if source is not None:
            _discard(t for t, _ in pending)
            raise InputError(Problem(str(path), "", f"is an input this command read ({source}): writing it would "
                                     "replace that input with this command's result; nothing was written; name "
                                     "another output file"))
    done: list[tuple[Path, str | None]] = []  # (output, its old file kept aside, or None if it was new)
    try:
        for tmp, path in pending:
            backup = _keep_aside(path)
            try:
                os.replace(tmp, path)
            except BaseException:
                _discard([backup] if backup else [])
                raise
            done.append((path, backup))
    except OSError as exc:
        failed = pending[len(done)][1]
        put_back(done)
        _discard(t for t, _ in pending[len(done):])
        raise InputError(Problem(str(failed), "", f"cannot write: {exc.strerror or exc}; no output of this command "
                                 "was written")) from None
    _discard(b for _, b in done if b is not None)


def _keep_aside(path: Path) -> str | None:
    """A hard link to the file ``path`` names now (or a copy where links are not allowed), beside it, to put back
    if a later output cannot be moved into place; None when there is no file."""
    if not os.path.lexists(path):
        return None
    folder = path.parent if str(path.parent) else Path(".")
    fd, backup = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=".old", dir=folder)
    os.close(fd)
    os.unlink(backup)
    try:
        os.link(path, backup, follow_symlinks=False)
    except OSError:
        import shutil

        shutil.copy2(path, backup, follow_symlinks=False)
    return backup


def atomic_write_text(path: str | Path, text: str) -> None:
    atomic_write(path, lambda p: p.write_text(text, encoding="utf-8"))


def check_output_path(path: str | Path | None, field: str, suffixes: tuple[str, ...]) -> None:
    """:func:`check_output` under the name the batch commands use (``field`` names the output: ``out``,
    ``plot``...; the command line maps it to its flag)."""
    check_output(path, field, suffixes)


def put_back(moved) -> None:
    """Undo moves into place, the last first: each ``(path, backup)``'s backup back at ``path`` (the file it
    replaced), or no file where there was none; best effort (an error here leaves that path as it is)."""
    for path, backup in reversed(list(moved)):
        try:
            if backup is not None:
                os.replace(backup, path)
            else:
                os.unlink(path)
        except OSError:
            pass
