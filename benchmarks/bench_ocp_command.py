"""`locoplan ocp ROUTE --objective energy` as a user runs it: wall clock of the whole command (Python's start,
the imports, CasADi, the refined optimal control, the plan and its check, the table), warm (compiled
kernels and point functions already in the cache folder), with the refinement's outcome beside it.

    python benchmarks/bench_ocp_command.py [--repeat 5] [--routes freight-20km] [--target 4]

One row per route and model (the default, --point-mass, --no-air-brake): the median and the range of the
wall clock over ``--repeat`` runs after one warm-up run (which compiles what the cache folder lacks), the
CPU time of the command (user + system, children included), the NLP solves and whether the mesh met its
tolerance, the objective against E* (``locoplan bound``, the cell method: an independent transcription).
The target is on the wall clock of freight-20km; the machine's load average is printed, since 2 cores
shared with other work stretch the wall clock (the CPU time shows what the command itself needs).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

MODELS = {"default": [], "point mass": ["--point-mass"], "no air brake": ["--no-air-brake"]}
TARGET_S = 4.0
"""The wall clock of `ocp --objective energy` on freight-20km at 1500 s, warm, on this 2-core machine."""


def run(args: list[str], env: dict) -> tuple[float, float, dict]:
    """One command: (wall clock [s], CPU time of the process and its children [s], its --json object)."""
    before = os.times()
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "locoplan", *args, "--json"], cwd=ROOT, env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    if proc.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(args)} failed ({proc.returncode}): {proc.stderr[-500:]}")
    return wall, cpu, json.loads(proc.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--routes", default="freight-20km", help="route names under routes/, comma-separated")
    ap.add_argument("--time", type=float, default=1500.0, help="planned running time [s]")
    ap.add_argument("--target", type=float, default=TARGET_S)
    args = ap.parse_args()
    env = dict(os.environ)
    env.setdefault("LOCOPLAN_CACHE_DIR", tempfile.mkdtemp(prefix="bench_ocp_command_"))  # warm after the warm-up
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; cache {env['LOCOPLAN_CACHE_DIR']}")
    head = (f"{'route':<16} {'model':<13} {'wall median [s]':>15} {'range [s]':>13} {'CPU [s]':>8} {'solves':>6} "
            f"{'met 1e-5':>8} {'objective':>10} {'E*':>10} {'vs E*':>9}  target")
    print(head)
    print("-" * len(head))
    for name in args.routes.split(","):
        route = f"routes/{name.strip()}.yaml"
        for model, flags in MODELS.items():
            cmd = ["ocp", route, "--objective", "energy", "--time", f"{args.time:g}", *flags]
            run(cmd, env)  # warm-up: kernels and point functions compiled into the cache folder
            walls, cpus, out = [], [], None
            for _ in range(args.repeat):
                w, c, out = run(cmd, env)
                walls.append(w)
                cpus.append(c)
            _, _, bound = run(["bound", route, "--time", f"{args.time:g}", *flags], env)
            e_star = float(bound["energy_kwh"])
            med = statistics.median(walls)
            mesh = out["mesh"]
            verdict = (("met" if med <= args.target else "MISSED") + f" (<= {args.target:g} s)"
                       if name.strip() == "freight-20km" and model == "default" else "")
            print(f"{name.strip():<16} {model:<13} {med:15.2f} {min(walls):6.2f}-{max(walls):<6.2f} "
                  f"{statistics.median(cpus):8.2f} {len(out['mesh_history']):6d} {'yes' if mesh['converged'] else 'NO':>8} "
                  f"{out['objective']:10.3f} {e_star:10.3f} {100 * (out['objective'] / e_star - 1):+8.4f}%  {verdict}")


if __name__ == "__main__":
    main()
