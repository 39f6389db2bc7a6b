"""The optimum with the air brake's cycle, bracketed: E* (the air brake relaxed) .. the cycle optimum, on the lines
where the air brake cycles, with the plan read off the cycle DP's drive and the proposed plan placed in it.

    python benchmarks/bench_cycle_optimum.py [--lines heavy,fribourg,stadelhofen,freight,random]
                                             [--random 2] [--seed 7] [--no-proposed] [--json out.json]

Per case: the line, the train, the running time T (the schedule, or 1.1 x the fastest run), E* at T
(``ocp.bound.energy_bound``), the cycle optimum at T with its stated accuracy and its wall time, cold
(``strategy.cycle_start.cycle_optimum``: the DP on two nested grids and the relaxed DP on the finer one); the plan
read off the cycle DP's drive and bisected to T on the calculator (``cycle_plan_start``), its time and energy there
and its gap to the cycle optimum at its own time; and the proposed strategy's plan (``locoplan optimize``, ISSA seed
1) with its gaps to E* and to the cycle optimum, both at its own running time. Lines: heavy-haul-60km with HXD1 x 2 +
100 x C80; CH_Fribourg_Bern and the CH_Stadelhofen_Altstetten legs with HXD1 + 50 x C80 at 1.1 x; freight-20km at
its schedule; ``--random N`` lines of ``benchmarks/random_lines.py``'s generator (steep, 30 per mille) on which the
air brake cycles and the fastest run keeps the cycle (on some, whose steepest pitch the air brake can barely hold,
the cycle cannot hold the speed: no plan runs, and no drive either), with HXD1 + 50 x C80 at 1.1 x.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from random_lines import random_route  # noqa: E402

from locoplan.errors import LocoplanError  # noqa: E402
from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.ocp.bound import energy_bound  # noqa: E402
from locoplan.optimize.cycle_dp import cycle_binds  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402
from locoplan.strategy import cycle_start  # noqa: E402


def cases(names: list[str], n_random: int, seed: int):
    """(label, route, train, time or factor) of each case asked for."""
    c80x50 = load_train("HXD1-C80x50")
    if "heavy" in names:
        yield "heavy-haul-60km", load_route(ROOT / "routes/heavy-haul-60km.yaml"), load_train("HXD1x2-C80x100"), None
    if "fribourg" in names:
        yield "CH_Fribourg_Bern", load_route(ROOT / "routes/real/CH_Fribourg_Bern.yaml"), c80x50, 1.1
    if "stadelhofen" in names:
        for leg in (1, 2, 3):
            yield (f"CH_Stadelhofen_Altstetten-leg{leg}",
                   load_route(ROOT / f"routes/real/CH_Stadelhofen_Altstetten-leg{leg}.yaml"), c80x50, 1.1)
    if "freight" in names:
        yield "freight-20km", load_route(ROOT / "routes/freight-20km.yaml"), c80x50, None
    if "random" in names:
        rng = np.random.default_rng(seed)
        found = 0
        for i in range(200):
            route = random_route(rng, i, 30.0)
            if found >= n_random or route.length_m < 3 * c80x50.length_m:
                if found >= n_random:
                    break
                continue
            try:
                calc = TractionCalculator(route, c80x50)
            except LocoplanError:
                continue
            # (a line where even the fastest run's cycle cannot hold the speed has no plan, nor any drive: left out)
            if (calc.impossible is None and len(calc.cycle_regions_m)
                    and calc.evaluate(("T",), np.zeros((1, 0))).feasible[0]):
                found += 1
                yield f"random line {i} ({route.length_m / 1000:.1f} km)", route, c80x50, 1.1


def fmt(x, spec=".2f", unit=""):
    return "-" if x is None else f"{x:{spec}}{unit}"


def run_case(label, route, train, factor, proposed: bool) -> dict:
    options = ModelOptions()
    calc = TractionCalculator(route, train, options)
    t = float(route.schedule.run_time_s) if factor is None else round(factor * calc.fastest_time_s, 1)
    row = {"line": label, "train": train.name, "time_s": t, "cycles": bool(cycle_binds(calc))}
    b = energy_bound(route, train, options, t)
    row["estar_kwh"] = b.energy_kwh
    start = time.perf_counter()
    try:
        co = cycle_start.cycle_optimum(route, train, options, t, calc=calc)
    except LocoplanError as exc:
        row["error"] = str(exc)
        return row
    row["cycle_wall_s"] = time.perf_counter() - start
    row["cycle_kwh"] = co.energy_kwh
    row["cycle_accuracy_percent"] = co.accuracy_percent
    row["grids"] = list(co.grids)
    if co.energy_kwh is None:
        return row
    row["cycle_over_estar_percent"] = 100 * (co.energy_kwh - b.energy_kwh) / b.energy_kwh
    start = time.perf_counter()
    plan = cycle_start.cycle_plan_start(route, train, options, t, calc=calc)
    row["plan_wall_s"] = time.perf_counter() - start
    if plan is not None:
        res = calc.evaluate(plan.conditions, plan.switches_m, **plan.cycle_kwargs())
        if res.feasible[0]:
            tp, ep = float(res.running_time_s[0]), float(res.traction_energy_kwh[0])
            at = cycle_start.cycle_optimum(route, train, options, tp, calc=calc)
            row.update(plan_time_s=tp, plan_kwh=ep, plan=plan.text(),
                       plan_over_cycle_percent=None if at.energy_kwh is None else 100 * (ep - at.energy_kwh) / at.energy_kwh,
                       plan_over_estar_percent=100 * (ep / energy_bound(route, train, options, tp).energy_kwh - 1))
    if proposed:
        from locoplan.runner import make_context, run_strategy
        from locoplan.settings import RunSettings

        start = time.perf_counter()
        ctx = make_context(route, train, RunSettings(options, time_s=t, yardstick=True), calculators=None)
        s = run_strategy(ctx, "proposed").summary
        row.update(proposed_wall_s=time.perf_counter() - start, proposed_time_s=s["running_time_s"],
                   proposed_kwh=s["traction_energy_kwh"], proposed_over_estar_percent=s["gap_to_optimum_percent"],
                   proposed_over_cycle_percent=s["gap_to_cycle_optimum_percent"],
                   proposed_cycle_kwh=s["optimum_with_cycle_kwh"])
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", default="heavy,fribourg,stadelhofen,freight,random")
    ap.add_argument("--random", type=int, default=2, help="generated lines on which the air brake cycles")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--no-proposed", action="store_true", help="skip the proposed strategy's plan")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as cache:  # cold: every E* and cycle optimum solved here
        os.environ["LOCOPLAN_CACHE_DIR"] = os.environ.get("LOCOPLAN_BENCH_CACHE", cache)
        native = Path(os.environ.get("LOCOPLAN_NATIVE_DIR", ""))
        print(f"kernels: {native if native.parts else 'per LOCOPLAN_CACHE_DIR'}", file=sys.stderr)
        head = ("| line | train | T [s] | E* [kWh] | cycle optimum [kWh] | within | +% over E* | wall [s] | "
                "plan from drive: T [s] | E [kWh] | over cycle opt. | proposed: T [s] | E [kWh] | over E* | over cycle opt. |")
        print(head)
        print("|" + "---|" * (head.count("|") - 1))
        for label, route, train, factor in cases([x.strip() for x in args.lines.split(",")], args.random, args.seed):
            row = run_case(label, route, train, factor, not args.no_proposed)
            rows.append(row)
            print(f"| {label} | {train.name} | {row['time_s']:.1f} | {row['estar_kwh']:.2f} | "
                  f"{fmt(row.get('cycle_kwh'))} | {fmt(row.get('cycle_accuracy_percent'), '.2f', ' %')} | "
                  f"{fmt(row.get('cycle_over_estar_percent'), '+.2f')} | {fmt(row.get('cycle_wall_s'), '.2f')} | "
                  f"{fmt(row.get('plan_time_s'), '.1f')} | {fmt(row.get('plan_kwh'))} | "
                  f"{fmt(row.get('plan_over_cycle_percent'), '+.2f', ' %')} | {fmt(row.get('proposed_time_s'), '.1f')} | "
                  f"{fmt(row.get('proposed_kwh'))} | {fmt(row.get('proposed_over_estar_percent'), '+.2f', ' %')} | "
                  f"{fmt(row.get('proposed_over_cycle_percent'), '+.2f', ' %')} |"
                  + (f" {row['error']}" if "error" in row else ""), flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
