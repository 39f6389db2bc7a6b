"""The ISSA paper on routes/freight-20km.yaml with HXD1-C80x50: the 10-run study of ISSA, SSA and PSO
(Tables 10-12) and the acceptance check: in every run the proposed plan is within the
schedule's +-30 s and uses less traction energy than four-stage and than time-saving.

    python benchmarks/issa_tables_study.py [--runs 10] [--workers 2]

Prints markdown tables (pasted into the README).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.io.load import load_route
from locoplan.runner import study_table
from locoplan.runs import RunSpec, make_executor, run_many
from locoplan.runs.plans import compare_specs, study_specs
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--algorithms", default="issa,ssa,pso")
    ap.add_argument("--workers", type=int, default=1, help="Worker processes (the results do not depend on it).")
    ap.add_argument("--point-mass", action="store_true",
                    help="the papers' model and the ISSA paper's own builder (reproduces the study as first measured)")
    args = ap.parse_args()
    route = load_route(ROOT / "routes/freight-20km.yaml")
    options = ModelOptions.papers() if args.point_mass else ModelOptions()
    spec = RunSpec(str(ROOT / "routes/freight-20km.yaml"), str(ROOT / "configs/consists/HXD1-C80x50.yaml"),
                   settings=RunSettings(options, builder="issa-paper" if args.point_mass else None))
    t0 = time.perf_counter()
    baselines = run_many(compare_specs(spec, ["time-saving", "four-stage", "energy-saving"]))
    base = {r.summary["strategy"]: r.summary for r in baselines.records}
    e_min, source = base["four-stage"]["e_min_kwh"], base["four-stage"]["e_min_source"]
    print(f"E_min ({source}) = {e_min:.2f} kWh\n")
    print("| strategy | time [s] | energy [kWh] |\n| --- | --- | --- |")
    for name, s in base.items():
        print(f"| {name} | {s['running_time_s']:.1f} | {s['traction_energy_kwh']:.2f} |")
    tol = route.schedule.tolerance_s
    algorithms = args.algorithms.split(",")
    records = run_many(study_specs(spec, algorithms, args.runs), make_executor(args.workers)).records
    results = {alg: [r for r in records if r.spec["algorithm"] == alg] for alg in algorithms}
    print("\n| algorithm | seed | time [s] | energy [kWh] | fitness | on time | < four-stage | < time-saving | solve [s] |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    all_ok = True
    best_energy = min([s["traction_energy_kwh"] for s in base.values()]
                      + [r.summary["traction_energy_kwh"] for runs in results.values() for r in runs])
    for alg, runs in results.items():
        for r in runs:
            s = r.summary
            ok = (s["punctuality_error_s"] <= tol, s["traction_energy_kwh"] < base["four-stage"]["traction_energy_kwh"],
                  s["traction_energy_kwh"] < base["time-saving"]["traction_energy_kwh"])
            all_ok &= all(ok)
            print(f"| {alg} | {s['seed']} | {s['running_time_s']:.1f} | {s['traction_energy_kwh']:.2f} | {s['fitness']:.5f} | "
                  + " | ".join("yes" if x else "NO" for x in ok) + f" | {s['solve_time_s']:.2f} |")
    print("\n| algorithm | best-fitness run E / T | worst-fitness run E / T | mean E / T | mean fitness (sd) | punctual | punctual best E / T / fitness |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for row in study_table(results, tol):
        pb = row["punctual_best"]
        print(f"| {row['algorithm']} | {row['best']['traction_energy_kwh']:.2f} / {row['best']['running_time_s']:.1f} | "
              f"{row['worst']['traction_energy_kwh']:.2f} / {row['worst']['running_time_s']:.1f} | "
              f"{row['mean_traction_energy_kwh']:.2f} / {row['mean_running_time_s']:.1f} | "
              f"{row['mean_fitness']:.5f} ({row['std_fitness']:.5f}) | {row['punctual_runs']}/{row['runs']} | "
              + ("-" if pb is None else f"{pb['traction_energy_kwh']:.2f} / {pb['running_time_s']:.1f} / {pb['fitness']:.5f}") + " |")
    proposed = [r.summary for runs in results.values() for r in runs]
    on_time = [s for s in proposed if s["punctuality_error_s"] <= tol]
    best_on_time = min(s["traction_energy_kwh"] for s in on_time) if on_time else float("nan")
    print(f"\nlowest energy of any method here: {best_energy:.2f} kWh (energy-saving ignores the timetable); "
          f"lowest on-time energy: {best_on_time:.2f} kWh; mean proposed energy {np.mean([s['traction_energy_kwh'] for s in proposed]):.2f} kWh")
    print(f"every run on time and below four-stage and time-saving: {'yes' if all_ok else 'NO'}; "
          f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
