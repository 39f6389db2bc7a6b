"""What ``locoplan results`` does with a store: filter, export, summarise, plot (never a re-run).

Rows are :meth:`RunRecord.row` dicts: the ``--json`` summary's field names (``route``, ``strategy``,
``algorithm``, ``seed``, ``planned_time_s``, ``running_time_s``, ``traction_energy_kwh``, ...) plus
``kind`` (``route`` or ``journey``), ``key``, ``route_file``, ``route_sha``, ``consist_sha`` (the contents' hashes),
``time_spec``, ``verdict``, ``wall_time_s``, ``worker``, ``locoplan_version``; a journey run's row has the journey's totals (``journey``,
``optimum_kwh``, ``legs``, ``windows_missed``, ...) and ``journey_file``.
"""

from __future__ import annotations

import csv
import io
import json
import math
import operator
import re
import textwrap
from pathlib import Path

import numpy as np

from ..errors import InputError, Problem
from ..reporting.files import atomic_write
from ..reporting.writers import clean, csv_row, to_json, with_provenance

FORMATS = ("csv", "parquet", "json")
_OPS = {"<=": operator.le, ">=": operator.ge, "!=": operator.ne, "=": operator.eq, "<": operator.lt, ">": operator.gt,
        "~": lambda x, v: str(v) in str(x)}
_WHERE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=|!=|=|<|>|~)\s*(.*?)\s*$")
DEFAULT_BY = ("route", "consist", "planned_time_s", "strategy", "algorithm")
JOURNEY_BY = ("kind", "journey")
"""Grouped by first as well when journey runs are among the rows (a journey and a route on one line apart)."""


def default_by(rows: list[dict]) -> list[str]:
    """The summary's groups when none are asked for: ``DEFAULT_BY``, after ``JOURNEY_BY`` when any row is a
    journey run's."""
    return [*JOURNEY_BY, *DEFAULT_BY] if any(r.get("kind") == "journey" for r in rows) else list(DEFAULT_BY)


def parse_where(conditions: list[str], fields: set[str]):
    """``FIELD OP VALUE`` (OP one of = != < <= > >=, or ~ for 'contains'; VALUE a number, true/false/null,
    or text), all of
    which must hold. Returns a predicate on rows; an unknown field or a malformed condition is an
    InputError naming it."""
    tests = []
    for text in conditions:
        m = _WHERE.match(text)
        if not m:
            raise InputError(Problem("", "where", f"expected FIELD OP VALUE with OP one of = != < <= > >= ~ (got {text!r})"))
        name, op, raw = m.groups()
        if fields and name not in fields:
            raise InputError(Problem("", "where", f"unknown field {name!r} (fields: {', '.join(sorted(fields))})"))
        if not raw.strip():
            raise InputError(Problem("", "where", f"{text!r} has no value after {op!r}: write FIELD OP VALUE (null for none)"))
        value = raw.strip("'\"") if op == "~" else _value(raw)
        if isinstance(value, float) and not math.isfinite(value):  # nan compares false with everything, inf is no bound
            raise InputError(Problem("", "where", f"{text!r}: {raw.strip()!r} is not a finite number, so the condition "
                                     "would keep every run or none"))
        if op in _ORDER and isinstance(value, str) and (m_unit := _WITH_UNIT.match(value)):
            raise InputError(Problem("", "where", f"{text!r}: {value!r} is a number with a unit; write the number alone, "
                                     f"{name}{op}{m_unit.group(1)} (the field's unit is in its name: _s seconds, _kwh "
                                     "kWh, _m metres, ...)"))
        tests.append((name, _OPS[op], value, op, raw.strip().strip("'\""), text))

    def keep(row: dict) -> bool:
        for name, fn, value, op, written, text in tests:
            x = row.get(name)
            if x is None or value is None:
                if not ((x is None) == (value is None) if op == "=" else (x is None) != (value is None) if op == "!=" else False):
                    return False
                continue
            if op == "~":
                if not fn(x, value):
                    return False
                continue
            number = isinstance(x, (int, float)) and not isinstance(x, bool)
            if number and not isinstance(value, (int, float)):  # never numbers compared as text ('1000' < '200')
                raise InputError(Problem("", "where", f"{text!r}: {name} is a number (e.g. {x:g}), and {written!r} is "
                                         "not one: write a number"))
            if isinstance(x, str) and not isinstance(value, str):
                if op not in ("=", "!="):
                    raise InputError(Problem("", "where", f"{text!r}: {name} is text (e.g. {x!r}): compare it with = != "
                                             "or ~ (contains), not with a number"))
                value = written  # a route named '100' is the text as written
            try:
                if not fn(x, value):
                    return False
            except TypeError:  # a list or a mapping against a value: no order between them
                raise InputError(Problem("", "where", f"{text!r}: {name} holds {type(x).__name__} values, which "
                                         f"{op!r} cannot compare with {written!r}; use ~ (contains)")) from None
        return True
    return keep


