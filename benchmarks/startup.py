"""Start-up costs: `locoplan --help`, `locoplan optimize --help`, `simulate` and `optimize` the first time on a machine
(the kernels are compiled ahead of time into the cache folder; E* is solved) and after (the compiled
module and E* are loaded), and the same with LOCOPLAN_NATIVE=0 (numba's JIT functions, loaded from
numba's own on-disk cache), the path taken where the ahead-of-time build is not possible.

    python benchmarks/startup.py [--repeat 3] [--help-only]

A fresh machine is emulated by empty LOCOPLAN_NATIVE_DIR, LOCOPLAN_CACHE_DIR and NUMBA_CACHE_DIR.
Wall times of whole commands (median of --repeat where it says so), stdout to /dev/null. The help rows
load none of the planner (tests/test_cli_startup.py); --help-only measures them alone (a few seconds).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def wall(args: list[str], env: dict) -> float:
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "locoplan", *args], env=env, check=True, stdout=subprocess.DEVNULL,
                   cwd=ROOT)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--help-only", action="store_true", help="only the two --help rows")
    args = ap.parse_args()
    route = str(ROOT / "routes/freight-20km.yaml")
    sim, opt = ["simulate", route, "--json"], ["optimize", route, "--json"]
    rows = []

    def median(cmd, env):
        return statistics.median(wall(cmd, env) for _ in range(args.repeat))

    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=f"{tmp}/numba", LOCOPLAN_NATIVE_DIR=f"{tmp}/native",
                   LOCOPLAN_CACHE_DIR=f"{tmp}/cache")
        env.pop("LOCOPLAN_NATIVE", None)
        rows.append((f"locoplan --help (median of {args.repeat})", median(["--help"], env)))
        rows.append((f"locoplan optimize --help (median of {args.repeat})", median(["optimize", "--help"], env)))
        if args.help_only:
            return _print(rows)
        rows.append(("simulate, first run on a machine (builds the kernels)", wall(sim, env)))
        rows.append((f"simulate, after (median of {args.repeat})", median(sim, env)))
        rows.append(("optimize, first run (solves E* for the gap)", wall(opt, env)))
        rows.append((f"optimize, after (median of {args.repeat})", median(opt, env)))
        jit = dict(env, LOCOPLAN_NATIVE="0")
        rows.append(("LOCOPLAN_NATIVE=0: simulate, first run (numba JIT compiles)", wall(sim, jit)))
        rows.append((f"LOCOPLAN_NATIVE=0: simulate, after (median of {args.repeat})", median(sim, jit)))
        wall(opt, jit)  # the DP's JIT compile
        rows.append((f"LOCOPLAN_NATIVE=0: optimize, after (median of {args.repeat})", median(opt, jit)))
    _print(rows)


def _print(rows: list[tuple[str, float]]) -> None:
    width = max(len(r[0]) for r in rows)
    print(f"| {'command':{width}} | wall [s] |\n| {'-' * width} | -------: |")
    for name, s in rows:
        print(f"| {name:{width}} | {s:>8.2f} |")


if __name__ == "__main__":
    main()
