"""`locoplan optimize` on every shipped route with every shipped freight consist (issue 8: the method must
carry over to lines it was not tuned on).

    python benchmarks/all_routes.py [--factor 1.15] [--consists HXD1-C80x30,HXD1-C80x50,Fr100]

For each route x consist: the fastest run; if even it fails, the physical reason (no plan can exist);
else `locoplan optimize ROUTE --consist C --time factor x fastest --no-gap --json` as a user runs it,
with its exit code, running time, energy and whether it is on time. Prints one line per case and a count.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout's locoplan, installed or not

from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.sim.calculator import TractionCalculator  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factor", type=float, default=1.15)
    ap.add_argument("--consists", default="HXD1-C80x30,HXD1-C80x50,Fr100")
    args = ap.parse_args()
    routes = sorted(ROOT.glob("routes/real/*.yaml")) + sorted(ROOT.glob("routes/railtoolkit/*.yaml")) + sorted(ROOT.glob("routes/*.yaml"))
    counts = {"on time": 0, "late": 0, "impossible": 0, "failed": 0}
    for path in routes:
        for consist in args.consists.split(","):
            route, train = load_route(path), load_train(consist)
            calc = TractionCalculator(route, train)
            fastest = calc.evaluate(("T",), np.zeros((1, 0)))
            name = f"{path.relative_to(ROOT)} {consist}"
            if not fastest.feasible[0]:
                counts["impossible"] += 1
                print(f"{name}: no plan can exist: {fastest.reason(0)}", flush=True)
                continue
            t0 = round(args.factor * float(fastest.running_time_s[0]), 1)
            p = subprocess.run([sys.executable, "-m", "locoplan", "optimize", str(path), "--consist", consist,
                                "--time", str(t0), "--no-gap", "--json"], cwd=ROOT, capture_output=True, text=True)
            if p.returncode:
                counts["failed"] += 1
                print(f"{name}: exit {p.returncode}: {p.stderr.strip()[:200]}", flush=True)
                continue
            d = json.loads(p.stdout)
            counts["on time" if d["punctual"] else "late"] += 1
            print(f"{name}: T0 {t0} s, {d['running_time_s']} s, {d['traction_energy_kwh']} kWh, "
                  f"{'on time' if d['punctual'] else 'LATE'}", flush=True)
    print(", ".join(f"{k} {v}" for k, v in counts.items()), f"of {sum(counts.values())}")


if __name__ == "__main__":
    main()