_ORDER = ("<", "<=", ">", ">=")
_WITH_UNIT = re.compile(r"^([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([A-Za-z%][A-Za-z/%.]*)$")
"""A number followed by a unit (``1000s``, ``25 min``, ``1.5kWh``): refused in a comparison (the unit is in the field's
name), never compared as text."""


def _value(raw: str):
    low = raw.lower()
    if low in ("true", "false"):
        return low == "true"
    if low in ("null", "none"):
        return None
    try:
        return float(raw)
    except ValueError:
        return raw.strip("'\"")


def rows_of(records, where: list[str] | None = None) -> list[dict]:
    rows = [r.row() for r in records]
    if where:
        fields = set().union(*(r.keys() for r in rows)) if rows else set()
        keep = parse_where(where, fields)
        rows = [r for r in rows if keep(r)]
    return rows


SUMMARY_FIELDS = ("feasible", "punctual", "traction_energy_kwh", "running_time_s", "gap_to_optimum_percent", *JOURNEY_BY,
                  "kind", "route", "consist", "route_sha", "consist_sha")
"""The fields :func:`summarize_rows` reads besides its ``by`` fields."""

PLOT_FIELDS = ("feasible", "route", "journey", "consist", "planned_time_s", "strategy", "algorithm", "running_time_s",
               "traction_energy_kwh")
"""The fields the plots of ``locoplan results`` read (``reporting/plot_runs.py``)."""


def iter_rows(records, where: list[str] | None = None, seen: set[str] | None = None):
    """The rows of ``records`` (read one at a time) that pass ``where``; every field name met goes into ``seen``."""
    keep = parse_where(where, set()) if where else None
    for r in records:
        row = r.row()
        if seen is not None:
            seen.update(row)
        if keep is None or keep(row):
            yield row


def stream_rows(records, where: list[str] | None = None, fields=None, on_row=None) -> tuple[list[dict], set[str]]:
    """As :func:`rows_of`, over an iterable of records read one at a time (a store of any size), keeping of
    each row only ``fields`` if given (a summary needs a few of a row's 35), and handing each whole row to
    ``on_row`` (an export's first pass, :class:`ExportShape`); also returns every field name seen (a
    ``--where`` or ``--by`` naming none of them is an InputError)."""
    seen: set[str] = set()
    out = []
    for row in iter_rows(records, where, seen):
        if on_row is not None:
            on_row(row)
        out.append({k: row.get(k) for k in fields} if fields is not None else row)
    for text in where or ():
        name = _WHERE.match(text).group(1)
        if seen and name not in seen:
            raise InputError(Problem("", "where", f"unknown field {name!r} (fields: {', '.join(sorted(seen))})"))
    return out, seen


def _flat(value):
    """A cell of a CSV / Parquet column: lists and dicts as JSON text."""
    return json.dumps(clean(value)) if isinstance(value, (list, dict)) else value


def export(rows: list[dict], path: str | Path | None, fmt: str) -> str | None:
    """Write ``rows`` as ``fmt`` to ``path`` (atomically), or return the text for stdout (csv, json)."""
    check_format(fmt, path)
    shape = ExportShape(fmt)
    for r in rows:
        shape.add(r)
    if path is None:
        buf = io.StringIO()
        write_export(rows, shape, buf)
        return buf.getvalue()
    export_to_file(rows, shape, path)
    return None


