"""E* (the least traction energy in a running time) against line length: the yardstick's cost and
whether it converges.

    python benchmarks/bench_bound.py [--lengths 20,50,100,300] [--factor 1.15] [--point-mass] [--no-air-brake]

Lines: routes/freight-20km.yaml for 20, else the real lines joined end to end as benchmarks/scaling.py
builds them; HXD1 + 50 x C80; T = factor x the fastest run. Each E* is solved cold (an empty
LOCOPLAN_CACHE_DIR per line, no warm start). Beside it, as an independent estimate from a different
method, the DP drive (optimize/dp.py) bisected to the same time: its plan's energy and time on the
exact calculator. Where that time is at most T the plan's energy is at least E*(T) (E* falls with
time), so "DP - E*" is then how far above the optimum the DP's structure alone lands.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from scaling import joined_route  # noqa: E402

from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.optimize.dp import PricedDriveSolver  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402
from locoplan.strategy.general_builder import sequence_from_drive  # noqa: E402


def line(length_km: float):
    if length_km == 20:
        return load_route(ROOT / "routes/freight-20km.yaml")
    return joined_route(length_km)


def dp_energy(calc: TractionCalculator, t0: float) -> tuple[float, float, float]:
    """(energy of the DP drive's plan on the calculator [kWh], its time [s], wall [s])."""
    t = time.perf_counter()
    solver = PricedDriveSolver(calc)
    drive = solver.for_time(t0)
    seq = sequence_from_drive(calc, drive)
    starts = list(seq.nominal_m) + [float("nan")] * (len(seq.conditions) - 1 - len(seq.nominal_m))  # the stop's B
    res = calc.evaluate(seq.conditions, [starts])
    return float(res.traction_energy_kwh[0]), float(res.running_time_s[0]), time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="20,50,100,300")
    ap.add_argument("--factor", type=float, default=1.15)
    ap.add_argument("--point-mass", action="store_true")
    ap.add_argument("--no-air-brake", action="store_true")
    args = ap.parse_args()
    options = ModelOptions(point_mass=args.point_mass, air_brake=not args.no_air_brake)
    train = load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")
    print(f"HXD1 + 50 x C80, T = {args.factor:g} x fastest, model: point mass {args.point_mass}, "
          f"air brake {not args.no_air_brake}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    head = f"{'line':>8} {'T [s]':>8} {'E* [kWh]':>10} {'conv.':>5} {'points':>7} {'E* wall s':>9} " \
           f"{'DP [kWh]':>9} {'DP t [s]':>9} {'DP - E*':>8} {'DP wall s':>9}"
    print(head)
    for km in (float(x) for x in args.lengths.split(",")):
        route = line(km)
        calc = TractionCalculator(route, train, options)
        t0 = round(args.factor * calc.fastest_time_s, 1)
        with tempfile.TemporaryDirectory() as cache:
            os.environ["LOCOPLAN_CACHE_DIR"] = cache
            from locoplan.ocp import bound as bound_mod

            bound_mod._BOUNDS.clear()
            bound_mod._WARM.clear()
            t = time.perf_counter()
            b = bound_mod.energy_bound(route, train, options, t0, calc=calc)
            wall = time.perf_counter() - t
        e_dp, t_dp, w_dp = dp_energy(calc, t0)
        print(f"{km:>6g}km {t0:>8.1f} {b.energy_kwh:>10.2f} {'yes' if b.converged else 'NO':>5} {b.points:>7} "
              f"{wall:>9.1f} {e_dp:>9.2f} {t_dp:>9.1f} {100 * (e_dp / b.energy_kwh - 1):>+7.2f}% {w_dp:>9.1f}", flush=True)


if __name__ == "__main__":
    main()
