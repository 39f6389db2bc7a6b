"""MPOC on the real lines of TTOBench: six tracks (limits capped at 80 km/h, stop-to-stop legs),
HXD1 + 30 C80 (3200 t) and HXD1 + 50 C80 (5200 t), at 1.1 and 1.2 x the fastest running time: every
case solved and confirmed by the traction calculator (its plan holds the limits, stops and runs on
time).

    python benchmarks/ttobench_mpoc.py [--lines NAME,...] [--factors 1.1,1.2]

Prints one row per case: phases, fastest time, T, E* (the NLP objective), the plan's re-simulated
energy and time, their gap, whether the mesh tolerance was met, and the solve time (building and
refinement, wall clock; the plan's fit and check are not included).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks")]  # this checkout first

from ttobench_routes import LINES, line  # noqa: E402

from locoplan.errors import LocoplanError  # noqa: E402
from locoplan.io.load import load_train  # noqa: E402
from locoplan.ocp.mpoc import run_mpoc  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402

CONSISTS = ("HXD1-C80x30", "HXD1-C80x50")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", default=",".join(LINES))
    ap.add_argument("--factors", default="1.1,1.2")
    args = ap.parse_args()
    import casadi  # noqa: F401  (loaded once, as a running process has it)

    factors = [float(x) for x in args.factors.split(",")]
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    head = (f"{'line':<32} {'train':>6} {'km':>5} {'phases':>6} {'fastest':>8} {'T':>7} {'E* kWh':>9} "
            f"{'plan kWh':>9} {'gap %':>6} {'plan s':>8} {'mesh':>5} {'solve s':>8} confirmed")
    print(head)
    print("-" * len(head))
    ok = total = 0
    for consist in CONSISTS:
        train = load_train(ROOT / f"configs/consists/{consist}.yaml")
        for name in args.lines.split(","):
            route = line(name)
            calc = TractionCalculator(route, train, ModelOptions())
            fast = calc.fastest_time_s
            for f in factors:
                T = round(f * fast, 1)
                total += 1
                t0 = time.perf_counter()
                try:
                    run = run_mpoc(route, train, ModelOptions(), T, calc=calc)
                except LocoplanError as exc:
                    print(f"{name:<32} {train.mass_t:>5.0f}t {route.length_m / 1000:5.1f} {'-':>6} {fast:8.1f} {T:7.1f} "
                          f"failed: {exc}")
                    continue
                wall = time.perf_counter() - t0
                s = run.summary
                ok += bool(s["feasible"])
                print(f"{name:<32} {train.mass_t:>5.0f}t {route.length_m / 1000:5.1f} {s['phases']:6d} {fast:8.1f} {T:7.1f} "
                      f"{s['objective']:9.2f} {s['resimulated_energy_kwh']:9.2f} {s['plan_energy_gap_percent']:+6.2f} "
                      f"{s['resimulated_running_time_s']:8.1f} {'ok' if s['mesh']['converged'] else 'no':>5} "
                      f"{run.solution.wall_time_s:8.2f} {'yes' if s['feasible'] else 'NO: ' + s['reason']}  (total {wall:.1f} s)")
    print(f"\n{ok} of {total} cases confirmed")


if __name__ == "__main__":
    main()