def check_format(fmt: str, path: str | Path | None) -> None:
    """An export format ``locoplan results`` writes, to a file or (csv, json) to stdout."""
    if fmt not in FORMATS:
        raise InputError(Problem("", "format", f"unknown format {fmt!r} (one of: {', '.join(FORMATS)})"))
    if fmt == "parquet":
        if path is None:
            raise InputError(Problem("", "out", "Parquet is binary: give a file with --out"))
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise InputError(Problem("", "format", "Parquet needs pyarrow: pip install 'locoplan[parquet]'")) from None


class ExportShape:
    """What an export's head needs, gathered in a first pass over the rows, so that the second pass can
    write them one at a time (an export of any size in bounded memory): the number of rows, the columns
    in order of first appearance (a CSV's after splitting ``weights`` and ``window_s``) and, for Parquet,
    the Python types each column holds (its Arrow type)."""

    def __init__(self, fmt: str, source: str = "<rows>"):
        self.fmt, self.source = fmt, source
        self.rows = 0
        self._cols: dict[str, None] = {}
        self._kinds: dict[str, set[type]] = {}

    def add(self, row: dict) -> None:
        self.rows += 1
        if self.fmt == "csv":
            self._cols.update(dict.fromkeys(csv_row(row)))
            return
        self._cols.update(dict.fromkeys(row))
        if self.fmt == "parquet":
            for k, v in row.items():
                self._kinds.setdefault(k, set()).add(type(_flat(clean(v))))

    @property
    def columns(self) -> list[str]:
        return list(self._cols)

    def changed(self) -> InputError:
        """The rows of the second pass are not those of the first."""
        return InputError(Problem(self.source, "", "the store changed while it was exported (a run was replaced or "
                                  "removed): nothing was written; run the same command again"))

    def arrow_schema(self):
        """Each column's type as pyarrow infers it from the whole column: null, bool, int64, double (ints
        and floats), string; a column that mixes text with numbers or booleans is written as text."""
        import pyarrow as pa

        fields = []
        for c in self._cols:
            kinds = self._kinds.get(c, set()) - {type(None)}
            if not kinds:
                kind = pa.null()
            elif kinds == {bool}:
                kind = pa.bool_()
            elif kinds == {int}:
                kind = pa.int64()
            elif kinds <= {int, float}:
                kind = pa.float64()
            else:
                kind = pa.string()
            fields.append(pa.field(c, kind))
        return pa.schema(fields)


PARQUET_ROW_GROUP = 10_000
"""Rows per Parquet row group (the rows of one group are held in memory while it is written)."""


def export_to_file(rows, shape: ExportShape, path: str | Path) -> None:
    """Write ``rows`` (an iterable, read once) to ``path`` as ``shape.fmt``, atomically (``atomic_write``)."""
    if shape.fmt == "parquet":
        atomic_write(path, lambda p: _write_parquet(rows, shape, p))
    else:
        atomic_write(path, lambda p: _write_text(rows, shape, p))


def _write_text(rows, shape: ExportShape, path: Path) -> None:
    with open(path, "w", encoding="utf-8", newline="") as fh:
        write_export(rows, shape, fh)


def write_export(rows, shape: ExportShape, stream) -> None:
    """Write ``rows`` (an iterable, read once) to a text ``stream`` as CSV or JSON, a row at a time: the
    same text as the whole export made at once (one JSON object, ``{"results": [...]`` with the
    provenance fields after it)."""
    n = 0
    if shape.fmt == "csv":  # numbers, true/false, empty cells; weights and window as columns of their own
        w = csv.DictWriter(stream, fieldnames=shape.columns, lineterminator="\n", restval="")
        w.writeheader()
        for r in rows:
            flat = csv_row(r)
            if not flat.keys() <= shape._cols.keys():
                raise shape.changed()
            w.writerow(flat)
            n += 1
    else:
        if shape.rows == 0:
            stream.write(to_json(with_provenance({"results": []})) + "\n")
            return
        mark = "\u0000locoplan-rows"
        head, tail = to_json(with_provenance({"results": [mark]})).split(f"    {json.dumps(mark)}")
        stream.write(head)
        for r in rows:
            stream.write(("" if n == 0 else ",\n") + textwrap.indent(to_json(r), "    "))
            n += 1
        stream.write(tail + "\n")
    if n != shape.rows:
        raise shape.changed()


