"""A result store that resumes: one SQLite file, a table of runs keyed by the spec's hash.

Why SQLite: one file a user can copy, no server, and transactions: each finished run is one
``INSERT`` committed on its own (WAL journal, ``synchronous=FULL``), so killing the batch at any
moment leaves every committed run whole and no half-written row; a restart asks the store which keys
it has and runs only the rest. Many readers may read while the batch writes. After each commit the
journal is checkpointed into the file (and truncated on close), so the ``.sqlite`` file alone holds
every committed run even after a kill.

Tables: ``meta`` (store format, the locoplan version that created it), ``runs`` (key, a few columns to
filter on, the record as JSON), ``refs`` (per-group references computed once: E_min, the optimum).
A store of another format is refused (exit 2, naming it); :meth:`Store.check_writer` also refuses to
add runs of another locoplan version to a store (a resumed batch would mix two programs' results), and
a second writer while one batch holds the store (it would compute every run twice).

Every SQLite failure after opening (a full disk, a read-only file, a damaged file, a dropped table) is an
:class:`~locoplan.errors.InputError` that names the store, says what SQLite found and how to go on; a
damaged record (broken JSON, missing fields, a summary field of the wrong type) is set aside in
:attr:`Store.damaged` with what is wrong, and the other records stay usable (``batch`` runs the damaged ones
again and writes them over). A damaged file: ``results`` reads the runs outside its bad pages and names the
row ids it cannot read; ``batch`` refuses it (a write could spread the damage). A store file removed or
replaced while a batch writes stops the batch at its next commit; a new store that cannot be made leaves
no file.
"""

from __future__ import annotations

import errno
import fcntl
import json
import math
import os
import shlex
import sqlite3
import stat
import time
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import quote

from .. import __version__
from ..errors import InputError, Problem
from ..reporting.files import existing_folder, make_folder
from ..reporting.writers import clean
from .spec import RunRecord

