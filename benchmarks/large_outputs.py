"""Issue 24's memory promise at the largest documented sizes: each command run as ``python -m locoplan`` under
the hostile corpus's 1 GiB address-space cap, with its peak memory (the child's own maximum RSS).

- ``results`` on a store of 100,000 runs: the summary, and the csv, json (to a file and to stdout) and parquet
  exports (each streamed from the store a row at a time);
- ``drivers simulate`` at its limit of 20,000 logs: 20 drivers x 1 run x 1,000 planned times (the logs are
  written as they are made, the runs searched and recorded a block at a time);
- ``learn`` on those 20,000 logs (each log read and checked, then only its summary kept; the good runs' logs
  read again one at a time for the layers' rows), and ``compare --strategies drivers --logs`` on them.

    python benchmarks/large_outputs.py                       # all three (drivers and learn: about 20 min on freight-20km)
    python benchmarks/large_outputs.py --only results        # about 3 minutes
    python benchmarks/large_outputs.py --only drivers        # the logs, then learn from them
    python benchmarks/large_outputs.py --only learn --logs DIR   # learn from logs made before
    python benchmarks/large_outputs.py --only drivers --route routes/real/CH_Stadelhofen_Altstetten-leg1.yaml
"""

from __future__ import annotations

import argparse
import json
import re
import sqlite3
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
import hostile  # noqa: E402

LIMIT_S = 3 * 3600.0


def run(argv: list[str], cwd: Path, label: str, stdout_file: str | None = None) -> dict:
    code, out, err, seconds, peak = hostile.run(argv, cwd, timeout_s=LIMIT_S, stdout_file=stdout_file)
    row = {"what": label, "exit": code, "seconds": round(seconds, 1), "peak_mib": round(peak / 2**20)}
    print(f"{label:<48} exit {code}  {seconds:7.1f} s  peak {peak / 2**20:6.0f} MiB", flush=True)
    if code != 0:
        print(err[-2000:], file=sys.stderr)
    return row


def big_store(tmp: Path, runs: int) -> Path:
    """A store of ``runs`` runs: a small real batch (12 runs: three strategies, two seeds, three times), its
    records copied under new keys and seeds in one transaction."""
    route = tmp / "route.yaml"
    route.write_text(hostile.route(), encoding="utf-8")
    study = tmp / "study.yaml"
    study.write_text(f"schema: locoplan/study@1\nroutes: [{route}]\nconsists: [{hostile.SMALL}]\ntimes: [200, 220, 1000]\n"
                     "strategies: [time-saving, four-stage, proposed]\nseeds: [1, 2]\n", encoding="utf-8")
    store = tmp / "big.sqlite"
    code, _, err, _, _ = hostile.run(["batch", str(study), "--store", str(store), "--workers", "1", "--quiet"], tmp,
                                     timeout_s=900)
    if code not in (0, 1):
        raise SystemExit(f"the seed batch failed:\n{err}")
    with sqlite3.connect(store) as conn:
        base = conn.execute("SELECT * FROM runs").fetchall()
        made = len(base)
        copies = []
        for i in range(runs - made):
            row = list(base[i % len(base)])
            record = json.loads(row[10])
            record["key"] = row[0] = f"{row[0][:48]}-{i:07d}"
            record["summary"]["seed"] = row[5] = 1000 + i
            row[10] = json.dumps(record)
            copies.append(row)
            if len(copies) == 10_000:
                conn.executemany("INSERT INTO runs VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", copies)
                copies.clear()
        conn.executemany("INSERT INTO runs VALUES (?,?,?,?,?,?,?,?,?,?,?,?)", copies)
    return store


def results_cases(tmp: Path, runs: int) -> list[dict]:
    t = time.perf_counter()
    store = big_store(tmp, runs)
    print(f"store of {runs:,} runs made in {time.perf_counter() - t:.0f} s ({store.stat().st_size / 2**20:.0f} MiB)")
    rows = [run(["results", str(store)], tmp, f"results: summary of {runs:,} runs")]
    for fmt in ("csv", "json", "parquet"):
        rows.append(run(["results", str(store), "--format", fmt, "--out", str(tmp / f"export.{fmt}")], tmp,
                        f"results --format {fmt} --out ({runs:,} rows)"))
    for fmt in ("csv", "json"):
        rows.append(run(["results", str(store), "--format", fmt], tmp, f"results --format {fmt} > /dev/null ({runs:,} rows)",
                        stdout_file="/dev/null"))
    rows.append(run(["results", str(store), "--plot", str(tmp / "p.png"), "--boxplot", str(tmp / "b.png")], tmp,
                    f"results --plot --boxplot ({runs:,} runs)"))
    return rows


