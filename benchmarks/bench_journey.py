"""Journeys on the shipped multi-stop lines: the optimal allocation of the running time against equal
supplements, every stop in its window, and the wall time.

    taskset -c 0 python benchmarks/bench_journey.py [--factors 1.1,1.2] [--consists HXD1-C80x50,HXD1-C80x30]
                                                     [--strategies proposed] [--point-mass] [--no-air-brake]
                                                     [--journeys JOURNEY.yaml ...]

Lines: routes/journeys/ (CN_Songjiazhuang_Yizhuang: 13 legs; CH_Stadelhofen_Altstetten: 3 legs, both
imported with `locoplan import ttobench --journey --cap-kmh 80`). For each train and factor: the total
running time is the factor x the fastest run (dwells excluded); every intermediate stop gets a window of
+-2 % of that total around where equal supplements would bring the train (so that some windows bind),
and a dwell of 30 s. Printed: the journey's E*, its accuracy, the E* of equal supplements and what the
optimal allocation saves, whether every stop of the optimum and of the plans is inside its window, the
plans' energy and gap (the journey's, and the largest of a leg's), how many windows the plans keep, how far
the legs' plans add up from the total (against its tolerance), how many legs were planned again, and the
wall time: the allocation with the legs' E*, the comparison with equal supplements, and everything (the plans
of every leg included).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from locoplan.errors import InfeasibleError  # noqa: E402
from locoplan.io.load import load_journey, load_train  # noqa: E402
from locoplan.runs.journey import WINDOW_SLACK_S, legs_of, plan_journey  # noqa: E402
from locoplan.settings import RunSettings  # noqa: E402
from locoplan.sim.calculator import ModelOptions  # noqa: E402

LINES = ["CN_Songjiazhuang_Yizhuang", "CH_Stadelhofen_Altstetten"]
DWELL_S = 30.0
WINDOW_SHARE = 0.02


def with_windows(journey, legs, total_s: float):
    """The journey with a dwell at every intermediate stop and a window of +-WINDOW_SHARE of the total
    around the equal-supplement arrival."""
    fast = np.array([leg.fastest_s for leg in legs])
    eq = fast * total_s / fast.sum()
    stations, run = list(journey.stations), 0.0
    for k, leg in enumerate(legs[:-1]):
        run += eq[k]
        i = leg.last
        clock = run + DWELL_S * k
        half = WINDOW_SHARE * total_s
        stations[i] = stations[i].model_copy(update={"dwell_s": DWELL_S, "earliest_s": round(float(clock - half), 1),
                                                     "latest_s": round(float(clock + half), 1)})
    return journey.model_copy(update={"stations": stations})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factors", default="1.1,1.2")
    ap.add_argument("--journeys", nargs="*", type=Path, default=[ROOT / "routes/journeys" / f"{x}-journey.yaml" for x in LINES],
                    help="journey files (default: the two shipped); e.g. one written by locoplan import ttobench --journey")
    ap.add_argument("--consists", default="HXD1-C80x50,HXD1-C80x30")
    ap.add_argument("--strategies", default="proposed")
    ap.add_argument("--point-mass", action="store_true")
    ap.add_argument("--no-air-brake", action="store_true")
    args = ap.parse_args()
    # as the commands' options: --point-mass is the papers' model, without the wagons' air brake
    options = ModelOptions(point_mass=args.point_mass, air_brake=not (args.no_air_brake or args.point_mass))
    strategies = tuple(args.strategies.split(","))
    print(f"model: point mass {options.point_mass}, air brake {options.air_brake}; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; windows +-{100 * WINDOW_SHARE:g} % of the total, "
          f"dwells {DWELL_S:g} s")
    print(f"{'line':<27} {'train':<12} {'f':>4} {'legs':>4} {'T [s]':>7} {'E* [kWh]':>9} {'within':>7} "
          f"{'eq. [kWh]':>9} {'saved':>14} {'held':>4} {'in win.':>7} {'plans [kWh]':>11} {'gap':>9} "
          f"{'leg gap max':>11} {'windows kept':>12} {'sum - T [s]':>13} {'replans':>7} "
          f"{'E* [s]':>6} {'cmp [s]':>7} {'all [s]':>7}")
    for path in args.journeys:
        j0, route = load_journey(path)
        name = path.name.removesuffix("-journey.yaml")
        for consist in args.consists.split(","):
            train = load_train(consist)
            try:
                legs = legs_of(j0, route, train, options)
            except InfeasibleError as exc:  # (the point-mass train stalls on a climb the real-length one makes)
                print(f"{name:<27} {consist:<12} {'-':>4} {'-':>4} no run: {exc}", flush=True)
                continue
            fastest = sum(leg.fastest_s for leg in legs)
            for f in (float(x) for x in args.factors.split(",")):
                total = round(f * fastest, 1)
                j = with_windows(j0, legs, total)
                t0 = time.perf_counter()
                marks = {}
                res = plan_journey(j, route, train, RunSettings(options, time_s=total), strategies=strategies,
                                   step=lambda s: marks.setdefault(s.split(":")[0], time.perf_counter()))
                wall = time.perf_counter() - t0
                t_eq, t_plans = marks.get("equal supplements", t0), marks.get("leg 1", t0 + wall)
                e_star_wall = t_eq - t0  # the allocation and the legs' E*
                s = res.summary
                eq = next(a for a in s["allocations"] if a["allocation"] == "equal supplements")
                inside = all(st["window_s"][0] is None or st["window_s"][0] - WINDOW_SLACK_S <= st["optimum_s"]
                             <= st["window_s"][1] + WINDOW_SLACK_S for st in s["stations"])
                held = sum(1 for st in s["stations"] if st["window_s"][0] is not None and
                           min(abs(st["optimum_s"] - st["window_s"][0]), abs(st["optimum_s"] - st["window_s"][1])) < 0.5)
                p = s["plans"][strategies[0]]
                gap = "-" if p["gap_to_optimum_kwh"] is None else (
                    f"{p['gap_to_optimum_percent']:+.2f} %" if p["gap_to_optimum_percent"] is not None
                    else f"{p['gap_to_optimum_kwh']:+.1f} kWh")
                leg_gaps = [row["plans"][strategies[0]].get("gap_to_optimum_percent") for row in s["legs_table"]]
                leg_gap = max((g for g in leg_gaps if g is not None), default=None)
                kept = [st["plans"][strategies[0]]["in_window"] for st in s["stations"]]
                n_win = sum(1 for x in kept if x is not None)
                err = "-" if p["punctuality_error_s"] is None else f"{p['punctuality_error_s']:+.1f}/{s['tolerance_s']:.1f}"
                replans = sum(row["plans"][strategies[0]]["replans"] for row in s["legs_table"])
                saved = eq["optimum_kwh"] - s["optimum_kwh"]
                print(f"{name:<27} {consist:<12} {f:>4g} {s['legs']:>4} {total:>7.1f} {s['optimum_kwh']:>9.2f} "
                      f"{s['optimum_accuracy_percent']:>6.2g}% {eq['optimum_kwh']:>9.2f} "
                      f"{saved:>7.2f} ({100 * saved / eq['optimum_kwh']:>4.1f}%) {held:>4} {'yes' if inside else 'NO':>7} "
                      f"{'-' if p['traction_energy_kwh'] is None else format(p['traction_energy_kwh'], '.2f'):>11} {gap:>9} "
                      f"{'-' if leg_gap is None else format(leg_gap, '+.2f') + ' %':>11} "
                      f"{sum(1 for x in kept if x):>5}/{n_win:<6} {err:>13} {replans:>7} "
                      f"{e_star_wall:>6.1f} {t_plans - t_eq:>7.1f} {wall:>7.1f}", flush=True)

if __name__ == "__main__":
    main()
