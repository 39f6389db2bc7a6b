"""A generated corpus of hostile inputs (issue 10): files and option values that once gave tracebacks,
hangs, memory blow-ups or wrong successes, one or more per class, plus a few valid controls.

``build(tmp)`` writes every file into ``tmp`` and returns the cases; ``run_case`` runs one case as a
subprocess of ``python -m locoplan`` under a time limit and a memory cap and says what went wrong.
Used by ``tests/test_hostile.py`` (fast, two at a time) and ``benchmarks/hostile_corpus.py`` (every
case alone, with its peak memory). Nothing here is random except ``_garbage``, which is seeded.

A case passes when: no traceback; the exit code is the expected one (2 invalid input, 1 valid but
infeasible, 0 for the few valid controls); every expected text (the file, the field, the why) is in
stderr; it finished inside the time limit and under the memory cap; and its ``after`` check (nothing
half-written, file modes) holds.
"""

from __future__ import annotations

import os
import resource
import stat
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
TIME_LIMIT_S = 20.0
MEMORY_CAP_BYTES = 1 << 30  # 1 GiB of address space per case (RLIMIT_AS)

CMDLINE = "<command line>"


@dataclass
class Case:
    name: str
    cls: str  # yaml, file, number, physics, params, option, output, message
    argv: list[str]
    exit: int = 2
    expect: tuple[str, ...] = ()  # each must appear in stderr (file, field, why)
    batch_file: str | None = None  # a file case `validate` can check together with others
    expect_out: tuple[str, ...] = ()  # each must appear in stdout
    after: Callable[[], str | None] | None = None  # extra check after the run; returns a complaint or None
    umask: int | None = None
    fsize: int | None = None  # RLIMIT_FSIZE [bytes]: writes past it fail as on a full disk (run alone only)
    stdout_file: str | None = None  # stdout goes here (e.g. /dev/full) instead of a pipe (run alone only)
    permissions: bool = False  # file permissions hold even for root (CAP_DAC_OVERRIDE dropped; run alone only)
    forbid: tuple[str, ...] = ()  # none may appear in stderr (a forged line, an ANSI escape)
    max_stderr_chars: int | None = None  # stderr stays shorter (messages capped and summarised)
    stdin_ok: bool = False
    note: str = ""
    stderr_file: str | None = None  # stderr goes here (e.g. /dev/full) instead of a pipe (run alone only)
    env: dict[str, str] | None = None  # more environment (fresh cache folders; run alone only)
    during: Callable[[], None] | None = None  # done in a thread while the command runs (run alone only)
    time_limit_s: float | None = None  # a longer limit than TIME_LIMIT_S (only for a slow case)
    slow: bool = False  # run by the benchmark only (benchmarks/hostile_corpus.py), not by the test suite
    forbid_out: tuple[str, ...] = ()  # none may appear in stdout (a value a damaged cache planted)
    close_stdout: bool = False  # the command runs with its stdout closed (`locoplan ... >&-`; run alone only)

    @property
    def alone_only(self) -> bool:
        """The case sets up its own process (umask, file-size limit, stdout, stderr, environment) or acts on it
        while it runs: never run in a shared batch."""
        return (self.umask is not None or self.fsize is not None or self.stdout_file is not None or self.permissions
                or self.stderr_file is not None or self.env is not None or self.during is not None or self.close_stdout)


@dataclass
class Outcome:
    case: Case
    returncode: int | None
    stdout: str
    stderr: str
    seconds: float
    peak_rss_bytes: int
    problems: list[str] = field(default_factory=list)

    @property
    def traceback(self) -> bool:
        return "Traceback" in self.stderr or "Traceback" in self.stdout

    @property
    def hang(self) -> bool:
        return self.returncode is None

    @property
    def wrong_success(self) -> bool:
        return self.returncode == 0 and self.case.exit != 0


# ------------------------------------------------------------------------------------------ templates
ROUTE = """schema: locoplan/route@1
name: {name}
length_m: {length}
{schedule}speed_limits:
  - {{from_m: 0, to_m: {length}, kmh: {kmh}}}
gradients:
  - {{from_m: 0, to_m: {length}, permille: {permille}}}
{extra}"""


def route(name="hostile", length="1500", kmh="60", permille="0", schedule="schedule: {run_time_s: 200, tolerance_s: 10}\n",
          extra="") -> str:
    return ROUTE.format(name=name, length=length, kmh=kmh, permille=permille, schedule=schedule, extra=extra)


VEHICLE = """schema: locoplan/vehicle@1
name: {name}
kind: locomotive
mass_t: {mass}
length_m: 20
max_speed_kmh: 120
resistance_n_per_kn: {{a: {a}, b: 0.0053, c: 0.000675}}
traction_kn: [[0, 532.0], [120, {force}]]
brake_kn: [[0, 461.0], [120, 461.0]]
"""

CONSIST = """schema: locoplan/consist@1
name: hostile consist
vehicles:
  - {{type: {loco}, count: {count}}}
  - {{type: C64-seed000, count: 1{load}}}
"""

PARAMS = """schema: locoplan/optimizer@1
algorithm: issa
pop_size: {pop}
max_iter: {iters}
{extra}"""

SMALL = "HXD1-C64-seed000"  # a 284 t train: quick to run


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """The 'billion laughs': each level repeats the previous one ``width`` times (9**9 leaves)."""
    lines = ['a0: &a0 ["lol"]']
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def _garbage(n: int, seed: int = 10) -> bytes:
    import random

    return bytes(random.Random(seed).getrandbits(8) for _ in range(n))


