"""The ISSA paper on real lines: `optimize` on the six TTOBench lines x two trains x two times, in any train model.

    python benchmarks/real_lines.py [--lines ...] [--consists HXD1-C80x30,HXD1-C80x50] [--factors 1.1,1.2]
                                    [--point-mass | --no-air-brake | --continuous-air-brake] [--json out.json]

For every case: the fastest run, T0 = factor x fastest, the proposed plan (ISSA seed 1, window +-1 % of
T0) with its running time, energy and whether it is on time, four-stage beside it, and the gap to the
optimum, (E - E*) / E*, with E* the minimum traction energy at the plan's own running time from
`locoplan.ocp` (the MPOC paper's optimal control) when it is installed. Prints a table and the maximum and
median gap. Targets: every case on time and within 1 % of T0, gap <= 3 % everywhere, median <= 1.5 %.
``--point-mass`` runs the papers' train model (point mass, electric brake alone), ``--no-air-brake`` the
train-length model with the electric brake alone: the locomotive then holds long descents by itself, and
plans enter them slower where it cannot (the braking envelope, docs/model.md). ``--continuous-air-brake``
lets the plans modulate the wagons' air brake at will instead of cycling it (what E* relaxes it to).

    python benchmarks/real_lines.py --compare [--strategies time-saving,energy-saving,four-stage,proposed]

runs `locoplan compare` on the same cases as a user would (a subprocess each, --json --no-gap) and
prints its exit code and, per strategy, whether it is feasible and punctual or the reason it has no plan.
Target: exit 0 on every case, every strategy present, each feasible or marked infeasible with a reason.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import math
import json
import statistics
import time
from pathlib import Path

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

import numpy as np

from locoplan.io.load import load_route, load_train
from locoplan.runner import make_context, run_strategy, schedule_verdict
from locoplan.settings import RunSettings
from locoplan.ocp.bound import percent_floor_kwh
from locoplan.sim.calculator import ModelOptions, TractionCalculator

ROOT = Path(__file__).resolve().parents[1]
LINES = ["00_var_speed_limit_100", "CH_Fribourg_Bern", "CH_StGallen_Wil", "CH_Stadelhofen_Altstetten-leg1",
         "CN_Songjiazhuang_Yizhuang-leg1", "SE_Vasteras_Kolback"]


def optimum_kwh(route, train, time_s: float, options=None):
    """E* at ``time_s`` from the MPOC paper's optimal control, or None where it is not available."""
    try:
        from locoplan.ocp.bound import energy_bound  # noqa: PLC0415  (the MPOC paper: optional here)
    except ImportError:
        return None
    try:
        return float(energy_bound(route, train, options, time_s=time_s).energy_kwh)
    except Exception:  # an unconfirmed optimum is reported as missing, not as a number
        return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", default=",".join(LINES))
    ap.add_argument("--consists", default="HXD1-C80x30,HXD1-C80x50")
    ap.add_argument("--factors", default="1.1,1.2")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--markdown", action="store_true", help="also print the table as markdown (docs/real-lines.md)")
    ap.add_argument("--compare", action="store_true", help="run `locoplan compare` on every case instead")
    ap.add_argument("--strategies", default="time-saving,energy-saving,four-stage,proposed")
    model = ap.add_mutually_exclusive_group()
    model.add_argument("--point-mass", action="store_true", help="the papers' model: point mass, electric brake alone")
    model.add_argument("--no-air-brake", action="store_true", help="the train-length model, electric brake alone")
    model.add_argument("--continuous-air-brake", action="store_true",
                       help="the air brake as a continuous force, not cycled (ModelOptions(air_cycle=False))")
    args = ap.parse_args()
    args.options = (ModelOptions.papers() if args.point_mass else ModelOptions(air_brake=False) if args.no_air_brake
                    else ModelOptions(air_cycle=False) if args.continuous_air_brake else ModelOptions())
    if args.continuous_air_brake and args.compare:
        ap.error("--continuous-air-brake is not a command-line option of locoplan compare")
    args.model_flags = ["--point-mass"] if args.point_mass else ["--no-air-brake"] if args.no_air_brake else []
    if args.compare:
        return compare_cases(args)
    rows = []
    head = (f"{'line':32} {'mass':>6} {'x':>4} {'T0 [s]':>8} {'time [s]':>9} {'on time':>7} {'E [kWh]':>9} "
            f"{'E* [kWh]':>9} {'gap %':>6} {'4-stage':>9} {'solve s':>8}")
    print(head)
    md = ["| line | train | x fastest | T0 [s] | time [s] | on time | E [kWh] | E* [kWh] | E*cycle [kWh] | over | "
          "four-stage [kWh] |", "| --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: |"]
    for line in args.lines.split(","):
        route = load_route(ROOT / "routes/real" / f"{line}.yaml")
        for consist in args.consists.split(","):
            train = load_train(ROOT / "configs/consists" / f"{consist}.yaml")
            calc = TractionCalculator(route, train, args.options)
            fastest = calc.fastest_time_s
            if not math.isfinite(fastest):  # not even the fastest run gets there: what every command says
                why = calc.evaluate(("T",), np.zeros((1, 0))).reason(0)
                rows.append({"line": line, "consist": consist, "mass_t": train.mass_t, "impossible": why})
                print(f"{line:32} {train.mass_t:>6.0f} impossible: {why}", flush=True)
                continue
            for factor in (float(x) for x in args.factors.split(",")):
                t0 = round(factor * fastest, 1)
                ctx = make_context(route, train, RunSettings(args.options, time_s=t0, tolerance_s=0.01 * t0))
                start = time.perf_counter()
                run = run_strategy(ctx, "proposed")
                solve = time.perf_counter() - start
                from locoplan.runner import cycle_gap  # the optimum keeping the air brake's cycle, where it binds
                cyc = cycle_gap(replace(ctx, yardstick=True), run.result)["optimum_with_cycle_kwh"]
                four = run_strategy(ctx, "four-stage").summary
                s = run.summary
                on_time = schedule_verdict(ctx, run) is None
                e_star = optimum_kwh(route, train, s["running_time_s"], args.options) if s["feasible"] else None
                gap = None if e_star is None else 100.0 * (s["traction_energy_kwh"] / e_star - 1.0)
                gap_kwh = None if e_star is None else s["traction_energy_kwh"] - e_star
                if e_star is not None and e_star < percent_floor_kwh(route, train):
                    gap = None  # a falling line the train can nearly coast: E* too small for a percentage
                rows.append({"line": line, "consist": consist, "mass_t": train.mass_t, "factor": factor,
                             "planned_time_s": t0, "running_time_s": s["running_time_s"], "on_time": on_time,
                             "traction_energy_kwh": s["traction_energy_kwh"], "optimum_kwh": e_star,
                             "gap_to_optimum_percent": None if gap is None else round(gap, 2),
                             "gap_kwh": None if gap_kwh is None else round(gap_kwh, 2),
                             "four_stage_kwh": four["traction_energy_kwh"], "solve_time_s": round(solve, 2),
                             "plan": s["plan"], "cycle_optimum_kwh": cyc,
                             "cycles": bool(s.get("air_applications"))})
                if args.markdown:
                    yard = cyc if cyc is not None else e_star
                    over = (None if yard is None else 100.0 * (s["traction_energy_kwh"] / yard - 1.0)
                            if yard >= percent_floor_kwh(route, train) else None)
                    over_text = ("-" if yard is None else f"{over:+.2f} %" if over is not None
                                 else f"{s['traction_energy_kwh'] - yard:+.2f} kWh")
                    md.append(f"| {line} | {train.mass_t:.0f} t | {factor:g} | {t0:.1f} | {s['running_time_s']:.1f} | "
                              f"{'yes' if on_time else 'no'} | {s['traction_energy_kwh']:.2f} | "
                              f"{'-' if e_star is None else f'{e_star:.2f}'} | {'-' if cyc is None else f'{cyc:.2f}'} | "
                              f"{over_text} | {four['traction_energy_kwh']:.2f} |")
                print(f"{line:32} {train.mass_t:>6.0f} {factor:>4} {t0:>8.1f} {s['running_time_s']:>9.1f} "
                      f"{'yes' if on_time else 'NO':>7} {s['traction_energy_kwh']:>9.2f} "
                      f"{'-' if e_star is None else f'{e_star:.2f}':>9} "
                      f"{('-' if gap_kwh is None else f'{gap_kwh:+.2f} kWh') if gap is None else f'{gap:.2f}':>6} "
                      f"{four['traction_energy_kwh']:>9.2f} {solve:>8.2f}", flush=True)
    impossible = [r for r in rows if "impossible" in r]
    rows = [r for r in rows if "impossible" not in r]
    gaps = [r["gap_to_optimum_percent"] for r in rows if r["gap_to_optimum_percent"] is not None]
    small = [r for r in rows if r["gap_to_optimum_percent"] is None and r["gap_kwh"] is not None]
    print(f"cases {len(rows)}, on time {sum(r['on_time'] for r in rows)}"
          + (f", {len(impossible)} line x train impossible (not even the fastest run)" if impossible else "")
          + (f", gap max {max(gaps):.2f} %, median {statistics.median(gaps):.2f} % over {len(gaps)}" if gaps else "")
          + (f"; E* too small for a percentage on {len(small)} (falling lines): gaps "
             + ", ".join(f"{r['gap_kwh']:+.2f} kWh (E* {r['optimum_kwh']:.2f})" for r in small) if small else ""))
    over = []
    for r in rows:  # against the optimum keeping the cycle where the plan cycles and it binds, else E*
        yard = r["cycle_optimum_kwh"] if r["cycles"] and r["cycle_optimum_kwh"] is not None else r["optimum_kwh"]
        if yard is not None:
            over.append((100.0 * (r["traction_energy_kwh"] / yard - 1.0)) if yard >= 30.0
                        else (r["traction_energy_kwh"] - yard) / 0.3)
    if over:
        print(f"within 1 % of the yardstick (the cycle optimum where the plan cycles; 0.3 kWh under 30 kWh): "
              f"{sum(x <= 1.0 + 1e-9 for x in over)} of {len(over)}, max {max(over):+.2f}")
    if args.markdown:
        print("\n".join(md))
    if args.json:
        args.json.write_text(json.dumps({"results": rows, "impossible": impossible}, indent=2) + "\n")


