"""E* (the least traction energy in a running time): its cost against line length, its accuracy, and
two independent methods side by side.

    taskset -c 0 python benchmarks/bench_bound.py [--lengths 20,50,100,300] [--check-lengths 20,50]
        [--lines 10] [--real] [--commands] [--point-mass] [--no-air-brake] [--factor 1.15]

Part 1, lines: routes/freight-20km.yaml for 20, else the real lines joined end to end as
benchmarks/scaling.py builds them; HXD1 + 50 x C80; T = factor x the fastest run; each E* solved cold
(an empty LOCOPLAN_CACHE_DIR, no warm start): the cell solver's wall time (ocp/cells.py), whether its
grids agreed to the tolerance, E*'s estimated accuracy, the cells of the finest grid, and on the
--check-lengths the second method (multi-phase Radau collocation with hp refinement, ocp/energy.py)
and the difference.
Part 2 (--lines N, --real): the two methods on N lines of benchmarks/random_lines.py (random trains,
seed 7) and on the shipped real lines (HXD1 + 50 x C80): the largest difference.
Part 3 (--commands): wall time of `locoplan optimize` on the 100 km line and of a 20-point
`locoplan bound --times` on the 50 km line, cold E* caches (the compiled kernels of this machine kept).
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from scaling import joined_route  # noqa: E402

from locoplan.errors import LocoplanError  # noqa: E402
from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.ocp import bound as bound_mod  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402


def line(length_km: float):
    if length_km == 20:
        return load_route(ROOT / "routes/freight-20km.yaml")
    return joined_route(length_km)


def cold_bound(route, train, options, t0, calc):
    """E* solved from nothing: an empty disk cache, no solution kept in the process."""
    with tempfile.TemporaryDirectory() as cache:
        os.environ["LOCOPLAN_CACHE_DIR"] = cache
        bound_mod._BOUNDS.clear()
        bound_mod._WARM.clear()
        t = time.perf_counter()
        b = bound_mod.energy_bound(route, train, options, t0, calc=calc)
        return b, time.perf_counter() - t


def pct(x):
    return "?" if x is None else f"{x:.2g}"


def part_lines(args, train, options) -> None:
    checks = {float(x) for x in args.check_lengths.split(",") if x}
    print("\nE* against line length (one solve each, cold)")
    print(f"{'line':>8} {'T [s]':>8} {'E* [kWh]':>10} {'tol met':>7} {'within %':>8} {'cells':>7} {'wall s':>7} "
          f"{'2nd [kWh]':>10} {'2nd within %':>12} {'diff %':>8} {'2nd wall s':>10}")
    walls = {}
    for km in (float(x) for x in args.lengths.split(",")):
        route = line(km)
        calc = TractionCalculator(route, train, options)
        t0 = round(args.factor * calc.fastest_time_s, 1)
        b, wall = cold_bound(route, train, options, t0, calc)
        walls[km] = wall
        tail = f"{'-':>10} {'-':>12} {'-':>8} {'-':>10}"
        if km in checks:
            c = bound_mod.check_bound(route, train, options, t0, mesh_tol=1e-5, max_degree=10)
            tail = (f"{c.energy_kwh:>10.2f} {pct(c.accuracy_percent):>12} {100 * (b.energy_kwh / c.energy_kwh - 1):>+8.3f} "
                    f"{c.solve_time_s:>10.1f}")
        print(f"{km:>6g}km {t0:>8.1f} {b.energy_kwh:>10.2f} {'yes' if b.converged else 'NO':>7} {pct(b.accuracy_percent):>8} "
              f"{b.cells:>7} {wall:>7.2f} {tail}", flush=True)
    if len(walls) > 1:
        lo, hi = min(walls), max(walls)
        print(f"cost ratio {hi:g} km / {lo:g} km: {walls[hi] / walls[lo]:.1f} (length ratio {hi / lo:g})")


def part_agreement(args, train, options) -> None:
    from random_lines import random_route, random_train

    cases = []
    if args.lines:
        rng = np.random.default_rng(7)
        folder = Path(tempfile.mkdtemp(prefix="bench-bound-"))
        for i in range(args.lines):
            r = random_route(rng, i)
            cases.append((r.name, r, random_train(rng, folder, i)))
    if args.real:
        for f in sorted((ROOT / "routes/real").glob("*.yaml")):
            cases.append((f.stem, load_route(f), train))
    if not cases:
        return
    print("\nTwo independent methods: the cells (ocp/cells.py) and multi-phase Radau hp (ocp/energy.py)")
    print(f"{'line':<36} {'km':>5} {'T [s]':>7} {'cells [kWh]':>11} {'within %':>8} {'Radau [kWh]':>11} {'within %':>8} {'diff %':>8}")
    diffs = []
    for name, route, tr in cases:
        calc = TractionCalculator(route, tr, options)
        if not np.isfinite(calc.fastest_time_s):
            print(f"{name[:36]:<36} the train cannot run this line")
            continue
        t0 = round(args.factor * calc.fastest_time_s, 1)
        try:
            b, _ = cold_bound(route, tr, options, t0, calc)
            c = bound_mod.check_bound(route, tr, options, t0, mesh_tol=1e-5, max_degree=10)
        except LocoplanError as exc:
            print(f"{name[:36]:<36} {route.length_m / 1000:>5.1f} {t0:>7.1f} failed: {str(exc)[:60]}")
            continue
        # relative to E*, or to the floor below which no gap is given in per cent (a coasting line)
        d = 100 * (b.energy_kwh - c.energy_kwh) / max(c.energy_kwh, bound_mod.percent_floor_kwh(route, tr))
        diffs.append(abs(d))
        print(f"{name[:36]:<36} {route.length_m / 1000:>5.1f} {t0:>7.1f} {b.energy_kwh:>11.2f} {pct(b.accuracy_percent):>8} "
              f"{c.energy_kwh:>11.2f} {pct(c.accuracy_percent):>8} {d:>+8.3f}", flush=True)
    if diffs:
        print(f"largest difference {max(diffs):.3f} % over {len(diffs)} lines (median {np.median(diffs):.3f} %)")


def part_commands(args) -> None:
    print("\nCommands, cold caches (wall time)")
    with tempfile.TemporaryDirectory() as d:
        r100, r50 = Path(d) / "line100.yaml", Path(d) / "line50.yaml"
        import yaml

        for km, path in ((100, r100), (50, r50)):
            path.write_text(yaml.safe_dump(joined_route(km).model_dump(mode="json", by_alias=True, exclude_none=True), sort_keys=False))
        route100 = load_route(r100)
        calc = TractionCalculator(route100, load_train(ROOT / "configs/consists/HXD1-C80x50.yaml"))
        t100 = round(1.15 * calc.fastest_time_s)
        calc50 = TractionCalculator(load_route(r50), load_train(ROOT / "configs/consists/HXD1-C80x50.yaml"))
        a, b = round(1.05 * calc50.fastest_time_s), round(1.5 * calc50.fastest_time_s)
        step = max(1, round((b - a) / 19))
        model = (["--point-mass"] if args.point_mass else []) + (["--no-air-brake"] if args.no_air_brake else [])
        for label, cmd in ((f"optimize, 100 km, T = {t100} s", ["optimize", str(r100), "--time", str(t100), "--json"]),
                           (f"bound --times {a}:{a + 19 * step}:{step}, 50 km", ["bound", str(r50), "--times", f"{a}:{a + 19 * step}:{step}", "--json"])):
            env = {**os.environ, "LOCOPLAN_CACHE_DIR": str(Path(d) / f"cache-{len(label)}")}
            t = time.perf_counter()
            p = subprocess.run([sys.executable, "-m", "locoplan", *cmd, *model], capture_output=True, text=True, env=env, cwd=ROOT)
            wall = time.perf_counter() - t
            print(f"{label:<48} {wall:>7.1f} s  (exit {p.returncode})", flush=True)
            if p.returncode not in (0, 1):
                print(p.stderr[-400:])


def main() -> None:
    from locoplan.sim.native import native_dir

    # the kernels compiled for this machine stay where they are while the E* caches are emptied
    os.environ["LOCOPLAN_NATIVE_DIR"] = str(native_dir())
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="20,50,100,300")
    ap.add_argument("--check-lengths", default="20,50")
    ap.add_argument("--lines", type=int, default=0)
    ap.add_argument("--real", action="store_true")
    ap.add_argument("--commands", action="store_true")
    ap.add_argument("--factor", type=float, default=1.15)
    ap.add_argument("--point-mass", action="store_true")
    ap.add_argument("--no-air-brake", action="store_true")
    args = ap.parse_args()
    options = ModelOptions(point_mass=args.point_mass, air_brake=not args.no_air_brake)
    train = load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")
    print(f"HXD1 + 50 x C80, T = {args.factor:g} x fastest, model: point mass {args.point_mass}, "
          f"air brake {not args.no_air_brake}; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if args.lengths:
        part_lines(args, train, options)
    part_agreement(args, train, options)
    if args.commands:
        part_commands(args)


if __name__ == "__main__":
    main()