def drivers_case(tmp: Path, route: str, drivers: int, times: int) -> tuple[dict, Path]:
    first = 1450 if "freight-20km" in route else None
    if first is None:  # a planned time every second from 1.15 x the fastest run
        code, out, err, _, _ = hostile.run(["simulate", route, "--strategy", "time-saving", "--json"], tmp, timeout_s=600)
        first = int(json.loads(out)["running_time_s"] * 1.15) + 1
    times_arg = ",".join(str(first + i) for i in range(times))
    out_dir = tmp / "logs"
    row = run(["drivers", "simulate", route, "--drivers", str(drivers), "--runs", "1", "--times", times_arg, "--out",
               str(out_dir)], tmp, f"drivers simulate: {drivers} x {times} = {drivers * times:,} logs")
    row["logs"] = len(list((out_dir / "logs").iterdir())) if (out_dir / "logs").is_dir() else 0
    print(f"  {row['logs']:,} logs written to {out_dir}; left beside it: "
          f"{sorted(p.name for p in tmp.iterdir() if p.name.startswith('logs.'))}")
    return row, out_dir


def learn_cases(tmp: Path, logs: Path, route: str) -> list[dict]:
    n = sum(1 for _ in (logs / "logs").iterdir()) if (logs / "logs").is_dir() else 0
    out = tmp / "patterns.json"
    rows = [run(["learn", str(logs), "--out", str(out), "--json"], tmp, f"learn: {n:,} logs")]
    if rows[0]["exit"] == 0:
        report = json.loads(out.read_text())["report"]
        print(f"  {report['data']['runs']:,} runs, {report['data']['good_runs']:,} good runs; held-out R^2: upper "
              f"{report['heldout']['upper']['r2']}, lower chained {report['heldout']['lower']['chained_r2']}")
    # the drivers of the first run's job (consist and planned time) among all the logs
    with open(logs / "manifest.yaml", encoding="utf-8") as fh:
        first = next(line for line in fh if line.lstrip().startswith("- {log:"))
    consist = re.search(r"consist: ([^,}]+)", first).group(1).strip()
    time_s = re.search(r"scheduled_time_s: ([0-9.]+)", first).group(1)
    rows.append(run(["compare", route, "--strategies", "drivers", "--logs", str(logs), "--consist", str(logs / consist),
                     "--time", time_s, "--e-min", "1", "--no-gap", "--json"], tmp, f"compare --strategies drivers: {n:,} logs"))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=("results", "drivers", "learn"))
    ap.add_argument("--logs", type=Path, help="learn from this log folder (default: the logs drivers simulate makes)")
    ap.add_argument("--runs", type=int, default=100_000, help="runs in the store")
    ap.add_argument("--route", default=str(ROOT / "routes/freight-20km.yaml"), help="route of drivers simulate")
    ap.add_argument("--drivers", type=int, default=20)
    ap.add_argument("--times", type=int, default=1000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        hostile.warm_up(tmp)
        rows = []
        if args.only in (None, "results"):
            rows += results_cases(tmp, args.runs)
        logs = args.logs
        if args.only in (None, "drivers") or (args.only == "learn" and logs is None):
            row, logs = drivers_case(tmp, args.route, args.drivers, args.times)
            rows.append(row)
        if args.only in (None, "drivers", "learn"):
            rows += learn_cases(tmp, logs.resolve(), args.route)
    worst = max(r["peak_mib"] for r in rows)
    print(f"\nlargest peak: {worst} MiB (limit {hostile.MEMORY_CAP_BYTES / 2**20:.0f} MiB of address space)")
    return 0 if all(r["exit"] == 0 for r in rows) and worst < hostile.MEMORY_CAP_BYTES / 2**20 else 1


if __name__ == "__main__":
    sys.exit(main())
