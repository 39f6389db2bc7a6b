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
    stdin_ok: bool = False
    note: str = ""


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
    file_case("key_bool.yaml", "yaml", route() + "yes: 5\n", "key", "not a string")
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
    option("advise_mass_huge", ["advise", good_route, "--patterns", str(tmp / "none.json"), "--mass", "1e12"], "--mass")
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
    return cases


# ------------------------------------------------------------------------------------------ running
def _limits(umask: int | None):
    def apply():
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP_BYTES, MEMORY_CAP_BYTES))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        os.setsid()
        if umask is not None:
            os.umask(umask)
    return apply


def run(argv: list[str], cwd: Path, umask: int | None = None, timeout_s: float = TIME_LIMIT_S, module: str = "locoplan"):
    """Run ``python -m locoplan *argv`` (or the script ``module``) under the caps; (returncode or None on
    timeout, stdout, stderr, seconds, this child's peak RSS in bytes)."""
    env = dict(os.environ, COLUMNS="200", NO_COLOR="1", PYTHONPATH=str(ROOT))
    env.pop("FORCE_COLOR", None)
    t = time.perf_counter()
    cmd = [sys.executable, "-m", module] if module == "locoplan" else [sys.executable, module]
    proc = subprocess.Popen([*cmd, *argv], cwd=cwd, env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_limits(umask))
    chunks: dict[str, bytes] = {}
    readers = [threading.Thread(target=lambda k=k, f=f: chunks.__setitem__(k, f.read()))
               for k, f in (("out", proc.stdout), ("err", proc.stderr))]
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
        o.problems.append(f"no answer within {TIME_LIMIT_S:g} s")
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
    if case.exit != 0 and "error: : " in err:
        o.problems.append("a message with an empty file field")
    if case.after is not None:
        complaint = case.after()
        if complaint:
            o.problems.append(complaint)
    return o


def run_case(case: Case, cwd: Path) -> Outcome:
    return judge(case, *run(case.argv, cwd, case.umask))


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