def _write_parquet(rows, shape: ExportShape, path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = shape.arrow_schema()
    text = {c for c in shape.columns if schema.field(c).type == pa.string()}
    n = 0
    with pq.ParquetWriter(path, schema) as writer:
        group: list[dict] = []

        def cell(row: dict, c: str):
            value = _flat(clean(row.get(c)))
            return json.dumps(value) if c in text and value is not None and not isinstance(value, str) else value

        def flush() -> None:
            writer.write_table(pa.table({c: [cell(r, c) for r in group] for c in shape.columns}, schema=schema))
            group.clear()

        for r in rows:
            if not r.keys() <= shape._cols.keys():
                raise shape.changed()
            group.append(r)
            n += 1
            if len(group) == PARQUET_ROW_GROUP:
                flush()
        if group or n == 0:
            flush()
    if n != shape.rows:
        raise shape.changed()


def _stats(values: list[float]) -> tuple[float | None, float | None, float | None]:
    if not values:
        return None, None, None
    a = np.array(values, dtype=float)
    return round(float(a.mean()), 3), round(float(a.min()), 3), round(float(a.std(ddof=1)), 3) if len(a) > 1 else 0.0


def _group_order(key: tuple) -> tuple:
    """Groups in order of their fields: numbers by value, then text, then null (a field that is a number in
    one group and text in another sorts, never raises)."""
    return tuple((x is None, not isinstance(x, (int, float)), x if isinstance(x, (int, float)) else str(x)) for x in key)


CONTENT_OF = {"route": "route_sha", "journey": "route_sha", "consist": "consist_sha"}
"""The fields that name an input, and the field holding the content hash of what they named in each run."""


def two_contents(rows: list[dict]) -> dict[tuple[str, str], list[str]]:
    """The names that covered more than one content among ``rows`` (a route edited between two batches, two files
    of one name): {(field, name): [content hashes]} (runs stored before contents were recorded count as one
    content of their own only where no other is known)."""
    seen: dict[tuple[str, str], set] = {}
    for r in rows:
        for f, sha in CONTENT_OF.items():
            if r.get(f) is not None and r.get(sha) is not None and (f != "route" or r.get("kind", "route") == "route"):
                seen.setdefault((f, str(r[f])), set()).add(r[sha])
    return {k: sorted(v) for k, v in seen.items() if len(v) > 1}


def summarize_rows(rows: list[dict], by: list[str] | None = None) -> list[dict]:
    """One row per group of ``by`` fields (None: :func:`default_by`): runs, feasible and punctual runs, energy mean / best / sd,
    time mean / sd (over the feasible runs), and the gap to the optimum (mean, best) where the records
    have one (``gap_to_optimum_percent``; none until an optimum is known). Runs are grouped by what they ran, not
    by its name: where a route, journey or consist name covered two contents (``two_contents``), each content is a
    group of its own, named ``NAME @ HASH`` (the first 8 digits of its content hash)."""
    by = default_by(rows) if by is None else by
    split = two_contents(rows)

    def value(r: dict, k: str):
        v = r.get(k)
        sha = CONTENT_OF.get(k)
        if sha is not None and v is not None and (k, str(v)) in split:
            return f"{v} @ {str(r.get(sha))[:8]}"
        return v

    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(value(r, k) for k in by), []).append(r)
    out = []
    for key in sorted(groups, key=_group_order):
        rs = groups[key]
        ok = [r for r in rs if r.get("feasible")]
        e_mean, e_best, e_sd = _stats([r["traction_energy_kwh"] for r in ok])
        t_mean, _, t_sd = _stats([r["running_time_s"] for r in ok])
        gaps = [r["gap_to_optimum_percent"] for r in ok if r.get("gap_to_optimum_percent") is not None]
        g_mean, g_best, _ = _stats(gaps)
        out.append({**dict(zip(by, key)), "runs": len(rs), "feasible_runs": len(ok),
                    "punctual_runs": sum(1 for r in ok if r.get("punctual")),
                    "energy_mean_kwh": e_mean, "energy_best_kwh": e_best, "energy_sd_kwh": e_sd,
                    "time_mean_s": t_mean, "time_sd_s": t_sd, "gap_mean_percent": g_mean, "gap_best_percent": g_best})
    return out
