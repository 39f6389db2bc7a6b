"""Read route, vehicle and consist files into validated models; every problem names file, line and field."""

from __future__ import annotations

import codecs
import difflib
import json
import math
import os
import re
import stat
from contextlib import contextmanager
from contextvars import ContextVar
from importlib import resources
from pathlib import Path
from typing import Any, Optional

import yaml
from pydantic import BaseModel, ValidationError

from ..errors import InputError, Problem
from ..model.common import RuleViolations
from ..model.consist import Consist, Vehicle
from ..model.journey import Journey
from ..model.disturbance import Disturbance
from ..model.route import Route
from ..model.train import Train, build_train, shorter_than_train  # noqa: F401  (build_train: re-exported for the loaders' callers)

SCHEMAS: dict[str, type[BaseModel]] = {
    "locoplan/route@1": Route,
    "locoplan/vehicle@1": Vehicle,
    "locoplan/consist@1": Consist,
    "locoplan/journey@1": Journey,
    "locoplan/disturbance@1": Disturbance,
}

CATALOGUE = resources.files("locoplan.catalogue")
"""The shipped catalogue folder (``locoplan/catalogue``)."""


def _line_map(node: yaml.Node, path: tuple = (), out: dict | None = None) -> dict[tuple, int]:
    """Map each key path, e.g. ('speed_limits', 2, 'kmh'), to its 1-based line in the YAML text."""
    out = {} if out is None else out
    out.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for key, value in node.value:
            sub = path + (key.value,)
            out[sub] = key.start_mark.line + 1
            _line_map(value, sub, out)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            out[path + (i,)] = item.start_mark.line + 1
            _line_map(item, path + (i,), out)
    return out


def _duplicate_keys(node: yaml.Node, name: str, path: tuple = ()) -> list[Problem]:
    """Every key written twice in one mapping (YAML would silently keep the last one)."""
    out: list[Problem] = []
    if isinstance(node, yaml.MappingNode):
        seen: dict = {}
        for key, value in node.value:
            if not node.start_mark.index <= key.start_mark.index <= node.end_mark.index:
                continue  # brought in by a merge key ('<<: *x'): an explicit key may override it, as YAML says
            k = key.value
            if k in seen:
                out.append(Problem(name, field_name(path + (k,)),
                                   f"duplicate key: written on line {seen[k]} and again on line {key.start_mark.line + 1} "
                                   "(YAML would silently keep the last; remove one)", key.start_mark.line + 1))
            else:
                seen[k] = key.start_mark.line + 1
            out += _duplicate_keys(value, name, path + (k,))
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            out += _duplicate_keys(item, name, path + (i,))
    return out


def field_name(loc: tuple) -> str:
    """('speed_limits', 2, 'kmh') -> 'speed_limits[2].kmh'."""
    text = ""
    for part in loc:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def _line_for(lines: dict[tuple, int], loc: tuple) -> int | None:
    loc = tuple(loc)
    while loc not in lines and loc:
        loc = loc[:-1]
    return lines.get(loc)


# ------------------------------------------------------------------------------------------ reading
MAX_FILE_BYTES = 10 * 1024 * 1024
"""Largest input file read [bytes]: 10 MB holds a route of ~250,000 sections (20x the longest real line
shipped), and keeps a mistaken ``/dev/zero``-like input from filling the memory."""
MAX_DEPTH = 32
"""Deepest nesting of lists and mappings: every locoplan file needs 4 levels; Python's own recursion
(the YAML composer, pydantic) fails near 1,000."""
MAX_NODES = 100_000
"""Most values (YAML nodes, aliases expanded) in one file: the largest real line shipped holds about
2,500 (355 sections); 100,000 is 14,000 sections, and parsing and checking them takes seconds, not minutes."""
MAX_ALIAS_NODES = 100_000
"""Nodes that YAML aliases may add when expanded: an anchor reused a few times is fine, the 'billion
laughs' (9 levels of 9 aliases = 387 million nodes) is not."""
MAX_NUMBER_DIGITS = 30
"""Longest number literal: no physical quantity here needs more than 17 significant digits (a float's
precision); 5,000 digits is an attack on Python's integer parser, not a value."""

_NOT_REGULAR = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _kind_problem(name: str, mode: int) -> Problem | None:
    if stat.S_ISDIR(mode):
        return Problem(name, "", "is a folder, not a file")
    for test, kind in _NOT_REGULAR:
        if test(mode):
            return Problem(name, "", f"is {kind}, not a regular file (input files are read whole, so a stream cannot be one)")
    return None


def _too_big(name: str, size: int, limit: int) -> Problem:
    return Problem(name, "", f"is {size / 2**20:,.1f} MiB or more, larger than the {limit / 2**20:g} MiB limit for input "
                   "files (the longest real line shipped takes 0.1 MiB)")


