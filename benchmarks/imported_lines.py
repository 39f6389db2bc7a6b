"""Imported lines: the railtoolkit freight train against its peer tool's running times, and the fastest
run of both freight trains on every shipped real line.

    python benchmarks/imported_lines.py

Table 1: locoplan's fastest run (time-saving) of the imported TrainRuns.jl freight train (catalogue
Fr100: DB V90 + 10 loaded Facs 124, 920 t) over the four shipped railtoolkit paths, against the
running times TrainRuns.jl's own test suite expects (test/highlevel_test.jl, default settings: mass
point, 20 m distance steps). Table 2: time-saving on every routes/real file with HXD1 + 30 x C80
(3200 t) and HXD1 + 50 x C80 (5200 t), in the default model and in the papers' model (point mass,
electric brake only).
"""

from __future__ import annotations

from pathlib import Path

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.io.load import load_route, load_train
from locoplan.runner import make_context, run_strategy
from locoplan.settings import RunSettings
from locoplan.sim.calculator import ModelOptions

ROOT = Path(__file__).resolve().parents[1]
TRAINRUNS_S = {"const": 746.6594691660882, "slope": 842.3797947097586, "speed": 751.9727357301351,
               "realworld": 8789.299477891092}
XI_TRAINRUNS = (1.09 * 80 + 10 * 1.03 * 25) / (80 + 10 * 25)
"""TrainRuns.jl's train rotating-mass factor: weighted by the *empty* masses, then applied to the loaded train."""


def fastest(route, train, options: ModelOptions) -> str:
    run = run_strategy(make_context(route, train, RunSettings(options, need_time=False)), "time-saving",
                       with_fitness=False)
    return f"{run.summary['running_time_s']:.1f}" if run.result.feasible[0] else f"infeasible: {run.result.reason(0)}"


def main() -> None:
    train = load_train("Fr100")
    models = [("point mass, 20 m", ModelOptions(step_m=20, point_mass=True, air_brake=True)),
              (f"+ TrainRuns xi {XI_TRAINRUNS:.4f}", ModelOptions(step_m=20, point_mass=True, air_brake=True,
                                                                  rotating_mass=XI_TRAINRUNS - 1)),
              ("default (train length, 50 m)", ModelOptions())]
    print(f"Table 1: {train.name} ({train.mass_t:g} t), fastest run [s] vs TrainRuns.jl")
    print(f"{'path':<10} {'TrainRuns.jl':>12} " + " ".join(f"{name:>30}" for name, _ in models))
    for path, peer in TRAINRUNS_S.items():
        route = load_route(ROOT / "routes/railtoolkit" / f"{path}.yaml")
        cells = []
        for _, opts in models:
            t = float(fastest(route, train, opts))
            cells.append(f"{t:.1f} ({100 * (t - peer) / peer:+.2f} %)")
        print(f"{path:<10} {peer:>12.1f} " + " ".join(f"{c:>30}" for c in cells))

    print("\nTable 2: fastest run [s] on routes/real (limits capped at 80 km/h)")
    trains = [load_train(c) for c in ("HXD1-C80x30", "HXD1-C80x50")]
    print(f"{'route':<38} {'km':>6} {'3200 t':>8} {'5200 t':>8}   seeds' model (point mass, electric brake only)")
    for path in sorted((ROOT / "routes/real").glob("*.yaml")):
        route = load_route(path)
        default = [fastest(route, t, ModelOptions()) for t in trains]
        seeds = [fastest(route, t, ModelOptions.papers()) for t in trains]
        seeds_text = ", ".join(f"{t.mass_t:g} t {s}" for t, s in zip(trains, seeds) if s.startswith("infeasible"))
        print(f"{path.stem:<38} {route.length_m / 1000:>6.2f} {default[0]:>8} {default[1]:>8}   {seeds_text or 'both feasible'}")


if __name__ == "__main__":
    main()
