"""How the cost grows with route length and with the number of switching points (issue 12).

    taskset -c 0 python benchmarks/scaling.py [--repeat 5]

Long routes are real lines joined end to end (the six TTOBench lines in routes/real, repeated as
needed, each leg's limits and gradients shifted by the length so far, limits capped at 80 km/h as
shipped). For each length: the calculator's cells, its set-up time, the time per plan in batches of 50
(a 9-condition plan), and the wall time of the proposed strategy (ISSA, seed 1, planned time 1.15 x
the fastest run). Then, on routes/freight-20km.yaml, the time per plan against the number of switching
points. The cost should grow about linearly with length.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.io.load import load_route, load_train
from locoplan.model.route import Route
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import TractionCalculator

ROOT = Path(__file__).resolve().parents[1]
PARTS = ["CH_Fribourg_Bern", "SE_Vasteras_Kolback", "CH_StGallen_Wil", "00_var_speed_limit_100"]


def joined_route(length_km: float) -> Route:
    """Real lines joined end to end until ``length_km`` (the last one cut)."""
    limits, grades, curves = [], [], []
    offset = 0.0
    target = length_km * 1000.0
    i = 0
    while offset < target - 1.0:
        part = load_route(ROOT / "routes/real" / f"{PARTS[i % len(PARTS)]}.yaml")
        i += 1
        take = min(part.length_m, target - offset)

        def shifted(sections, key):
            out = []
            for sec in sections:
                if sec.from_m >= take:
                    break
                out.append({"from_m": offset + sec.from_m, "to_m": offset + min(sec.to_m, take), key: getattr(sec, key)})
            return out

        limits += shifted(part.speed_limits, "kmh")
        grades += shifted(part.gradients, "permille")
        curves += [{"from_m": offset + c.from_m, "to_m": offset + c.to_m, "radius_m": c.radius_m}
                   for c in part.curves if c.to_m <= take]
        offset += take
    return Route.model_validate({"schema": "locoplan/route@1", "name": f"joined {length_km:g} km", "length_m": offset,
                                 "speed_limits": limits, "gradients": grades, "curves": curves})


def per_plan_s(calc: TractionCalculator, conditions: tuple[str, ...], repeat: int) -> float:
    rng = np.random.default_rng(0)
    X = np.sort(rng.uniform(0, calc.route.length_m, (50, len(conditions) - 1)), axis=1)
    calc.evaluate(conditions, X)
    t = time.perf_counter()
    for _ in range(repeat):
        calc.evaluate(conditions, X)
    return (time.perf_counter() - t) / (repeat * 50)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--lengths", default="20,50,100,300")
    args = ap.parse_args()
    train = load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")
    print(f"{'length [km]':>11} {'cells':>7} {'set-up [s]':>10} {'per plan [us]':>13} {'optimize [s]':>12} "
          f"{'on time':>7} {'energy [kWh]':>12}")
    for km in (float(x) for x in args.lengths.split(",")):
        route = joined_route(km)
        t = time.perf_counter()
        calc = TractionCalculator(route, train)
        setup = time.perf_counter() - t
        plan = per_plan_s(calc, tuple("TKTCTCKCB"), args.repeat)
        ctx = make_context(route, train, RunSettings(time_s=round(1.15 * calc.fastest_time_s),
                                                     tolerance_s=0.01 * 1.15 * calc.fastest_time_s))
        t = time.perf_counter()
        run = run_strategy(ctx, "proposed")
        opt = time.perf_counter() - t
        s = run.summary
        print(f"{km:>11g} {len(calc.h_m):>7} {setup:>10.2f} {plan * 1e6:>13.1f} {opt:>12.2f} "
              f"{'yes' if s['punctual'] else 'no':>7} {s['traction_energy_kwh']:>12.1f}", flush=True)
    route = load_route(ROOT / "routes/freight-20km.yaml")
    calc = TractionCalculator(route, train)
    print(f"\nroutes/freight-20km.yaml, {len(calc.h_m)} cells: time per plan against switching points")
    print(f"{'switches':>8} {'per plan [us]':>13}")
    for n in (1, 2, 4, 8, 16, 32):
        conditions = tuple(("T", "C")[i % 2] for i in range(n)) + ("B",)
        print(f"{n:>8} {per_plan_s(calc, conditions, args.repeat) * 1e6:>13.1f}", flush=True)


if __name__ == "__main__":
    main()
