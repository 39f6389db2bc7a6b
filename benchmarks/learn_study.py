"""The pattern-curve patent end to end: simulate drivers, learn the double-layer patterns, and measure the advice on
runs held out from learning (other masses and times, and a line not learned from) against the
drivers, the good drivers, the best driver, and the ISSA paper's proposed plan (ISSA).

    python benchmarks/learn_study.py [--drivers 40] [--runs 2] [--seed 1] [--workdir DIR] [--out study.json]

Learned from: freight-20km (1450 / 1550 s) and rolling-24km (1650 / 1750 s) at 3200 / 4200 / 5200 t.
Held out: freight-20km at 3700 and 4700 t, 1500 s; rolling-24km at 4700 t, 1700 s; ridge-18km (never
learned from) at 3600 and 4800 t, 1300 and 1400 s. The drivers of every case are the same simulated
population (same seed), driving that case; the logs are synthetic.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from locoplan.io.load import build_train, load_consist, load_route  # noqa: E402
from locoplan.io.logs import load_logs  # noqa: E402
from locoplan.reporting.writers import to_json  # noqa: E402
from locoplan.learn.drivers import SimulationSpec, consist_for_mass  # noqa: E402
from locoplan.learn.patterns import LearnSettings, learn  # noqa: E402
from locoplan.reporting.logs import simulate_drivers  # noqa: E402
from locoplan.runner import make_context, run_strategy  # noqa: E402
from locoplan.settings import RunSettings  # noqa: E402
from locoplan.sim.calculator import ModelOptions  # noqa: E402

TRAIN = [("routes/freight-20km.yaml", (3200, 4200, 5200), (1450, 1550)),
         ("routes/rolling-24km.yaml", (3200, 4200, 5200), (1650, 1750))]
HELD_OUT = [("routes/freight-20km.yaml", (3700, 4700), (1500,)),
            ("routes/rolling-24km.yaml", (4700,), (1700,)),
            ("routes/ridge-18km.yaml", (3600, 4800), (1300, 1400))]


def simulate(route: str, masses, times, folder: Path, args, base) -> Path:
    spec = SimulationSpec(ROOT / route, load_route(ROOT / route), *base, masses_t=tuple(masses), times_s=tuple(times),
                          n_drivers=args.drivers, n_runs=args.runs, seed=args.seed)
    folder.mkdir(parents=True, exist_ok=True)
    out = folder / f"{Path(route).stem}-{'-'.join(str(m) for m in masses)}-{'-'.join(str(t) for t in times)}"
    simulate_drivers(spec, out)
    return out


def optimum_kwh(route, train, options, time_s: float):
    """E*, the least traction energy in ``time_s`` (the MPOC paper's optimal control), or None where it does not
    solve and confirm (the table then shows "-")."""
    from locoplan.errors import LocoplanError
    from locoplan.ocp.bound import energy_bound

    try:
        return round(float(energy_bound(route, train, options, time_s).energy_kwh), 2)
    except LocoplanError:
        return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drivers", type=int, default=40)
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workdir", type=Path, default=None, help="keep logs and patterns here (default: a temporary folder)")
    ap.add_argument("--out", type=Path, default=None, help="write the table as JSON")
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="learn_study."))
    if work.exists() and any(work.iterdir()):
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    consist, vehicles, files, _, _ = load_consist(ROOT / "configs/consists/HXD1-C80x50.yaml")
    base = (consist, vehicles, files)
    options = ModelOptions()
    t0 = time.perf_counter()
    train_dirs = [simulate(r, m, t, work / "train", args, base) for r, m, t in TRAIN]
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    learned = learn(load_logs(train_dirs), LearnSettings(seed=args.seed), options)
    t_learn = time.perf_counter() - t0
    (work / "patterns.json").write_text(to_json(learned.patterns.to_dict()))
    rep = learned.patterns.report
    print(f"learned from {rep['data']['runs']} synthetic runs ({rep['data']['good_runs']} good) in {t_learn:.1f} s "
          f"(simulation {t_sim:.1f} s); upper form {rep['upper']['form']} order {rep['upper']['order']}, "
          f"lower order {rep['lower']['order']}")
    for name in ("heldout", "fit"):
        r = rep[name]
        print(f"  {name:8s} runs {r['runs']:4d}: shares R2 {r['upper']['r2']:.4f} RMSE {r['upper']['rmse_share']:.5f} "
              f"(section time MAE {r['upper']['mean_abs_error_s']:.1f} s); speeds R2 one division "
              f"{r['lower']['one_step_r2']:.4f} ({r['lower']['one_step_rmse_kmh']:.2f} km/h), chained "
              f"{r['lower']['chained_r2']:.4f} ({r['lower']['chained_rmse_kmh']:.2f} km/h)")
    rows = []
    for route, masses, times in HELD_OUT:
        logs = simulate(route, masses, times, work / "heldout", args, base)
        r = load_route(ROOT / route)
        for mass in masses:
            train = build_train(consist_for_mass(consist, vehicles, mass), vehicles)
            for t in times:
                ctx = make_context(r, train, RunSettings(options, time_s=float(t)))
                ctx.inputs.update(logs=[logs], patterns=work / "patterns.json")
                drv = run_strategy(ctx, "drivers").summary
                adv = run_strategy(ctx, "advice").summary
                t_p = time.perf_counter()
                pro = run_strategy(ctx, "proposed").summary
                row = {"route": r.name, "route_learned": route in [x[0] for x in TRAIN], "mass_t": mass, "time_s": t,
                       "tolerance_s": ctx.tolerance_s,
                       "drivers_mean_kwh": drv["drivers_mean_kwh"], "good_drivers_mean_kwh": drv["good_drivers_mean_kwh"],
                       "best_driver_kwh": drv["best_driver_kwh"], "drivers_mean_time_s": drv["running_time_s"],
                       "advice_kwh": adv["traction_energy_kwh"], "advice_time_s": adv["running_time_s"],
                       "advice_punctual": adv["punctual"], "advice_feasible": adv["feasible"],
                       "advice_solve_s": adv["solve_time_s"],
                       "proposed_kwh": pro["traction_energy_kwh"], "proposed_time_s": pro["running_time_s"],
                       "proposed_punctual": pro["punctual"], "proposed_solve_s": round(time.perf_counter() - t_p, 2)}
                row["advice_vs_good_percent"] = round(100 * (row["advice_kwh"] / row["good_drivers_mean_kwh"] - 1), 1)
                row["optimum_kwh"] = optimum_kwh(r, train, options, float(t))
                rows.append(row)
                print(f"  {Path(route).stem} {mass} t {t} s: drivers {row['drivers_mean_kwh']:.1f}, good "
                      f"{row['good_drivers_mean_kwh']:.1f}, best {row['best_driver_kwh']:.1f}, advice {row['advice_kwh']:.1f} "
                      f"({row['advice_time_s']:.1f} s), proposed {row['proposed_kwh']:.1f} ({row['proposed_time_s']:.1f} s)",
                      flush=True)
    print()
    print("| line (learned?) | mass [t] | T0 [s] | drivers' mean [kWh] | good drivers' mean | best driver | advice [kWh] / time [s] | advice vs good | proposed (ISSA) [kWh] / time [s] | optimum E* at T0 [kWh] |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for x in rows:
        ok = "" if x["advice_punctual"] and x["advice_feasible"] else " **not punctual**"
        print(f"| {x['route']} ({'yes' if x['route_learned'] else 'no'}) | {x['mass_t']} | {x['time_s']} +- {x['tolerance_s']:g} | "
              f"{x['drivers_mean_kwh']:.1f} | {x['good_drivers_mean_kwh']:.1f} | {x['best_driver_kwh']:.1f} | "
              f"{x['advice_kwh']:.1f} / {x['advice_time_s']:.1f}{ok} | {x['advice_vs_good_percent']:+.1f} % | "
              f"{x['proposed_kwh']:.1f} / {x['proposed_time_s']:.1f} | "
              f"{'-' if x['optimum_kwh'] is None else format(x['optimum_kwh'], '.1f')} |")
    wins = sum(x["advice_kwh"] < x["good_drivers_mean_kwh"] and x["advice_punctual"] for x in rows)
    print(f"\nadvice punctual and below the good drivers' mean in {wins} of {len(rows)} held-out cases; "
          f"drivers {args.drivers} x {args.runs} runs per mass and time, seed {args.seed}; work folder {work}")
    if args.out:
        args.out.write_text(to_json({"settings": vars(args) | {"workdir": str(work), "out": str(args.out)},
                                     "report": rep, "rows": rows}) + "\n")


if __name__ == "__main__":
    main()