def read_bytes(path: str | Path, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes. A missing file, a folder, a FIFO, a device,
    an unreadable or too large file raises ``InputError`` (never blocks: FIFOs are refused unopened)."""
    name = str(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(Problem(name, "", "no such file")) from None
    except OSError as exc:
        raise InputError(Problem(name, "", f"cannot read: {exc.strerror or exc}")) from None
    problem = _kind_problem(name, st.st_mode)
    if problem is None and st.st_size > limit:
        problem = _too_big(name, st.st_size, limit)
    if problem is not None:
        raise InputError(problem)
    try:
        # O_NONBLOCK: a FIFO put in the file's place after the stat cannot block the open
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as fh:
            problem = _kind_problem(name, os.fstat(fh.fileno()).st_mode)
            data = b"" if problem else fh.read(limit + 1)
    except OSError as exc:
        raise InputError(Problem(name, "", f"cannot read: {exc.strerror or exc}")) from None
    if problem is None and len(data) > limit:  # e.g. a /proc file, whose size says 0
        problem = _too_big(name, len(data), limit)
    if problem is not None:
        raise InputError(problem)
    _record_read(name, data)
    return data


# ------------------------------------------------------------------------------------------ provenance
_READS: ContextVar[Optional[dict]] = ContextVar("locoplan_input_files", default=None)


@contextmanager
def recording_reads():
    """Within this context every input file read (by :func:`read_bytes`, so every file locoplan reads) is
    recorded with its content hash; :func:`files_read` lists them. Contexts nest: each gets its own list."""
    token = _READS.set({})
    try:
        yield
    finally:
        _READS.reset(token)


def file_entry(name: str, data: bytes) -> dict:
    """``{"path", "sha256", "bytes"}`` of a file's content as read."""
    import hashlib

    return {"path": name, "sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}


def _record_read(name: str, data: bytes) -> None:
    reads = _READS.get()
    if reads is not None:
        key = os.path.realpath(name)
        if key not in reads:
            reads[key] = file_entry(name, data)


def files_read() -> Optional[list[dict]]:
    """The files read so far in the innermost :func:`recording_reads` context, in the order first read
    (None outside one)."""
    reads = _READS.get()
    return None if reads is None else list(reads.values())


def hash_file(path: str | Path, chunk: int = 1 << 20) -> Optional[dict]:
    """:func:`file_entry` of a regular file read in chunks (a result store of any size); None when it is
    not one or cannot be read."""
    import hashlib

    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return None
        digest, size = hashlib.sha256(), 0
        with open(path, "rb") as fh:
            while block := fh.read(chunk):
                digest.update(block)
                size += len(block)
    except OSError:
        return None
    return {"path": str(path), "sha256": digest.hexdigest(), "bytes": size}


_WIDE_BOMS = ((codecs.BOM_UTF32_LE, "UTF-32"), (codecs.BOM_UTF32_BE, "UTF-32"),
              (codecs.BOM_UTF16_LE, "UTF-16"), (codecs.BOM_UTF16_BE, "UTF-16"))


def decode_text(data: bytes, name: str) -> str:
    """UTF-8 text (a UTF-8 byte-order mark is dropped); UTF-16/32 or other bytes raise ``InputError``
    naming the line and column of the first byte that is not UTF-8."""
    for bom, encoding in _WIDE_BOMS:  # UTF-32 first: its little-endian mark begins with UTF-16's
        if data.startswith(bom):
            raise InputError(Problem(name, "", f"is {encoding} text (byte-order mark {bom.hex(' ').upper()}): "
                                     "save it as UTF-8", 1))
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8):]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise InputError(Problem(name, "", f"not UTF-8 text: byte 0x{data[exc.start]:02X} in column {column} "
                                 "(save the file as UTF-8)", line)) from None


def read_text(path: str | Path, limit: int = MAX_FILE_BYTES) -> str:
    """A regular file's UTF-8 text, at most ``limit`` bytes; anything else raises ``InputError``."""
    return decode_text(read_bytes(path, limit), str(path))


# ------------------------------------------------------------------------------------------ YAML
_BASE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when present: fast, and its parser does not recurse


class _LOADER(_BASE_LOADER):  # type: ignore[misc,valid-type]
    """The safe loader, reading integers as YAML 1.2 does: ``060`` and ``08`` are sixty and eight (YAML 1.1
    would read the octal 48, a silent 20 % off a speed limit, and the text '08'); ``0o60`` is the octal 48
    (text to YAML 1.1). The forms YAML 1.1 reads as numbers and YAML 1.2 as text, base-60 (``3:20``),
    digit groups (``1_500``) and binary (``0b101``), are refused by the scan, naming file, line and field."""


_OCTAL_11 = re.compile(r"^[-+]?0[0-7_]+$")
_DECIMAL_12 = re.compile(r"^[-+]?0[0-9]+$")  # a leading zero: decimal to YAML 1.2
_OCTAL_12 = re.compile(r"^[-+]?0o[0-7]+$")
_SEXAGESIMAL_11 = re.compile(r"^[-+]?[0-9][0-9_]*(:[0-5]?[0-9])+(\.[0-9_]*)?$")


def _construct_int(loader, node):
    value = loader.construct_scalar(node)
    if _OCTAL_11.match(value) or _DECIMAL_12.match(value):
        return int(value.replace("_", ""), 10)
    if _OCTAL_12.match(value):
        sign = -1 if value.startswith("-") else 1
        return sign * int(value.lstrip("+-")[2:], 8)
    return yaml.constructor.SafeConstructor.construct_yaml_int(loader, node)


_LOADER.add_constructor("tag:yaml.org,2002:int", _construct_int)
# integers YAML 1.2 reads and YAML 1.1 leaves as text: 08, 0189 (a leading zero before an 8 or 9), 0o60
_LOADER.add_implicit_resolver("tag:yaml.org,2002:int", re.compile(r"^(?:[-+]?0[0-9]*[89][0-9]*|[-+]?0o[0-7]+)$"),
                              list("-+0"))
