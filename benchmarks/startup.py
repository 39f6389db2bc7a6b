"""Start-up costs (issue 12): `locoplan --help`, and `simulate` the first time on a machine (the numba
kernels compile and are cached) and after (the cache is loaded).

    python benchmarks/startup.py [--repeat 3]

A fresh machine is emulated by an empty NUMBA_CACHE_DIR (numba then compiles and writes its cache
there, exactly as it does into the installed package's __pycache__ on the first run after install).
Wall times of whole commands, median of --repeat.
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
    subprocess.run([sys.executable, "-m", "locoplan", *args], env=env, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    route = str(ROOT / "routes/freight-20km.yaml")
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        rows.append(("locoplan --help", statistics.median(wall(["--help"], env) for _ in range(args.repeat))))
        rows.append(("simulate, first run (compiles the kernel)", wall(["simulate", route, "--json"], env)))
        rows.append(("simulate, cached", statistics.median(wall(["simulate", route, "--json"], env) for _ in range(args.repeat))))
        rows.append(("optimize, first run (compiles the DP)", wall(["optimize", route, "--json"], env)))
        rows.append(("optimize, cached", statistics.median(wall(["optimize", route, "--json"], env) for _ in range(args.repeat))))
    print(f"{'command':45} {'wall [s]':>8}")
    for name, s in rows:
        print(f"{name:45} {s:>8.2f}")


if __name__ == "__main__":
    main()
