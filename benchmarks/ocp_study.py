"""The two-stage Gauss paper's Tables 2-3 on this machine: every method several times, median solve time, as markdown.

    python benchmarks/ocp_study.py [--repeats 7] [--out docs/ocp-study.md]

CVP 20 / 40, GPM 34 / 48, two-stage 17 / 24 (stage 2 "hp" and the paper's "global") on
routes/seed000-flat.yaml (Table 2) and routes/seed000-grade30.yaml (Table 3) with
configs/consists/HXD1-C64-seed000.yaml. Each row is solved ``--repeats`` times after one untimed
warm-up solve; the solve time is the median wall time of ``solve_min_time`` (building the CasADi NLPs
and running IPOPT, every stage). Objectives and the re-simulation check come from the first solve.
Prints the machine, the table, the exact minima, the solve-time ratios next to the paper's, and why the
unconfirmed rows are unconfirmed (the same markdown as ``locoplan ocp-study --out FILE.md``).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
from pathlib import Path

import casadi

import sys as _sys
from pathlib import Path as _Path
_sys.path.insert(0, str(_Path(__file__).resolve().parents[1]))  # this checkout's locoplan, installed or not

from locoplan.io.load import load_route, load_train
from locoplan.ocp.registry import DEFAULT_OCP_CONSIST, study_route_files
from locoplan.ocp.min_time_study import run_study
from locoplan.reporting.ocp_study import study_markdown

ROOT = Path(__file__).resolve().parents[1]


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7, help="solves per row; the median is reported")
    ap.add_argument("--out", type=Path, default=None, help="also write the markdown to this file")
    args = ap.parse_args()
    os.chdir(ROOT)
    routes = {k: (load_route(p), p) for k, p in study_route_files().items()}
    study = run_study(load_train(DEFAULT_OCP_CONSIST), routes, repeats=args.repeats)
    head = (f"Measured {datetime.date.today().isoformat()} on {_cpu()} ({os.cpu_count()} CPUs), Python "
            f"{platform.python_version()}, CasADi {casadi.__version__} / IPOPT, median of {args.repeats} solves "
            f"(`python benchmarks/ocp_study.py --repeats {args.repeats}`).\n\n")
    text = head + study_markdown(study)
    print(text, end="")
    if args.out:
        args.out.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
