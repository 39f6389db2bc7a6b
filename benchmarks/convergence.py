"""Step-size convergence of the traction calculator on routes/freight-20km.yaml (issue 2: halving the
step must change time by < 0.05 % and energy by < 0.1 %), and the two-stage Gauss paper exact minimum time.

    python benchmarks/convergence.py
"""

from __future__ import annotations

from pathlib import Path

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.io.load import load_route, load_train
from locoplan.model.plan import parse_sequence
from locoplan.sim.calculator import ModelOptions, TractionCalculator

ROOT = Path(__file__).resolve().parents[1]
PLANS = ["T:0", "T:0,K:2200,C:17540,B", "T:0,K:2603,T:4518,C:7390,T:9136,C:10236,K:12327,C:16502,B"]


def main() -> None:
    route = load_route(ROOT / "routes/freight-20km.yaml")
    train = load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")
    print(f"{'plan':<58} {'step m':>6} {'cells':>5} {'time s':>10} {'energy kWh':>11} {'dT %':>8} {'dE %':>8}")
    for text in PLANS:
        plan = parse_sequence(text, route.length_m)
        prev = None
        for step in (100.0, 50.0, 25.0, 12.5, 6.25):
            calc = TractionCalculator(route, train, ModelOptions(step_m=step))
            r = calc.evaluate(plan.conditions, plan.switches_m)
            t, e = float(r.running_time_s[0]), float(r.traction_energy_kwh[0])
            d = ("", "") if prev is None else (f"{100 * (prev[0] / t - 1):+.4f}", f"{100 * (prev[1] / e - 1):+.4f}")
            print(f"{text:<58} {step:>6g} {len(calc.h_m):>5} {t:>10.3f} {e:>11.3f} {d[0]:>8} {d[1]:>8}")
            prev = (t, e)
    paper_train = load_train(ROOT / "configs/consists/HXD1-C64-seed000.yaml")
    for name in ("seed000-flat", "seed000-grade30"):
        calc = TractionCalculator(load_route(ROOT / f"routes/{name}.yaml"), paper_train)
        print(f"fastest run on {name} (default step): {calc.fastest_time_s:.3f} s")


if __name__ == "__main__":
    main()
