"""Plan evaluations per second of the batch traction calculator on routes/freight-20km.yaml: its compiled
kernel as numba's JIT function and as the same function compiled ahead of time (``locoplan.sim.native``,
which the commands load), for batches of 1, 10, 50 and 200 plans, and peak memory. Targets: >= 20,000
plans/s for batches of 50 and >= 5,000 plans/s for single plans, on one core.

    taskset -c 0 python benchmarks/bench_calculator.py [--repeat 40] [--step 50]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.sim import native
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
    kernels = {"numba JIT": native._jit("benchmark"), "ahead of time": native.kernels()}
    if not kernels["ahead of time"].source.startswith("native"):
        print(f"ahead-of-time kernels unavailable: {kernels['ahead of time'].source}")
        del kernels["ahead of time"]
    t0 = time.perf_counter()
    calc = TractionCalculator(route, train, opts)
    setup_s = time.perf_counter() - t0
    seq = tuple("TKTCTCKCB")  # the ISSA paper's proposed sequence: 8 switching points
    print(f"route freight-20km, {train.name}, default train model, grid {len(calc.h_m)} cells "
          f"(step {opts.step_m:g} m), route set-up {setup_s * 1e3:.0f} ms")
    print(f"{'batch':>6} {'backend':>20} {'ms / batch':>11} {'plans / s':>10} {'peak MiB':>9}")
    for batch in (1, 10, 50, 200):
        X = np.sort(np.random.default_rng(batch).uniform(0, route.length_m, (batch, len(seq) - 1)), axis=1)
        for name, kernel in kernels.items():
            native._kernels = kernel
            calc.evaluate(seq, X)  # warm-up (and, the first time on a machine, the kernel's compile)
            repeat = args.repeat * 20
            t0 = time.perf_counter()
            for _ in range(repeat):
                calc.evaluate(seq, X)
            dt = (time.perf_counter() - t0) / repeat
            tracemalloc.start()
            calc.evaluate(seq, X)
            peak = tracemalloc.get_traced_memory()[1] / 2**20
            tracemalloc.stop()
            print(f"{batch:>6} {name:>20} {dt * 1e3:>11.3f} {batch / dt:>10.0f} {peak:>9.2f}")


if __name__ == "__main__":
    main()
