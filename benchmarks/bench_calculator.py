"""Plan evaluations per second of the batch traction calculator (issue 2 target: >= 2,000 / s on one
core for batches of 50 plans on routes/freight-20km.yaml), and peak memory.

    python benchmarks/bench_calculator.py [--repeat 40] [--step 50]

Prints a table; pin to one core with `taskset -c 0` for the one-core figure.
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np

from locoplan.io.load import load_route, load_train
from locoplan.sim.calculator import ModelOptions, TractionCalculator

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=40)
    ap.add_argument("--step", type=float, default=None, help="grid spacing [m] (default: the calculator's)")
    args = ap.parse_args()
    route = load_route(ROOT / "routes/freight-20km.yaml")
    train = load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")
    opts = ModelOptions() if args.step is None else ModelOptions(step_m=args.step)
    t0 = time.perf_counter()
    calc = TractionCalculator(route, train, opts)
    setup_s = time.perf_counter() - t0
    seq = tuple("TKTCTCKCB")  # seed 002's proposed sequence: 8 switching points
    rng = np.random.default_rng(0)
    print(f"route freight-20km, {train.name}, grid {len(calc.h_m)} cells (step {calc.options.step_m:g} m), "
          f"route set-up {setup_s * 1e3:.0f} ms")
    print(f"{'batch':>6} {'ms / batch':>11} {'plans / s':>10} {'peak MiB':>9}")
    for batch in (1, 10, 50, 200):
        X = np.sort(rng.uniform(0, route.length_m, (batch, len(seq) - 1)), axis=1)
        calc.evaluate(seq, X)  # warm-up
        t0 = time.perf_counter()
        for _ in range(args.repeat):
            calc.evaluate(seq, X)
        dt = (time.perf_counter() - t0) / args.repeat
        tracemalloc.start()
        calc.evaluate(seq, X)
        peak = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        print(f"{batch:>6} {dt * 1e3:>11.2f} {batch / dt:>10.0f} {peak:>9.2f}")


if __name__ == "__main__":
    main()
