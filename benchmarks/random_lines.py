"""Seed 002 on lines and trains nobody tuned it on: randomly generated routes x randomly sized consists.

    python benchmarks/random_lines.py [--cases 40] [--seed 7] [--no-gap] [--json out.json]
                                      [--max-grade 20] [--point-mass | --no-air-brake] [--fastest]

Each case draws (numpy Generator, ``--seed``) a route of 4-60 km (station throats, 2-8 speed limits of
40-100 km/h, a random walk of gradients up to +-20 per mille with steeper pitches now and then, curves,
tunnels, up to two neutral sections) and a train (HXD1 + 15-60 C80 at 50-80 t load, HXD1 + 20-50 C64,
or V 90 + 5-15 Facs 124 braking at 0.225 m/s^2 as Fr100), then T0 = factor x the fastest run with factor 1.05-1.6. If not even the
fastest run reaches the stop the case is "impossible" (the commands refuse it, exit 1). Otherwise the
proposed plan (ISSA seed 1, window +-1 % of T0), whether it is on time, and the gap to the optimum E*
(seed 001) at its own running time. Prints one line per case and a summary: on time, failures (with
their reasons), gap max and median. Expected: every possible case on time, no failure, gaps like the
real lines' (docs/real-lines.md).

``--max-grade 30`` draws steeper lines (pitches up to +-30 per mille, steep ones of 22.5-37.5), which with
``--no-air-brake`` (or ``--point-mass``) have descents the locomotive's brake cannot hold; ``--fastest``
checks only the fastest run of every case against an independent fine-step computation
(benchmarks/fastest_check.py), in the chosen model: target within 0.05 %.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.errors import LocoplanError  # noqa: E402
from locoplan.io.load import load_train  # noqa: E402
from locoplan.model.route import Route  # noqa: E402
from locoplan.runner import make_context, run_strategy, schedule_verdict  # noqa: E402
from locoplan.sim.calculator import ModelOptions, TractionCalculator  # noqa: E402
_sys.path.insert(0, str(_Path(__file__).resolve().parent))  # fastest_check, beside this file

LIMITS_KMH = np.arange(40, 101, 5)


def random_route(rng: np.random.Generator, i: int, max_grade_permille: float = 20.0) -> Route:
    """A random line; ``max_grade_permille`` scales its gradients (20: pitches up to +-20, steep ones of
    15-25 per mille now and then; 30: up to +-30 and 22.5-37.5)."""
    scale = max_grade_permille / 20.0
    L = float(np.round(rng.uniform(4_000, 60_000), -2))
    # speed limits: throats at both ends, 0-6 inner changes at least 800 m apart
    n_inner = int(rng.integers(0, 7))
    cuts = np.sort(rng.uniform(0.08 * L, 0.92 * L, n_inner))
    cuts = cuts[np.concatenate([[True], np.diff(cuts) > 800])] if len(cuts) else cuts
    edges = [0.0, float(np.round(min(0.08 * L, 2000), -1)), *np.round(cuts, -1),
             float(np.round(L - min(0.06 * L, 1500), -1)), L]
    edges = sorted(set(edges))
    limits = []
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        end = k in (0, len(edges) - 2)
        kmh = float(rng.choice(LIMITS_KMH[LIMITS_KMH <= 60] if end else LIMITS_KMH))
        limits.append({"from_m": a, "to_m": b, "kmh": kmh})
    # gradients: 300-3000 m pitches, a random walk, steep now and then
    grads, s, g = [], 0.0, 0.0
    while s < L:
        length = float(np.round(rng.uniform(300, 3000), -1))
        b = min(L, s + length)
        if L - b < 200:
            b = L
        g = float(np.clip(0.6 * g + rng.normal(0, 6 * scale), -max_grade_permille, max_grade_permille))
        if rng.random() < 0.08:
            g = float(rng.choice([-1, 1]) * min(rng.uniform(15, 25) * scale, 40.0))
        grads.append({"from_m": s, "to_m": b, "permille": round(g, 1)})
        s = b
    curves = []
    for a in np.sort(rng.uniform(0, L - 1000, int(rng.integers(0, 5)))):
        c = {"from_m": float(np.round(a)), "to_m": float(np.round(a + rng.uniform(200, 900))),
             "radius_m": float(np.round(rng.uniform(350, 1500), -1))}
        if not curves or c["from_m"] > curves[-1]["to_m"]:
            curves.append(c)
    tunnels = []
    if rng.random() < 0.4:
        a = float(np.round(rng.uniform(0.1, 0.8) * L))
        tunnels.append({"from_m": a, "to_m": a + float(np.round(rng.uniform(300, 3000)))})
        tunnels[0]["to_m"] = min(tunnels[0]["to_m"], L - 100)
    neutral = []
    for a in np.sort(rng.uniform(0.15 * L, 0.85 * L, int(rng.integers(0, 3)))):
        if not neutral or a > neutral[-1]["to_m"] + 1000:
            neutral.append({"from_m": float(np.round(a)), "to_m": float(np.round(a + rng.uniform(150, 250))),
                            "coast_before_s": 10, "coast_after_s": 10})
    return Route.model_validate({"schema": "locoplan/route@1", "name": f"random line {i}", "length_m": L,
                                 "speed_limits": limits, "gradients": grads, "curves": curves, "tunnels": tunnels,
                                 "neutral_sections": neutral})


def random_train(rng: np.random.Generator, folder: Path, i: int):
    kind = int(rng.integers(0, 3))
    if kind == 0:
        n, load = int(rng.integers(15, 61)), int(rng.integers(50, 81))
        name, vehicles = f"HXD1 + {n} x C80 ({load} t)", [{"type": "HXD1", "count": 1}, {"type": "C80", "count": n, "load_t": load}]
    elif kind == 1:
        n = int(rng.integers(20, 51))
        name, vehicles = f"HXD1 + {n} x C64", [{"type": "HXD1", "count": 1}, {"type": "C64", "count": n, "load_t": 61}]
    else:
        n = int(rng.integers(5, 16))
        name, vehicles = f"V 90 + {n} x Facs 124", [{"type": "DB_V90", "count": 1}, {"type": "Facs124", "count": n, "load_t": 59}]
    path = folder / f"train{i}.yaml"
    lines = ["schema: locoplan/consist@1", f"name: {name}", "vehicles:"]
    lines += ["  - {" + ", ".join(f"{k}: {v}" for k, v in v.items()) + "}" for v in vehicles]
    if kind == 2:  # railtoolkit's V 90 and Facs 124 give no brake forces: the consist's deceleration (as Fr100)
        lines.append("brake_deceleration_ms2: 0.225")
    path.write_text("\n".join(lines) + "\n")
    return load_train(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=40)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--no-gap", action="store_true", help="skip E* (seed 001's optimum)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--max-grade", type=float, default=20.0, help="scale of the gradients [per mille]")
    model = ap.add_mutually_exclusive_group()
    model.add_argument("--point-mass", action="store_true", help="the seeds' model: point mass, electric brake alone")
    model.add_argument("--no-air-brake", action="store_true", help="the train-length model, electric brake alone")
    ap.add_argument("--fastest", action="store_true", help="check the fastest run against the fine-step oracle only")
    args = ap.parse_args()
    options = (ModelOptions.seeds() if args.point_mass else ModelOptions(air_brake=False) if args.no_air_brake
               else ModelOptions())
    rng = np.random.default_rng(args.seed)
    if args.fastest:
        return fastest_cases(args, rng, options)
    rows = []
    print(f"{'case':>4} {'km':>5} {'train':26} {'x':>5} {'T0 [s]':>8} {'time [s]':>9} {'on time':>7} {'E [kWh]':>8} "
          f"{'gap %':>6} {'solve s':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.cases):
            route = random_route(rng, i)
            train = random_train(rng, Path(tmp), i)
            factor = float(np.round(rng.uniform(1.05, 1.6), 2))
            row = {"case": i, "km": route.length_m / 1000, "train": train.name, "factor": factor}
            head = f"{i:>4} {route.length_m / 1000:>5.1f} {train.name[:26]:26} {factor:>5.2f}"
            if route.length_m < 2 * train.length_m:
                continue
            fastest = TractionCalculator(route, train, options).evaluate(("T",), np.zeros((1, 0)))
            if not fastest.feasible[0]:
                row["status"] = "impossible"
                print(f"{head} impossible: {fastest.reason(0)}", flush=True)
                rows.append(row)
                continue
            t0 = round(factor * float(fastest.running_time_s[0]), 1)
            try:
                ctx = make_context(route, train, options, time_s=t0, tolerance_s=0.01 * t0)
                start = time.perf_counter()
                run = run_strategy(ctx, "proposed")
                solve = time.perf_counter() - start
            except LocoplanError as exc:
                row.update(status="failed", reason=str(exc))
                print(f"{head} FAILED: {exc}", flush=True)
                rows.append(row)
                continue
            s = run.summary
            on_time = schedule_verdict(ctx, run) is None
            g = None
            if not args.no_gap and s["feasible"]:
                from locoplan.ocp.bound import gap_to_optimum
                g = gap_to_optimum(route, train, ctx.calc.options, s["running_time_s"], s["traction_energy_kwh"],
                                   calc=ctx.calc)
            row.update(status="on time" if on_time else "late", t0_s=t0, time_s=s["running_time_s"],
                       energy_kwh=s["traction_energy_kwh"], optimum_kwh=None if g is None else g.optimum_kwh,
                       gap_kwh=None if g is None else g.gap_kwh, gap_percent=None if g is None else g.gap_percent,
                       solve_s=round(solve, 2))
            rows.append(row)
            gap_text = "-" if g is None else (f"{g.gap_percent:+.2f}" if g.gap_percent is not None else
                                              f"{g.gap_kwh:+.2f} kWh over E* {g.optimum_kwh:.2f}")
            print(f"{head} {t0:>8.1f} {s['running_time_s']:>9.1f} {'yes' if on_time else 'NO':>7} "
                  f"{s['traction_energy_kwh']:>8.2f} {gap_text:>6} {solve:>7.2f}", flush=True)
    count = {k: sum(r["status"] == k for r in rows) for k in ("on time", "late", "impossible", "failed")}
    gaps = [r["gap_percent"] for r in rows if r.get("gap_percent") is not None]
    small = [r for r in rows if r.get("gap_percent") is None and r.get("gap_kwh") is not None]
    print(f"\n{len(rows)} cases: " + ", ".join(f"{v} {k}" for k, v in count.items()))
    if gaps:
        print(f"gap to E*: max {max(gaps):.2f} %, median {statistics.median(gaps):.2f} % over {len(gaps)} cases")
    if small:
        print(f"E* too small for a percentage on {len(small)} (falling lines): gaps "
              + ", ".join(f"{r['gap_kwh']:+.2f} kWh (E* {r['optimum_kwh']:.2f})" for r in small))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))


def fastest_cases(args, rng: np.random.Generator, options: ModelOptions) -> None:
    """``--fastest``: the fastest run of every case against the independent fine-step computation."""
    from fastest_check import check, row_text, summarise  # noqa: PLC0415

    rows = []
    print(f"{'case':>4} {'km':>5} {'train':26} {'fastest [s]':>11} {'oracle [s]':>11} {'diff %':>8} {'steep cells':>11} "
          f"{'enter -km/h':>11}")
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.cases):
            route = random_route(rng, i, args.max_grade)
            train = random_train(rng, Path(tmp), i)
            rng.uniform(1.05, 1.6)  # the factor the optimising run would draw: same lines for the same seed
            if route.length_m < 2 * train.length_m:
                continue
            r = check(TractionCalculator(route, train, options))
            r.update(case=i, km=route.length_m / 1000, train=train.name)
            rows.append(r)
            print(f"{i:>4} {r['km']:>5.1f} {train.name[:26]:26} {row_text(r)}", flush=True)
    summarise(rows)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=float))


if __name__ == "__main__":
    main()
