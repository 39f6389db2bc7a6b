"""The MPOC paper's Tables 3-5, our analogues: MPOC-N, MPOC-C, MPOC and SFS on a freight line with neutral
sections and on the two legs of the high-speed reconstruction (CRH380A).

    python benchmarks/mpoc_tables.py

Every energy is the traction calculator's re-simulation of the strategy's plan (MPOC-N's on the route
without its neutral sections: a lower bound the train cannot drive); the NLP optima of MPOC-N and
MPOC are shown beside them. Table 3: what honouring the neutral sections in the model saves against
coasting through them afterwards (MPOC-C). Table 4: MPOC against the standard four-stage method with
neutral-section coasting (SFS, coasting point by brute force at 1 m). Table 5: solve times (wall).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout first

from locoplan.io.load import load_route, load_train  # noqa: E402
from locoplan.ocp.mpoc import run_mpoc  # noqa: E402
from locoplan.ocp.train_energy import EnergyOptions  # noqa: E402
from locoplan.runner import make_context, run_strategy  # noqa: E402
from locoplan.settings import RunSettings  # noqa: E402
from locoplan.sim.calculator import ModelOptions  # noqa: E402

CASES = [("routes/freight-20km-ns.yaml", "HXD1-C80x50"),
         ("routes/hsr-leg1-ns.yaml", "CRH380A"),
         ("routes/hsr-leg2-ns.yaml", "CRH380A")]
NAMES = ("mpoc-n", "mpoc-c", "mpoc", "sfs")


def main() -> None:
    import casadi  # noqa: F401  (loaded once, as a running process has it)

    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    rows = []
    for path, consist in CASES:
        route = load_route(ROOT / path)
        train = load_train(ROOT / f"configs/consists/{consist}.yaml")
        ctx = make_context(route, train, RunSettings(ModelOptions(), yardstick=False))
        res = {n: run_strategy(ctx, n).summary for n in NAMES}
        nlp = {n: run_mpoc(route, train, ModelOptions(), ctx.t0_s, energy=EnergyOptions(ignore_neutral=(n == "mpoc-n")),
                           calc=None).summary["objective"] for n in ("mpoc-n", "mpoc")}
        rows.append((route, train, ctx.t0_s, res, nlp))

    print("\nTable 3: neutral sections in the model (MPOC) or coasted through afterwards (MPOC-C); energies in kWh")
    print(f"{'line':<46} {'T [s]':>6} {'MPOC-N':>8} {'(NLP)':>8} {'MPOC-C':>8} {'MPOC':>8} {'(NLP)':>8} {'saving':>7} {'order':>6}")
    for route, _train, T, r, nlp in rows:
        e = {n: r[n]["traction_energy_kwh"] for n in NAMES}
        order = nlp["mpoc-n"] <= nlp["mpoc"] * (1 + 1e-5) and e["mpoc"] <= e["mpoc-c"]
        print(f"{route.name[:46]:<46} {T:6.0f} {e['mpoc-n']:8.2f} {nlp['mpoc-n']:8.2f} {e['mpoc-c']:8.2f} {e['mpoc']:8.2f} "
              f"{nlp['mpoc']:8.2f} {100 * (1 - e['mpoc'] / e['mpoc-c']):6.2f}% {'ok' if order else 'NO':>6}")
    print("\nTable 4: MPOC against the standard four-stage method with neutral-section coasting (SFS)")
    print(f"{'line':<46} {'SFS [kWh]':>10} {'SFS time':>9} {'MPOC [kWh]':>11} {'MPOC time':>10} {'saving':>7} {'order':>6}")
    for route, _train, _T, r, _nlp in rows:
        s, m = r["sfs"], r["mpoc"]
        print(f"{route.name[:46]:<46} {s['traction_energy_kwh']:10.2f} {s['running_time_s']:9.1f} {m['traction_energy_kwh']:11.2f} "
              f"{m['running_time_s']:10.1f} {100 * (1 - m['traction_energy_kwh'] / s['traction_energy_kwh']):6.2f}% "
              f"{'ok' if m['traction_energy_kwh'] <= s['traction_energy_kwh'] else 'NO':>6}")
    print("\nTable 5: solve time [s] (wall clock: MPOC = build, NLP solves, refinement, plan and its check; SFS = "
          "brute force at 1 m)")
    print(f"{'line':<46} {'train':<24} {'MPOC-N':>7} {'MPOC-C':>7} {'MPOC':>7} {'SFS':>7}")
    for route, train, _T, r, _nlp in rows:
        print(f"{route.name[:46]:<46} {train.name[:24]:<24} " + " ".join(f"{r[n]['solve_time_s']:7.2f}" for n in NAMES))


if __name__ == "__main__":
    main()