def compare_cases(args) -> None:
    """`locoplan compare` on every case, as a user runs it; a table of exit codes and per-strategy verdicts."""
    import subprocess
    import sys

    names = args.strategies.split(",")
    print(f"{'line':32} {'mass':>6} {'x':>4} {'exit':>4}  " + "  ".join(f"{n:>14}" for n in names))
    bad = 0
    for line in args.lines.split(","):
        path = ROOT / "routes/real" / f"{line}.yaml"
        route = load_route(path)
        for consist in args.consists.split(","):
            train = load_train(ROOT / "configs/consists" / f"{consist}.yaml")
            fastest = TractionCalculator(route, train, args.options).fastest_time_s
            for factor in (float(x) for x in args.factors.split(",")):
                t0 = round(factor * fastest, 1)
                p = subprocess.run([sys.executable, "-m", "locoplan", "compare", str(path), *args.model_flags, "--consist", consist,
                                    "--time", str(t0), "--tolerance", str(round(0.01 * t0, 2)), "--strategies",
                                    args.strategies, "--json", "--no-gap"], cwd=ROOT, capture_output=True, text=True)
                try:
                    got = {r["strategy"]: r for r in json.loads(p.stdout)["results"]}
                except (ValueError, KeyError):
                    got = {}
                cells = []
                for n in names:
                    r = got.get(n)
                    if r is None:
                        cells.append("MISSING")
                    elif r["feasible"]:
                        cells.append("on time" if r["punctual"] else "off time")
                    else:
                        cells.append("infeasible" if r.get("reason") else "NO REASON")
                bad += p.returncode != 0 or any(c in ("MISSING", "NO REASON") for c in cells)
                print(f"{line:32} {train.mass_t:>6.0f} {factor:>4} {p.returncode:>4}  " + "  ".join(f"{c:>14}" for c in cells),
                      flush=True)
    print(f"cases with a failed compare, a missing strategy or an unexplained infeasible one: {bad}")


if __name__ == "__main__":
    main()
