"""Re-planning on board: the set-up of a stream and the time per state (docs/replan.md).

    taskset -c 0 python benchmarks/bench_replan.py [--states 1000]

Lines: routes/freight-20km.yaml (its schedule, 1500 +- 30 s) and the real lines joined end to end to 100 km
(``scaling.joined_route``, planned at 1.15 x the fastest run, +- 1 %), HXD1 + 50 x C80, and routes/heavy-haul-60km.yaml
with HXD1 x 2 + 100 x C80 (its schedule), the default model (where the air brake's cycle binds, the cycle DP's
look-up, the brake's state on the departure drive given with each state; else the priced DP's). For each:
the set-up in the process (the calculator, the DP's cost-to-go at every price of the ladder, the first advice), the
wall time of ``locoplan replan ROUTE --stream`` from its start to its first line of advice (a new process: Python,
imports, the compiled kernels loaded, the set-up), and the time per state over ``--states`` states drawn along the
departure plan and around it (a third each at its speed, 10 % slower and 10 % faster; half of them 30 s late),
p50 / p99 / max. States the re-planner refuses (over the limit, beyond a braking curve) are counted apart.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not
sys.path.insert(0, str(Path(__file__).resolve().parent))

from scaling import joined_route  # noqa: E402

from locoplan.errors import LocoplanError  # noqa: E402
from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.optimize.replan import Replanner, TrainState  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def command_first_line_s(route_path: Path, time_arg: list[str]) -> float:
    """Wall time of ``locoplan replan ROUTE --stream`` until its first advice line."""
    t = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "locoplan", "replan", str(route_path), "--stream", *time_arg],
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                         cwd=ROOT)
    p.stdin.write(json.dumps({"s_m": 0, "v_kmh": 0, "t_s": 0}) + "\n")
    p.stdin.flush()
    p.stdout.readline()
    wall = time.perf_counter() - t
    p.stdin.close()
    p.wait()
    return wall


def air_at(plan, t_s: float, t_rec: float) -> tuple[str, float | None]:
    """The air brake's state on a drive at clock ``t_s`` (its events): applied, recharging (and the time left) or
    charged."""
    before = [e for e in plan.air_events if e[1] <= t_s + 1e-9 and e[3] != "charged"]
    if not before:
        return "charged", None
    if before[-1][3] == "apply":
        return "applied", None
    left = t_rec - (t_s - before[-1][1])
    return ("recharging", left) if left > 1e-6 else ("charged", None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=1000)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("freight-20km", "heavy-haul-60km", "100 km"):
            train = load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")
            if name == "freight-20km":
                path = ROOT / "routes/freight-20km.yaml"
                route = load_route(path)
                t0, tol, time_arg = 1500.0, 30.0, []
            elif name == "heavy-haul-60km":
                path = ROOT / "routes/heavy-haul-60km.yaml"
                route = load_route(path)
                train = load_train(ROOT / "configs/consists/HXD1x2-C80x100.yaml")
                t0, tol = float(route.schedule.run_time_s), float(route.schedule.tolerance_s)
                time_arg = ["--consist", str(ROOT / "configs/consists/HXD1x2-C80x100.yaml")]
            else:
                route = joined_route(100)
                path = Path(tmp) / "joined-100km.yaml"
                path.write_text(yaml.safe_dump(route.model_dump(mode="json", by_alias=True, exclude_none=True),
                                               sort_keys=False))
                t0 = round(1.15 * TractionCalculator(route, train).fastest_time_s)
                tol, time_arg = 0.01 * t0, ["--time", str(t0)]
            t = time.perf_counter()
            rp = Replanner(route, train, ModelOptions(), planned_s=t0, tolerance_s=tol)
            plan = rp.replan(TrainState(0.0, 0.0, 0.0))
            setup = time.perf_counter() - t
            wall = command_first_line_s(path, time_arg)
            t_rec = rp.cyc.t_rec if rp.cyc is not None else 0.0
            rng = np.random.default_rng(1)
            ms, refused, late = [], 0, 0
            for _ in range(args.states):
                i = int(rng.integers(0, len(plan.s_m) - 1))
                f = float(rng.choice([0.9, 1.0, 1.1]))
                air = air_at(plan, float(plan.t_s[i]), t_rec) if rp.cyc is not None else (None, None)
                st = TrainState(float(plan.s_m[i]), float(plan.v_kmh[i]) * f,
                                float(plan.t_s[i]) + float(rng.choice([0.0, 30.0])), None, *air)
                t = time.perf_counter()
                try:
                    q = rp.replan(st)
                    late += not q.on_time
                except LocoplanError:
                    refused += 1
                ms.append(1e3 * (time.perf_counter() - t))
            ms = np.array(ms)
            cells, nbytes = (rp.cyc.n, rp.cyc.V.nbytes) if rp.cyc is not None else (len(rp.s_nodes) - 1, rp.V.nbytes)
            rows.append((f"{name} ({'cycle' if rp.cyc is not None else 'priced'} DP)", cells, len(rp.prices),
                         nbytes / 1e6, setup, wall,
                         *np.percentile(ms, [50, 99]), ms.max(), refused, late))
    print("| line | DP cells | prices | cost-to-go [MB] | set-up [s] | command to first advice [s] | p50 [ms] | "
          "p99 [ms] | max [ms] | refused | late |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for r in rows:
        print(f"| {r[0]} | {r[1]:,} | {r[2]} | {r[3]:.0f} | {r[4]:.2f} | {r[5]:.2f} | {r[6]:.2f} | {r[7]:.2f} | "
              f"{r[8]:.2f} | {r[9]} | {r[10]} |")
    print(f"({args.states} states per line; one core: {os.sched_getaffinity(0) if hasattr(os, 'sched_getaffinity') else '?'})")


if __name__ == "__main__":
    main()