# booleans as YAML 1.2 reads them: true and false only (YAML 1.1 also reads yes, no, on, off, y... as booleans, so
# that `window: no` or a route named Off would change type silently); the others are text, and a boolean field
# given one says so (_message)
_BOOL_12 = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
for _first, _resolvers in _LOADER.yaml_implicit_resolvers.items():
    _LOADER.yaml_implicit_resolvers[_first] = [(tag, _BOOL_12 if tag == "tag:yaml.org,2002:bool" else regexp)
                                               for tag, regexp in _resolvers
                                               if tag != "tag:yaml.org,2002:bool" or _first in "tTfF"]
_YAML11_BOOLS = {"yes": True, "no": False, "on": True, "off": False, "y": True, "n": False}
"""Words YAML 1.1 reads as booleans and YAML 1.2 as text (PyYAML's 1.1 resolver takes yes/no/on/off, others y/n)."""
_RESOLVER = _LOADER("")
_STR, _MERGE = "tag:yaml.org,2002:str", "tag:yaml.org,2002:merge"
_NUMBER_TAGS = {"tag:yaml.org,2002:int": "an integer", "tag:yaml.org,2002:float": "a number"}
_READ_AS = {"tag:yaml.org,2002:int": "an integer", "tag:yaml.org,2002:float": "a number",
            "tag:yaml.org,2002:bool": "a boolean", "tag:yaml.org,2002:null": "null",
            "tag:yaml.org,2002:timestamp": "a date"}


def _base60(text: str) -> float:
    """'3:20' -> 200 (what YAML 1.1 reads); huge forms only as far as a float goes."""
    sign = -1.0 if text.startswith("-") else 1.0
    value = 0.0
    for part in text.lstrip("+-").replace("_", "").split(":"):
        value = value * 60 + float(part)
        if value > 1e300:
            return sign * float("inf")
    return sign * value


def _yaml11_only(text: str) -> str | None:
    """A number literal YAML 1.1 reads and YAML 1.2 does not (digit groups ``1_500``, binary ``0b101``): the
    number it stands for, written plainly; None for any other literal."""
    t = text.lower()
    body = t.lstrip("+-")
    sign = "-" if t.startswith("-") else ""
    if body.startswith("0b"):
        try:
            return f"{sign}{int(body[2:].replace('_', ''), 2)}"
        except ValueError:
            return None
    if "_" not in t:
        return None
    cleaned = t.replace("_", "")
    if body.startswith("0x"):
        try:
            return f"{sign}{int(cleaned.lstrip('+-')[2:], 16)}"
        except ValueError:
            return None
    return cleaned.lstrip("+") if cleaned.lstrip("+-") not in ("", ".") else None


def _digits(text: str) -> int:
    """Digits of a YAML number literal: '0x' + 3,000 hex digits counts 3,000, '1.5e+10' counts 2."""
    t = text.lower().lstrip("+-").replace("_", "")
    if t.startswith(("0x", "0o", "0b")):
        return len(t) - 2
    return sum(ch.isdigit() for ch in t.split("e")[0])


class _Open:
    """One open list or mapping while scanning the event stream."""

    __slots__ = ("size", "anchor", "is_map", "want_key", "key", "index")

    def __init__(self, anchor: str | None, is_map: bool):
        self.size, self.anchor, self.is_map = 1, anchor, is_map
        self.want_key, self.key, self.index = True, None, 0


