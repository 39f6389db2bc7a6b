"""The fastest run against an independent fine-step computation, in every train model, on every shipped
real line: descents that full braking cannot hold are entered slower (the braking envelope).

    python benchmarks/fastest_check.py [--lines all] [--consists HXD1-C80x30,HXD1-C80x50]
                                       [--models point-mass,no-air-brake,default] [--ds 1.0] [--json out.json]

For every line x train x model: the calculator's fastest run (50 m cells, the compiled kernel) and the
same run from ``tests/fastest_oracle.py`` (RK4 in v^2/2 in steps of at most ``--ds`` metres, its own
envelope and its own integration; the line's cells, gravity, limits and neutral spans taken from the
calculator, the forces from the consist's curves). Prints the two running times, their difference, the
lowest envelope speed under the limit on a descent (how much slower the train must enter one), and the
largest difference. Target: every case within 0.05 %; a line is "impossible" only when both say so.
``benchmarks/random_lines.py --fastest`` does the same on generated lines (``--max-grade 30``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's locoplan, installed or not
sys.path.insert(0, str(ROOT / "tests"))

from fastest_oracle import FastestOracle  # noqa: E402
from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402

MODELS = {"point-mass": ModelOptions.papers(), "no-air-brake": ModelOptions(air_brake=False), "default": ModelOptions()}
TARGET_PERCENT = 0.05


def check(calc: TractionCalculator, ds_m: float = 1.0) -> dict:
    """One case: both fastest times [s], their difference [%], and how far below the limit the envelope goes
    on descents full braking cannot hold [km/h]."""
    res = calc.evaluate(("T",), np.zeros((1, 0)))
    t_calc = float(res.running_time_s[0]) if res.feasible[0] else math.nan
    start = time.perf_counter()
    t_ref, _ = FastestOracle.of(calc, ds_m).fastest()
    ref_s = time.perf_counter() - start
    steep = ~calc.brake_holds_limit
    below = 0.0
    if steep.any():
        env_kmh = np.sqrt(2 * calc.e_envelope[:-1]) * 3.6
        below = float(np.max(np.where(steep, calc.limit_kmh - env_kmh, 0.0)))
    both_nan = math.isnan(t_calc) and math.isnan(t_ref)
    dev = 0.0 if both_nan else 100.0 * (t_calc / t_ref - 1.0)
    return {"time_s": t_calc, "oracle_s": t_ref, "diff_percent": dev, "steep_cells": int(steep.sum()),
            "entry_below_kmh": below, "reason": None if res.feasible[0] else res.reason(0), "oracle_wall_s": ref_s}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", default="all")
    ap.add_argument("--consists", default="HXD1-C80x30,HXD1-C80x50")
    ap.add_argument("--models", default="point-mass,no-air-brake,default")
    ap.add_argument("--ds", type=float, default=1.0, help="the oracle's step [m]")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    lines = (sorted(p.stem for p in (ROOT / "routes/real").glob("*.yaml")) if args.lines == "all"
             else args.lines.split(","))
    rows = []
    print(f"{'line':36} {'mass':>6} {'model':12} {'fastest [s]':>11} {'oracle [s]':>11} {'diff %':>8} "
          f"{'steep cells':>11} {'enter -km/h':>11}")
    for line in lines:
        route = load_route(ROOT / "routes/real" / f"{line}.yaml")
        for consist in args.consists.split(","):
            train = load_train(consist)
            for model in args.models.split(","):
                r = check(TractionCalculator(route, train, MODELS[model]), args.ds)
                r.update(line=line, consist=consist, mass_t=train.mass_t, model=model)
                rows.append(r)
                print(f"{line:36} {train.mass_t:>6.0f} {model:12} {row_text(r)}", flush=True)
    summarise(rows)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float) + "\n")


def row_text(r: dict) -> str:
    """A case's numbers as the tables print them: both times, their difference, the descents."""
    t = "impossible" if math.isnan(r["time_s"]) else f"{r['time_s']:.2f}"
    o = "impossible" if math.isnan(r["oracle_s"]) else f"{r['oracle_s']:.2f}"
    return f"{t:>11} {o:>11} {r['diff_percent']:>8.4f} {r['steep_cells']:>11} {r['entry_below_kmh']:>11.1f}"


def summarise(rows: list[dict]) -> None:
    devs = [abs(r["diff_percent"]) for r in rows if math.isfinite(r["diff_percent"])]
    split = [r for r in rows if math.isnan(r["time_s"]) != math.isnan(r["oracle_s"])]
    steep = sum(r["steep_cells"] > 0 for r in rows)
    print(f"\n{len(rows)} cases, {steep} with descents full braking cannot hold; largest |diff| "
          f"{max(devs) if devs else float('nan'):.4f} % (target {TARGET_PERCENT} %); "
          f"{sum(math.isnan(r['time_s']) and math.isnan(r['oracle_s']) for r in rows)} impossible by both; "
          f"{len(split)} where only one says impossible")
    for r in split:
        print(f"  disagree: {r.get('line', r.get('case'))} {r.get('model', '')}: calculator {r['time_s']}, oracle {r['oracle_s']}"
              f" ({r['reason']})")


if __name__ == "__main__":
    main()