# ------------------------------------------------------------------------------------------ corpus
def build(tmp: Path) -> list[Case]:
    """Write the corpus into ``tmp``; return its cases (file cases first)."""
    tmp = Path(tmp)
    files = tmp / "files"
    files.mkdir(parents=True, exist_ok=True)
    cases: list[Case] = []

    def write(name: str, content: str | bytes) -> str:
        p = files / name
        if isinstance(content, bytes):
            p.write_bytes(content)
        else:
            p.write_text(content, encoding="utf-8")
        return str(p)

    def file_case(name, cls, content, *why, exit=2, note="", field_=None):
        path = write(name, content)
        expect = () if exit == 0 else (path,) + ((field_,) if field_ else ()) + tuple(why)
        cases.append(Case(name, cls, ["validate", path], exit, expect, batch_file=path, note=note))
        return path

    good_route = write("good_route.yaml", route())

    # --- yaml: structure that blows up parsers (aliases, nesting, keys, tags, documents)
    file_case("alias_bomb.yaml", "yaml", route() + alias_bomb(), "alias", note="9**9 nodes when expanded")
    file_case("alias_bomb_wide.yaml", "yaml", route() + alias_bomb(5, 40), "alias", note="40**5 nodes")
    file_case("alias_bomb_maps.yaml", "yaml", route() + "".join(
        f"m{i}: &m{i} {{a: *m{i - 1}, b: *m{i - 1}, c: *m{i - 1}, d: *m{i - 1}}}\n" if i else "m0: &m0 {a: 1}\n" for i in range(12)),
        "alias", note="mappings of aliases, 4**11 nodes")
    file_case("alias_bomb_merge.yaml", "yaml", route() + "".join(
        f"m{i}: &m{i} {{<<: [*m{i - 1}], x{i}: [*m{i - 1}, *m{i - 1}, *m{i - 1}]}}\n" if i else "m0: &m0 {a: 1}\n" for i in range(14)),
        "alias", note="merge keys of aliases")
    file_case("many_values.yaml", "yaml", route(length="250000", extra="tunnels:\n" + "".join(
        f"  - {{from_m: {10 * i}, to_m: {10 * i + 5}}}\n" for i in range(22000))), "100,000 values")
    file_case("alias_recursive.yaml", "yaml", route() + "loop: &x [1, *x]\n", "recursive", field_="loop")
    file_case("alias_unknown.yaml", "yaml", route() + "x: *nowhere\n", "not valid YAML")
    file_case("alias_small_ok.yaml", "yaml", route(extra="tunnels:\n  - &t {from_m: 100, to_m: 200}\n"
                                                       "curves:\n  - {from_m: 100, to_m: 200, radius_m: 800}\n")
              + "", exit=0, note="a legitimate anchor is fine")
    file_case("merge_key.yaml", "yaml",
              route(extra="curves:\n  - &c {from_m: 100, to_m: 200, radius_m: 800}\ntunnels:\n  - {<<: *c}\n"),
              "tunnels[0].radius_m", "unknown key", note="a merge key carries radius_m into a tunnel: named, no crash")
    file_case("nested_lists.yaml", "yaml", route() + "deep: " + "[" * 5000 + "]" * 5000 + "\n", "nested")
    file_case("nested_maps.yaml", "yaml", route() + "deep: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n", "nested")
    file_case("nested_block.yaml", "yaml", route() + "deep:\n" + "".join("  " * i + "- \n" for i in range(1, 400)),
              "nested")
    file_case("nested_100.yaml", "yaml", route() + "deep: " + "[" * 100 + "]" * 100 + "\n", "nested", field_="deep")
    file_case("key_int.yaml", "yaml", route() + "1: one\n", "key", "not a string")
    file_case("key_list.yaml", "yaml", route() + "? [a, b]\n: c\n", "key", "not a string")
    file_case("key_null.yaml", "yaml", route() + "~: nothing\n", "key", "not a string")
    file_case("key_bool.yaml", "yaml", route() + "true: 5\n", "key", "not a string")
    file_case("key_yes.yaml", "yaml", route() + "yes: 5\n", ":9: yes: unknown key",
              note="text to YAML 1.2 (a boolean key to YAML 1.1): an unknown key, named")
    file_case("key_map_in_section.yaml", "yaml", route().replace("{from_m: 0, to_m: 1500, kmh: 60}",
                                                                 "{from_m: 0, to_m: 1500, kmh: 60, 7: 1}"),
              "speed_limits[0]", "not a string")
    file_case("dup_key.yaml", "yaml", route() + "length_m: 1600\n", "length_m", "duplicate key")
    file_case("tag_python.yaml", "yaml", route() + 'x: !!python/object/apply:os.system ["echo hi"]\n', "not valid YAML")
    file_case("tag_custom.yaml", "yaml", route().replace("length_m: 1500", "length_m: !metres 1500"), "not valid YAML")
    file_case("tag_timestamp.yaml", "yaml", route().replace("length_m: 1500", "length_m: 2001-12-14"), "length_m")
    file_case("tag_binary.yaml", "yaml", route().replace("name: hostile", "name: !!binary aGVsbG8="), "name")
    file_case("two_documents.yaml", "yaml", route() + "---\n" + route(), "not valid YAML", "single document")
    file_case("top_scalar.yaml", "yaml", "just some text\n", "expected a mapping")
    file_case("top_list.yaml", "yaml", "- 1\n- 2\n", "expected a mapping")
    file_case("only_comments.yaml", "yaml", "# nothing here\n# at all\n", "file is empty")
    file_case("nul_bytes.yaml", "yaml", route().replace("hostile", "host\x00ile"), "not valid YAML")
    file_case("nul_in_value.yaml", "yaml", route() + "x: 1\x00\n", "control character U+0000")
    file_case("control_chars.yaml", "yaml", route().replace("hostile", "host\x07ile\x1b[31m"), "not valid YAML")
    file_case("markup_in_values.yaml", "message", route().replace("name: hostile", "name: hostile\n'[m]': 1"),
              "[m]", "unknown key", note="rich markup must not eat '[m]'")

    # --- encoding
    latin1 = file_case("latin1.yaml", "file", route().replace("hostile", "Zürich").encode("latin-1"), "UTF-8")
    cases[-1].expect += (f"{latin1}:2:",)
    file_case("utf16.yaml", "file", route().encode("utf-16"), "UTF-16", "UTF-8")
    file_case("utf32.yaml", "file", route().encode("utf-32"), "UTF-32", "UTF-8")
    file_case("utf8_bom_ok.yaml", "file", "\ufeff" + route(), exit=0, note="a UTF-8 byte-order mark is fine")
    file_case("garbage.yaml", "file", _garbage(4000), "UTF-8")
    file_case("gzip.yaml", "file", b"\x1f\x8b\x08\x00" + _garbage(200, 3), "UTF-8")

    # --- file types and sizes
    big = write("big.yaml", route() + "# " + "x" * 78 + "\n" * 1)  # placeholder, replaced below
    with open(big, "a", encoding="utf-8") as fh:
        line = "# " + "padding " * 12 + "\n"
        fh.write(line * (11 * 1024 * 1024 // len(line) + 1))
    cases.append(Case("big.yaml", "file", ["validate", big], 2, (big, "MiB"), batch_file=big, note="11 MB"))
    folder = files / "a_folder.yaml"
    folder.mkdir(exist_ok=True)
    cases.append(Case("folder_as_file", "file", ["validate", str(folder)], 2, (str(folder), "folder"), batch_file=str(folder)))
    fifo = files / "fifo.yaml"
    if not fifo.exists():
        os.mkfifo(fifo)
    cases.append(Case("fifo_as_file", "file", ["validate", str(fifo)], 2, (str(fifo), "FIFO"), batch_file=str(fifo)))
    cases.append(Case("dev_zero", "file", ["validate", "/dev/zero"], 2, ("/dev/zero", "not a regular file"), batch_file="/dev/zero"))
    cases.append(Case("dev_null", "file", ["validate", "/dev/null"], 2, ("/dev/null", "not a regular file"), batch_file="/dev/null"))
    cases.append(Case("dev_urandom_route", "file", ["simulate", "/dev/urandom", "--consist", SMALL], 2,
                      ("/dev/urandom", "not a regular file")))
    cases.append(Case("proc_mem", "file", ["validate", "/proc/self/mem"], 2, ("/proc/self/mem",), batch_file="/proc/self/mem"))
    loop = files / "loop.yaml"
    if not loop.is_symlink():
        os.symlink(loop, loop)
    cases.append(Case("symlink_loop", "file", ["validate", str(loop)], 2, (str(loop), "cannot read"), batch_file=str(loop)))
    missing = str(files / "missing.yaml")
    cases.append(Case("missing_file", "file", ["validate", missing], 2, (missing, "no such file"), batch_file=missing))
    cases.append(Case("fifo_route_simulate", "file", ["simulate", str(fifo), "--consist", SMALL], 2, (str(fifo), "FIFO")))
    cases.append(Case("fifo_consist", "file", ["simulate", good_route, "--consist", str(fifo)], 2, (str(fifo), "FIFO")))
    cases.append(Case("zero_consist", "file", ["simulate", good_route, "--consist", "/dev/zero"], 2,
                      ("/dev/zero", "not a regular file")))
    cases.append(Case("folder_consist", "file", ["simulate", good_route, "--consist", str(folder)], 2, (str(folder), "folder")))

    # --- numbers: huge integers, non-finite values, floats beyond any bound
    digits = "9" * 5000
    file_case("int_5000_digits.yaml", "number", route(length=digits), "length_m", "digits")
    file_case("int_4000_digits.yaml", "number", route(length="9" * 4000), "length_m", "digits")
    file_case("int_hex_huge.yaml", "number", route(length="0x" + "f" * 3000), "length_m", "digits")
    file_case("int_sexagesimal.yaml", "number", route(length=":".join(["59"] * 400)), "length_m")
    file_case("float_overflow.yaml", "number", route(length="1.0e+400"), "length_m", "finite")
    file_case("exponent_as_text.yaml", "number", route(length="1e400"), "length_m", "is text", "1.0e+400")
    file_case("length_inf.yaml", "number", route(length=".inf"), "length_m", "finite")
    file_case("length_nan.yaml", "number", route(length=".nan"), "length_m", "finite")
    file_case("length_1e308.yaml", "number", route(length="1.0e+308"), "length_m", "2,000 km")
    file_case("length_neg_inf.yaml", "number", route(length="-.inf"), "length_m")
    file_case("kmh_nan.yaml", "number", route(kmh=".nan"), "speed_limits[0].kmh", "finite")
    file_case("permille_inf.yaml", "number", route(permille=".inf"), "gradients[0].permille", "finite")
    file_case("from_nan.yaml", "number", route().replace("{from_m: 0, to_m: 1500, permille", "{from_m: .nan, to_m: 1500, permille"),
              "gradients[0].from_m", "finite")
    file_case("radius_inf.yaml", "number", route(extra="curves:\n  - {from_m: 10, to_m: 20, radius_m: .inf}\n"),
              "curves[0].radius_m", "finite")
    file_case("run_time_inf.yaml", "number", route(schedule="schedule: {run_time_s: .inf}\n"), "schedule.run_time_s", "finite")
    file_case("run_time_1e308.yaml", "number", route(schedule="schedule: {run_time_s: 1.0e+308}\n"), "schedule.run_time_s", "a week")
    file_case("tolerance_nan.yaml", "number", route(schedule="schedule: {run_time_s: 200, tolerance_s: .nan}\n"),
              "schedule.tolerance_s", "finite")
    file_case("coast_1e308.yaml", "number",
              route(extra="neutral_sections:\n  - {from_m: 500, to_m: 520, coast_before_s: 1.0e+308}\n"),
              "neutral_sections[0].coast_before_s", "600 s")

    # --- physics: implausible routes, sections, speeds
    file_case("length_1e-6.yaml", "physics", route(length="0.000001"), "length_m", "10 m")
    file_case("length_5m.yaml", "physics", route(length="5"), "length_m", "10 m")
    file_case("length_10000km.yaml", "physics", route(length="1.0e+7"), "length_m", "2,000 km")
    file_case("kmh_tiny.yaml", "physics", route(kmh="0.001"), "speed_limits[0].kmh", "1 km/h")
    file_case("kmh_1e308.yaml", "physics", route(kmh="1.0e+308"), "speed_limits[0].kmh", "400 km/h")
    file_case("reversed.yaml", "physics", route(extra="tunnels:\n  - {from_m: 900, to_m: 100}\n"),
              "tunnels[0]", "from_m > to_m: section reversed")
    file_case("zero_length_section.yaml", "physics", route(extra="tunnels:\n  - {from_m: 900, to_m: 900}\n"),
              "tunnels[0]", "zero length")
    file_case("tolerance_gt_time.yaml", "physics", route(schedule="schedule: {run_time_s: 200, tolerance_s: 500}\n"),
              "schedule.tolerance_s")
    tiny = write("tiny_route.yaml", route(length="0.000001"))
    cases.append(Case("tiny_route_simulate", "physics", ["simulate", tiny, "--consist", SMALL], 2, (tiny, "length_m")))
    big_len = write("big_length.yaml", route(length="1.0e+308"))
    cases.append(Case("length_1e308_simulate", "physics", ["simulate", big_len, "--consist", SMALL], 2, (big_len, "length_m")))
    short = write("short_route.yaml", route(length="300"))
    for cmd in (["simulate"], ["optimize", "--time", "100"], ["compare", "--time", "100"],
                ["sweep", "--times", "100,110"], ["study", "--runs", "1", "--time", "100"]):
        cases.append(Case(f"shorter_than_train_{cmd[0]}", "physics", [cmd[0], short, *cmd[1:]], 2,
                          (short, "not longer than the train")))
    steep = write("steep.yaml", route(length="6000", permille="40", kmh="80",
                                      schedule="schedule: {run_time_s: 600, tolerance_s: 30}\n"))
    cases.append(Case("stalls_simulate", "message", ["simulate", steep, "--consist", "HXD1-C80x50"], 1,
                      ("stalled at", "+40.0 per mille")))
    cases.append(Case("stalls_optimize", "message", ["optimize", steep, "--consist", "HXD1-C80x50"], 1,
                      ("stalled at", "per mille")))
    slow = write("slow_limit.yaml", route(kmh="1"))
    cases.append(Case("slow_limit_optimize", "message", ["optimize", slow, "--consist", SMALL], 1,
                      ("1 km/h", " h")))
    downhill = write("downhill.yaml", route(length="8000", permille="-40", kmh="40",
                                            schedule="schedule: {run_time_s: 900, tolerance_s: 30}\n"))
    cases.append(Case("cannot_hold_limit", "message", ["simulate", downhill, "--consist", "HXD1-C80x50", "--no-air-brake"], 1,
                      ("cannot hold 40 km/h", "-40.0 per mille")))
    cases.append(Case("time_below_fastest", "message", ["optimize", good_route, "--consist", SMALL, "--time", "50"], 1,
                      ("below the fastest possible run",)))

    # --- consists and vehicles
    def consist_case(name, cls, text, *why, cmd=("validate",), stock=None, exit=2, named=True):
        path = write(name, text)
        if cmd == ("validate",):
            cases.append(Case(name, cls, ["validate", path], exit, (path,) + why, batch_file=path))
        else:
            argv = [cmd[0], good_route, *cmd[1:], "--consist", path] + (["--stock-dir", stock] if stock else [])
            cases.append(Case(name, cls, argv, exit, ((path,) if named else ()) + why))
        return path

    consist_case("billion_wagons.yaml", "physics", CONSIST.format(loco="HXD1-seed000", count="1", load="")
                 .replace("count: 1}\n", "count: 1000000000}\n", 1).replace("{type: HXD1-seed000, count: 1000000000}",
                                                                          "{type: HXD1-seed000, count: 1}")
                 .replace("{type: C64-seed000, count: 1}", "{type: C64-seed000, count: 1000000000}"),
                 "vehicles[1].count", cmd=("optimize", "--time", "200"))
    consist_case("billion_wagons_v.yaml", "physics", CONSIST.format(loco="HXD1-seed000", count="1", load="")
                 .replace("{type: C64-seed000, count: 1}", "{type: C64-seed000, count: 1000000000}"), "vehicles[1].count")
    many = "schema: locoplan/consist@1\nname: many\nvehicles:\n" + "  - {type: HXD1-seed000, count: 1}\n" * 1200
    consist_case("1200_entries.yaml", "physics", many, "vehicles", "1200 vehicles", cmd=("compare", "--time", "200"))
    consist_case("count_5000_digits.yaml", "number", CONSIST.format(loco="HXD1-seed000", count=digits, load=""),
                 "vehicles[0].count", "digits")
    consist_case("count_inf.yaml", "number", CONSIST.format(loco="HXD1-seed000", count=".inf", load=""), "vehicles[0].count")
    consist_case("load_nan.yaml", "number", CONSIST.format(loco="HXD1-seed000", count="1", load=", load_t: .nan"),
                 "vehicles[1].load_t", "finite")
    consist_case("consist_alias_bomb.yaml", "yaml", CONSIST.format(loco="HXD1-seed000", count="1", load="") + alias_bomb(),
                 "alias", cmd=("simulate",))
    stock = files / "stock"
    stock.mkdir(exist_ok=True)
    (stock / "BadLoco.yaml").write_text(VEHICLE.format(name="BadLoco", mass=".inf", a="2.23", force="532"), encoding="utf-8")
    (stock / "NanLoco.yaml").write_text(VEHICLE.format(name="NanLoco", mass="200", a=".nan", force="532"), encoding="utf-8")
    (stock / "HugeLoco.yaml").write_text(VEHICLE.format(name="HugeLoco", mass="200", a="2.23", force="1.0e+308"), encoding="utf-8")
    consist_case("uses_bad_loco.yaml", "number", CONSIST.format(loco="BadLoco", count="1", load=""),
                 str(stock / "BadLoco.yaml"), "mass_t", "finite", cmd=("simulate",), stock=str(stock), named=False)
    consist_case("uses_nan_loco.yaml", "number", CONSIST.format(loco="NanLoco", count="1", load=""),
                 str(stock / "NanLoco.yaml"), "resistance_n_per_kn.a", cmd=("simulate",), stock=str(stock), named=False)
    consist_case("uses_huge_force.yaml", "number", CONSIST.format(loco="HugeLoco", count="1", load=""),
                 str(stock / "HugeLoco.yaml"), "traction_kn[1]", cmd=("simulate",), stock=str(stock), named=False)
    # a stock folder holding a FIFO and a /dev/zero link among its vehicle files: looked at, never hung on
    trap = files / "trapped_stock"
    trap.mkdir(exist_ok=True)
    (trap / "HXD1-seed000.yaml").write_text((ROOT / "configs/rolling_stock/HXD1-seed000.yaml").read_text(), encoding="utf-8")
    if not (trap / "Pipe.yaml").exists():
        os.mkfifo(trap / "Pipe.yaml")
    if not (trap / "Zero.yaml").is_symlink():
        os.symlink("/dev/zero", trap / "Zero.yaml")
    trapped = write("trapped_consist.yaml", CONSIST.format(loco="HXD1-seed000", count="1", load=""))
    cases.append(Case("stock_dir_with_fifo", "file", ["simulate", good_route, "--consist", trapped, "--stock-dir", str(trap),
                                                      "--json"], 0, (), note="the FIFO and /dev/zero are skipped"))
    cases.append(Case("stock_dir_missing", "option", ["simulate", good_route, "--consist", SMALL, "--stock-dir", "/nonexistent"],
                      2, ("/nonexistent", "--stock-dir", "no such folder")))
    cases.append(Case("stock_dir_is_file", "option", ["simulate", good_route, "--consist", SMALL, "--stock-dir", good_route],
                      2, (good_route, "--stock-dir", "not a folder")))
    cases.append(Case("stock_dir_missing_validate", "option", ["validate", good_route, "--stock-dir", "/nonexistent"],
                      2, ("/nonexistent", "--stock-dir")))

    # --- optimiser parameter files
    def params_case(name, text, *why, exit=2):
        path = write(name, text)
        cases.append(Case(name, "params", ["optimize", good_route, "--consist", SMALL, "--params", path], exit, (path,) + why))

    params_case("pop_1e8.yaml", PARAMS.format(pop="100000000", iters="100", extra=""), "pop_size", "1,000")
    params_case("iter_1e9.yaml", PARAMS.format(pop="50", iters="1000000000", extra=""), "max_iter", "10,000")
    params_case("pop_times_iter.yaml", PARAMS.format(pop="1000", iters="10000", extra=""), "evaluations")
    params_case("batches_1e9.yaml", PARAMS.format(pop="50", iters="100", extra="max_sample_batches: 1000000000\n"),
                "max_sample_batches")
    params_case("w_max_inf.yaml", PARAMS.format(pop="50", iters="100", extra="w_max: .inf\n"), "w_max", "finite")
    params_case("levy_nan.yaml", PARAMS.format(pop="50", iters="100", extra="levy_scale: .nan\n"), "levy_scale", "finite")
    params_case("pop_5000_digits.yaml", PARAMS.format(pop=digits, iters="100", extra=""), "pop_size", "digits")
    params_case("params_alias_bomb.yaml", PARAMS.format(pop="50", iters="100", extra="") + alias_bomb(), "alias")
    params_case("params_nested.yaml", PARAMS.format(pop="50", iters="100", extra="x: " + "[" * 3000 + "]" * 3000 + "\n"), "nested")
    cases.append(Case("params_fifo", "params", ["optimize", good_route, "--consist", SMALL, "--params", str(fifo)], 2,
                      (str(fifo), "FIFO")))
    cases.append(Case("params_dev_zero", "params", ["optimize", good_route, "--consist", SMALL, "--params", "/dev/zero"], 2,
                      ("/dev/zero", "not a regular file")))
    cases.append(Case("params_dir_missing", "params", ["study", good_route, "--consist", SMALL, "--runs", "1",
                                                       "--params-dir", "/nonexistent"], 2, ("/nonexistent", "--params-dir")))

    # --- option values
    sim = ["simulate", good_route, "--consist", SMALL]
    opt = ["optimize", good_route, "--consist", SMALL]

    def option(name, argv, *why, exit=2, cls="option"):
        cases.append(Case(name, cls, argv, exit, why))

    for v in ("nan", "inf", "-inf", "1e9", "0", "-1", "1e-9", "0.01"):
        option(f"step_{v}", sim + ["--step", v], CMDLINE, "--step")
    option("step_above_route", ["simulate", write("r300.yaml", route(length="300")), "--consist", SMALL, "--step", "200"],
           CMDLINE, "--step", "cells")
    for v in ("-1", "-99999999999999999999", str(2 ** 63)):
        option(f"seed_{v}", opt + ["--seed", v], CMDLINE, "--seed", "0 .. 2**63 - 1")
    option("seed_study_negative", ["study", good_route, "--consist", SMALL, "--runs", "2", "--seed", "-1"], CMDLINE, "--seed")
    for v in ("nan", "inf", "0", "-5", "1e308", "1e-300", "0.5"):
        option(f"time_{v}", opt + ["--time", v], CMDLINE, "--time")
    option("time_nan_simulate", sim + ["--time", "nan"], CMDLINE, "--time")
    for v in ("nan", "inf", "-1", "0", "1e300"):
        option(f"e_min_{v}", sim + ["--strategy", "proposed", "--e-min", v], CMDLINE, "--e-min")
    option("e_min_nan_optimize", opt + ["--e-min", "nan"], CMDLINE, "--e-min")
    for v in ("nan", "inf", "-1"):
        option(f"tolerance_{v}", opt + ["--tolerance", v], CMDLINE, "--tolerance")
    for v in ("T:0,C:nan", "T:0,C:inf", "T:0,C:-inf", "T:0,C:1e308", "T:nan", "T:0,C:nan,B", ",,,", "T:0,C:1e-400,B"):
        option(f"sequence_{v}", sim + ["--sequence", v], CMDLINE, "--sequence")
    for v in ("nan,0.5", "nan,nan", "inf,-inf", "0.5", "a,b", "1e308,-1e308", "-0.5,1.5", "0.5,0.5,0"):
        option(f"weights_{v}", opt + ["--weights", v], CMDLINE, "--weights")
    swp = ["sweep", good_route, "--consist", SMALL]
    for v in ("0:1:0.0000001", "0:1e300:1e-300", "0:inf:0.1", "0:1:nan", "0:1:0", "1:0:0.1", "nan", "0.5,nan", "0:1:inf"):
        option(f"sweep_weights_{v}", swp + ["--weight-grid", v], CMDLINE, "--weight-grid")
    option("sweep_weights_limit", swp + ["--weight-grid", "0:1:0.0000001"], "1,000 runs")
    option("sweep_weights_old_name", swp + ["--weights", "0:1:0.0000001"], "1,000 runs")
    for v in ("0:1000000000:1", "nan", "inf", "-5", "1e308,200", "200,0"):
        option(f"sweep_times_{v}", swp + ["--times", v], CMDLINE, "--times")
    for v in (str(10 ** 9), "-1", "0", str(10 ** 30)):
        option(f"runs_{v}", ["study", good_route, "--consist", SMALL, "--runs", v], CMDLINE, "--runs")
    for v in ("nan", "inf", "-1", "1"):
        option(f"rotating_{v}", sim + ["--rotating-mass", v], CMDLINE, "--rotating-mass")
    option("algorithm_bogus", opt + ["--algorithm", "bogus"], CMDLINE, "--algorithm", "unknown optimiser")
    option("strategies_empty", ["compare", good_route, "--consist", SMALL, "--strategies", ",,"], CMDLINE, "--strategies")
    option("drivers_1e9", ["drivers", "simulate", good_route, "--consist", SMALL, "--out", str(tmp / "logs1"),
                           "--drivers", "1000000000"], CMDLINE, "--drivers")
    option("drivers_runs_1e9", ["drivers", "simulate", good_route, "--consist", SMALL, "--out", str(tmp / "logs2"),
                                "--runs", "1000000000"], CMDLINE, "--runs")
    option("drivers_masses_huge", ["drivers", "simulate", good_route, "--out", str(tmp / "logs3"), "--masses", "1e12"],
           "--masses")
    option("drivers_masses_nan", ["drivers", "simulate", good_route, "--out", str(tmp / "logs4"), "--masses", "nan"],
           CMDLINE, "--masses")
    option("drivers_seed_neg", ["drivers", "simulate", good_route, "--consist", SMALL, "--out", str(tmp / "logs5"),
                                "--seed", "-1"], CMDLINE, "--seed")
    option("drivers_tolerance_nan", ["drivers", "simulate", good_route, "--consist", SMALL, "--out", str(tmp / "logs6"),
                                     "--tolerance", "nan"], CMDLINE, "--tolerance")
    option("drivers_times_inf", ["drivers", "simulate", good_route, "--consist", SMALL, "--out", str(tmp / "logs7"),
                                 "--times", "inf"], CMDLINE, "--times")
    logs_dir = ROOT / "tests" / "data" / "learn"
    option("learn_divisions_huge", ["learn", str(logs_dir), "--out", str(tmp / "p1.json"), "--divisions", "1000000000"],
           CMDLINE, "--divisions")
    option("learn_holdout_nan", ["learn", str(logs_dir), "--out", str(tmp / "p2.json"), "--holdout", "nan"], CMDLINE, "--holdout")
    option("learn_seed_neg", ["learn", str(logs_dir), "--out", str(tmp / "p3.json"), "--seed", "-1"], CMDLINE, "--seed")
    option("learn_level_inf", ["learn", str(logs_dir), "--out", str(tmp / "p4.json"), "--level", "inf"], CMDLINE, "--level")
    option("advise_mass_huge", ["advise", good_route, "--patterns", str(tmp / "none.json"), "--mass", "1e12"], "--mass:")
    option("advise_patterns_fifo", ["advise", good_route, "--patterns", str(fifo)], str(fifo), "FIFO")
    option("ocp_nodes_huge", ["ocp", str(ROOT / "routes/seed000-flat.yaml"), "--method", "cvp", "--nodes", "1000000000"],
           "--nodes")
    option("ocp_study_repeats_huge", ["ocp-study", "--repeats", "1000000000"], "--repeats")
    option("import_cap_nan", ["import", "ttobench", str(good_route), "--out", str(tmp), "--cap-kmh", "nan"], "--cap-kmh")
    option("import_load_inf", ["import", "railtoolkit", str(good_route), "--out", str(tmp), "--load-fraction", "inf"],
           "--load-fraction")

    # --- output paths: checked before the work, all outputs or none, modes from the umask
    out_dir = tmp / "out"
    out_dir.mkdir(exist_ok=True)
    dir_json = out_dir / "folder.json"
    dir_json.mkdir(exist_ok=True)
    option("out_is_folder", sim + ["--out", str(dir_json)], str(dir_json), "--out", "folder", cls="output")
    option("out_dot", sim + ["--out", str(out_dir)], "--out", cls="output")
    option("out_unwritable", sim + ["--out", "/proc/locoplan.json"], "/proc/locoplan.json", "--out", "cannot write", cls="output")
    in_the_way = out_dir / "a-file"
    in_the_way.write_text("")
    # a missing folder is created; a file where a folder must be is refused
    option("out_folder_is_a_file", sim + ["--out", str(in_the_way / "no/such/x.json")], "--out", "is not a folder", cls="output")
    option("out_name_too_long", sim + ["--out", str(out_dir / ("x" * 300 + ".json"))], "--out", "cannot write", cls="output")
    pipe_json = out_dir / "pipe.json"
    if not pipe_json.exists():
        os.mkfifo(pipe_json)
    option("out_is_a_fifo", sim + ["--out", str(pipe_json)], str(pipe_json), "--out", "not a regular file", cls="output")
    option("drivers_out_unwritable", ["drivers", "simulate", good_route, "--out", "/proc/logs", "--drivers", "1", "--runs", "1"],
           "/proc/logs", "--out", "cannot write", cls="output")
    option("out_parent_is_file", sim + ["--out", good_route + "/x.json"], "--out", cls="output")
    (out_dir / "folder.png").mkdir(exist_ok=True)
    option("plot_is_folder", sim + ["--plot", str(out_dir / "folder.png")], "--plot", "folder", cls="output")
    first = out_dir / "first.json"

    def nothing_written(*paths: Path):
        def check():
            there = [str(p) for p in paths if p.exists()]
            stray = [p.name for p in out_dir.iterdir() if p.name.startswith(".") and p.is_file()]
            if there or stray:
                return f"left behind: {there + stray}"
            return None
        return check

    cases.append(Case("out_ok_plot_unwritable", "output", sim + ["--out", str(first), "--plot", "/proc/locoplan.png"], 2,
                      ("/proc/locoplan.png", "--plot"), after=nothing_written(first)))
    second = out_dir / "second.csv"
    cases.append(Case("out_ok_plot_folder_is_a_file", "output", opt + ["--out", str(second), "--plot", str(in_the_way / "nope/p.png")],
                      2, ("--plot", "is not a folder"), after=nothing_written(second)))
    third = out_dir / "third.json"
    cases.append(Case("outputs_then_infeasible_input", "output", sim + ["--out", str(third), "--sequence", "T:0,C:nan"], 2,
                      ("--sequence",), after=nothing_written(third)))

    def mode_is(path: Path, want: int):
        def check():
            if not path.exists():
                return f"{path} was not written"
            got = stat.S_IMODE(path.stat().st_mode)
            return None if got == want else f"{path.name} has mode {got:o}, expected {want:o}"
        return check

    study_png = out_dir / "study.png"
    cases.append(Case("study_plot_ok", "output", ["study", good_route, "--consist", SMALL, "--algorithms", "issa", "--runs", "1",
                                                   "--params-dir", str(ROOT / "tests/data/optimizers"), "--plot", str(study_png)],
                      0, (), after=lambda: None if study_png.is_file() else "study.png was not written"))
    new_csv = out_dir / "new.csv"
    cases.append(Case("umask_022_new_file", "output", sim + ["--out", str(new_csv)], 0, (), after=mode_is(new_csv, 0o644),
                      umask=0o022))
    kept = out_dir / "kept.json"
    kept.write_text("{}\n")
    kept.chmod(0o644)
    cases.append(Case("umask_022_overwrite_0644", "output", sim + ["--out", str(kept)], 0, (), after=mode_is(kept, 0o644),
                      umask=0o022))
    tight = out_dir / "tight.json"
    cases.append(Case("umask_077_new_file", "output", sim + ["--out", str(tight)], 0, (), after=mode_is(tight, 0o600),
                      umask=0o077))

    # --- messages: never an empty file field, never markup eaten
    option("empty_file_field_weights", opt + ["--weights", "x"], f"{CMDLINE}: --weights")
    option("markup_sequence", sim + ["--sequence", "T:0,[bold]X:5"], "[BOLD]X", cls="message")
    marked = write("marked_route.yaml", route(name="'[bold]Strecke[/bold] [m]'"))
    cases.append(Case("markup_route_name", "message", ["simulate", marked, "--consist", SMALL], 0, (),
                      expect_out=("[bold]Strecke[/bold] [m]",)))
    cases.append(Case("markup_help", "message", ["simulate", "--help"], 0, (), expect_out=("[m]", "[s]", "[kWh]")))
    nocurve = write("no_curve.yaml", VEHICLE.format(name="NoCurve", mass="200", a="2.23", force="532")
                    .replace("traction_kn: [[0, 532.0], [120, 532]]\n", ""))
    cases.append(Case("markup_curve_hint", "message", ["validate", nocurve], 2, (nocurve, "traction_kn",
                                                                                "[[speed_kmh, force_kn], ...]")))
    markup_route = write("[m]route.yaml", route(length="abc"))
    cases.append(Case("markup_in_path", "message", ["simulate", markup_route, "--consist", SMALL], 2, ("[m]route.yaml", "length_m")))

    _every_numeric_option(cases, tmp)
    _every_text_number_option(cases, tmp)
    for v in ("nan", "0", "-1", "inf", "1e-300"):  # --time beside --times is checked, not ignored
        cases.append(Case(f"sweep_time_{v}_with_times", "option", ["sweep", good_route, "--consist", SMALL, "--times", "200,210",
                                                                  "--time", v], 2, (CMDLINE, "--time")))
    for v in ("nan", "-1", "abc"):  # ocp --time is checked whatever the objective (minimum time does not use it)
        cases.append(Case(f"ocp_time_{v}_objective_time", "option", ["ocp", good_route, "--time", v], 2, (CMDLINE, "--time")))
    cases.append(Case("ocp_efficiency_tiny", "option", ["ocp", good_route, "--objective", "energy", "--efficiency", "1e-300"], 2,
                      (CMDLINE, "--efficiency", "[0.1, 1]")))
    cases.append(Case("sequence_empty_item", "option", ["simulate", good_route, "--consist", SMALL, "--sequence", "T:0,,C:900"],
                      2, (CMDLINE, "--sequence", "item 2", "is empty")))
    for flag, v in (("--times", "200,,210"), ("--times", "200,210,")):
        cases.append(Case(f"bound_times_empty_item_{v}", "option", ["bound", good_route, flag, v], 2, (CMDLINE, flag, "is empty")))
    _output_and_message_cases(cases, write, good_route, tmp)
    _schema_cases(cases, write, good_route, tmp)
    _yaml11_cases(cases, write, good_route, tmp)
    _yaml11_bool_cases(cases, write, good_route, tmp)
    _store_cases(cases, write, good_route, tmp)
    _study_cases(cases, write, good_route, steep, tmp)
    _import_and_json_cases(cases, write, good_route, tmp)
    _full_disk_cases(cases, good_route, tmp)
    _hang_cases(cases, write, good_route, tmp)
    _neutral_near_stop_cases(cases, write)
    _partial_folder_cases(cases, good_route, tmp)
    _store_mid_run_cases(cases, write, good_route, tmp)
    _stderr_full_cases(cases, write, good_route, tmp)
    _journey_cases(cases, write, good_route, tmp)
    _trust_cases(cases, write, good_route, steep, tmp)
    merge_ok = write("merge_override.yaml", route(extra="curves:\n  - &c {from_m: 100, to_m: 200, radius_m: 800}\n"
                                                       "  - {<<: *c, from_m: 300, to_m: 400}\n"))
    cases.append(Case("merge_key_overridden", "message", ["validate", merge_ok], 0, (),
                      note="an explicit key overrides a merged one (YAML's rule): no duplicate"))
    merge_dup = write("merge_dup.yaml", route(extra="curves:\n  - &c {from_m: 100, to_m: 200, radius_m: 800}\n"
                                                    "  - {<<: *c, from_m: 300, to_m: 400, from_m: 310}\n"))
    cases.append(Case("merge_key_real_duplicate", "message", ["validate", merge_dup], 2, (merge_dup, "curves[1].from_m",
                                                                                        "duplicate key")))
    tiny_route = write("route_100m.yaml", route(length="100"))
    cases.append(Case("route_shorter_than_train_not_step", "message", ["simulate", tiny_route], 2,
                      (tiny_route, "not longer than the train"), forbid=("--step",)))
    ns_start = write("neutral_at_start.yaml", route(extra="neutral_sections:\n  - {from_m: 0, to_m: 50}\n"))
    cases.append(Case("neutral_section_at_start", "message", ["simulate", ns_start, "--consist", SMALL], 2,
                      (ns_start, "neutral_sections[0]", "can never start"), forbid=("stalled at",)))
    return cases


def commands():
    """(command words, click command) of every command of the app, subcommands included."""
    import typer

    sys.path.insert(0, str(ROOT))
    from locoplan.cli import app

    def walk(group, prefix=()):
        for name, cmd in group.commands.items():
            if hasattr(cmd, "commands"):
                yield from walk(cmd, prefix + (name,))
            else:
                yield prefix + (name,), cmd
    return list(walk(typer.main.get_command(app)))


def numeric_options(cmd) -> list[tuple[str, str]]:
    """(flag, 'int' or 'float') of every numeric option of a click command."""
    out = []
    for p in cmd.params:
        ann = getattr(getattr(p, "type_descriptor", None), "annotation", None)
        if p.opts and p.opts[0].startswith("--") and ann in (int, float):
            out.append((p.opts[0], "int" if ann is int else "float"))
    return out


def _missing_required(cmd, tmp: Path) -> list[str]:
    """A command's required arguments and options, each naming a file that does not exist."""
    args = []
    for p in cmd.params:
        if p.required and not p.opts[0].startswith("--"):
            args += ["railtoolkit"] if p.name == "fmt" else [str(tmp / "no_such_input.yaml")]
        elif p.required:
            args += [p.opts[0], str(tmp / f"no_such_{p.name}")]
    return args


def _every_numeric_option(cases: list[Case], tmp: Path) -> None:
    """Every numeric option of every command, given nan, inf, a negative, zero and a huge value: refused by its
    bound before any file is read (the arguments name files that do not exist), naming the option."""
    sys.path.insert(0, str(ROOT))
    from locoplan import bounds

    for words, cmd in commands():
        args = _missing_required(cmd, tmp)
        for flag, kind in numeric_options(cmd):
            entry = bounds.OPTIONS.get(f"{' '.join(words)} {flag}") or bounds.OPTIONS[flag]
            lo, hi = entry[1], entry[2]
            values = ["-1", "1e30"] + (["nan", "inf", "-inf"] if kind == "float" else [str(10**40)])
            if lo > 0 or entry[3]:
                values.append("0")
            if kind == "float" and lo > 0:
                values.append("1e-300")  # positive, below the bound (a mesh tolerance that would run for minutes)
            if kind == "int" and hi < 1000:
                values.append("1000")
            for v in values:
                if kind == "int" and v == "1e30":
                    v = str(int(hi) + 1)
                if kind == "float" and float(v) == hi + 1:
                    continue
                name = f"every_option_{'_'.join(words)}_{flag[2:]}_{v}"
                cases.append(Case(name, "option", [*words, *args, flag, v], 2, (flag,),
                                  note="every numeric option through the bounds module"))


NOT_NUMBERS = {"NAME", "NAME,...", "STATE", "T|K|C|B", "STATION", "TAG", "ID", "FILE", "FILE|NAME", "DIR", "MODE", "time|energy", "traction|net", "ADDRESS", "csv|parquet|json", "EXPR",
               "FIELD,...", "PLAN"}
"""Metavars of text options that hold no number (``PLAN``, a --sequence, is checked against its route's length)."""


def text_number_options(cmd) -> list[str]:
    """Flags of a command's text options that hold numbers (a time form, a list, a grid, a curve)."""
    out = []
    for p in cmd.params:
        ann = getattr(getattr(p, "type_descriptor", None), "annotation", None)
        if p.opts and p.opts[0].startswith("--") and ann is str and p.metavar not in NOT_NUMBERS:
            out.append(p.opts[0])
    return out


def _every_text_number_option(cases: list[Case], tmp: Path) -> None:
    """Every text option that holds numbers (--time, --times, --weights, --factors, --seeds, --masses,
    --efficiency, ...), given nan, inf, a negative, a huge value, text, an empty item and an overflowing
    float: refused by its parser in the bounds module before any file is read, naming the option."""
    for words, cmd in commands():
        args = _missing_required(cmd, tmp)
        for flag in text_number_options(cmd):
            named = "--weight-grid" if words == ("sweep",) and flag == "--weights" else flag  # an old name, told as the new
            for label, v in (("nan", "nan"), ("inf", "inf"), ("neg", "-1"), ("huge", "1e30"), ("text", "abc"),
                             ("empty_item", "1,,2"), ("overflow", "1e400")):
                cases.append(Case(f"every_text_number_{'_'.join(words)}_{flag[2:]}_{label}", "option", [*words, *args, flag, v],
                                  2, (CMDLINE, named), note="a text option's numbers through the bounds module"))


def _output_and_message_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """stdout on a full device; empty option values; messages that must stay one line each, short and plain."""
    sim = ["simulate", good_route, "--consist", SMALL]
    full = "/dev/full"
    for name, argv in (("validate", ["validate", good_route]), ("validate_json", ["validate", good_route, "--json"]),
                       ("simulate_json", sim + ["--json"]), ("optimize_json", ["optimize", good_route, "--consist", SMALL, "--json"]),
                       ("simulate_table", sim)):
        cases.append(Case(f"stdout_dev_full_{name}", "output", argv, 2, ("<stdout>", "No space left"), stdout_file=full))
    for name, argv, flag in (("bound_times", ["bound", good_route, "--times", ""], "--times"),
                             ("pareto_factors", ["pareto", good_route, "--factors", ""], "--factors"),
                             ("drivers_times", ["drivers", "simulate", good_route, "--out", str(tmp / "logs_e"), "--times", ""], "--times"),
                             ("consist", sim[:2] + ["--consist", ""], "--consist"),
                             ("strategy_blank", sim + ["--strategy", "  "], "--strategy"),
                             ("weights", ["optimize", good_route, "--weights", ""], "--weights"),
                             ("sweep_times", ["sweep", good_route, "--times", ""], "--times"),
                             ("seeds", ["pareto", good_route, "--seeds", ""], "--seeds")):
        cases.append(Case(f"empty_value_{name}", "option", argv, 2, (CMDLINE, flag, "is empty")))
    out_dir = tmp / "out"
    out_dir.mkdir(exist_ok=True)
    cases.append(Case("out_is_existing_folder_no_suffix", "output", sim + ["--out", str(out_dir)], 2, ("--out", "is a folder"),
                      forbid=("unknown output type",)))
    # a newline in a file name must not forge an 'error:' line, an ANSI escape must not reach the terminal
    forged = "bad\nerror: forged.yaml"
    cases.append(Case("newline_in_file_name", "message", ["simulate", str(tmp / forged), "--consist", SMALL], 2,
                      ("\\nerror: forged.yaml", "no such file"), forbid=("\nerror: forged",)))
    cases.append(Case("ansi_in_option", "message", sim[:2] + ["--consist", "\x1b[31mred\x1b[0m"], 2, ("\\x1b[31mred",),
                      forbid=("\x1b",)))
    huge = "T:0," + "K" * 100_000
    cases.append(Case("option_100kb", "message", sim + ["--sequence", huge], 2, (CMDLINE, "--sequence", "characters"),
                      max_stderr_chars=3_000))
    keys = write("unknown_30000_keys.yaml", route() + "".join(f"k{i}: 1\n" for i in range(30_000)))
    cases.append(Case("unknown_30000_keys", "message", ["validate", keys], 2, ("unknown key", "29,950 more problems"),
                      max_stderr_chars=30_000))
    cases.append(Case("unknown_30000_keys_simulate", "message", ["simulate", keys, "--consist", SMALL], 2,
                      ("unknown key", "29,950 more problems"), max_stderr_chars=30_000))


def _study_cases(cases: list[Case], write, good_route: str, steep: str, tmp: Path) -> None:
    """Study files: every value the command line bounds, bounded the same, but named at the file's line."""
    def study(name: str, body: str, *why: str, exit: int = 2, route: str = good_route, field_: str = "",
              consist: str = SMALL):
        path = write(name, f"schema: locoplan/study@1\nroutes: [{route}]\nconsists: [{consist}]\n{body}")
        store = str(tmp / "stores" / f"{name}.sqlite")
        # named as study.yaml:LINE: FIELD (the line of the field's key; the file's first three lines are its head)
        key = field_.split("[")[0].split(".")[0]
        line = next((4 + i for i, text in enumerate(body.splitlines()) if text.startswith(f"{key}:")), None)
        where = (f"{path}:{line}: {field_}",) if field_ and line else (f"{path}:", field_) if field_ else (f"{path}:",)
        cases.append(Case(name, "study", ["batch", path, "--store", store, "--workers", "1", "--quiet"], exit,
                          where + why, forbid=(CMDLINE,)))

    study("study_weights_nan.yaml", "times: [200]\nweights: [.nan, .nan]\n", "finite", field_="weights[0]")
    study("study_weights_inf.yaml", "times: [200]\nweights: [.inf, 0]\n", "finite", field_="weights[0]")
    study("study_times_true.yaml", "times: [true]\n", "expected seconds", field_="times[0]")
    study("study_times_null.yaml", "times: [~]\n", "expected seconds", field_="times[0]")
    study("study_times_list.yaml", "times: [[200]]\n", "expected seconds", field_="times[0]")
    study("study_times_huge.yaml", "times: [1.0e+9]\n", "a week", field_="times[0]")
    study("study_times_zero.yaml", "times: [0]\n", "a second", field_="times[0]")
    study("study_times_nan.yaml", "times: [.nan]\n", "finite", field_="times[0]")
    study("study_times_base60.yaml", "times: [3:20]\n", "base-60", field_="times[0]")
    study("study_factor_huge.yaml", "times: [1000x]\n", "at most 10,", field_="times[0]")
    study("study_factor_50x.yaml", "times: [50x]\n", "at most 10, as on the command line", field_="times[0]")
    # strict types, as in every locoplan file: a boolean or a quoted number is no seed, weight, tolerance or flag
    study("study_seed_true.yaml", "times: [200]\nseeds: [true]\n", "valid integer", field_="seeds[0]")
    study("study_seed_quoted.yaml", "times: [200]\nseeds: ['7']\n", "valid integer", field_="seeds[0]")
    study("study_tolerance_true.yaml", "times: [200]\ntolerance_s: true\n", "valid number", field_="tolerance_s")
    study("study_tolerance_quoted.yaml", "times: [200]\ntolerance_s: '10'\n", "valid number", field_="tolerance_s")
    study("study_weights_bool.yaml", "times: [200]\nweights: [true, false]\n", "valid number", field_="weights[0]")
    study("study_weights_quoted.yaml", "times: [200]\nweights: ['0.5', '0.5']\n", "valid number", field_="weights[0]")
    study("study_weights_three.yaml", "times: [200]\nweights: [0.2, 0.3, 0.5]\n", field_="weights")
    study("study_step_true.yaml", "times: [200]\nmodel: {step_m: true}\n", "valid number", field_="model.step_m")
    study("study_window_one.yaml", "times: [200]\nwindow: 1\n", "valid boolean", field_="window")
    study("study_tolerance_at_t0.yaml", "times: [200]\ntolerance_s: 200\n", "not below the planned running time",
          field_="tolerance_s")
    study("study_tolerance_above_factor_time.yaml", "times: [1.1x]\ntolerance_s: 1000\n",
          "not below the planned running time", field_="tolerance_s")
    study("study_tolerance_above_t0.yaml", "times: [200]\ntolerance_s: 1000\n", "not below the planned running time",
          field_="tolerance_s")
    study("study_tolerance_inf.yaml", "times: [200]\ntolerance_s: .inf\n", "finite", field_="tolerance_s")
    study("study_step_tiny.yaml", "times: [200]\nmodel: {step_m: 0.0001}\n", "0.1", field_="model.step_m")
    study("study_seed_huge.yaml", f"times: [200]\nseeds: [{2**64}]\n", "2**63", field_="seeds[0]")
    study("study_seed_negative.yaml", "times: [200]\nseeds: [-1]\n", "2**63", field_="seeds[0]")
    study("study_rotating_nan.yaml", "times: [200]\nmodel: {rotating_mass: .nan}\n", "finite",
          field_="model.rotating_mass")
    study("study_factor_unclimbable.yaml", "times: [1.1x]\n", "times[0]", "stalled at", exit=1, route=steep,
          consist="HXD1-C80x50")


def _import_and_json_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """Imports and JSON inputs: all files or none, names a file system takes, JSON that blows up parsers."""
    import json

    ext = ROOT.parent / "shared" / "data" / "external"
    if not ext.is_dir():
        ext = Path("/work/shared/data/external")
    track = ext / "ttobench" / "tracks" / "00_var_speed_limit_100.json"
    rt_path, rt_train = ext / "railtoolkit" / "paths" / "slope.yaml", ext / "railtoolkit" / "trains" / "freight.yaml"
    imports = tmp / "imports"
    imports.mkdir(exist_ok=True)

    def folder(name: str) -> Path:
        d = imports / name
        d.mkdir(exist_ok=True)
        return d

    def unchanged(d: Path, *allowed: str):
        def check():
            extra = sorted(p.name for p in d.iterdir() if p.name not in allowed)
            return f"left in {d.name}: {extra}" if extra else None
        return check

    if track.is_file():
        text = track.read_text()
        data = json.loads(text)
        j = imports / "json"
        j.mkdir(exist_ok=True)
        (j / "int_5000.json").write_text(text.replace('"value": 0', '"value": ' + "9" * 5000, 1))
        (j / "deep.json").write_text(text.rstrip()[:-1] + ', "x": ' + "[" * 100_000 + "]" * 100_000 + "}\n")
        (j / "nan.json").write_text(text.replace('"value": 0', '"value": NaN', 1))
        long_id = dict(data, metadata=dict(data["metadata"], id="x" * 300))
        (j / "long_id.json").write_text(json.dumps(long_id))
        (j / "exp_huge.json").write_text(text.replace('"value": 0', '"value": 1e99999', 1))
        (j / "float_5000.json").write_text(text.replace('"value": 0', '"value": 0.' + "1" * 5000, 1))
        (j / "deep_objects.json").write_text('{"a": ' * 100_000 + "1" + "}" * 100_000)
        (j / "dup_key.json").write_text(text.rstrip()[:-1] + ', "metadata": {"id": "other"}}\n')
        (j / "top_list.json").write_text("[1, 2]\n")
        (j / "empty.json").write_text("")
        for label, bad_id in (("id_slash", "../escape"), ("id_nul", "a\u0000b"), ("id_number", 7), ("id_empty", ""),
                              ("id_dotdot", "..")):
            (j / f"{label}.json").write_text(json.dumps(dict(data, metadata=dict(data["metadata"], id=bad_id))))
        # 128 two-byte letters (256 bytes, past the 255 a file system takes): ids are ASCII letters, digits, _ - .
        (j / "id_multibyte.json").write_text(json.dumps(dict(data, metadata=dict(data["metadata"], id="é" * 128)),
                                                        ensure_ascii=False), encoding="utf-8")
        for name, why in (("int_5000", "5,000 digits"), ("deep", "nested deeper"), ("nan", "NaN"), ("long_id", "255"),
                          ("exp_huge", "beyond the range"), ("float_5000", "5,001 digits"), ("deep_objects", "nested deeper"),
                          ("dup_key", "metadata: duplicate key"), ("top_list", "expected a JSON object"),
                          ("empty", "not valid JSON"), ("id_slash", "metadata.id"), ("id_nul", "metadata.id"),
                          ("id_number", "metadata.id"), ("id_empty", "metadata.id"), ("id_dotdot", "metadata.id"),
                          ("id_multibyte", "letters, digits")):
            d = folder(f"tto_{name}")
            cases.append(Case(f"ttobench_{name}", "json", ["import", "ttobench", str(j / f"{name}.json"), "--out", str(d)], 2,
                              (str(j / f"{name}.json"), why), after=unchanged(d)))
        d = folder("tto_fifo")
        fifo = d / "00_var_speed_limit_100.yaml"
        if not fifo.exists():
            os.mkfifo(fifo)
        cases.append(Case("ttobench_onto_fifo", "json", ["import", "ttobench", str(track), "--out", str(d)], 2,
                          (str(fifo), "not a regular file"), after=unchanged(d, fifo.name)))
        d = folder("tto_full")
        cases.append(Case("ttobench_disk_full", "json", ["import", "ttobench", str(track), "--out", str(d)], 2,
                          ("--out", "none was written"), fsize=1000, after=unchanged(d)))
        pat = imports / "patterns_deep.json"
        pat.write_text("{" + '"a": [' * 50_000 + "]" * 50_000 + "}")
        cases.append(Case("patterns_deep", "json", ["advise", good_route, "--patterns", str(pat)], 2,
                          (str(pat), "nested deeper")))
        pat2 = imports / "patterns_int.json"
        pat2.write_text('{"schema": ' + "7" * 5000 + "}")
        cases.append(Case("patterns_int_5000", "json", ["advise", good_route, "--patterns", str(pat2)], 2,
                          (str(pat2), "5,000 digits")))
        for label, body, why in (("nan", '{"schema": NaN}', "NaN"), ("exp_huge", '{"schema": 1e99999}', "beyond the range"),
                                 ("dup_key", '{"schema": "locoplan/patterns@1",\n "schema": "x"}', "duplicate key"),
                                 ("deep_objects", '{"a": ' * 100_000 + "1" + "}" * 100_000, "nested deeper"),
                                 ("top_list", "[]", "valid dictionary")):
            pat3 = imports / f"patterns_{label}.json"
            pat3.write_text(body)
            cases.append(Case(f"patterns_{label}", "json", ["advise", good_route, "--patterns", str(pat3)], 2, (str(pat3), why)))
    if rt_path.is_file():
        d = folder("rt_stock_is_file")
        (d / "rolling_stock").write_text("in the way\n")
        cases.append(Case("railtoolkit_folder_is_a_file", "json", ["import", "railtoolkit", str(rt_path), str(rt_train),
                                                                    "--out", str(d)], 2,
                          (str(d / "rolling_stock"), "is a file where the folder"), after=unchanged(d, "rolling_stock")))
        d = folder("rt_consists_is_file")
        (d / "consists").write_text("in the way\n")
        cases.append(Case("railtoolkit_consists_is_a_file", "json", ["import", "railtoolkit", str(rt_path), str(rt_train),
                                                                      "--out", str(d)], 2,
                          (str(d / "consists"), "is a file where the folder"), after=unchanged(d, "consists")))
        d = folder("rt_fifo")
        if not (d / "slope.yaml").exists():
            os.mkfifo(d / "slope.yaml")
        cases.append(Case("railtoolkit_onto_fifo", "json", ["import", "railtoolkit", str(rt_path), "--out", str(d)], 2,
                          (str(d / "slope.yaml"), "not a regular file"), after=unchanged(d, "slope.yaml")))
        d = folder("rt_full")
        cases.append(Case("railtoolkit_disk_full", "json", ["import", "railtoolkit", str(rt_path), str(rt_train), "--out",
                                                             str(d)], 2, ("--out", "none was written"), fsize=1000,
                          after=unchanged(d)))
    # YAML 1.1 numbers: octal read as YAML 1.2 (060 is sixty), base-60 refused
    oct_route = write("octal_length.yaml", route(length="01500", kmh="060"))
    cases.append(Case("yaml11_octal_is_decimal", "number", ["validate", oct_route, "--json"], 0, (),
                      expect_out=('"length_m": 1500.0',), note="YAML 1.1 would read 832 m"))
    base60 = write("base60_time.yaml", route(schedule="schedule: {run_time_s: 3:20}\n"))
    cases.append(Case("yaml11_base60_time", "number", ["validate", base60], 2, (base60, "schedule.run_time_s", "base-60")))
    base60f = write("base60_length.yaml", route(length="1:05.5"))
    cases.append(Case("yaml11_base60_float", "number", ["validate", base60f], 2, (base60f, "length_m", "base-60")))
    # outputs: two naming one file, the logs folder's mode, the logs on a full disk
    out_dir = tmp / "out"
    store = tmp / "stores" / "for_plots.sqlite"
    cases.append(Case("results_plot_and_boxplot_same_file", "output",
                      ["results", str(store), "--plot", str(out_dir / "same.png"), "--boxplot", str(out_dir / "same.png")],
                      2, ("--boxplot", "same file as --plot")))
    cases.append(Case("simulate_out_and_plot_same_file", "output",
                      ["simulate", good_route, "--consist", SMALL, "--out", str(out_dir / "x.svg"), "--plot", str(out_dir / "x.svg")],
                      2, ("--out",)))
    logs = tmp / "logs_mode"
    cases.append(Case("drivers_folder_mode", "output", ["drivers", "simulate", good_route, "--out", str(logs), "--drivers", "2",
                                                        "--runs", "1"], 0, (), umask=0o022,
                      after=lambda: None if logs.is_dir() and stat.S_IMODE(logs.stat().st_mode) == 0o755
                      else f"logs folder mode {oct(stat.S_IMODE(logs.stat().st_mode)) if logs.exists() else 'missing'}"))
    logs_full = tmp / "logs_full"
    cases.append(Case("drivers_disk_full", "output", ["drivers", "simulate", good_route, "--out", str(logs_full), "--drivers",
                                                      "2", "--runs", "1"], 2, (str(logs_full), "nothing was written"),
                      fsize=3000, after=lambda: "logs left" if logs_full.exists() else None))
    for cmd in (["optimize"], ["compare"], ["sweep", "--times", "200,210"], ["study", "--runs", "1"],
                ["pareto", "--times", "200,210"], ["pareto"], ["optimize", "--time", "1.2x"]):
        for tol in ("1000", "200"):  # above T0, and T0 itself (a window opening at departure)
            cases.append(Case(f"tolerance_{tol}_t0_{'_'.join(cmd)}", "option", [cmd[0], good_route, "--consist", SMALL,
                                                                               *cmd[1:], "--tolerance", tol], 2,
                              (CMDLINE, "--tolerance", "not below the planned running time")))
    for tol in ("1000", "200"):
        cases.append(Case(f"tolerance_{tol}_t0_drivers", "option", ["drivers", "simulate", good_route, "--out",
                                                                  str(tmp / f"logs_tol_{tol}"), "--drivers", "2", "--runs", "1",
                                                                  "--tolerance", tol], 2,
                          (CMDLINE, "--tolerance", "not below the planned running time")))
    # a window below T0 whose earliest aim the driver simulator cannot drive (it gave a traceback)
    cases.append(Case("tolerance_wide_drivers", "option", ["drivers", "simulate", good_route, "--out", str(tmp / "logs_tol_wide"),
                                                           "--drivers", "2", "--runs", "1", "--tolerance", "199.99"], 2,
                      (CMDLINE, "--tolerance", "less than half the fastest possible run", "at most")))
    wide = write("wide_window.yaml", route(schedule="schedule: {run_time_s: 200, tolerance_s: 190}\n"))
    cases.append(Case("route_tolerance_wide_drivers", "option", ["drivers", "simulate", wide, "--out", str(tmp / "logs_tol_route"),
                                                                 "--drivers", "2", "--runs", "1"], 2,
                      (wide, "schedule.tolerance_s", "less than half the fastest possible run")))
    cases.append(Case("route_tolerance_above_times_drivers", "option", ["drivers", "simulate", wide, "--out",
                                                                        str(tmp / "logs_tol_route2"), "--drivers", "2",
                                                                        "--runs", "1", "--times", "180"], 2,
                      (wide, "schedule.tolerance_s", "not below the planned running time 180 s")))


def _full_disk_cases(cases: list[Case], good_route: str, tmp: Path) -> None:
    """Every kind of output of every command that writes one, on a full disk (RLIMIT_FSIZE: a write past
    200 bytes fails as on a full disk): a message naming the file, exit 2, and no file left (nor a hidden
    temporary one); stdout on /dev/full for help, usage and the commands not covered above."""
    full = tmp / "full_disk"
    full.mkdir(exist_ok=True)
    import shutil

    # a store in a read-only folder: results reads it without a journal (none can be made there), so the one
    # write that fails is the output's
    ro = tmp / "stores" / "full_disk_read_only"
    if ro.exists():
        ro.chmod(0o755)
        shutil.rmtree(ro)
    ro.mkdir()
    store = ro / "s.sqlite"
    shutil.copy(tmp / "stores" / "alone.sqlite", store)
    ro.chmod(0o555)
    commands = {
        "simulate": (["simulate", good_route, "--consist", SMALL], (".json", ".csv", ".png")),
        "optimize": (["optimize", good_route, "--consist", SMALL], (".json", ".csv", ".svg")),
        "compare": (["compare", good_route, "--consist", SMALL, "--strategies", "time-saving,four-stage", "--e-min", "5"],
                    (".json", ".png")),  # E_min given: no optimal control solved (seconds under load)
        "sweep": (["sweep", good_route, "--consist", SMALL, "--times", "200,210"], (".csv", ".png")),
        "study": (["study", good_route, "--consist", SMALL, "--runs", "1", "--algorithms", "issa", "--params-dir",
                   str(ROOT / "tests/data/optimizers")], (".json", ".png")),
        "bound": (["bound", good_route, "--consist", SMALL], (".json", ".png")),
        "ocp": (["ocp", good_route], (".csv", ".json", ".png")),
        "results": (["results", str(store)], (".csv", ".json", ".png")),
    }

    def nothing_left(target: Path):
        def check():
            left = [p.name for p in target.parent.iterdir()]
            return f"left behind: {left}" if left else None
        return check

    for name, (argv, suffixes) in commands.items():
        for suffix in suffixes:
            folder = full / f"{name}{suffix.replace('.', '_')}"  # one folder each: cases run two at a time
            folder.mkdir(exist_ok=True)
            target = folder / f"{name}{suffix}"
            flag = "--plot" if suffix in (".png", ".svg") else "--out"
            cases.append(Case(f"full_disk_{name}_{flag[2:]}{suffix.replace('.', '_')}", "output", argv + [flag, str(target)], 2,
                              (str(target), "cannot write", "File too large"), fsize=200, after=nothing_left(target),
                              permissions=name == "results"))
    # what click prints itself (help, usage, the version) and more commands' reports, on a full stdout
    for name, argv in (("help", ["--help"]), ("command_help", ["simulate", "--help"]), ("version", ["--version"]),
                       ("usage_json", ["simulate", "--bogus", "x", "--json"]),
                       ("compare", commands["compare"][0] + ["--json"]), ("bound", commands["bound"][0] + ["--json"]),
                       ("ocp", ["ocp", good_route]), ("results", ["results", str(store)])):
        cases.append(Case(f"stdout_dev_full_{name}", "output", argv, 2, ("<stdout>", "No space left"), stdout_file="/dev/full",
                          forbid=("Traceback",)))
    # files written whole before the report: the message says so (not "nothing else was written")
    track = Path("/work/shared/data/external/ttobench/tracks/00_var_speed_limit_100.json")
    if track.is_file():
        d = tmp / "imports" / "tto_stdout_full"
        d.mkdir(parents=True, exist_ok=True)
        cases.append(Case("stdout_dev_full_import_files_kept", "output", ["import", "ttobench", str(track), "--out", str(d)], 2,
                          ("<stdout>", "No space left", "the files were written whole", "00_var_speed_limit_100.yaml"),
                          stdout_file="/dev/full", forbid=("nothing else was written",)))
    # --where: a number that compares with nothing (nan), no bound (inf), or no value at all: refused, not 0 runs
    for label, cond in (("nan", "planned_time_s>nan"), ("inf", "planned_time_s<inf"), ("overflow", "planned_time_s>1e400"),
                        ("no_value", "planned_time_s>")):
        cases.append(Case(f"results_where_{label}", "option", ["results", str(tmp / "stores" / "alone.sqlite"), "--where", cond],
                          2, (CMDLINE, "--where", cond)))
    logs = tmp / "logs_stdout_full"
    cases.append(Case("stdout_dev_full_drivers_files_kept", "output", ["drivers", "simulate", good_route, "--out", str(logs),
                                                                       "--drivers", "2", "--runs", "1"], 2,
                      ("<stdout>", "the files were written whole", str(logs)), stdout_file="/dev/full",
                      forbid=("nothing else was written",)))


_SERVERS: list = []
"""Sockets and servers the corpus keeps open for its whole life (a silent server, an HTTP server)."""


def _servers() -> dict[str, int]:
    """Ports on 127.0.0.1: 'silent' accepts (the kernel does) and never answers, 'http' is an HTTP server,
    'closed' had a listener a moment ago and has none now."""
    import http.server
    import socket

    if not _SERVERS:
        silent = socket.socket()
        silent.bind(("127.0.0.1", 0))
        silent.listen(16)
        class Quiet(http.server.BaseHTTPRequestHandler):
            def do_GET(self):
                self.send_response(200)
                self.end_headers()

            def log_message(self, *args):
                pass
        http_server = http.server.HTTPServer(("127.0.0.1", 0), Quiet)
        threading.Thread(target=http_server.serve_forever, daemon=True).start()
        gone = socket.socket()
        gone.bind(("127.0.0.1", 0))
        closed_port = gone.getsockname()[1]
        gone.close()
        _SERVERS.extend([silent, http_server, closed_port])
    silent, http_server, closed_port = _SERVERS
    return {"silent": silent.getsockname()[1], "http": http_server.server_address[1], "closed": closed_port}


def _hang_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """What once hung or did work before refusing: a Dask address that is no scheduler, a seed range past
    2**63 - 1, too many seeds or workers, a route glob over a loop of links."""
    study = write("hang_study.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                                     "times: [200]\nstrategies: [time-saving]\n")
    for kind, why in (("silent", "says nothing"), ("http", "HTTP server"), ("closed", "cannot reach")):
        port = _servers()[kind]
        cases.append(Case(f"scheduler_{kind}", "option", ["batch", study, "--store", str(tmp / "stores" / f"dask_{kind}.sqlite"),
                                                          "--scheduler", f"tcp://127.0.0.1:{port}", "--quiet"], 2,
                          (CMDLINE, "--scheduler", why), note="once: hung past 300 s / 60 s, or 31 s"))
    cases.append(Case("scheduler_no_port", "option", ["batch", study, "--store", str(tmp / "stores" / "dask_np.sqlite"),
                                                      "--scheduler", "tcp://127.0.0.1", "--quiet"], 2, ("--scheduler", "port")))
    top = 2**63 - 1
    cases.append(Case("study_seed_range_past_limit", "option", ["study", good_route, "--consist", SMALL, "--runs", "6",
                                                                "--seed", str(top - 2)], 2, (CMDLINE, "--seed", "2**63 - 1")))
    cases.append(Case("pareto_seeds_too_many", "option", ["pareto", good_route, "--consist", SMALL, "--seeds",
                                                          ",".join(str(i) for i in range(900))], 2, (CMDLINE, "--seeds", "1,000 runs")))
    cases.append(Case("pareto_seeds_negative", "option", ["pareto", good_route, "--consist", SMALL, "--seeds", "1,-1"], 2,
                      (CMDLINE, "--seeds", "2**63 - 1")))
    cases.append(Case("pareto_strategies_named", "message", ["pareto", good_route, "--consist", SMALL, "--strategies", "bogus"],
                      2, (CMDLINE, "--strategies", "unknown strategy")))
    cases.append(Case("workers_10000", "option", ["batch", study, "--store", str(tmp / "stores" / "w.sqlite"), "--workers",
                                                  "10000"], 2, (CMDLINE, "--workers", "1,024")))
    # a loop of links under a recursive glob: walked once, not forever
    tree = tmp / "files" / "glob_loop"
    (tree / "a" / "b").mkdir(parents=True, exist_ok=True)
    Path(tree / "a" / "b" / "r.yaml").write_text(Path(good_route).read_text())
    for link, target in ((tree / "a" / "b" / "up", ".."), (tree / "a" / "loop", "../..")):
        if not link.is_symlink():
            os.symlink(target, link)
    looped = write("glob_loop_study.yaml", f"schema: locoplan/study@1\nroutes: ['{tree}/**/*.yaml']\nconsists: [{SMALL}]\n"
                                           "times: [200]\nstrategies: [time-saving]\n")
    cases.append(Case("route_glob_symlink_loop", "file", ["batch", looped, "--store", str(tmp / "stores" / "loop.sqlite"),
                                                          "--workers", "1", "--json"], 0, (), expect_out=('"runs": 1',)))


def _neutral_near_stop_cases(cases: list[Case], write) -> None:
    """A neutral section near the stop, its span (10 s margins, the train's length) reaching the stop: the light
    train's only brake is electric (none in the span), yet the fastest run coasts in; optimize and the least-energy
    strategy must find their plans too (they said 'no drive ... reaches the stop')."""
    for length, before_stop, kmh in ((50, 150, 60), (20, 0, 80), (150, 250, 80)):
        path = write(f"neutral_near_stop_{length}_{before_stop}.yaml", route(
            length="1400", kmh=str(kmh), extra="neutral_sections:\n  - {from_m: %d, to_m: %d, coast_before_s: 10, "
            "coast_after_s: 10}\n" % (1400 - before_stop - length, 1400 - before_stop)))
        cases.append(Case(f"neutral_near_stop_{length}_{before_stop}_optimize", "physics",
                          ["optimize", path, "--consist", SMALL, "--time", "1.1x", "--json"], 0, (),
                          expect_out=('"feasible": true',), note="once: no drive reaches the stop"))
        cases.append(Case(f"neutral_near_stop_{length}_{before_stop}_energy_saving", "physics",
                          ["simulate", path, "--consist", SMALL, "--strategy", "energy-saving", "--json"], 0, (),
                          expect_out=('"feasible": true',)))


def _partial_folder_cases(cases: list[Case], good_route: str, tmp: Path) -> None:
    """``drivers simulate`` writes into ``NAME.incomplete-PID`` and renames it when complete; one left by a run
    killed outright (unlocked, marked) is removed by the next run into NAME and named on stderr; one another
    live run holds (its lock) is left alone."""
    import fcntl

    logs = tmp / "logs_after_kill"
    stale, live = tmp / "logs_after_kill.incomplete-1", tmp / "logs_after_kill.incomplete-2"
    for folder in (stale, live):
        (folder / "logs").mkdir(parents=True, exist_ok=True)
        (folder / "INCOMPLETE.txt").write_text("left by a killed run\n")
        (folder / "logs" / "D01-m5200-t200-r1.csv").write_text("time_s,position_m,speed_kmh,force_kn\n")
    fd = os.open(live, os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    _HELD.append(fd)
    unmarked = tmp / "logs_after_kill.incomplete-3"  # not made by locoplan (no INCOMPLETE.txt): never touched
    unmarked.mkdir(exist_ok=True)

    def check():
        if stale.exists():
            return f"{stale.name} was not removed"
        if not live.is_dir() or not unmarked.is_dir():
            return "a folder in use or not locoplan's was removed"
        if not (logs / "manifest.yaml").is_file() or (logs / "INCOMPLETE.txt").exists():
            return "the logs folder is not complete"
        return None
    cases.append(Case("drivers_removes_a_killed_runs_folder", "output",
                      ["drivers", "simulate", good_route, "--out", str(logs), "--drivers", "2", "--runs", "1"], 0,
                      ("note: removed", str(stale), "stopped before it finished"), after=check,
                      forbid=(live.name, unmarked.name)))


MID_RUN_TIMES = list(range(200, 305, 5))
"""The planned times of the mid-run store cases' batch (x 2 strategies): enough runs that the batch is still
writing well after its first commit, when the watching thread acts (6 runs had all been written within the
thread's 50 ms poll once the calculator got faster)."""


def _store_mid_run_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """The store while a batch writes to it (a thread acts once the first run is committed): made read-only (the
    open file stays writable, so the batch completes and keeps every run), removed, or replaced by another store
    (the batch stops, and the file now there is left whole)."""
    import shutil
    import sqlite3

    sys.path.insert(0, str(ROOT))
    from locoplan.runs.spec import RunRecord
    from locoplan.runs.store import Store

    study = write("store_mid_run_study.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                                              f"times: [{', '.join(str(t) for t in MID_RUN_TIMES)}]\n"
                                              "strategies: [time-saving, four-stage]\n")
    n_runs = 2 * len(MID_RUN_TIMES)
    folder = tmp / "stores" / "mid_run"
    if folder.exists():
        folder.chmod(0o755)
        shutil.rmtree(folder)
    folder.mkdir(parents=True)

    def committed(path: Path) -> int:
        try:
            with sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=1) as conn:
                return int(conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0])
        except sqlite3.Error:
            return 0

    def once_committed(path: Path, act):
        def during():
            deadline = time.monotonic() + TIME_LIMIT_S
            while committed(path) < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            act()
        return during

    ro = folder / "read_only.sqlite"

    def make_read_only():
        ro.chmod(0o444)
        folder.chmod(0o555)

    def all_kept():
        folder.chmod(0o755)
        n = committed(ro)
        return None if n == n_runs else f"{n} runs in the store, expected {n_runs}"
    cases.append(Case("batch_store_made_read_only_mid_run", "store", ["batch", study, "--store", str(ro), "--workers", "1",
                                                                       "--quiet", "--json"], 0, (), expect_out=(f'"runs": {n_runs}',),
                      during=once_committed(ro, make_read_only), after=all_kept, permissions=True,
                      note="permissions are checked when a file is opened: the batch goes on and keeps every run"))
    for how in ("removed", "replaced"):
        path = folder / f"{how}.sqlite"

        def act(path=path, how=how):
            for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
                p.unlink(missing_ok=True)
            if how == "replaced":
                with Store(path) as other:
                    other.put(RunRecord("other0000", {"route": "other", "consist": "c", "strategy": "time-saving",
                                                      "algorithm": None, "planned_time_s": 200.0, "feasible": True,
                                                      "running_time_s": 99.0, "traction_energy_kwh": 15.0},
                                        {"route": good_route, "consist": SMALL}, None, 0.1,
                                        {"locoplan": other.meta["locoplan"]}, "host:1"))

        def whole(path=path, how=how):
            n = committed(path)
            return None if how == "removed" or n == 1 else f"the replacing store holds {n} runs, expected its 1"
        cases.append(Case(f"batch_store_{how}_mid_run", "store", ["batch", study, "--store", str(path), "--workers", "1",
                                                                  "--quiet"], 2,
                          (str(path), "was removed or replaced", "run the same command again"),
                          during=once_committed(path, act), after=whole))


def _stderr_full_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """stderr on a full device: the messages are lost, but every output is written and the exit code is what it
    would have been (2 bad input, 1 infeasible or a result without the damaged runs of a store, 0 a success), never 2
    for the lost messages."""
    out_dir = tmp / "stderr_full"
    out_dir.mkdir(exist_ok=True)
    bad = write("stderr_full_bad.yaml", route(length="abc"))
    plan = out_dir / "plan.json"
    logs = out_dir / "logs"
    sim = ["simulate", good_route, "--consist", SMALL]
    for name, argv, code, out, after in (
            ("bad_input", ["validate", bad], 2, (), None),
            ("usage", ["simulate", "--bogus"], 2, (), None),
            ("infeasible", ["optimize", good_route, "--consist", SMALL, "--time", "50"], 1, (), None),
            ("damaged_store", ["results", str(tmp / "stores" / "broken_records.sqlite"), "--json"], 1, ('"runs": 1',), None),
            ("out_file", sim + ["--out", str(plan)], 0, ("running time",),
             lambda: None if plan.is_file() else "plan.json was not written"),
            ("drivers", ["drivers", "simulate", good_route, "--out", str(logs), "--drivers", "2", "--runs", "1"], 0, (),
             lambda: None if (logs / "manifest.yaml").is_file() else "the logs were not written")):
        cases.append(Case(f"stderr_dev_full_{name}", "output", argv, code, (), expect_out=out, after=after,
                          stderr_file="/dev/full", note="the lost messages do not change the outcome"))
    # a file-size limit with fresh cache folders: the kernels' caches cannot be written (the ahead-of-time build
    # has no room, numba's cache files are too large): not the command's concern, and never blamed on stdout
    fresh = tmp / "fresh_caches"
    caches = {"LOCOPLAN_NATIVE_DIR": str(fresh / "native"), "LOCOPLAN_CACHE_DIR": str(fresh / "cache"),
              "NUMBA_CACHE_DIR": str(fresh / "numba")}
    study = write("fresh_caches_study.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                                             "times: [200]\nstrategies: [time-saving]\n")
    cases.append(Case("fresh_caches_file_size_limit", "output", ["batch", study, "--store", str(fresh / "s.sqlite"),
                                                                  "--workers", "1", "--quiet", "--json"], 0, (),
                      expect_out=('"runs": 1',), forbid=("<stdout>",), fsize=100 * 1024, env=caches, slow=True,
                      time_limit_s=600.0, after=lambda: None if not list((fresh / "native").glob("*.failed"))
                      else "a build that had no room was recorded as failed",
                      note="once: '<stdout>: cannot write the output: File too large' (numba's cache file)"))


def _schema_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """``schema:`` as a list, a mapping or a number, in every kind of file every loader reads."""
    text = Path(good_route).read_text(encoding="utf-8")
    manifest = (ROOT / "tests/data/bad_logs/mph/manifest.yaml").read_text(encoding="utf-8").replace(
        "../../learn/line-6km.yaml", str(ROOT / "tests/data/learn/line-6km.yaml"))
    kinds = {
        "route": (text, lambda p: ["validate", p]),
        "route_simulate": (text, lambda p: ["simulate", p, "--consist", SMALL]),
        "consist": (CONSIST.format(loco="HXD1-seed000", count="1", load=""),
                    lambda p: ["simulate", good_route, "--consist", p]),
        "vehicle": (VEHICLE.format(name="V", mass="200", a="2.23", force="532"), lambda p: ["validate", p]),
        "params": (PARAMS.format(pop="10", iters="5", extra=""),
                   lambda p: ["optimize", good_route, "--consist", SMALL, "--params", p]),
        "study": (f"schema: locoplan/study@1\nroutes: [{good_route}]\ntimes: [200]\n",
                  lambda p: ["batch", p, "--store", str(tmp / "schema_study.sqlite"), "--workers", "1"]),
        "manifest": (manifest, lambda p: ["learn", p, "--out", str(tmp / "schema_patterns.json")]),
        "railtoolkit": ("schema: railtoolkit/path\nschema_version: '2022.05'\npaths: []\n",
                        lambda p: ["import", "railtoolkit", p, "--out", str(tmp / "schema_import")]),
        # a per-run sidecar <log>.yaml beside its log (learn reads a folder of them)
        "sidecar": ("schema: locoplan/driver-run@1\nroute: " + str(ROOT / "tests/data/learn/line-6km.yaml") +
                    "\nconsist: HXD1-C80x50\nsynthetic: false\nlog: run.csv\ndriver_id: D01\nmass_t: 5200\n"
                    "scheduled_time_s: 3\nactual_time_s: 3\ndate: 2024-05-01\n",
                    lambda p: ["learn", str(Path(p).parent), "--out", str(tmp / "schema_sidecar.json")]),
        # a vehicle file found in --stock-dir by the name a consist gives (read when the consist is loaded)
        "stock_vehicle": ((ROOT / "configs/rolling_stock/HXD1-seed000.yaml").read_text(encoding="utf-8"),
                          lambda p: ["simulate", good_route, "--consist", stock_consist, "--stock-dir", str(Path(p).parent)]),
    }
    stock_consist = write("schema_stock_consist.yaml", CONSIST.format(loco="HXD1-seed000", count="1", load=""))
    import re as _re

    (tmp / "schema_import").mkdir(exist_ok=True)

    for kind, (body, argv) in kinds.items():
        for form, value, said in (("list", "[a, b]", "a list"), ("map", "{a: 1}", "a mapping"), ("number", "7", "a number")):
            if kind not in ("route", "study", "manifest", "railtoolkit") and form == "number":
                continue
            changed = _re.sub(r"(?m)^schema: .*$", f"schema: {value}", body, count=1)
            folder = tmp / "files" / f"schema_{kind}_{form}"
            folder.mkdir(exist_ok=True)
            path = folder / {"manifest": "manifest.yaml", "sidecar": "run.yaml",
                             "stock_vehicle": "HXD1-seed000.yaml"}.get(kind, f"{kind}.yaml")
            path.write_text(changed, encoding="utf-8")
            if kind in ("manifest", "sidecar"):
                (folder / "run.csv").write_text((ROOT / "tests/data/bad_logs/mph/run.csv").read_text())
            cases.append(Case(f"schema_{form}_{kind}", "yaml", argv(str(path)), 2,
                              (f"{path}:", "schema", said), note="a schema that is not text crashed every loader"))
    # other YAML types in the schema's place, named by what YAML read
    for form, value, said in (("bool", "true", "a boolean"), ("date", "2001-12-14", "a date"),
                              ("binary", "!!binary aGVsbG8=", "binary data"), ("empty_list", "[]", "a list")):
        path = write(f"schema_{form}.yaml", _re.sub(r"(?m)^schema: .*$", f"schema: {value}", text, count=1))
        cases.append(Case(f"schema_{form}_route", "yaml", ["validate", path], 2, (f"{path}:1:", "schema", said)))
    # a patterns.json (JSON: no lines) whose schema is a list or a mapping
    for form, value, said in (("list", '["locoplan/patterns@1"]', "a list"), ("map", '{"a": 1}', "a mapping")):
        path = write(f"schema_{form}_patterns.json", '{"schema": %s, "settings": {}}\n' % value)
        cases.append(Case(f"schema_{form}_patterns", "yaml", ["advise", good_route, "--patterns", path], 2,
                          (path, "schema", said)))


def _yaml11_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """YAML 1.1 number forms in every kind of file every loader reads: those YAML 1.2 reads as text (base-60
    ``3:20``, digit groups ``1_500``, binary ``0b101``) refused at file:line and field; those YAML 1.2 reads
    otherwise (``060``, ``08``, ``0o60``) read as YAML 1.2 does."""
    import re as _re

    manifest = (ROOT / "tests/data/bad_logs/mph/manifest.yaml").read_text(encoding="utf-8").replace(
        "../../learn/line-6km.yaml", str(ROOT / "tests/data/learn/line-6km.yaml"))
    rt = Path("/work/shared/data/external/railtoolkit/paths/slope.yaml")
    if not rt.is_file():
        rt = ROOT.parent / "shared" / "data" / "external" / "railtoolkit" / "paths" / "slope.yaml"
    kinds = {  # kind: (text, the line to change (a regex), its replacement with {v}, field, argv)
        "route": (route(), r"(?m)^length_m: .*$", "length_m: {v}", "length_m", lambda p: ["validate", p]),
        "vehicle": (VEHICLE.format(name="V", mass="200", a="2.23", force="532"), r"(?m)^mass_t: .*$", "mass_t: {v}",
                    "mass_t", lambda p: ["validate", p]),
        "consist": (CONSIST.format(loco="HXD1-seed000", count="1", load=""), r"count: 1}\n$", "count: {v}}}\n",
                    "vehicles[1].count", lambda p: ["simulate", good_route, "--consist", p]),
        "params": (PARAMS.format(pop="10", iters="5", extra=""), r"(?m)^pop_size: .*$", "pop_size: {v}", "pop_size",
                   lambda p: ["optimize", good_route, "--consist", SMALL, "--params", p]),
        "study": (f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\ntimes: [200]\n",
                  r"(?m)^times: .*$", "times: [{v}]", "times[0]",
                  lambda p: ["batch", p, "--store", str(tmp / "stores" / "yaml11.sqlite"), "--workers", "1"]),
        "manifest": (manifest, r"mass_t: 5200", "mass_t: {v}", "runs[0].mass_t",
                     lambda p: ["learn", str(Path(p).parent), "--out", str(tmp / "yaml11_patterns.json")]),
    }
    if rt.is_file():
        kinds["railtoolkit"] = (rt.read_text(encoding="utf-8"), r"(?m)^(      - \[ +0\.0, +)160,", r"\g<1>{v},",
                                "characteristic_sections", lambda p: ["import", "railtoolkit", p, "--out",
                                                                       str(tmp / "yaml11_import")])
    (tmp / "yaml11_import").mkdir(exist_ok=True)
    for kind, (text, pattern, repl, field_, argv) in kinds.items():
        for form, value, why in (("base60", "3:20", "base-60"), ("groups", "1_600", "YAML 1.2"),
                                 ("binary", "0b1010", "YAML 1.2")):
            folder = tmp / "files" / f"yaml11_{kind}_{form}"
            folder.mkdir(exist_ok=True)
            path = folder / ("manifest.yaml" if kind == "manifest" else f"{kind}.yaml")
            changed, n = _re.subn(pattern, repl.replace("{v}", value), text, count=1)
            assert n == 1, (kind, form)
            path.write_text(changed, encoding="utf-8")
            if kind == "manifest":
                (folder / "run.csv").write_text((ROOT / "tests/data/bad_logs/mph/run.csv").read_text())
            cases.append(Case(f"yaml11_{form}_{kind}", "number", argv(str(path)), 2, (f"{path}:", field_, why),
                              note="YAML 1.1 reads a number, YAML 1.2 text: refused, never read silently"))
    # read as YAML 1.2 does: 08 is eight (YAML 1.1: text), 0o2734 the octal 1500 (YAML 1.1: text)
    for name, length in (("yaml12_leading_zero_8", "08"), ("yaml12_octal_0o", "0o2734")):
        path = write(f"{name}.yaml", route(length=length if length != "08" else "01508"))
        cases.append(Case(name, "number", ["validate", path, "--json"], 0, (),
                          expect_out=('"length_m": 1508.0',) if length == "08" else ('"length_m": 1500.0',)))
    if rt.is_file():  # a YAML 1.2 railtoolkit file with 0160 km/h imports 160 km/h (YAML 1.1: the octal 112)
        src = write("rt_leading_zero.yaml", _re.sub(r"(?m)^(      - \[ +0\.0, +)160,", r"\g<1>0160,", rt.read_text(), count=1))
        out = tmp / "yaml12_rt_import"
        out.mkdir(exist_ok=True)
        cases.append(Case("yaml12_railtoolkit_0160", "number", ["import", "railtoolkit", src, "--out", str(out)], 0, (),
                          after=lambda: None if "kmh: 160}" in (out / "slope.yaml").read_text() else "not read as 160 km/h"))


def _journey_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """Journey files: the route they name (a folder, a device, missing), their stations' shape and values,
    windows no run can keep, and journey's own options; a study's journeys entries; every one named, none a
    traceback."""
    folder = str(Path(good_route).parent)
    head = "schema: locoplan/journey@1\nname: hostile journey\n"
    ends = "  - {name: A, at_m: 0}\n  - {name: C, at_m: 1500}\n"

    def journey(name: str, body: str) -> str:
        return write(name, head + body)

    good = journey("journey_good.yaml", f"route: {Path(good_route).name}\nstations:\n{ends}")
    for name, route_ref, words in (("journey_route_folder", ".", ("route", "no route file")),
                                   ("journey_route_device", "/dev/zero", ("route", "no route file")),
                                   ("journey_route_missing", "nowhere.yaml", ("route", "nowhere.yaml"))):
        f = journey(f"{name}.yaml", f"route: {route_ref}\nstations:\n{ends}")
        cases.append(Case(name, "file", ["journey", f, "--time", "300", "--consist", SMALL], 2, (f,) + words))
    for name, body, field_, words in (
            ("journey_stations_mapping", "stations: {a: 1}\n", "stations", ("valid list",)),
            ("journey_stations_empty", "stations: []\n", "stations", ("at least 2",)),
            ("journey_run_time_nan", f"run_time_s: .nan\nstations:\n{ends}", "run_time_s", ("finite",)),
            ("journey_run_time_huge", f"run_time_s: 1.0e+300\nstations:\n{ends}", "run_time_s", ("implausible",)),
            ("journey_dwell_negative", "stations:\n  - {name: A, at_m: 0}\n  - {name: B, at_m: 700, dwell_s: -5}\n"
             "  - {name: C, at_m: 1500}\n", "stations[1].dwell_s", ("greater than or equal",)),
            ("journey_station_beyond", "stations:\n  - {name: A, at_m: 0}\n  - {name: C, at_m: 1e12}\n",
             "stations[1].at_m", ("beyond",))):
        f = journey(f"{name}.yaml", f"route: {Path(good_route).name}\n{body}")
        cases.append(Case(name, "file", ["validate", f], 2, (f, field_) + words, batch_file=f))
    late = journey("journey_window_impossible.yaml", f"route: {Path(good_route).name}\nstations:\n  - {{name: A, at_m: 0}}\n"
                   "  - {name: B, at_m: 700, latest_s: 1}\n  - {name: C, at_m: 1500}\n")
    cases.append(Case("journey_window_impossible", "physics", ["journey", late, "--time", "300", "--consist", SMALL], 1,
                      ("no run keeps the journey's windows", "latest_s")))
    for v in ("nan", "-1", "0.5x", "1e9"):
        cases.append(Case(f"journey_time_{v}", "option", ["journey", good, "--time", v, "--consist", SMALL], 2,
                          (CMDLINE, "--time")))
    cases.append(Case("journey_no_time", "message", ["journey", good, "--consist", SMALL], 2, (good, "run_time_s", "1.15x")))
    cases.append(Case("journey_unknown_strategy", "option", ["journey", good, "--time", "300", "--strategies", "nope"], 2,
                      (CMDLINE, "--strategies", "nope")))
    cases.append(Case("journey_out_type", "output", ["journey", good, "--time", "300", "--out", str(Path(folder) / "x.txt")],
                      2, ("--out", ".csv")))
    missing_route = journey("journey_pareto_no_route.yaml", f"route: nowhere.yaml\nstations:\n{ends}")
    cases.append(Case("journey_pareto_route_missing", "file", ["pareto", missing_route, "--consist", SMALL, "--no-optimum"], 2,
                      (missing_route, "route", "nowhere.yaml")))
    timed = journey("journey_timed.yaml", f"route: {Path(good_route).name}\nrun_time_s: 300\nstations:\n{ends}")
    beyond = journey("journey_study_beyond.yaml", f"route: {Path(good_route).name}\nstations:\n  - {{name: A, at_m: 0}}\n"
                     "  - {name: C, at_m: 1.0e+12}\n")

    def study(name: str, body: str, *why: str):
        """A study file of journeys, run by batch: refused before any run, named at the study's line."""
        path = write(f"{name}.yaml", f"schema: locoplan/study@1\nconsists: [{SMALL}]\n{body}")
        cases.append(Case(name, "study", ["batch", path, "--store", str(tmp / "stores" / f"{name}.sqlite"), "--workers", "1",
                                          "--quiet"], 2, why if why[0] != "@" else (path,) + why[1:], forbid=(CMDLINE,)))
        return path

    study("study_journeys_missing", "journeys: [nowhere-journey.yaml]\n", "@", ":3: journeys[0]", "no such journey file")
    study("study_journeys_glob_none", "journeys: ['nothing/*.yaml']\n", "@", ":3: journeys[0]", "matches no journey file")
    study("study_journeys_glob_only_routes", f"journeys: ['{Path(good_route).parent}/route*.yaml']\n", "@", ":3: journeys[0]",
          "matches no journey file")
    study("study_journeys_route_file", f"journeys: [{good_route}]\n", "@", ":3: journeys[0]", "not a journey",
          "list it under routes")
    study("study_routes_journey_file", f"routes: [{timed}]\n", "@", ":3: routes[0]", "not a route", "list it under journeys")
    study("study_journeys_mapping", "journeys: {a: 1}\n", "@", ":3: journeys", "valid list")
    study("study_journeys_number", "journeys: [5]\n", "@", ":3: journeys[0]", "valid string")
    study("study_journeys_folder", f"journeys: [{folder}]\n", "@", ":3: journeys[0]", "is a folder", "*.yaml")
    study("study_journeys_device", "journeys: [/dev/zero]\n", "@", ":3: journeys[0]", "not a regular file")
    study("study_journeys_no_time", f"journeys: [{good}]\n", "@", ":3: journeys[0]", "gives no running time", "1.1x")
    study("study_journeys_tolerance_leg", f"journeys: [{timed}]\ntolerance_s: 100000\n", "@", ":4: tolerance_s",
          "fastest run of a leg")
    study("study_journeys_factor_low", f"journeys: [{timed}]\ntimes: [0.5x]\n", "@", ":4: times[0]", ">= 1")
    study("study_journeys_none", "seeds: [1]\n", "@", ":", "routes", "name the routes or the journeys")
    study("study_journeys_bad_journey", f"journeys: [{beyond}]\n", beyond, "stations[1].at_m", "beyond")


def _yaml11_bool_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """YAML 1.1 booleans (yes, no, on, off in any case) in every boolean field of every kind of file: text to YAML
    1.2, as locoplan reads them, so a boolean field refuses them at file:line, naming the field and what YAML 1.1
    would have read; in a text field they are the text written (a route named Off)."""
    manifest = (ROOT / "tests/data/bad_logs/mph/manifest.yaml").read_text(encoding="utf-8").replace(
        "../../learn/line-6km.yaml", str(ROOT / "tests/data/learn/line-6km.yaml"))
    sidecar = ("schema: locoplan/driver-run@1\nroute: " + str(ROOT / "tests/data/learn/line-6km.yaml") +
               "\nconsist: HXD1-C80x50\nsynthetic: false\nlog: run.csv\ndriver_id: D01\nmass_t: 5200\n"
               "scheduled_time_s: 3\nactual_time_s: 3\ndate: 2024-05-01\n")
    study = f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\ntimes: [200]\n"
    store = str(tmp / "stores" / "yaml11_bool.sqlite")
    for kind, text, line, field_, value, read in (
            ("study_window", study + "window: no\n", 5, "window", "no", "false"),
            ("study_gap", study + "gap: Yes\n", 5, "gap", "Yes", "true"),
            ("study_point_mass", study + "model: {point_mass: on}\n", 5, "model.point_mass", "on", "true"),
            ("study_air_brake", study + "model:\n  air_brake: OFF\n", 6, "model.air_brake", "OFF", "false"),
            ("study_strict_limits", study + "model: {strict_limits: yes}\n", 5, "model.strict_limits", "yes", "true"),
            ("manifest", manifest.replace("synthetic: false", "synthetic: no"), 2, "synthetic", "no", "false"),
            ("sidecar", sidecar.replace("synthetic: false", "synthetic: On"), 4, "synthetic", "On", "true")):
        folder = tmp / "files" / f"yaml11_bool_{kind}"
        folder.mkdir(exist_ok=True)
        path = folder / {"manifest": "manifest.yaml", "sidecar": "run.yaml"}.get(kind, "study.yaml")
        path.write_text(text, encoding="utf-8")
        if kind in ("manifest", "sidecar"):
            (folder / "run.csv").write_text((ROOT / "tests/data/bad_logs/mph/run.csv").read_text())
            argv = ["learn", str(folder if kind == "sidecar" else path), "--out", str(tmp / f"yaml11_bool_{kind}.json")]
        else:
            argv = ["batch", str(path), "--store", store, "--workers", "1", "--quiet"]
        cases.append(Case(f"yaml11_bool_{kind}", "yaml", argv, 2,
                          (f"{path}:{line}: {field_}:", f"'{value}' is text to YAML 1.2", f"the boolean {read}", "true or false"),
                          note="YAML 1.1 would read a boolean silently"))
    named = write("yaml11_bool_text.yaml", route(name="Off"))
    cases.append(Case("yaml11_bool_as_text", "yaml", ["validate", named, "--json"], 0, (), expect_out=('"Off"',),
                      note="a route named Off is the text Off (YAML 1.1: the boolean false)"))


def _store_cases(cases: list[Case], write, good_route: str, tmp: Path) -> None:
    """Result stores that are not files, are damaged, lose a table, fill the disk or have a writer."""
    import json
    import shutil
    import sqlite3

    sys.path.insert(0, str(ROOT))
    from locoplan.runs.spec import RunRecord
    from locoplan.runs.store import Store

    stores = tmp / "stores"
    stores.mkdir(exist_ok=True)
    study = write("store_study.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                                      "times: [200, 210]\nstrategies: [time-saving, four-stage]\n")

    def batch(store: str, *more: str) -> list[str]:
        return ["batch", study, "--store", store, "--workers", "1", "--quiet", *more]

    def made(name: str, n: int = 3) -> Path:
        path = stores / name
        for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm"), Path(f"{path}-journal")):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            elif p.exists() or p.is_symlink():
                p.unlink()
        with Store(path) as s:
            for i in range(n):
                s.put(RunRecord(f"key{i:04d}", {"route": "hostile", "consist": "c", "strategy": "time-saving", "algorithm": None,
                                                "planned_time_s": 200.0 + i, "feasible": True, "running_time_s": 99.0,
                                                "traction_energy_kwh": 15.0 + i},
                                {"route": good_route, "consist": SMALL}, None, 0.1, {"locoplan": s.meta["locoplan"]},
                                "host:1"))
        return path

    def readable(path: Path, n: int):
        def check():
            with sqlite3.connect(path) as conn:
                rows = conn.execute("SELECT record FROM runs").fetchall()
            bad = [t for (t,) in rows if not _is_record(t)]
            return None if len(rows) >= n and not bad else f"{path.name}: {len(rows)} rows, {len(bad)} unreadable"
        return check

    folder = stores / "a_folder.sqlite"
    folder.mkdir(exist_ok=True)
    for dev in ("/dev/null", "/dev/full"):
        cases.append(Case(f"store_{dev[5:]}", "store", batch(dev), 2, (dev, "not a regular file")))
        cases.append(Case(f"results_{dev[5:]}", "store", ["results", dev], 2, (dev, "not a regular file")))
    cases.append(Case("store_folder", "store", batch(str(folder)), 2, (str(folder), "is a folder")))
    cases.append(Case("results_folder", "store", ["results", str(folder)], 2, (str(folder), "is a folder")))
    cases.append(Case("results_not_sqlite", "store", ["results", good_route], 2, (good_route, "not a locoplan result store")))
    fifo = stores / "fifo.sqlite"
    if not fifo.exists():
        os.mkfifo(fifo)
    cases.append(Case("store_fifo", "store", batch(str(fifo)), 2, (str(fifo), "not a regular file")))

    # damaged records: reported by key and what is wrong; the rest is used (exit 1: the result lacks them); batch runs
    # them again
    broken = made("broken_records.sqlite", 4)
    with sqlite3.connect(broken) as conn:
        conn.execute("UPDATE runs SET record = '{bad' WHERE key = 'key0000'")
        conn.execute("UPDATE runs SET record = '{}' WHERE key = 'key0001'")
        conn.execute("UPDATE runs SET record = '[1, 2]' WHERE key = 'key0002'")
    cases.append(Case("results_broken_records", "store", ["results", str(broken), "--json"], 1,
                      ("key0000", "not valid JSON", "key0001", "lacks 'key', 'summary'", "key0002", "not a JSON object",
                       "left out"), expect_out=('"runs": 1',)))
    # damaged summaries: a field of the wrong JSON type is named (summary.FIELD, what it is, what it should be)
    typed = made("typed_records.sqlite", 7)
    with sqlite3.connect(typed) as conn:
        for i, (field, value) in enumerate((("traction_energy_kwh", "abc"), ("planned_time_s", "x"), ("route", 5),
                                            ("feasible", "yes"), ("traction_energy_kwh", float("nan")),
                                            ("running_time_s", None))):
            rec = json.loads(conn.execute("SELECT record FROM runs WHERE key = ?", (f"key{i:04d}",)).fetchone()[0])
            rec["summary"][field] = value
            conn.execute("UPDATE runs SET record = ? WHERE key = ?", (json.dumps(rec), f"key{i:04d}"))
    typed_why = ("key0000", "summary.traction_energy_kwh is text", "key0001", "summary.planned_time_s is text",
                 "key0002", "summary.route is an integer", "key0003", "summary.feasible is text",
                 "key0004", "not a finite number", "key0005", "the run is feasible", "left out")
    for fmt in ([], ["--json"], ["--format", "csv"], ["--format", "json"]):
        cases.append(Case("_".join(["results_typed_records", *(f.strip("-") for f in fmt)]), "store",
                          ["results", str(typed), *fmt], 1, typed_why + ("the store is damaged",),
                          expect_out=('"runs": 1',) if fmt == ["--json"] else ("key0006",) if fmt else ()))
    cases.append(Case("results_broken_records_csv", "store", ["results", str(broken), "--format", "csv"], 1,
                      ("key0000", "left out"), expect_out=("key0003",)))
    # a dropped table, garbage over the file's first page
    dropped = made("dropped.sqlite")
    with sqlite3.connect(dropped) as conn:
        conn.execute("DROP TABLE runs")
    cases.append(Case("results_dropped_runs", "store", ["results", str(dropped)], 2, (str(dropped), "runs table is missing")))
    cases.append(Case("batch_dropped_runs", "store", batch(str(dropped)), 2, (str(dropped), "runs table is missing")))
    garbled = made("garbled.sqlite", 40)
    data = bytearray(garbled.read_bytes())
    data[4096:] = _garbage(len(data) - 4096, 7)  # every page but the first (the schema)
    garbled.write_bytes(bytes(data))
    cases.append(Case("results_malformed", "store", ["results", str(garbled)], 2, (str(garbled), "damaged", "malformed")))
    cases.append(Case("batch_malformed", "store", batch(str(garbled)), 2, (str(garbled), "damaged", "malformed")))
    # garbage over one page of runs mid-file: results uses the rest, names the damaged row ids, exit 1; batch refuses
    partly = made("garbled_one_page.sqlite", 200)
    data = bytearray(partly.read_bytes())
    page = (len(data) // 4096 - 3) * 4096
    data[page:page + 4096] = _garbage(4096, 8)
    partly.write_bytes(bytes(data))
    with sqlite3.connect(f"file:{partly}?mode=ro", uri=True) as conn:
        try:
            conn.execute("SELECT COUNT(*) FROM runs WHERE record LIKE '%'").fetchone()
            raise AssertionError("the garbage page did not damage the runs table")
        except sqlite3.DatabaseError:
            pass
        readable_runs = 0  # the oracle: the rows SQLite reads one by one, whole records
        for rid in range(1, 201):
            try:
                row = conn.execute("SELECT record FROM runs WHERE rowid = ?", (rid,)).fetchone()
            except sqlite3.DatabaseError:
                continue
            readable_runs += row is not None and _is_record(row[0])
    assert 100 < readable_runs < 200, readable_runs
    cases.append(Case("results_malformed_one_page", "store", ["results", str(partly), "--json"], 1,
                      (str(partly), "rowids", "in a damaged part of the store file", "malformed", "run the batch into a new store"),
                      expect_out=(f'"runs": {readable_runs},',)))
    cases.append(Case("batch_malformed_one_page", "store", batch(str(partly)), 2,
                      (str(partly), "damaged", "batch does not write into a damaged file", "another --store")))
    empty_meta = made("no_format.sqlite")
    with sqlite3.connect(empty_meta) as conn:
        conn.execute("DELETE FROM meta")
    cases.append(Case("results_meta_emptied", "store", ["results", str(empty_meta)], 2, (str(empty_meta), "format")))

    # SQLite's files beside the store: a journal that is a folder or a device is named
    for side in ("wal", "shm", "journal"):
        odd = made(f"odd_{side}.sqlite")
        (stores / f"odd_{side}.sqlite-{side}").mkdir()
        why = (str(odd), f"its journal {odd}-{side} is a folder", "move")
        cases.append(Case(f"results_{side}_is_folder", "store", ["results", str(odd)], 2, why))
        cases.append(Case(f"batch_{side}_is_folder", "store", batch(str(odd)), 2, why))
    fifo_wal = made("fifo_wal.sqlite")
    os.mkfifo(f"{fifo_wal}-wal")
    cases.append(Case("results_wal_is_fifo", "store", ["results", str(fifo_wal)], 2,
                      (str(fifo_wal), "-wal is not a regular file")))

    # a full disk after the store is open: the committed runs survive, the message says how to go on
    # (RLIMIT_FSIZE 33 KiB: SQLite's -shm, 32 KiB, fits; the -wal holds a few runs' commits, then its next write
    # fails as on a full disk; the limit is per file, so a limit near the store's own size never reaches the -wal)
    full = made("full.sqlite", 30)
    long_study = write("store_study_12.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                                              "times: [200, 210, 220, 230, 240, 250]\nstrategies: [time-saving, four-stage]\n")
    cases.append(Case("batch_disk_full", "store", ["batch", long_study, "--store", str(full), "--workers", "1", "--quiet"], 2,
                      (str(full), "the runs committed so far are kept", "run the same command again"), fsize=33 * 1024,
                      after=readable(full, 31), note="RLIMIT_FSIZE: the journal fills after a few commits"))
    new_full = stores / "new_on_full_disk.sqlite"
    cases.append(Case("batch_new_store_disk_full", "store", batch(str(new_full)), 2,
                      (str(new_full), "run the same command again"), fsize=4096,
                      after=lambda: f"{new_full.name} left" if any(Path(f"{new_full}{x}").exists() for x in ("", "-wal", "-shm"))
                      else None, note="a new store that cannot be made leaves nothing"))
    no_room = made("read_on_full_disk.sqlite", 3)
    cases.append(Case("results_disk_full_no_room_for_shm", "store", ["results", str(no_room), "--json"], 0, (), fsize=4096,
                      expect_out=('"runs": 3',), note="the -shm cannot be made: the file is read as it is"))
    no_room_wal = made("read_on_full_disk_wal.sqlite", 3)
    Path(f"{no_room_wal}-wal").write_bytes(_garbage(5000, 3))
    cases.append(Case("results_disk_full_runs_in_wal", "store", ["results", str(no_room_wal)], 2,
                      (str(no_room_wal), "still in its journal", "disk is full", "free some space"), fsize=4096))
    full_read = made("full_read.sqlite", 30)
    cases.append(Case("results_disk_full_is_fine", "store", ["results", str(full_read), "--json"], 0, (),
                      fsize=full_read.stat().st_size + 1024,
                      expect_out=('"runs": 30',), note="reading needs no space"))

    # a second writer: another process holds the store's writer lock
    held = made("held.sqlite")
    import fcntl

    fd = os.open(held, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    _HELD.append(fd)
    cases.append(Case("batch_second_writer", "store", batch(str(held)), 2, (str(held), "another locoplan batch")))
    cases.append(Case("results_while_writing", "store", ["results", str(held), "--json"], 0, (), expect_out=('"runs": 3',)))

    # read-only: a store file, a folder (batch refuses before any run; results reads)
    ro_dir = stores / "read_only_folder"
    ro_dir.mkdir(exist_ok=True)
    os.chmod(ro_dir, 0o755)
    in_ro = made("read_only_folder/s.sqlite")
    os.chmod(ro_dir, 0o555)
    ro_file = made("read_only_file.sqlite")
    os.chmod(ro_file, 0o444)
    for name, path, why in (("batch_read_only_folder", in_ro, "is read-only"),
                            ("batch_new_store_read_only_folder", ro_dir / "new.sqlite", "is read-only"),
                            ("batch_read_only_store", ro_file, "read-only")):
        cases.append(Case(name, "store", batch(str(path)), 2, (str(path), why), permissions=True))
    for name, path in (("results_read_only_folder", in_ro), ("results_read_only_store", ro_file)):
        cases.append(Case(name, "store", ["results", str(path), "--json"], 0, (), expect_out=('"runs": 3',), permissions=True))

    # WAL: the store file alone holds every committed run (checkpointed after each commit)
    alone = made("alone.sqlite", 5)
    copy = stores / "alone_copy.sqlite"
    shutil.copy(alone, copy)
    cases.append(Case("store_file_alone_has_every_run", "store", ["results", str(copy), "--json"], 0, (),
                      expect_out=('"runs": 5',)))


def _trust_cases(cases: list[Case], write, good_route: str, steep: str, tmp: Path) -> None:
    """What is read back and what is written over: outputs that name an input (through links, by inode), caches that
    hold damaged or out-of-range entries, a line with no fastest run, the process's own environment (a closed stdout,
    an ASCII terminal, COLUMNS=0, TERM=dumb), stores damaged mid-file, study files that multiply to millions, implausible
    log values, and journeys whose stops lie closer than a route can be long."""
    import sqlite3

    sys.path.insert(0, str(ROOT))
    from locoplan.runs.spec import RunRecord
    from locoplan.runs.store import Store

    work = tmp / "trust"
    work.mkdir(exist_ok=True)

    def unchanged(*paths: Path):
        before = {p: p.read_bytes() for p in paths}

        def check():
            changed = [p.name for p, b in before.items() if not p.is_file() or p.read_bytes() != b]
            return f"changed or lost: {changed}" if changed else None
        return check

    def store_of(name: str, n: int = 4) -> Path:
        path = work / name
        for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
            if p.exists() or p.is_symlink():
                p.unlink()
        with Store(path) as st:
            for i in range(n):
                st.put(RunRecord(f"key{i:04d}", {"route": "hostile", "consist": "c", "strategy": "time-saving",
                                                 "algorithm": None, "planned_time_s": 200.0 + i, "feasible": True,
                                                 "running_time_s": 99.0, "traction_energy_kwh": 15.0 + i},
                                 {"route": good_route, "consist": SMALL}, None, 0.1, {"locoplan": st.meta["locoplan"]},
                                 "host:1"))
        return path

    # --- an output names an input: refused before any work (exit 2), the input byte for byte as it was
    as_csv = store_of("runs.csv")
    cases.append(Case("inout_results_out_is_store", "inout", ["results", str(as_csv), "--format", "csv", "--out", str(as_csv)],
                      2, (str(as_csv), "--out", "is the input STORE"), after=unchanged(as_csv)))
    store = store_of("inout.sqlite")
    json_store = work / "inout_summary.json"
    if json_store.exists():
        json_store.unlink()
    os.link(store, json_store)  # a hard link: another name, the same inode
    cases.append(Case("inout_results_out_hard_link", "inout", ["results", str(store), "--out", str(json_store)], 2,
                      (str(json_store), "--out", "is the input STORE"), after=unchanged(store)))
    png_store = work / "inout_plot.png"
    if png_store.is_symlink() or png_store.exists():
        png_store.unlink()
    png_store.symlink_to(store)
    cases.append(Case("inout_results_plot_is_store", "inout", ["results", str(store), "--plot", str(png_store)], 2,
                      (str(png_store), "--plot", "is the input STORE"), after=unchanged(store)))
    plots = work / "plots"
    plots.mkdir(exist_ok=True)
    link = work / "plots_link"
    if not link.is_symlink():
        link.symlink_to(plots)

    def nothing_in(folder: Path):
        return lambda: f"written: {[p.name for p in folder.iterdir()]}" if any(folder.iterdir()) else None
    cases.append(Case("inout_two_outputs_through_folder_link", "inout",
                      ["results", str(store), "--plot", str(plots / "p.png"), "--boxplot", str(link / "p.png")], 2,
                      ("--boxplot", "names the same file as --plot"), after=nothing_in(plots)))
    route_csv = work / "route_as.csv"
    if route_csv.is_symlink() or route_csv.exists():
        route_csv.unlink()
    route_csv.symlink_to(good_route)
    for cmd in (["simulate"], ["optimize"], ["bound", "--times", "200,210"]):
        cases.append(Case(f"inout_{cmd[0]}_out_is_route", "inout", [cmd[0], good_route, "--consist", SMALL, *cmd[1:],
                                                                   "--out", str(route_csv)], 2,
                          (str(route_csv), "--out", "is the input ROUTE"), after=unchanged(Path(good_route))))
    patterns = work / "patterns.json"
    patterns.write_text("{}\n")
    cases.append(Case("inout_advise_out_is_patterns", "inout", ["advise", good_route, "--patterns", str(patterns), "--out",
                                                               str(patterns)], 2, (str(patterns), "--out", "is the input --patterns"),
                      after=unchanged(patterns)))
    study = write("inout_study.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                                      "times: [200]\nstrategies: [time-saving]\n")
    cases.append(Case("inout_batch_store_is_study", "inout", ["batch", study, "--store", study, "--workers", "1", "--quiet"], 2,
                      (study, "--store", "is the input STUDY.yaml"), after=unchanged(Path(study))))
    # a file named inside an input (a journey's route) is no output either: refused when the outputs are moved in
    line_json = work / "line.json"
    line_json.write_text(route(), encoding="utf-8")
    jr = work / "journey_on_json_route.yaml"
    jr.write_text(f"schema: locoplan/journey@1\nname: j\nroute: {line_json.name}\nrun_time_s: 300\nstations:\n"
                  "  - {name: A, at_m: 0}\n  - {name: C, at_m: 1500}\n")
    cases.append(Case("inout_journey_out_is_its_route", "inout", ["journey", str(jr), "--consist", SMALL, "--out", str(line_json)],
                      2, (str(line_json), "is an input this command read", "nothing was written"), after=unchanged(line_json)))
    # another program's SQLite file: refused, and left as it was (not switched to WAL)
    foreign = work / "foreign.db"
    if foreign.exists():
        foreign.unlink()
    with sqlite3.connect(foreign) as conn:
        conn.execute("CREATE TABLE t (x)")
        conn.execute("INSERT INTO t VALUES (1)")
    conn.close()
    cases.append(Case("inout_batch_foreign_sqlite_untouched", "inout", ["batch", study, "--store", str(foreign), "--workers", "1",
                                                                        "--quiet"], 2, (str(foreign), "not a locoplan result store"),
                      after=unchanged(foreign)))

    # --- a line with no fastest run: a factor of it is exit 1 with the physical reason, never a NaN traceback
    for cmd in (["bound", "--time", "1.1x"], ["optimize", "--time", "1.2x"], ["simulate", "--time", "+10%"],
                ["compare", "--time", "1.1x"], ["sweep", "--times", "1.1x,1.2x"], ["bound", "--times", "1.1x,1.3x"],
                ["pareto", "--no-optimum"], ["ocp", "--objective", "energy", "--time", "1.1x"]):
        cases.append(Case(f"no_fastest_run_{cmd[0]}_{cmd[-1]}", "physics", [cmd[0], steep, "--consist", "HXD1-C80x50", *cmd[1:]],
                          1, ("cannot run", "stalled at")))
    cases.append(Case("no_fastest_run_bound_json", "physics", ["bound", steep, "--consist", "HXD1-C80x50", "--time", "1.1x",
                                                               "--json"], 1, ("stalled at",),
                      expect_out=('"exit_code": 1', "stalled at")))
    steep_journey = write("steep_journey.yaml", f"schema: locoplan/journey@1\nname: steep j\nroute: {Path(steep).name}\n"
                          "stations:\n  - {name: A, at_m: 0}\n  - {name: B, at_m: 3000}\n  - {name: C, at_m: 6000}\n")
    cases.append(Case("no_fastest_run_journey_factor", "physics", ["journey", steep_journey, "--consist", "HXD1-C80x50", "--time",
                                                                   "1.1x"], 1, ("cannot run", "stalled at")))

    # --- the E* disk cache read back: a damaged or out-of-range entry is solved again, never printed
    _estar_cache_cases(cases, good_route, work)

    # --- the environment: a closed stdout, an encoding that cannot write the names, no width, a dumb terminal
    named = write("route_named_in_another_script.yaml", route(name="'Zürich–Genève :x: [bold]fett[/bold]'"))
    sim = ["simulate", named, "--consist", SMALL]
    bad = sim + ["--time", "-3"]
    fresh = work / "closed_stdout.sqlite"
    for p in (fresh, Path(f"{fresh}-wal"), Path(f"{fresh}-shm")):
        if p.exists():
            p.unlink()

    def store_whole():
        if not fresh.is_file():
            return "the store was not written"
        try:
            with sqlite3.connect(f"file:{fresh}?mode=ro", uri=True) as conn:
                n = conn.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        except sqlite3.Error as exc:
            return f"the store is damaged: {exc}"
        return None if n == 1 else f"the store holds {n} runs, expected 1"
    cases.append(Case("env_stdout_closed_simulate", "env", sim, 0, (), close_stdout=True))
    cases.append(Case("env_stdout_closed_error_kept", "env", bad, 2, (CMDLINE, "--time"), close_stdout=True))
    cases.append(Case("env_stdout_closed_json", "env", sim + ["--json"], 0, (), close_stdout=True))
    cases.append(Case("env_stdout_closed_batch_store_whole", "env", ["batch", study, "--store", str(fresh), "--workers", "1"],
                      0, (), close_stdout=True, after=store_whole,
                      note="a descriptor 1 left closed would be taken by the store, and the report written into it"))
    ascii_env = {"PYTHONIOENCODING": "ascii"}
    cases.append(Case("env_ascii_terminal_name", "env", sim, 0, (), env=ascii_env, expect_out=("Z?rich?Gen?ve", ":x:")))
    cases.append(Case("env_ascii_terminal_error", "env", ["simulate", str(work / "Zürich-nowhere.yaml")], 2,
                      ("nowhere.yaml", "no such file"), env=ascii_env))
    cases.append(Case("env_ascii_terminal_json", "env", sim + ["--json"], 0, (), env=ascii_env,
                      expect_out=("Z\\u00fcrich",)))
    for cols in ("0", "1"):
        cases.append(Case(f"env_columns_{cols}", "env", sim, 0, (), env={"COLUMNS": cols},
                          expect_out=("Zürich–Genève", "strategy", "traction energy")))
        cases.append(Case(f"env_columns_{cols}_error_kept", "env", bad, 2, (CMDLINE, "--time", "must be in"),
                          env={"COLUMNS": cols}))
    cases.append(Case("env_term_dumb", "env", sim, 0, (), env={"TERM": "dumb"}, expect_out=("strategy", "traction energy")))
    cases.append(Case("env_emoji_code_in_name", "env", sim, 0, (), expect_out=(":x:", "[bold]fett[/bold]"), forbid_out=("❌",)))
    cases.append(Case("env_emoji_code_in_message", "env", ["simulate", str(work / ":x:-nowhere.yaml")], 2, (":x:-nowhere.yaml",),
                      forbid=("❌",)))

    # --- stores: damage mid-file is exit 1 with the damage named; --where compares numbers as numbers
    whole = store_of("where.sqlite", 4)
    for text, why in (("planned_time_s<1000s", "a number with a unit"), ("planned_time_s<=2e2 s", "a number with a unit"),
                      ("planned_time_s<abc", "is a number"), ("route<5", "is text")):
        cases.append(Case(f"where_{text}", "store", ["results", str(whole), "--where", text], 2, (CMDLINE, "--where", why)))
    for text, n in (("planned_time_s<1000", 4), ("planned_time_s<201.5", 2), ("planned_time_s>=2e2", 4),
                    ("traction_energy_kwh>16.5", 2)):
        cases.append(Case(f"where_numeric_{text}", "store", ["results", str(whole), "--where", text, "--json"], 0, (),
                          expect_out=(f'"runs": {n},',)))
    mid = store_of("damaged_mid_file.sqlite", 200)
    data = bytearray(mid.read_bytes())
    page = (len(data) // 4096 // 2) * 4096
    data[page:page + 4096] = bytes(4096)  # a page of zeros in the middle (a lost block)
    mid.write_bytes(bytes(data))
    for fmt in ([], ["--json"], ["--format", "csv"]):
        cases.append(Case("_".join(["store_damaged_mid_file", *(f.strip("-") for f in fmt)]) or "store_damaged_mid_file",
                          "store", ["results", str(mid), *fmt], 1, (str(mid), "the store is damaged", "rowids"),
                          expect_out=('"exit_code": 1',) if fmt == ["--json"] else ()))

    # --- study files: the run count bounded before expansion; duplicates are one run
    big = write("study_millions.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}]\nconsists: [{SMALL}]\n"
                f"times: {list(range(200, 1200))}\nstrategies: [proposed]\nalgorithms: [issa, pso, ssa]\n"
                f"seeds: {list(range(3000))}\n")
    big_store = work / "millions.sqlite"
    cases.append(Case("study_lists_multiply_to_millions", "study", ["batch", big, "--store", str(big_store), "--quiet"], 2,
                      (big, "expands to 9,000,000 runs", "100,000"),
                      after=lambda: f"{big_store.name} was made" if big_store.exists() else None))
    dup = write("study_duplicate_times.yaml", f"schema: locoplan/study@1\nroutes: [{good_route}, {Path(good_route).parent}/./"
                f"{Path(good_route).name}]\nconsists: [{SMALL}]\ntimes: [200, 200.0, '200']\nstrategies: [time-saving]\n")
    cases.append(Case("study_duplicate_times_one_run", "study", ["batch", dup, "--store", str(work / "dup.sqlite"), "--workers",
                                                                 "1", "--json", "--quiet"], 0, (),
                      expect_out=('"runs": 1,', '"distinct_runs": 1,')))

    # --- implausible values: driver logs (every numeric column, the manifest) and journeys' stop spacing
    _log_cases(cases, good_route, work)
    close = write("journey_stops_5m.yaml", f"schema: locoplan/journey@1\nname: close stops\nroute: {Path(good_route).name}\n"
                  "run_time_s: 300\nstations:\n  - {name: A, at_m: 0}\n  - {name: B, at_m: 5}\n  - {name: C, at_m: 1500}\n")
    why = (close, "stations[1].at_m", "5 m long", "at least 10 m")
    cases.append(Case("journey_stops_5m_validate", "number", ["validate", close], 2, why, batch_file=close))
    for cmd in (["journey"], ["pareto", "--no-optimum"]):
        cases.append(Case(f"journey_stops_5m_{cmd[0]}", "number", [cmd[0], close, "--consist", SMALL, *cmd[1:]], 2, why))
    close_study = write("study_journey_stops_5m.yaml", f"schema: locoplan/study@1\njourneys: [{close}]\nconsists: [{SMALL}]\n"
                        "strategies: [time-saving]\n")
    cases.append(Case("journey_stops_5m_batch", "number", ["batch", close_study, "--store", str(work / "close.sqlite"),
                                                          "--workers", "1", "--quiet"], 2, why))
    passing = write("journey_passing_5m.yaml", f"schema: locoplan/journey@1\nname: passing\nroute: {Path(good_route).name}\n"
                    "run_time_s: 300\nstations:\n  - {name: A, at_m: 0}\n  - {name: B, at_m: 5, stop: false}\n"
                    "  - {name: C, at_m: 1500}\n")
    cases.append(Case("journey_passing_station_5m_ok", "number", ["validate", passing], 0, (), batch_file=passing))


def _estar_cache_cases(cases: list[Case], good_route: str, work: Path) -> None:
    """E* cache entries planted in a cache folder of each case's own: wrong types, not finite, negative, another time,
    a missing or unknown field, not JSON; and a valid entry whose key (the time to 0.01 s) also covers a time below
    the fastest run. Each must be solved again (never the planted 987.654) or refused."""
    import json
    import math

    from locoplan.io.load import load_route_and_train
    from locoplan.ocp import bound as estar
    from locoplan.sim.calculator import ModelOptions, TractionCalculator

    route_, train = load_route_and_train(good_route, SMALL, None)
    options = estar.relaxed(ModelOptions())
    base = estar._problem_key(route_, train, options, 0.0)

    def planted(name: str, time_s: float, content: str) -> dict[str, str]:
        folder = work / "caches" / name
        old = os.environ.get("LOCOPLAN_CACHE_DIR")
        os.environ["LOCOPLAN_CACHE_DIR"] = str(folder)
        try:
            f = estar._cache_file((base, round(time_s, 2), estar.METHOD, estar.E_STAR_TOL))
        finally:
            if old is None:
                os.environ.pop("LOCOPLAN_CACHE_DIR", None)
            else:
                os.environ["LOCOPLAN_CACHE_DIR"] = old
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(content)
        return {"LOCOPLAN_CACHE_DIR": str(folder)}

    good = {"time_s": 200.0, "energy_kwh": 987.654, "converged": True, "cells": 300, "step_m": 5.0, "solve_time_s": 0.1,
            "accuracy": 1e-5, "slope_kwh_per_s": -0.02, "method": "cells", "objective": "traction",
            "traction_kwh": 987.654, "recovered_kwh": 0.0}
    variants = {
        "energy_text": {**good, "energy_kwh": "987.654"},
        "energy_negative": {**good, "energy_kwh": -987.654, "traction_kwh": None},
        "energy_nan": {**good, "energy_kwh": math.nan, "traction_kwh": 987.654},
        "energy_infinite": {**good, "energy_kwh": math.inf, "traction_kwh": 987.654},
        "cells_fraction": {**good, "cells": 1.5},
        "converged_text": {**good, "converged": "yes"},
        "another_time": {**good, "time_s": 150.0},
        "field_missing": {k: v for k, v in good.items() if k != "cells"},
        "field_unknown": {**good, "extra": 1},
        "a_list": [good],
    }
    for name, entry in variants.items():
        env = planted(name, 200.0, json.dumps(entry))  # json writes NaN and Infinity as Python reads them back
        cases.append(Case(f"cache_estar_{name}", "cache", ["bound", good_route, "--consist", SMALL, "--time", "200", "--json"], 0,
                          (), env=env, expect_out=('"exit_code": 0',), forbid_out=("987.654", "Infinity", "NaN")))
    env = planted("not_json", 200.0, "\x00\x01 not json {")
    cases.append(Case("cache_estar_not_json", "cache", ["bound", good_route, "--consist", SMALL, "--time", "200", "--json"], 0,
                      (), env=env, expect_out=('"exit_code": 0',)))
    fastest = TractionCalculator(route_, train, options).fastest_time_s
    key_t = round(fastest, 2)
    below = math.floor((key_t - 0.0049) * 10_000) / 10_000  # rounds to the same key, below the fastest run
    if round(below, 2) == key_t and below < fastest:
        env = planted("below_fastest", key_t, json.dumps({**good, "time_s": key_t}))
        cases.append(Case("cache_estar_below_fastest_run", "cache", ["bound", good_route, "--consist", SMALL, "--time",
                                                                     f"{below:.4f}"], 1, ("below the fastest possible run",),
                          env=env, forbid_out=("987.654",)))


def _log_cases(cases: list[Case], good_route: str, work: Path) -> None:
    """A log set of one run (manifest, CSV) with one implausible value at a time: every numeric column, past its
    bound or past what the run's train can give, and the manifest's numbers; each named at file:line."""
    from locoplan.io.load import load_train

    mass = load_train(SMALL).mass_t
    rows = [(float(t), 7.5 * t, 27.0, 100.0) for t in range(201)]

    def log_set(name: str, column: int | None = None, value: str = "", manifest: dict[str, str] | None = None) -> Path:
        folder = work / "logs" / name
        folder.mkdir(parents=True, exist_ok=True)
        lines = ["time_s,position_m,speed_kmh,force_kn"]
        for i, row in enumerate(rows):
            cells = [f"{x:g}" for x in row]
            if column is not None and i == 3:  # line 5 of the file
                cells[column] = value
            lines.append(",".join(cells))
        (folder / "run.csv").write_text("\n".join(lines) + "\n")
        entry = {"log": "run.csv", "driver_id": "D01", "mass_t": f"{mass:g}", "scheduled_time_s": "200",
                 "actual_time_s": "200", "date": "2024-01-01", **(manifest or {})}
        (folder / "manifest.yaml").write_text(
            f"schema: locoplan/driver-logs@1\nroute: {good_route}\nconsist: {SMALL}\nsynthetic: true\nruns:\n"
            "  - {" + ", ".join(f"{k}: {v}" for k, v in entry.items()) + "}\n")
        return folder

    for name, column, value, why in (
            ("force_1e6", 3, "1e6", "not a plausible value"), ("force_1e308", 3, "1e308", "not a plausible value"),
            ("force_minus_1e6", 3, "-1e6", "not a plausible value"),
            ("force_past_the_train", 3, "5000", "more traction than the train"),
            ("brake_past_the_train", 3, "-50000", "more braking than the train"),
            ("speed_1e308", 2, "1e308", "not a plausible value"), ("speed_900", 2, "900", "not a plausible value"),
            ("time_1e308", 0, "1e308", "not a plausible value"), ("position_1e308", 1, "1e308", "not a plausible value")):
        folder = log_set(name, column, value)
        col = ("time_s", "position_m", "speed_kmh", "force_kn")[column]
        cases.append(Case(f"log_{name}", "number", ["learn", str(folder), "--out", str(folder / "p.json")], 2,
                          (f"{folder / 'run.csv'}:5: column {column + 1} ({col})", why),
                          after=lambda f=folder: "p.json written" if (f / "p.json").exists() else None))
    for field_, value in (("mass_t", "1.0e+308"), ("scheduled_time_s", "1.0e+308"), ("actual_time_s", "1.0e+300")):
        folder = log_set(f"manifest_{field_}", manifest={field_: value})
        cases.append(Case(f"log_manifest_{field_}_huge", "number", ["learn", str(folder), "--out", str(folder / "p.json")], 2,
                          (f"{folder / 'manifest.yaml'}:", f"runs[0].{field_}", "less than or equal")))


_HELD: list[int] = []
"""File descriptors holding store locks for the corpus's whole life (a 'second writer')."""


def _is_record(text) -> bool:
    import json

    try:
        return isinstance(json.loads(text).get("summary"), dict)
    except (ValueError, AttributeError, TypeError):
        return False


# ------------------------------------------------------------------------------------------ running
def _limits(umask: int | None, fsize: int | None = None, permissions: bool = False, close_stdout: bool = False):
    def apply():
        if permissions and os.geteuid() == 0:  # as root, a read-only file is read-only only without these
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            for cap in (1, 2, 3):  # CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER
                libc.prctl(24, cap, 0, 0, 0)  # PR_CAPBSET_DROP: gone from the bounding set, so at exec
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP_BYTES, MEMORY_CAP_BYTES))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        if fsize is not None:  # a file that would grow past it fails with EFBIG, as a full disk fails
            import signal

            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
        os.setsid()
        if umask is not None:
            os.umask(umask)
        if close_stdout:
            os.close(1)
    return apply


def run(argv: list[str], cwd: Path, umask: int | None = None, timeout_s: float = TIME_LIMIT_S, module: str = "locoplan",
        fsize: int | None = None, stdout_file: str | None = None, permissions: bool = False,
        stderr_file: str | None = None, more_env: dict[str, str] | None = None, during: Callable[[], None] | None = None,
        close_stdout: bool = False):
    """Run ``python -m locoplan *argv`` (or the script ``module``) under the caps; (returncode or None on
    timeout, stdout, stderr, seconds, this child's peak RSS in bytes)."""
    env = {**os.environ, "COLUMNS": "200", "NO_COLOR": "1", "PYTHONPATH": str(ROOT), **(more_env or {})}
    env.pop("FORCE_COLOR", None)
    t = time.perf_counter()
    cmd = [sys.executable, "-m", module] if module == "locoplan" else [sys.executable, module]
    sink = open(stdout_file, "wb") if stdout_file else None
    err_sink = open(stderr_file, "wb") if stderr_file else None
    proc = subprocess.Popen([*cmd, *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=sink or subprocess.PIPE, stderr=err_sink or subprocess.PIPE,
                            preexec_fn=_limits(umask, fsize, permissions, close_stdout))
    for s in (sink, err_sink):
        if s:
            s.close()
    if during is not None:
        threading.Thread(target=during, daemon=True).start()
    chunks: dict[str, bytes] = {"out": b"", "err": b""}
    readers = [threading.Thread(target=lambda k=k, f=f: chunks.__setitem__(k, f.read()))
               for k, f in (("out", proc.stdout), ("err", proc.stderr)) if f is not None]
    for r in readers:
        r.start()
    # wait4 (not Popen.wait) so that the peak memory is this child's own
    status, usage, code = 0, None, None
    while True:
        pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if pid:
            code = os.waitstatus_to_exitcode(status)
            break
        if time.perf_counter() - t > timeout_s:
            os.killpg(proc.pid, 9)
            _, status, usage = os.wait4(proc.pid, 0)
            break
        time.sleep(0.01)
    proc.returncode = -9 if code is None else code
    for r in readers:
        r.join()
    seconds = time.perf_counter() - t
    peak = usage.ru_maxrss * 1024
    return code, chunks["out"].decode("utf-8", "replace"), chunks["err"].decode("utf-8", "replace"), seconds, peak


def judge(case: Case, code, out: str, err: str, seconds: float, peak: int) -> Outcome:
    o = Outcome(case, code, out, err, seconds, peak)
    if o.hang:
        o.problems.append(f"no answer within {case.time_limit_s or TIME_LIMIT_S:g} s")
    if o.traceback:
        o.problems.append("traceback")
    if code is not None and code != case.exit:
        o.problems.append(f"exit {code}, expected {case.exit}")
    for text in case.expect:
        if text not in err:
            o.problems.append(f"stderr lacks {text!r}")
    for text in case.expect_out:
        if text not in out:
            o.problems.append(f"stdout lacks {text!r}")
    for text in case.forbid:
        if text in err:
            o.problems.append(f"stderr holds {text!r}")
    for text in case.forbid_out:
        if text in out:
            o.problems.append(f"stdout holds {text!r}")
    if case.max_stderr_chars is not None and len(err) > case.max_stderr_chars:
        o.problems.append(f"stderr is {len(err):,} characters, more than {case.max_stderr_chars:,}")
    if case.exit != 0 and "error: : " in err:
        o.problems.append("a message with an empty file field")
    if case.after is not None:
        complaint = case.after()
        if complaint:
            o.problems.append(complaint)
    return o


def warm_up(cwd: Path) -> None:
    """Build the compiled kernels (``locoplan.sim.native``, once per cache folder: seconds to a minute) before any
    case is timed: the time limit is a case's, not the first build's."""
    route_file = Path(cwd) / "warm_up_route.yaml"
    route_file.write_text(route(), encoding="utf-8")
    run(["optimize", str(route_file), "--consist", SMALL, "--json"], cwd, timeout_s=900)
    # E* of the corpus's route, cached (LOCOPLAN_CACHE_DIR), so that bound under a file-size limit reads it
    run(["bound", str(route_file), "--consist", SMALL, "--json"], cwd, timeout_s=900)
    # the other strategies' compiled code too (a case under a file-size limit cannot write a cache)
    run(["compare", str(route_file), "--consist", SMALL, "--strategies", "time-saving,four-stage", "--e-min", "5", "--json"],
        cwd, timeout_s=900)


def run_case(case: Case, cwd: Path) -> Outcome:
    return judge(case, *run(case.argv, cwd, case.umask, timeout_s=case.time_limit_s or TIME_LIMIT_S, fsize=case.fsize,
                            stdout_file=case.stdout_file, permissions=case.permissions, stderr_file=case.stderr_file,
                            more_env=case.env, during=case.during, close_stdout=case.close_stdout))


def run_batch(cases: list[Case], cwd: Path, timeout_s: float | None = None) -> list[Outcome]:
    """Several cases in ONE capped subprocess that imports locoplan once and runs each case's command
    in-process (``locoplan.cli.app``), for speed: the fast test. Each case still gets its own exit code,
    stdout and stderr; a case that hangs stops the batch at its time limit and is reported as the hang,
    the cases after it are run again in a new batch. The peak memory is the batch's."""
    import json
    import tempfile

    outcomes: list[Outcome] = []
    todo = list(cases)
    while todo:
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as fh:
            json.dump([c.argv for c in todo], fh)
        limit = timeout_s if timeout_s is not None else TIME_LIMIT_S + 2.0 * len(todo)
        code, out, err, seconds, peak = run(["--hostile-batch", fh.name], cwd, timeout_s=limit, module=str(Path(__file__)))
        os.unlink(fh.name)
        done = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
        for case, r in zip(todo, done):
            hung = r["seconds"] > TIME_LIMIT_S
            outcomes.append(judge(case, None if hung else r["code"], r["stdout"], r["stderr"], r["seconds"], peak))
        todo = todo[len(done):]
        if todo:  # the batch died or hung inside todo[0]: that case is the culprit, the rest go on
            culprit = todo.pop(0)
            outcomes.append(judge(culprit, None if code is None else code, "", err[-4000:], seconds, peak))
    return outcomes


def _batch_main(path: str) -> None:
    """``python tests/hostile.py --hostile-batch cases.json``: run each argv in-process, one JSON line each."""
    import contextlib
    import io
    import json
    import traceback

    sys.path.insert(0, str(ROOT))
    from locoplan.cli import app

    for argv in json.loads(Path(path).read_text()):
        out, err = io.StringIO(), io.StringIO()
        t = time.perf_counter()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                app(argv, prog_name="locoplan")
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            except BaseException:  # what Python would print: the test counts it as a traceback
                traceback.print_exc()
                code = 1
        print(json.dumps({"code": code, "stdout": out.getvalue(), "stderr": err.getvalue(),
                          "seconds": time.perf_counter() - t}), flush=True)


if __name__ == "__main__" and len(sys.argv) == 3 and sys.argv[1] == "--hostile-batch":
    _batch_main(sys.argv[2])
