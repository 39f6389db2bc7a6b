"""Cost of valid but heavy lines: a 20 km line of N gradient sections (20 km / N each, -6 .. +6 per mille, three
speed limits), HXD1 + 50 x C80 at 1.2 x its fastest run, each command a fresh process: wall time, peak memory
(the process's largest resident set) and exit code, E* solved afresh by each command, for N = 400 (50 m sections, the reference), 4,000, 8,000
and 12,000.

    python benchmarks/large_inputs.py [--sections 400,4000,8000,12000] [--commands validate,simulate,bound,optimize,mpoc,ocp-energy]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
CONSIST = str(ROOT / "configs/consists/HXD1-C80x50.yaml")


def line(n: int, length: float = 20000.0, seed: int = 3) -> dict:
    rng = np.random.default_rng(seed)
    ends = np.linspace(0.0, length, n + 1)
    grades = [{"from_m": float(a), "to_m": float(b), "permille": float(g)}
              for a, b, g in zip(ends[:-1], ends[1:], np.round(rng.uniform(-6.0, 6.0, n), 2))]
    limits = [{"from_m": 0.0, "to_m": 8000.0, "kmh": 80.0}, {"from_m": 8000.0, "to_m": 12000.0, "kmh": 60.0},
              {"from_m": 12000.0, "to_m": length, "kmh": 80.0}]
    return {"schema": "locoplan/route@1", "name": f"{n} sections", "length_m": length, "speed_limits": limits,
            "gradients": grades}


def run(args: list[str], cwd: Path, cache: Path) -> tuple[float, float, int]:
    """(wall [s], peak resident memory [MiB], exit code) of ``python -m locoplan ARGS``, E*'s cache in ``cache``."""
    t0 = time.perf_counter()
    env = {**os.environ, "LOCOPLAN_CACHE_DIR": str(cache)}
    proc = subprocess.Popen([sys.executable, "-m", "locoplan", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return time.perf_counter() - t0, usage.ru_maxrss / 1024.0, proc.returncode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sections", default="400,4000,8000,12000")
    ap.add_argument("--commands", default="validate,simulate,bound,optimize")
    args = ap.parse_args()
    commands = args.commands.split(",")
    print("| sections | command | exit | wall | peak memory |")
    print("| ---: | --- | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n in (int(x) for x in args.sections.split(",")):
            route = tmp / f"line{n}.yaml"
            route.write_text(yaml.safe_dump(line(n), sort_keys=False))
            for cmd in commands:
                argv = {"validate": ["validate", str(route)],
                        "simulate": ["simulate", str(route), "--consist", CONSIST],
                        "bound": ["bound", str(route), "--consist", CONSIST, "--time", "1.2x"],
                        "optimize": ["optimize", str(route), "--consist", CONSIST, "--time", "1.2x"],
                        "mpoc": ["compare", str(route), "--consist", CONSIST, "--time", "1.2x", "--strategies", "mpoc"],
                        "ocp-energy": ["ocp", str(route), "--consist", CONSIST, "--objective", "energy",
                                       "--time", "1.2x"]}[cmd]
                wall, mib, code = run(argv, tmp, tmp / f"cache-{n}-{cmd}")  # (a cold E* each time)
                print(f"| {n:,} | `{cmd}` | {code} | {wall:.1f} s | {mib:.0f} MiB |", flush=True)


if __name__ == "__main__":
    main()