STORE_FORMAT = 1
"""Bump when the tables change: older stores are then refused by name, never misread."""

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (name TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    key TEXT PRIMARY KEY,
    route TEXT, consist TEXT, strategy TEXT, algorithm TEXT, seed INTEGER, planned_time_s REAL,
    feasible INTEGER, running_time_s REAL, traction_energy_kwh REAL,
    record TEXT NOT NULL,
    finished_utc TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS refs (key TEXT PRIMARY KEY, kind TEXT NOT NULL, value REAL, note TEXT);
"""
_TABLES = ("meta", "runs", "refs")

_KEEP = "the runs committed so far are kept"


def _why(exc: sqlite3.Error, writing: bool, store: str = "STORE") -> str:
    """What an SQLite failure means for the user, and what to do."""
    text = str(exc)
    low = text.lower()
    go_on = "run the same command again to continue (it runs only what the store lacks)" if writing else "run it again"
    if "full" in low:
        return f"the disk holding the store is full (SQLite: {text}); {_KEEP}: free some space and {go_on}"
    if "readonly" in low or "read-only" in low:
        return (f"the store cannot be written (SQLite: {text}): the file or its folder is read-only; {_KEEP}: "
                f"make it writable, or copy it to a writable place, and {go_on}")
    if "malformed" in low or "not a database" in low or "corrupt" in low:
        if writing:
            return (f"the store file is damaged (SQLite: {text}), and batch does not write into a damaged file: "
                    f"'locoplan results {shlex.quote(store)}' shows the runs still readable; run the batch into a new "
                    "store (another --store)")
        return (f"the store file is damaged (SQLite: {text}) and no run in it can be read; "
                "run the batch again into a new store")
    if "no such table" in low or "no such column" in low:
        return f"not a locoplan result store, or a damaged one (SQLite: {text}); start a new store"
    if "locked" in low or "busy" in low:
        return f"the store is locked by another process (SQLite: {text}); wait for it to finish, or use another store"
    if "disk i/o" in low or "unable to open" in low:
        return (f"the store cannot be used (SQLite: {text}): an I/O error (a full disk, a device, a vanished "
                f"file?); {_KEEP}; check the disk and {go_on}")
    return f"the store failed (SQLite: {text})"


_NUMBER = (int, float)
_SUMMARY_TYPES = {
    **dict.fromkeys(("route", "consist", "strategy", "algorithm", "reason", "plan", "kind", "journey", "e_min_source"),
                   (str,)),
    **dict.fromkeys(("feasible", "punctual"), (bool,)),
    **dict.fromkeys(("running_time_s", "traction_energy_kwh", "planned_time_s", "punctuality_error_s", "fitness",
                     "gap_to_optimum_percent", "gap_to_optimum_kwh", "optimum_kwh", "optimum_accuracy_percent",
                     "e_min_kwh", "cruise_kmh", "solve_time_s", "equal_supplements_kwh", "dwell_s",
                     "fastest_running_time_s", "e_min_time_s"), _NUMBER),
    **dict.fromkeys(("seed", "n_evaluations", "legs", "stops", "timing_points", "windows"), (int,)),
    **dict.fromkeys(("window_s", "weights", "switching_points_m", "sequence", "windows_missed", "failures", "legs_table",
                     "stations", "allocations", "release_margins"), (list,)),
}
"""The JSON type of each summary field locoplan writes (each may also be null); a stored value of another
type (text for an energy, a number for a route, ``NaN``) makes the record damaged, so no summary, sort or
export meets it."""
_KIND = {str: "text", bool: "true/false", int: "an integer", float: "a number", list: "a list", dict: "a JSON object",
         type(None): "null"}


def _wrong(value, kinds: tuple) -> str | None:
    """None if ``value`` is one of ``kinds`` (a number finite, and no boolean), else what is wrong with it."""
    numeric = int in kinds or float in kinds
    if isinstance(value, bool):
        ok = bool in kinds
    elif isinstance(value, float) and float in kinds:
        if not math.isfinite(value):
            return f"is {value!r}, not a finite number"
        ok = True
    else:
        ok = isinstance(value, kinds) and not (isinstance(value, float) and float not in kinds)
    if ok:
        return None
    want = " or ".join(dict.fromkeys(_KIND[k] for k in kinds if not (numeric and k is int and float in kinds)))
    got = _KIND.get(type(value), type(value).__name__)
    return f"is {got} ({short(json.dumps(value, default=str), 30)}), expected {want}"


def _record_problem(raw) -> tuple[RunRecord | None, str | None]:
    """(record, None) or (None, what is wrong with the stored JSON)."""
    if not isinstance(raw, str):
        return None, f"the record is not JSON text (it is {type(raw).__name__})"
    try:
        data = json.loads(raw)
    except (ValueError, RecursionError) as exc:
        return None, f"the record is not valid JSON ({str(exc)[:80]})"
    if not isinstance(data, dict):
        return None, f"the record is not a JSON object (it is {type(data).__name__})"
    missing = [k for k in ("key", "summary", "spec", "wall_time_s", "versions", "worker") if k not in data]
    if missing:
        return None, f"the record lacks {', '.join(repr(k) for k in missing)}"
    for name, kinds in (("summary", (dict,)), ("spec", (dict,)), ("versions", (dict,)), ("key", (str,)),
                        ("worker", (str,)), ("wall_time_s", _NUMBER), ("cpu_time_s", _NUMBER + (type(None),)),
                        ("verdict", (str, type(None)))):
        if name in data and (why := _wrong(data[name], kinds)):
            return None, f"the record's {name!r} {why}"
    for name, value in data["summary"].items():
        kinds = _SUMMARY_TYPES.get(name)
        if kinds is not None and (why := _wrong(value, kinds + (type(None),))):
            return None, f"the record's summary.{name} {why}"
    if data["summary"].get("feasible") is True:
        lost = [n for n in ("running_time_s", "traction_energy_kwh") if data["summary"].get(n) is None]
        if lost:
            return None, f"the record's summary.{lost[0]} is missing or null, but the run is feasible (it has a time and an energy)"
    tags = data["spec"].get("tags")
    if tags is not None and not isinstance(tags, dict):
        return None, f"the record's spec.tags {_wrong(tags, (dict,))}"
    try:
        return RunRecord.from_json(data), None
    except (KeyError, TypeError, ValueError) as exc:
        return None, f"the record is incomplete ({exc.__class__.__name__}: {str(exc)[:80]})"


class Store:
    """Open (or create) the store at ``path``. ``create=False``: the file must exist, and it is opened
    read-only (``results``)."""

    def __init__(self, path: str | Path, create: bool = True) -> None:
        self.path = Path(path)
        self.name = name = str(self.path)
        self.writable = create
        self.damaged: dict[str, str] = {}
        """key (or 'rowid N' when the key itself is unreadable) -> what is wrong with that stored record."""
        self.replaced: dict[str, str] = {}
        """key -> what was wrong with the damaged record that :meth:`put` wrote over."""
        self.file_damaged = False
        """True once :meth:`iter_records` met damaged pages (their row ids are in :attr:`damaged`)."""
        self.last_rowid = -1
        """The highest row id :meth:`iter_records` has read (a second pass reads up to it)."""
        self._lock_fd: int | None = None
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            st = None
        except OSError as exc:
            raise InputError(Problem(name, "", f"cannot open the store: {exc.strerror or exc}")) from None
        if st is None and not create:
            raise InputError(Problem(name, "", "no such store"))
        if st is not None and stat.S_ISDIR(st.st_mode):
            raise InputError(Problem(name, "", "is a folder, not a store: name a file, e.g. "
                                     f"{self.path / 'runs.sqlite'}"))
        if st is not None and not stat.S_ISREG(st.st_mode):
            raise InputError(Problem(name, "", "is not a regular file (a device, a pipe or a socket): a store is an "
                                     "SQLite file with its journal beside it; name a file"))
        for suffix in ("-wal", "-shm", "-journal"):  # SQLite's files beside the store must be files too
            side = Path(name + suffix)
            try:
                side_mode = os.stat(side).st_mode
            except FileNotFoundError:
                continue
            except OSError as exc:
                raise InputError(Problem(name, "", f"cannot use its journal {side.name}: {exc.strerror or exc}")) from None
            if not stat.S_ISREG(side_mode):
                kind = "a folder" if stat.S_ISDIR(side_mode) else "not a regular file (a device, a pipe or a socket)"
                raise InputError(Problem(name, "", f"its journal {side} is {kind}: SQLite keeps a store's newest commits "
                                         f"in a file of that name beside it; move {side.name} away and run it again"))
        folder = self.path.parent if str(self.path.parent) else Path(".")
        if not folder.is_dir() and create:  # a new store's folder is created (the rule for every output)
            existing_folder(folder, name, "")
            make_folder(folder, name)
        if not folder.is_dir():
            raise InputError(Problem(name, "", f"folder {folder} does not exist"))
        if create and not os.access(folder, os.W_OK):
            raise InputError(Problem(name, "", f"folder {folder} is read-only: a store writes its file and its journal "
                                     "(-wal, -shm) there; choose a writable folder"))
        if create and st is not None and not os.access(self.path, os.W_OK):
            raise InputError(Problem(name, "", "the store file is read-only: batch adds runs to it; make it "
                                     "writable (chmod u+w), or read it with locoplan results"))
        fresh = st is None or st.st_size == 0
        try:
            try:
                if create:
                    self.conn = sqlite3.connect(name, timeout=60.0, isolation_level=None)
                    if fresh:  # an existing file is switched to WAL only once it is known to be a store (below)
                        self._wal()
                else:
                    self.conn = self._open_read_only(folder)
                tables = {r[0] for r in self.conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            except sqlite3.DatabaseError as exc:
                if "malformed" in str(exc) or isinstance(exc, sqlite3.OperationalError):
                    raise InputError(Problem(name, "", _why(exc, create, name))) from None
                raise InputError(Problem(name, "", f"not a locoplan result store (SQLite says: {exc})")) from None
            except sqlite3.Error as exc:
                raise InputError(Problem(name, "", _why(exc, create, name))) from None
            if create and (fresh or not tables):
                with self._transaction():
                    for stmt in _SCHEMA.strip().split(";"):
                        if stmt.strip():
                            self.conn.execute(stmt)
                    self.conn.execute("INSERT OR REPLACE INTO meta VALUES ('format', ?)", (str(STORE_FORMAT),))
                    self.conn.execute("INSERT OR REPLACE INTO meta VALUES ('locoplan', ?)", (__version__,))
                    self.conn.execute("INSERT OR REPLACE INTO meta VALUES ('created_utc', ?)", (_now(),))
                tables = set(_TABLES)
        except InputError:
            if st is None:  # a new store that could not be made (a full disk): nothing is left of it
                self._discard()
            raise
        if "meta" not in tables:
            raise InputError(Problem(name, "", "not a locoplan result store (no meta table)"))
        with self._sql():
            self.meta = {str(k): str(v) for k, v in self.conn.execute("SELECT name, value FROM meta")}
        if self.meta.get("format") != str(STORE_FORMAT):
            raise InputError(Problem(name, "format", f"store format {self.meta.get('format')!r} (written by locoplan "
                                     f"{self.meta.get('locoplan', '?')}); this locoplan reads format {STORE_FORMAT}: "
                                     "export it with the locoplan that wrote it, or start a new store"))
        missing = [t for t in _TABLES if t not in tables]
        if missing:
            raise InputError(Problem(name, "", f"a damaged locoplan result store: its {' and '.join(missing)} "
                                     f"table{'s are' if len(missing) > 1 else ' is'} missing (dropped?), so its runs "
                                     "are gone; start a new store"))
        if create and not fresh:  # batch never writes into a damaged file (a write could spread the damage)
            with self._sql(writing=True):
                found = [r[0] for r in self.conn.execute("PRAGMA quick_check(3)")]
            if found != ["ok"]:
                raise InputError(Problem(name, "", _why(sqlite3.DatabaseError(
                    f"database disk image is malformed: {short('; '.join(map(str, found)), 120)}"), True, name)))
        if create and not fresh:
            with self._sql(writing=True):
                self._wal()
        self._identity = _identity(self.path)
        """(device, inode) of the file opened: a store removed or replaced while a batch writes is noticed."""

    def _wal(self) -> None:
        """The write-ahead journal, and every commit synced (see the module's docstring). It stays with the file, so
        it is set only on a new store or one known to be a store: another program's SQLite file is left as it was."""
        self.conn.execute("PRAGMA journal_mode=WAL")
        self.conn.execute("PRAGMA synchronous=FULL")

    def _discard(self) -> None:
        conn = getattr(self, "conn", None)
        if conn is not None:
            conn.close()
        for p in (self.path, Path(self.name + "-wal"), Path(self.name + "-shm")):
            try:
                p.unlink()
            except OSError:
                pass

    def _still_there(self) -> None:
        """Refuse to go on writing to a store file that was removed or replaced since it was opened (SQLite
        would go on writing into the removed file, and every run since would be lost without a word)."""
        if self.writable and _identity(self.path) != self._identity:
            raise InputError(Problem(self.name, "", "the store file was removed or replaced while this batch wrote to "
                                     "it (the run just finished went into the removed file); the runs in the file now "
                                     "there are kept: run the same command again to continue"))

    def _open_read_only(self, folder: Path) -> sqlite3.Connection:
        """A read-only connection; in a read-only folder (no -shm can be made) the file is read as it is."""
        uri = "file:" + _uri_path(self.path)
        conn = sqlite3.connect(uri + "?mode=ro", uri=True, timeout=60.0, isolation_level=None)
        try:
            conn.execute("SELECT name FROM sqlite_master").fetchall()
            return conn
        except sqlite3.OperationalError as exc:
            conn.close()
            # a read-only folder, or a full disk: SQLite cannot make the -shm index a reader of a WAL store needs
            no_room = any(w in str(exc).lower() for w in ("disk i/o", "full"))
            if os.access(folder, os.W_OK) and not no_room:
                raise
            where = f"the disk is full (SQLite: {exc})" if no_room else f"its folder {folder} is read-only"
        wal = Path(self.name + "-wal")
        if wal.exists() and wal.stat().st_size > 0:
            raise InputError(Problem(self.name, "", f"the store's newest runs are still in its journal {wal.name}, and "
                                     f"{where}, so SQLite cannot read them: free some space, or copy the store with its "
                                     "-wal file to a writable place"))
        return sqlite3.connect(uri + "?mode=ro&immutable=1", uri=True, isolation_level=None)

    @contextmanager
    def _sql(self, writing: bool = False):
        """Every SQLite failure as an InputError naming the store, what SQLite found and how to go on."""
        try:
            yield
        except sqlite3.Error as exc:
            raise InputError(Problem(self.name, "", _why(exc, writing, self.name))) from None

    def _transaction(self):
        conn, store = self.conn, self

        class _Tx:
            def __enter__(self):
                try:
                    conn.execute("BEGIN IMMEDIATE")
                except sqlite3.Error as exc:
                    raise InputError(Problem(store.name, "", _why(exc, True, store.name))) from None

            def __exit__(self, kind, exc, tb):
                try:
                    conn.execute("COMMIT" if kind is None else "ROLLBACK")
                except sqlite3.Error as err:
                    if kind is None:
                        try:
                            conn.execute("ROLLBACK")
                        except sqlite3.Error:
                            pass
                        raise InputError(Problem(store.name, "", _why(err, True, store.name))) from None
                if isinstance(exc, sqlite3.Error):
                    raise InputError(Problem(store.name, "", _why(exc, True, store.name))) from None
                return False
        return _Tx()

    def check_writer(self) -> None:
        """Refuse to add this locoplan's runs to a store another locoplan version began, or that another
        process is adding runs to (a lock on the file, released by the system when that process ends,
        even by kill -9)."""
        if self.meta.get("locoplan") != __version__:
            raise InputError(Problem(str(self.path), "locoplan", f"store begun by locoplan {self.meta.get('locoplan')}, "
                                     f"this is {__version__}: its runs would mix two versions' results; "
                                     "start a new store (or finish it with that version)"))
        if self._lock_fd is None:
            try:
                fd = os.open(self.path, os.O_RDONLY | os.O_CLOEXEC)
            except OSError as exc:
                raise InputError(Problem(self.name, "", f"cannot open the store to lock it: {exc.strerror or exc}")) from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                    self._lock_fd = fd  # a file system without locks (some network mounts): go on unguarded
                    return
                os.close(fd)
                raise InputError(Problem(self.name, "", "another locoplan batch is adding runs to this store now: two "
                                         "would compute every run twice; wait for it to finish (then this command "
                                         "runs only what is left), or use another store")) from None
            self._lock_fd = fd

    # ---------------------------------------------------------------- runs
    def keys(self) -> set[str]:
        with self._sql():
            return {str(r[0]) for r in self.conn.execute("SELECT key FROM runs")}

    def put(self, record: RunRecord) -> bool:
        """Commit one run (one transaction). False if the key was already there (nothing written); a
        damaged record under the same key is written over."""
        s = record.summary
        verb = "INSERT OR REPLACE" if record.key in self.damaged else "INSERT OR IGNORE"
        with self._transaction():
            cur = self.conn.execute(
                f"{verb} INTO runs VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                (record.key, s.get("route"), s.get("consist"), s.get("strategy"), s.get("algorithm"), s.get("seed"),
                 s.get("planned_time_s"), None if s.get("feasible") is None else int(bool(s["feasible"])),
                 s.get("running_time_s"), s.get("traction_energy_kwh"),
                 json.dumps(clean(record.to_json()), allow_nan=False, default=str), _now()))
        self._still_there()
        if record.key in self.damaged:
            self.replaced[record.key] = self.damaged.pop(record.key)
        self._checkpoint()
        return cur.rowcount == 1

    def _checkpoint(self) -> None:
        """Copy the journal's commits into the store file (PASSIVE: never waits for a reader), so that the
        file alone holds them, also after a kill."""
        try:
            self.conn.execute("PRAGMA wal_checkpoint(PASSIVE)").fetchall()
        except sqlite3.Error:
            pass  # a later checkpoint (or the next open) does it; the commit itself is safe in the journal

    def _parsed(self, rows) -> dict[str, RunRecord]:
        out: dict[str, RunRecord] = {}
        for rowid, key, text in rows:
            record, why = _record_problem(text)
            label = str(key) if isinstance(key, str) and key else f"rowid {rowid}"
            if record is None:
                self.damaged[label] = why
            elif record.key != key:
                self.damaged[label] = f"the record's own key is {short(record.key)!r}, not its row's"
            else:
                out[key] = record
        return out

    def get(self, keys: list[str]) -> dict[str, RunRecord]:
        """The stored records of ``keys`` (those it has and can read; damaged ones go to :attr:`damaged`)."""
        out: dict[str, RunRecord] = {}
        with self._sql():
            for i in range(0, len(keys), 500):
                chunk = keys[i:i + 500]
                q = f"SELECT rowid, key, record FROM runs WHERE key IN ({','.join('?' * len(chunk))})"
                out.update(self._parsed(self.conn.execute(q, chunk)))
        return out

    def iter_records(self, chunk: int = 1000, upto: int | None = None):
        """Every readable run, in the order they finished, ``chunk`` rows at a time (memory stays bounded
        on a store of any size); damaged records go to :attr:`damaged`. With ``upto``, only the rows up to
        that row id (those a first pass read: :attr:`last_rowid`, the highest row id read so far)."""
        last, good = -1, 0
        top = (1 << 63) - 1 if upto is None else upto
        while True:
            try:
                rows = self.conn.execute("SELECT rowid, key, record FROM runs WHERE rowid > ? AND rowid <= ? ORDER BY rowid "
                                         "LIMIT ?", (last, top, chunk)).fetchall()
            except sqlite3.DatabaseError as exc:
                if self.writable or "malformed" not in str(exc):
                    raise InputError(Problem(self.name, "", _why(exc, self.writable, self.name))) from None
                rows, last = self._salvage(last, chunk, exc, good, top)
                if rows is None:
                    return
            else:
                if not rows:
                    return
                last = rows[-1][0]
            self.last_rowid = max(self.last_rowid, last)
            parsed = self._parsed(rows)
            good += len(parsed)
            yield from parsed.values()

    _SALVAGE_SPAN = 10_000_000
    """At most this many row ids are probed one by one past a damaged part of the file."""

    def _salvage(self, last: int, chunk: int, exc: sqlite3.Error, good: int, upto: int):
        """Reading a damaged file (``results``): the rows after ``last`` one row id at a time, so the runs
        outside the damaged pages stay usable; the row ids in damaged pages go to :attr:`damaged` as ranges.
        (rows, new last), or (None, last) at the end; the damage as an error when nothing is readable."""
        def refuse():
            return InputError(Problem(self.name, "", _why(exc, False, self.name)))
        try:
            top = self.conn.execute("SELECT max(rowid) FROM runs").fetchone()[0]
        except sqlite3.DatabaseError:
            raise refuse() from None
        if top is None or not isinstance(top, int) or top - last > self._SALVAGE_SPAN:
            raise refuse() from None
        top = min(top, upto)
        rows, rid, bad_from = [], last + 1, None

        def close_range(upto: int) -> None:
            span = f"rowid {bad_from}" if upto == bad_from else f"rowids {bad_from}..{upto}"
            self.damaged[span] = f"in a damaged part of the store file (SQLite: {exc}); the runs there cannot be read"
            self.file_damaged = True

        while rid <= top and len(rows) < chunk:
            try:
                row = self.conn.execute("SELECT rowid, key, record FROM runs WHERE rowid = ?", (rid,)).fetchone()
            except sqlite3.DatabaseError:
                if bad_from is None:
                    bad_from = rid
            else:
                if bad_from is not None:
                    close_range(rid - 1)
                    bad_from = None
                if row is not None:
                    rows.append(row)
            rid += 1
        if bad_from is not None:
            close_range(rid - 1)
        if not rows and rid > top:
            if good == 0:
                raise refuse() from None
            return None, last
        return rows, rid - 1

    def records(self) -> list[RunRecord]:
        """Every readable run, in the order they finished."""
        return list(self.iter_records())

    def __len__(self) -> int:
        with self._sql():
            return int(self.conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0])

    # ---------------------------------------------------------------- references (E_min, optimum)
    def refs(self, kind: str) -> dict[str, tuple[float | None, str | None]]:
        with self._sql():
            rows = self.conn.execute("SELECT key, value, note FROM refs WHERE kind = ?", (kind,)).fetchall()
        # a damaged reference is computed again rather than trusted
        return {k: (v, n) for k, v, n in rows if isinstance(k, str) and (v is None or isinstance(v, (int, float)))}

    def put_ref(self, key: str, kind: str, value: float | None, note: str | None = None) -> None:
        with self._transaction():
            self.conn.execute("INSERT OR REPLACE INTO refs VALUES (?,?,?,?)", (key, kind, value, note))
        self._still_there()
        self._checkpoint()

    def close(self) -> None:
        try:
            if self.writable:
                self.conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
        except sqlite3.Error:
            pass
        finally:
            self.conn.close()
            if self._lock_fd is not None:
                os.close(self._lock_fd)
                self._lock_fd = None

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def short(text: str, limit: int = 40) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _uri_path(path: Path) -> str:
    return quote(str(path.absolute()), safe="/")


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
