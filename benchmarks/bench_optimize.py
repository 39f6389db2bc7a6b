"""Wall time of the full `locoplan optimize routes/freight-20km.yaml` (ISSA, 50 x 100, E_min from the
energy-saving run), as a user runs it, and where the time goes.

    python benchmarks/bench_optimize.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    walls, data = [], None
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "locoplan", "optimize", "routes/freight-20km.yaml", "--json"],
                             cwd=ROOT, capture_output=True, text=True, check=True)
        walls.append(time.perf_counter() - t0)
        data = json.loads(out.stdout)
    from locoplan.io.load import load_route, load_train
    from locoplan.runner import make_context, run_strategy

    t0 = time.perf_counter()
    ctx = make_context(load_route(ROOT / "routes/freight-20km.yaml"), load_train(ROOT / "configs/consists/HXD1-C80x50.yaml"))
    t1 = time.perf_counter()
    ctx.e_min()
    t2 = time.perf_counter()
    run_strategy(ctx, "proposed")
    t3 = time.perf_counter()
    print("| what | seconds |\n| --- | --- |")
    print(f"| `locoplan optimize routes/freight-20km.yaml` wall, median of {args.repeat} | {statistics.median(walls):.2f} |")
    print(f"| of which: route set-up (2 grids) | {t1 - t0:.2f} |")
    print(f"| of which: E_min, the energy-saving ISSA run | {t2 - t1:.2f} |")
    print(f"| of which: the proposed ISSA run, 50 x 100 ({data['n_evaluations']} plan evaluations) | {t3 - t2:.2f} |")
    print(f"\nresult: {data['running_time_s']} s, {data['traction_energy_kwh']} kWh, fitness {data['fitness']}, "
          f"E_min {data['e_min_kwh']} kWh")


if __name__ == "__main__":
    main()
