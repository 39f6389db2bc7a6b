"""A result store that resumes: one SQLite file, a table of runs keyed by the spec's hash.

Why SQLite: one file a user can copy, no server, and transactions: each finished run is one
``INSERT`` committed on its own (WAL journal, ``synchronous=FULL``), so killing the batch at any
moment leaves every committed run whole and no half-written row; a restart asks the store which keys
it has and runs only the rest. Many readers may read while the batch writes.

Tables: ``meta`` (store format, the locoplan version that created it), ``runs`` (key, a few columns to
filter on, the record as JSON), ``refs`` (per-group references computed once: E_min, the optimum).
A store of another format is refused (exit 2, naming it); :meth:`Store.check_writer` also refuses to
add runs of another locoplan version to a store (a resumed batch would mix two programs' results).
"""

from __future__ import annotations

import json
import sqlite3
import time
from pathlib import Path

from ..errors import InputError, Problem
from ..io.report import clean
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


class Store:
    """Open (or create) the store at ``path``. ``create=False``: the file must exist (``results``)."""

    def __init__(self, path: str | Path, create: bool = True) -> None:
        self.path = Path(path)
        name = str(self.path)
        if not create and not self.path.is_file():
            raise InputError(Problem(name, "", "no such store"))
        folder = self.path.parent if str(self.path.parent) else Path(".")
        if not folder.is_dir() and create:  # a new store's folder is created (the rule for every output)
            from ..io.report import existing_folder, make_folder

            existing_folder(folder, name, "")
            make_folder(folder, name)
        fresh = not self.path.exists() or self.path.stat().st_size == 0
        try:
            self.conn = sqlite3.connect(str(self.path), timeout=60.0, isolation_level=None)
            self.conn.execute("PRAGMA journal_mode=WAL")
            self.conn.execute("PRAGMA synchronous=FULL")
            tables = {r[0] for r in self.conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        except sqlite3.DatabaseError as exc:
            raise InputError(Problem(name, "", f"not a locoplan result store (SQLite says: {exc})")) from None
        if fresh or not tables:
            from .. import __version__

            with self._transaction():
                for stmt in _SCHEMA.strip().split(";"):
                    if stmt.strip():
                        self.conn.execute(stmt)
                self.conn.execute("INSERT OR REPLACE INTO meta VALUES ('format', ?)", (str(STORE_FORMAT),))
                self.conn.execute("INSERT OR REPLACE INTO meta VALUES ('locoplan', ?)", (__version__,))
                self.conn.execute("INSERT OR REPLACE INTO meta VALUES ('created_utc', ?)", (_now(),))
        elif "meta" not in tables:
            raise InputError(Problem(name, "", "not a locoplan result store (no meta table)"))
        self.meta = dict(self.conn.execute("SELECT name, value FROM meta"))
        if self.meta.get("format") != str(STORE_FORMAT):
            raise InputError(Problem(name, "format", f"store format {self.meta.get('format')!r} (written by locoplan "
                                     f"{self.meta.get('locoplan', '?')}); this locoplan reads format {STORE_FORMAT}: "
                                     "export it with the locoplan that wrote it, or start a new store"))

    def _transaction(self):
        conn = self.conn

        class _Tx:
            def __enter__(self):
                conn.execute("BEGIN IMMEDIATE")

            def __exit__(self, kind, *_):
                conn.execute("COMMIT" if kind is None else "ROLLBACK")
        return _Tx()

    def check_writer(self) -> None:
        """Refuse to add this locoplan's runs to a store another locoplan version began."""
        from .. import __version__

        if self.meta.get("locoplan") != __version__:
            raise InputError(Problem(str(self.path), "locoplan", f"store begun by locoplan {self.meta.get('locoplan')}, "
                                     f"this is {__version__}: its runs would mix two versions' results; "
                                     "start a new store (or finish it with that version)"))

    # ---------------------------------------------------------------- runs
    def keys(self) -> set[str]:
        return {r[0] for r in self.conn.execute("SELECT key FROM runs")}

    def put(self, record: RunRecord) -> bool:
        """Commit one run (one transaction). False if the key was already there (nothing written)."""
        s = record.summary
        with self._transaction():
            cur = self.conn.execute(
                "INSERT OR IGNORE INTO runs VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                (record.key, s.get("route"), s.get("consist"), s.get("strategy"), s.get("algorithm"), s.get("seed"),
                 s.get("planned_time_s"), None if s.get("feasible") is None else int(bool(s["feasible"])),
                 s.get("running_time_s"), s.get("traction_energy_kwh"),
                 json.dumps(clean(record.to_json()), allow_nan=False, default=str), _now()))
        return cur.rowcount == 1

    def get(self, keys: list[str]) -> dict[str, RunRecord]:
        out = {}
        for i in range(0, len(keys), 500):
            chunk = keys[i:i + 500]
            q = f"SELECT key, record FROM runs WHERE key IN ({','.join('?' * len(chunk))})"
            for k, text in self.conn.execute(q, chunk):
                out[k] = RunRecord.from_json(json.loads(text))
        return out

    def records(self) -> list[RunRecord]:
        """Every run, in the order they finished."""
        return [RunRecord.from_json(json.loads(t)) for (t,) in self.conn.execute("SELECT record FROM runs ORDER BY rowid")]

    def __len__(self) -> int:
        return int(self.conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0])

    # ---------------------------------------------------------------- references (E_min, optimum)
    def refs(self, kind: str) -> dict[str, tuple[float | None, str | None]]:
        return {k: (v, n) for k, v, n in self.conn.execute("SELECT key, value, note FROM refs WHERE kind = ?", (kind,))}

    def put_ref(self, key: str, kind: str, value: float | None, note: str | None = None) -> None:
        with self._transaction():
            self.conn.execute("INSERT OR REPLACE INTO refs VALUES (?,?,?,?)", (key, kind, value, note))

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
