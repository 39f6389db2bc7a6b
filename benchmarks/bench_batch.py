"""Batch throughput (issue 11): the 540-run study of benchmarks/batch_study.yaml on 2 worker
processes and one by one in one process, the two compared record by record; what a worker's start
costs; and the scaling to expect on a cluster, computed from the measured run times.

    python benchmarks/bench_batch.py [--study benchmarks/batch_study.yaml] [--workers 2] [--keep DIR]
                                     [--sample N] [--one-by-one N]

``--sample N``: only N of the study's runs (every k-th). ``--one-by-one N``: run only N of the runs alone (every k-th) to save time; the default runs all. Prints markdown tables (pasted into docs/batch.md).
"""

from __future__ import annotations

import argparse
import heapq
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from locoplan.runs import SerialExecutor, Store, make_executor, run_many  # noqa: E402
from locoplan.runs.spec import load_inputs, spec_key  # noqa: E402
from locoplan.runs.study import load_study  # noqa: E402

START_CODE = """
import time, sys
t0 = time.perf_counter()
import locoplan.runs.spec, locoplan.runner
t1 = time.perf_counter()
from locoplan.io.load import load_route, load_train
from locoplan.runner import make_context
from locoplan.settings import RunSettings
ctx = make_context(load_route(sys.argv[1]), load_train('HXD1-C80x30'), need_time=False)
ctx.calc.fastest_time_s          # the calculator's compiled kernel: loaded from the cache (locoplan.sim.native)
t2 = time.perf_counter()
from locoplan.strategy.strategies import drive_solver
drive_solver(ctx).solve(1e-4)    # the priced-drive DP's kernels
t3 = time.perf_counter()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def worker_start(route: Path, repeats: int = 3) -> list[tuple[float, float, float]]:
    """(import, calculator kernel load, DP kernel load) [s] of a fresh interpreter, as a spawned worker pays."""
    out = []
    for _ in range(repeats):
        res = subprocess.run([sys.executable, "-c", START_CODE, str(route)], cwd=ROOT, capture_output=True, text=True,
                             env={**os.environ, "PYTHONPATH": str(ROOT)}, check=True)
        out.append(tuple(float(x) for x in res.stdout.split()))
    return out


def one_by_one(specs) -> list[dict]:
    """Each run alone, as `locoplan optimize ROUTE --time T --algorithm A --seed S` computes it."""
    from locoplan.io.load import load_route, load_train
    from locoplan.runner import make_context, run_strategy
    from locoplan.settings import RunSettings

    routes, trains, out = {}, {}, []
    for s in specs:
        if s.route not in routes:
            routes[s.route] = load_route(s.route)
        if s.consist not in trains:
            trains[s.consist] = load_train(s.consist)
        ctx = make_context(routes[s.route], trains[s.consist], RunSettings(s.options, time_s=s.time_s,
                                                                           algorithm=s.algorithm, seed=s.seed,
                                                                           weights=s.weights,
                                                                           tolerance_s=s.tolerance_s,
                                                                           builder=s.builder, yardstick=s.yardstick))
        summary = run_strategy(ctx, s.strategy).summary
        summary.pop("solve_time_s")
        out.append(summary)
    return out


def makespan(durations: list[float], workers: int) -> float:
    """Longest-first list scheduling of independent tasks on ``workers`` (what run_many does)."""
    loads = [0.0] * workers
    heapq.heapify(loads)
    for d in sorted(durations, reverse=True):
        heapq.heappush(loads, heapq.heappop(loads) + d)
    return max(loads)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", default=str(ROOT / "benchmarks/batch_study.yaml"))
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", default=None, help="Folder for the stores (default: a temporary one).")
    ap.add_argument("--sample", type=int, default=0, help="Run only N of the study's runs (every k-th; default: all).")
    ap.add_argument("--one-by-one", type=int, default=0, help="Run only N of the runs alone (default: all).")
    args = ap.parse_args()

    study = load_study(args.study)
    specs = study.specs if not args.sample else study.specs[:: max(1, len(study.specs) // args.sample)][: args.sample]
    folder = Path(args.keep or tempfile.mkdtemp(prefix="bench_batch_"))
    folder.mkdir(parents=True, exist_ok=True)
    print(f"study {args.study}: {len(specs)} of its {len(study.specs)} runs; stores in {folder}; {os.cpu_count()} cores, "
          f"load average before start {os.getloadavg()[0]:.2f}\n")

    starts = worker_start(Path(specs[0].route))
    print("| worker start (fresh interpreter) | import [s] | calculator kernel [s] | DP kernels [s] | total [s] |")
    print("| --- | --- | --- | --- | --- |")
    for i, (a, b, c) in enumerate(starts, 1):
        print(f"| start {i} | {a:.2f} | {b:.2f} | {c:.2f} | {a + b + c:.2f} |")

    # --- the batch on N worker processes, into a fresh store
    store_path = folder / f"runs_{args.workers}w.sqlite"
    for suffix in ("", "-wal", "-shm"):
        Path(f"{store_path}{suffix}").unlink(missing_ok=True)
    phases: dict[str, float] = {}
    t = time.perf_counter()

    def progress(ev):
        phases[ev.phase] = time.perf_counter() - t
    executor = make_executor(args.workers)
    with Store(store_path) as store:
        batch = run_many(specs, executor, store=store, progress=progress)
    executor.close()
    wall_n = time.perf_counter() - t
    load_n = os.getloadavg()[0]
    cpu = [r.cpu_time_s for r in batch.records]
    walls = [r.wall_time_s for r in batch.records]

    # --- the same batch on 1 worker (run_many in this process)
    t = time.perf_counter()
    phases_1: dict[str, float] = {}

    def progress_1(ev):
        phases_1[ev.phase] = time.perf_counter() - t
    serial = run_many(specs, SerialExecutor(), progress=progress_1)
    wall_1 = time.perf_counter() - t
    load_1 = os.getloadavg()[0]
    by_key = {r.key: r for r in batch.records}
    same_1 = sum(by_key[r.key].comparable() == r.comparable() for r in serial.records)

    # --- the same runs one by one, each as `locoplan optimize` does it: a fresh context, its own E_min
    pick = specs if not args.one_by_one else specs[:: max(1, len(specs) // args.one_by_one)][: args.one_by_one]
    t = time.perf_counter()
    alone = one_by_one(pick)
    wall_alone = time.perf_counter() - t
    inputs = load_inputs(pick)
    same = sum(by_key[spec_key(sp, inputs)].comparable() == a for sp, a in zip(pick, alone))
    e_min_s = phases.get("e_min", 0.0)
    print("\n| executor | runs | wall [s] | runs/s | E_min phase [s] | mean run wall [s] | mean run CPU [s] | load avg at end |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    print(f"| process pool, {args.workers} workers | {len(batch.ran)} | {wall_n:.1f} | {len(batch.ran) / wall_n:.3f} | "
          f"{e_min_s:.1f} | {sum(walls) / len(walls):.2f} | {sum(cpu) / len(cpu):.2f} | {load_n:.2f} |")
    s_cpu = [r.cpu_time_s for r in serial.records]
    s_wall = [r.wall_time_s for r in serial.records]
    print(f"| run_many, 1 process | {len(serial.ran)} | {wall_1:.1f} | {len(serial.ran) / wall_1:.3f} | - | "
          f"{sum(s_wall) / len(s_wall):.2f} | {sum(s_cpu) / len(s_cpu):.2f} | {load_1:.2f} |")
    print(f"| one by one, fresh context and E_min each (as `optimize`) | {len(pick)} | {wall_alone:.1f} | "
          f"{len(pick) / wall_alone:.3f} | - | - | - | {os.getloadavg()[0]:.2f} |")
    print(f"\nrecords of the {args.workers}-worker batch equal to the 1-worker batch's: {same_1}/{len(specs)}; "
          f"equal to the runs one by one: {same}/{len(pick)} (timing fields aside)")
    feasible = sum(bool(r.summary.get("feasible")) for r in batch.records)
    punctual = sum(bool(r.summary.get("punctual")) for r in batch.records)
    print(f"feasible {feasible}/{len(specs)}, punctual {punctual}/{len(specs)}, fail their job {len(batch.failures)}")

    # --- expected scaling: list scheduling of the measured per-run CPU times, plus the fixed costs
    start = max(sum(s) for s in starts)
    n_groups = len(batch.e_min_kwh)
    e_min_cpu = phases_1.get("e_min", 0.0) / max(n_groups, 1)  # mean E_min task [s], measured in one process
    print(f"\nexpected on a cluster (no other load): worker start {start:.1f} s, then {n_groups} E_min tasks of "
          f"~{e_min_cpu:.1f} s, then the {len(cpu)} runs (their measured CPU times) longest first")
    print("| workers | E_min phase [s] | runs phase [s] | total [s] | runs/s | speed-up vs 1 |")
    print("| --- | --- | --- | --- | --- | --- |")
    base = None
    for w in (1, 2, 4, 8, 16, 32, 64, 128):
        e_phase = makespan([e_min_cpu] * n_groups, w)
        r_phase = makespan(cpu, w)
        total = start + e_phase + r_phase
        base = base or total
        print(f"| {w} | {e_phase:.1f} | {r_phase:.1f} | {total:.1f} | {len(cpu) / total:.2f} | {base / total:.1f} |")
    json.dump({"wall_n": wall_n, "wall_1": wall_1, "cpu": cpu}, open(folder / "bench.json", "w"))


if __name__ == "__main__":
    main()