def _scan(text: str, name: str, max_nodes: int = MAX_NODES) -> None:
    """Refuse what would blow up composing or walking the YAML, before composing it: nesting deeper than
    ``MAX_DEPTH``, aliases adding more than ``MAX_ALIAS_NODES`` nodes or referring to themselves, keys
    that are not strings, number literals longer than ``MAX_NUMBER_DIGITS`` digits. Works on the event
    stream (iterative, constant stack), so even a 10 MB file of '[' costs no recursion."""
    stack: list[_Open] = []
    anchors: dict[str, int | None] = {}  # expanded node count of each anchored node (None while still open)
    added = 0  # nodes that aliases add when expanded
    written = 0  # nodes written out

    def where() -> str:
        parts: list = []
        for o in stack:
            if o.is_map and o.key is not None and not o.want_key:
                parts.append(o.key)
            elif not o.is_map:
                parts.append(o.index)
        if len(parts) > 4:  # a field 5,000 levels deep is no help: its first levels say where
            return field_name(tuple(parts[:3])) + "[...]"
        return field_name(tuple(parts))

    def fail(event, message: str):
        raise InputError(Problem(name, where(), message, event.start_mark.line + 1 if event.start_mark else None))

    def child_done(size: int) -> None:
        if not stack:
            return
        parent = stack[-1]
        parent.size += size
        if parent.is_map:
            parent.want_key = not parent.want_key
        else:
            parent.index += 1

    def key_check(event, value: str | None, tag: str | None, implicit) -> None:
        """``event`` arrives where its mapping expects a key: it must be a string (or a merge '<<')."""
        if value is None:
            what = {yaml.AliasEvent: "an alias", yaml.SequenceStartEvent: "a list"}.get(type(event), "a mapping")
            fail(event, f"a key is {what}, not a string; write keys as plain names")
        resolved = tag if tag and tag != "!" else _RESOLVER.resolve(yaml.ScalarNode, value, implicit)
        if resolved not in (_STR, _MERGE):
            kind = _READ_AS.get(resolved, f"tag {resolved}")
            fail(event, f"key {value!r} is not a string (YAML reads it as {kind}); quote it, or remove it")

    try:
        for event in yaml.parse(text, Loader=_LOADER):
            if isinstance(event, (yaml.ScalarEvent, yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                written += 1
                if written > max_nodes:
                    fail(event, f"holds more than {max_nodes:,} values: " + (
                        "no route, vehicle or consist needs so many (the largest real line shipped holds about 2,500; "
                        "355 sections)" if max_nodes == MAX_NODES else "more than this kind of file needs"))
            top = stack[-1] if stack else None
            at_key = top is not None and top.is_map and top.want_key
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                if at_key:
                    key_check(event, None, None, None)
                if len(stack) >= MAX_DEPTH:
                    fail(event, f"nested deeper than {MAX_DEPTH} levels (locoplan files need 4); the file is "
                                "refused before the parser's recursion is at risk")
                if event.anchor:
                    anchors[event.anchor] = None
                stack.append(_Open(event.anchor, isinstance(event, yaml.MappingStartEvent)))
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                done = stack.pop()
                if done.anchor:
                    anchors[done.anchor] = done.size
                child_done(done.size)
            elif isinstance(event, yaml.ScalarEvent):
                if at_key:
                    key_check(event, event.value, event.tag, event.implicit)
                    top.key = event.value
                else:
                    tag = event.tag if event.tag and event.tag != "!" else (
                        _RESOLVER.resolve(yaml.ScalarNode, event.value, event.implicit) if event.implicit[0] else _STR)
                    if tag in _NUMBER_TAGS and _SEXAGESIMAL_11.match(event.value):
                        fail(event, f"{event.value!r} is a base-60 number to YAML 1.1 (read as "
                                    f"{_base60(event.value):g}) and text to YAML 1.2: write one plain number "
                                    "(seconds, metres, ...), e.g. "
                                    f"{_base60(event.value):g} for {event.value}")
                    if tag in _NUMBER_TAGS:
                        n = _digits(event.value)
                        if n > MAX_NUMBER_DIGITS:
                            fail(event, f"{_NUMBER_TAGS[tag]} of {n:,} digits is not a plausible value "
                                        f"(at most {MAX_NUMBER_DIGITS} digits)")
                        plain = _yaml11_only(event.value)
                        if plain is not None:
                            fail(event, f"{event.value!r} is the number {plain} to YAML 1.1 and text to YAML 1.2: write "
                                        f"it as a plain number, {plain}")
                if event.anchor:
                    anchors[event.anchor] = 1
                child_done(1)
            elif isinstance(event, yaml.AliasEvent):
                if at_key:
                    key_check(event, None, None, None)
                size = anchors.get(event.anchor, 0)
                if event.anchor in anchors and size is None:
                    fail(event, f"recursive alias: *{event.anchor} refers to the list or mapping it is inside")
                added += size or 0
                if added > MAX_ALIAS_NODES:
                    fail(event, f"aliases expand this file by more than {MAX_ALIAS_NODES:,} nodes "
                                "(an alias bomb?); write the values out, or reuse fewer")
                child_done(size or 0)
    except yaml.YAMLError:
        return  # composing reports the syntax error with its line


def parse_yaml(text: str, name: str, max_nodes: int = MAX_NODES) -> tuple[Any, yaml.Node | None]:
    """Parse one YAML document safely: (data, node). ``InputError`` for anything malformed or hostile
    (see ``_scan``; ``max_nodes``: more values for a kind of file that needs them); data and node are None
    for an empty document."""
    _scan(text, name, max_nodes)
    loader = _LOADER(text)
    try:
        node = loader.get_single_node()
        data = None if node is None else loader.construct_document(node)
    except yaml.reader.ReaderError as exc:  # a control character: say which and where
        line = text.count("\n", 0, exc.position) + 1
        column = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        code = exc.character if isinstance(exc.character, int) else ord(exc.character)
        raise InputError(Problem(name, "", f"not valid YAML: control character U+{code:04X} in column {column} "
                                 "(YAML text may not contain it)", line)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark else None
        what = getattr(exc, "problem", None) or str(exc)
        context = getattr(exc, "context", None)
        if context and "document" in str(context) and "single" not in what:
            what = f"{context}, {what}"
        raise InputError(Problem(name, "", f"not valid YAML: {what}", line)) from None
    except (ValueError, RecursionError, MemoryError) as exc:  # a resolver's int(), a tree the scan let through
        raise InputError(Problem(name, "", f"not a usable YAML file: {exc.__class__.__name__}: {str(exc)[:120]}")) from None
    finally:
        loader.dispose()
    return data, node


_JSON_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')
_JSON_BRACKETS = re.compile(r"[\[\]{}]")


class _BadJsonNumber(Exception):
    pass


class _DuplicateJsonKey(Exception):
    pass


def _json_number(kind):
    def parse(text: str):
        if _digits(text) > MAX_NUMBER_DIGITS:
            raise _BadJsonNumber(text)
        value = kind(text)
        if kind is float and not math.isfinite(value):  # 1e99999: past a float's range, read as inf
            raise _BadJsonNumber(text)
        return value
    return parse


def _json_object(pairs: list) -> dict:
    """A JSON object; a key written twice is refused (JSON parsers keep the last one silently)."""
    out: dict = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateJsonKey(key)
        out[key] = value
    return out


def _json_constant(text: str):
    raise _BadJsonNumber(text)


def parse_json(text: str, name: str) -> Any:
    """Parse JSON as ``parse_yaml`` parses YAML: nesting deeper than ``MAX_DEPTH`` (checked before parsing,
    so Python's recursion is never at risk), numbers of more than ``MAX_NUMBER_DIGITS`` digits and the
    non-standard ``NaN`` / ``Infinity`` are refused with the line; a syntax error names line and column."""
    depth = top = 0
    for m in _JSON_BRACKETS.finditer(_JSON_STRING.sub('""', text)):
        depth += 1 if m.group() in "[{" else -1
        if depth > top:
            top = depth
            if top > MAX_DEPTH:
                raise InputError(Problem(name, "", f"nested deeper than {MAX_DEPTH} levels (locoplan's JSON inputs need "
                                         "4); the file is refused before the parser's recursion is at risk"))
    try:
        return json.loads(text, parse_int=_json_number(int), parse_float=_json_number(float),
                          parse_constant=_json_constant, object_pairs_hook=_json_object)
    except _BadJsonNumber as exc:
        literal = str(exc)
        at = text.find(literal)
        line = text.count("\n", 0, at) + 1 if at >= 0 else None
        if literal in ("NaN", "Infinity", "-Infinity"):
            raise InputError(Problem(name, "", f"{literal} is not a JSON number (nor a finite value)", line)) from None
        if _digits(literal) <= MAX_NUMBER_DIGITS:
            raise InputError(Problem(name, "", f"{literal} is beyond the range of a number (it would be read as infinite)",
                                     line)) from None
        raise InputError(Problem(name, "", f"a number of {_digits(literal):,} digits is not a plausible value (at most "
                                 f"{MAX_NUMBER_DIGITS} digits)", line)) from None
    except _DuplicateJsonKey as exc:
        key = str(exc)
        hits = [m.start() for m in re.finditer(re.escape(json.dumps(key)) + r"\s*:", text)]
        sure = len(hits) == 2  # the key appears only twice: those are the two places (else other objects hold it too)
        line = text.count("\n", 0, hits[1]) + 1 if sure else None
        first = f" (first on line {text.count(chr(10), 0, hits[0]) + 1})" if sure else " in one object"
        raise InputError(Problem(name, key, f"duplicate key{first}: JSON readers would keep the last one silently; "
                                 "write it once", line)) from None
    except json.JSONDecodeError as exc:
        raise InputError(Problem(name, "", f"not valid JSON: {exc.msg} (column {exc.colno})", exc.lineno)) from None
    except (RecursionError, ValueError) as exc:
        raise InputError(Problem(name, "", f"not usable JSON: {exc.__class__.__name__}: {str(exc)[:120]}")) from None


def yaml_kind(value: Any) -> str:
    """What a parsed value is, in words: 'a list', 'a mapping', 'a number', 'binary data', ..."""
    import datetime as _dt

    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (_dt.date, _dt.datetime)):
        return "a date"
    return {list: "a list", dict: "a mapping", int: "a number", float: "a number", bytes: "binary data",
            str: "text", type(None): "null"}.get(type(value), f"a {type(value).__name__}")


def read_yaml(path: Path, max_nodes: int = MAX_NODES) -> tuple[Any, dict[tuple, int]]:
    """Parse a YAML file; missing, unreadable, empty, malformed or hostile files raise ``InputError``."""
    name = str(path)
    data, node = parse_yaml(read_text(path), name, max_nodes)
    if node is None or data is None:
        raise InputError(Problem(name, "", "file is empty"))
    duplicates = _duplicate_keys(node, name)
    if duplicates:
        raise InputError(duplicates)
    if not isinstance(data, dict):
        raise InputError(Problem(name, "", f"expected a mapping of keys (schema: ..., name: ...), got {type(data).__name__}", 1))
    lines = _line_map(node)
    schema = data.get("schema")
    if schema is not None and not isinstance(schema, str):
        # every loader looks the schema up in a table: a list or mapping there is unhashable, a number no name
        raise InputError(Problem(name, "schema", f"expected the file's kind as text, e.g. 'locoplan/route@1', got "
                                 f"{yaml_kind(schema)} ({short_repr(schema)})", _line_for(lines, ("schema",))))
    return data, lines


def _allowed_keys(model: type[BaseModel], loc: tuple) -> list[str]:
    """Keys allowed at ``loc`` (for the 'did you mean' hint on an unknown key)."""
    current: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        fields = getattr(current, "model_fields", {})
        info = next((f for n, f in fields.items() if (f.alias or n) == part), None)
        if info is None:
            return []
        ann = info.annotation
        for arg in getattr(ann, "__args__", ()) or (ann,):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                current = arg
                break
            for sub in getattr(arg, "__args__", ()):
                if isinstance(sub, type) and issubclass(sub, BaseModel):
                    current = sub
                    break
        else:
            if isinstance(ann, type) and issubclass(ann, BaseModel):
                current = ann
    fields = getattr(current, "model_fields", {})
    return [f.alias or n for n, f in fields.items()]


UNIT_HINTS = {
    # a key's unit as people write it -> (the unit the format wants in key names, how to convert)
    "mps": ("kmh", "km/h: m/s x 3.6"), "ms": ("kmh", "km/h: m/s x 3.6"), "kph": ("kmh", "km/h"),
    "kmph": ("kmh", "km/h"), "mph": ("kmh", "km/h: mph x 1.609"), "percent": ("permille", "per mille: % x 10"),
    "pct": ("permille", "per mille: % x 10"), "km": ("m", "metres: km x 1000"), "kg": ("t", "tonnes: kg / 1000"),
    "n": ("kn", "kN: N / 1000"), "min": ("s", "seconds: min x 60"), "h": ("s", "seconds: h x 3600"),
}
"""Unit words in an unknown key (``mps:``, ``percent:``, ``from_km:``) and what the format wants instead."""


def _unit_hint(key: str, allowed: list[str]) -> tuple[str | None, str]:
    """(the allowed key meant, the unit the format wants and how to convert) for a key whose name is a
    unit the format does not use (``mps``, ``percent``, ``from_km``); (None, "") otherwise."""
    unit = key.lower().rsplit("_", 1)[-1]
    if unit not in UNIT_HINTS:
        return None, ""
    want, how = UNIT_HINTS[unit]
    stem = key.rsplit("_", 1)[0] + "_" + want if "_" in key else None
    target = stem if stem in allowed else next((k for k in allowed if k == want or k.endswith("_" + want)), None)
    return target, f"; the format wants {how}"


def _message(model: type[BaseModel], err: dict) -> str:
    kind, loc = err["type"], err["loc"]
    if kind == "extra_forbidden":
        key = str(loc[-1])
        allowed = _allowed_keys(model, tuple(loc))
        stem = key.rsplit("_", 1)[0]
        same_stem = [k for k in allowed if k.rsplit("_", 1)[0] == stem and k != key]
        close = same_stem or difflib.get_close_matches(key, allowed, n=1)
        target, how = _unit_hint(key, allowed)
        meant = target or (close[0] if close else None)
        hint = f"; did you mean '{meant}'?" if meant else ""
        if same_stem or how:
            hint += " (units live in key names: _m, _kmh, _s, _t, _kn, _permille)" + how
        return f"unknown key{hint} (allowed: {', '.join(allowed)})"
    if kind == "missing":
        return "required field is missing"
    if kind == "finite_number":
        return f"must be a finite number, got {err.get('input')!r}"
    msg = err["msg"]
    value = err.get("input")
    if kind == "bool_type" and isinstance(value, str) and value.lower() in _YAML11_BOOLS:
        return (f"{value!r} is text to YAML 1.2 (YAML 1.1 read it as the boolean "
                f"{str(_YAML11_BOOLS[value.lower()]).lower()}): write true or false")
    if kind == "float_type" and isinstance(value, str) and _EXPONENT_TEXT.match(value):
        return (f"{value!r} is text, not a number, to YAML 1.1: write a number in exponent form with a dot "
                f"and a signed exponent, e.g. {_yaml_float(value)}")
    if "input" in err and kind not in ("literal_error",):
        msg += f" (got {short_repr(err['input'])})"
    return msg


_EXPONENT_TEXT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$")
"""Exponent forms YAML 1.1 reads as text: '1e308', '3e3', '2.5e-3' without a dot or a signed exponent
(its float needs both: 1.0e+308). Only these get the hint; a quoted "2.5" is a plain type error."""


def _yaml_float(text: str) -> str:
    """'1e308' -> '1.0e+308' (the form YAML 1.1 reads as a float)."""
    mantissa, _, exponent = text.lower().partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    if exponent and exponent[0] not in "+-":
        exponent = "+" + exponent
    return mantissa + ("e" + exponent if exponent else "")


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)``, cut to ``limit`` characters: a message quotes a bad value, not a whole file."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 5] + " ...>"


def validate_data(data: dict, name: str, lines: dict[tuple, int], expect: str | None = None) -> BaseModel:
    """Validate parsed YAML against the schema its ``schema:`` key names (or ``expect``)."""
    schema = data.get("schema")
    if schema not in SCHEMAS:
        known = ", ".join(SCHEMAS)
        raise InputError(Problem(name, "schema", f"unknown or missing schema {schema!r} (one of: {known})",
                                 _line_for(lines, ("schema",))))
    if expect is not None and schema != expect:
        raise InputError(Problem(name, "schema", f"expected a {expect} file, got {schema}", _line_for(lines, ("schema",))))
    return validate_model(SCHEMAS[schema], data, name, lines)


def validate_model(model: type[BaseModel], data: dict, name: str, lines: dict[tuple, int]) -> BaseModel:
    """Validate parsed YAML against ``model``; every problem as file:line: field: message."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            violation = (err.get("ctx") or {}).get("error")
            if isinstance(violation, RuleViolations):
                for loc, msg in violation.problems:
                    full = tuple(err["loc"]) + tuple(loc)
                    problems.append(Problem(name, field_name(full), msg, _line_for(lines, full)))
            else:
                loc = tuple(err["loc"])
                problems.append(Problem(name, field_name(loc), _message(model, err), _line_for(lines, loc)))
        raise InputError(problems) from None


def load_file(path: str | Path, expect: str | None = None) -> BaseModel:
    path = Path(path)
    data, lines = read_yaml(path)
    return validate_data(data, str(path), lines, expect)


def file_schema(path: str | Path) -> str | None:
    """The ``schema:`` a YAML file declares (None: none). A file that cannot be read or parsed raises
    ``InputError``, as its loader would."""
    data, _ = read_yaml(Path(path))
    return data.get("schema")


def load_route(path: str | Path) -> Route:
    return load_file(path, "locoplan/route@1")  # type: ignore[return-value]


def load_journey(path: str | Path) -> tuple[Journey, Route]:
    """A journey file and the route file it names (relative to the journey's folder); the stations checked
    against the route: every one on it, the last at its end. Problems as file:line: field: message."""
    path = Path(path)
    data, lines = read_yaml(path)
    journey = validate_data(data, str(path), lines, "locoplan/journey@1")
    route_path = Path(journey.route)
    if not route_path.is_absolute():
        route_path = path.parent / route_path
    if not route_path.is_file():
        raise InputError(Problem(str(path), "route", f"no route file {route_path} (the path is relative to the "
                                 "journey file's folder)", _line_for(lines, ("route",))))
    route = load_route(route_path)
    problems = []
    last = len(journey.stations) - 1
    for i, st in enumerate(journey.stations):
        if st.at_m > route.length_m + 1e-3:
            problems.append(Problem(str(path), f"stations[{i}].at_m", f"{st.at_m:g} m lies beyond the end of "
                                    f"{route_path.name} ({route.length_m:g} m)", _line_for(lines, ("stations", i, "at_m"))))
    for i, st in enumerate(journey.stations[:-1]):
        for ns in route.neutral_sections:
            if st.stop and ns.from_m <= st.at_m < ns.to_m:
                problems.append(Problem(str(path), f"stations[{i}].at_m", f"the stop {st.name!r} at {st.at_m:g} m lies in the "
                                        f"neutral section {ns.from_m:g} .. {ns.to_m:g} m of {route_path.name}: a train "
                                        "standing there has no traction to start again", _line_for(lines, ("stations", i, "at_m"))))
    if abs(journey.stations[last].at_m - route.length_m) > 1e-3 and journey.stations[last].at_m <= route.length_m:
        problems.append(Problem(str(path), f"stations[{last}].at_m", f"the last station ends the journey at the end of "
                                f"the line: {route.length_m:g} m (got {journey.stations[last].at_m:g})",
                                _line_for(lines, ("stations", last, "at_m"))))
    if problems:
        raise InputError(problems)
    return journey, route


def load_disturbance(path: str | Path) -> Disturbance:
    """A disturbance file (``locoplan drive --disturb``), checked against the route it disturbs by the caller."""
    return load_file(path, "locoplan/disturbance@1")  # type: ignore[return-value]


def load_vehicle(path: str | Path) -> Vehicle:
    return load_file(path, "locoplan/vehicle@1")  # type: ignore[return-value]


def stock_dirs_for(consist_path: Path, stock_dir: str | Path | None = None) -> list[Path]:
    """Where vehicle types are looked up, in order (SPEC section 1)."""
    if stock_dir is not None:
        check_folder(stock_dir, "--stock-dir")
    dirs = [Path(stock_dir)] if stock_dir else []
    dirs.append(consist_path.parent.parent / "rolling_stock")
    dirs.append(Path(str(CATALOGUE / "rolling_stock")))
    return dirs


def check_folder(path: str | Path, option: str) -> Path:
    """``path`` must be an existing folder (an option such as ``--stock-dir`` naming one)."""
    path = Path(path)
    if not path.exists():
        raise InputError(Problem(str(path), option, "no such folder"))
    if not path.is_dir():
        raise InputError(Problem(str(path), option, "not a folder"))
    return path


def _vehicle_index(directory: Path) -> tuple[dict[str, Path], dict[str, list[Path]]]:
    """Vehicle name -> file in a folder (a file's ``name:`` is authoritative, its stem the fallback),
    and the names that more than one file of the folder declares (ambiguous: which file is meant?)."""
    index: dict[str, Path] = {}
    declared: dict[str, list[Path]] = {}
    if not directory.is_dir():
        return index, {}
    for file in sorted(directory.glob("*.yaml")):
        index.setdefault(file.stem, file)  # a FIFO or device is indexed by name, and refused if a consist uses it
        try:
            data, _ = parse_yaml(read_text(file), str(file))
        except InputError:
            continue
        if isinstance(data, dict) and isinstance(data.get("name"), str):
            declared.setdefault(data["name"], []).append(file)
    for vehicle, files in declared.items():
        index[vehicle] = files[0]
    return index, {k: v for k, v in declared.items() if len(v) > 1}


def resolve_consist_path(spec: str | Path) -> Path:
    """A consist given as a path, or as a name from ``configs/consists`` / the shipped catalogue."""
    path = Path(spec)
    if path.exists() or path.suffix in (".yaml", ".yml") or "/" in str(spec):
        if not path.exists() and not path.is_absolute():
            shipped = Path(str(CATALOGUE / "consists")) / path.name
            if str(spec) == f"configs/consists/{path.name}" and shipped.exists():
                return shipped  # the default path works from any directory
        return path
    for folder in (Path("configs/consists"), Path(str(CATALOGUE / "consists"))):
        candidate = folder / f"{spec}.yaml"
        if candidate.exists():
            return candidate
    raise InputError(Problem(str(spec), "consist", "no such file, nor a consist of that name; the catalogue has: "
                             + ", ".join(consist_names())))


def consist_names() -> list[str]:
    """The consists a bare ``--consist NAME`` finds: ``configs/consists/`` here, then the shipped catalogue."""
    names = set()
    for folder in (Path("configs/consists"), Path(str(CATALOGUE / "consists"))):
        if folder.is_dir():
            names.update(p.stem for p in folder.glob("*.yaml"))
    return sorted(names)


def load_route_and_train(route_path: str | Path, consist_spec: str | Path,
                         stock_dir: str | Path | None = None) -> tuple[Route, Train]:
    """A route and a train that can run on it (the route is longer than the train), every problem named."""
    route = load_route(route_path)
    train = load_train(consist_spec, stock_dir)
    if train.length_m >= route.length_m:
        raise InputError(shorter_than_train(route, train, str(route_path), str(resolve_consist_path(consist_spec))))
    return route, train


def load_train(consist_spec: str | Path, stock_dir: str | Path | None = None) -> Train:
    """Load a consist, resolve each vehicle type, and build the whole-train quantities."""
    consist, vehicles, _, path, lines = load_consist(consist_spec, stock_dir)
    return build_train(consist, vehicles, str(path), lines)


def load_consist(consist_spec: str | Path, stock_dir: str | Path | None = None):
    """A consist and its vehicles, unbuilt: (Consist, {type: Vehicle}, {type: vehicle file}, consist path,
    line map). For callers that change the consist (e.g. its wagon count or load) before building it."""
    path = resolve_consist_path(consist_spec)
    data, lines = read_yaml(path)
    consist: Consist = validate_data(data, str(path), lines, "locoplan/consist@1")  # type: ignore[assignment]
    dirs = stock_dirs_for(path, stock_dir)
    indexes = [(d, *_vehicle_index(d)) for d in dirs]
    vehicles: dict[str, Vehicle] = {}
    files: dict[str, Path] = {}
    problems: list[Problem] = []
    for i, entry in enumerate(consist.vehicles):
        loc = ("vehicles", i, "type")
        folder = next(((d, idx, dup) for d, idx, dup in indexes if entry.type in idx), None)
        found = None if folder is None else folder[1][entry.type]
        if folder is not None and entry.type in folder[2]:
            both = " and ".join(str(f) for f in folder[2][entry.type])
            problems.append(Problem(str(path), field_name(loc), f"vehicle type '{entry.type}' is ambiguous: {both} "
                                    "both declare this name (rename one)", _line_for(lines, loc)))
            continue
        if found is None:
            looked = ", ".join(str(d) for d in dirs)
            known = sorted({k for _, idx, _ in indexes for k in idx})
            close = difflib.get_close_matches(entry.type, known, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            problems.append(Problem(str(path), field_name(loc), f"unknown vehicle type '{entry.type}'{hint} (looked in {looked})",
                                    _line_for(lines, loc)))
            continue
        vehicle = load_vehicle(found)
        vehicles[entry.type] = vehicle
        files[entry.type] = found
        if vehicle.kind == "locomotive" and entry.load_t:
            loc = ("vehicles", i, "load_t")
            problems.append(Problem(str(path), field_name(loc), "a locomotive carries no load", _line_for(lines, loc)))
        if vehicle.max_load_t is not None and entry.load_t > vehicle.max_load_t:
            loc = ("vehicles", i, "load_t")
            problems.append(Problem(str(path), field_name(loc),
                                    f"{entry.load_t:g} t exceeds {vehicle.name}'s max_load_t {vehicle.max_load_t:g} t",
                                    _line_for(lines, loc)))
    if not problems and not any(v.kind == "locomotive" for v in vehicles.values()):
        problems.append(Problem(str(path), "vehicles", "the consist has no locomotive", _line_for(lines, ("vehicles",))))
    if problems:
        raise InputError(problems)
    return consist, vehicles, files, path, lines


SHORTEST_LINE_M = 200.0
"""A route shorter than this is not a freight line (the shortest train of the catalogue is longer):
its lengths were most likely written in kilometres."""
SHORTEST_SECTION_M = 10.0
"""Speed limits or gradients changing every few metres: positions most likely in kilometres."""


def route_warnings(route, path: str, lines: dict | None = None) -> list[Problem]:
    """Implausible but valid values in a route file, as problems to warn about (``validate``): a line
    shorter than any train, sections of a few metres, both the marks of a route written in km."""
    lines = lines or {}
    out = []
    if route.length_m < SHORTEST_LINE_M:
        out.append(Problem(path, "length_m", f"{route.length_m:g} m is shorter than any freight train (a 50-wagon "
                           f"train is about 635 m): was the route written in km? The format wants metres "
                           f"(length_m: {route.length_m * 1000:g} for {route.length_m:g} km)", lines.get(("length_m",))))
    for name in ("speed_limits", "gradients"):
        sections = getattr(route, name)
        short = [k for k, x in enumerate(sections) if x.to_m - x.from_m < SHORTEST_SECTION_M]
        if short:
            k = short[0]
            out.append(Problem(path, f"{name}[{k}]", f"{len(short)} of {len(sections)} sections are shorter than "
                               f"{SHORTEST_SECTION_M:g} m (e.g. {sections[k].from_m:g} .. {sections[k].to_m:g} m): "
                               "positions in km? The format wants metres (from_m, to_m)", lines.get((name, k))))
    return out
