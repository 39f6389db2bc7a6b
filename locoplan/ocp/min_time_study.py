"""The two-stage Gauss paper's Tables 2-3 on this machine: CVP 20 / 40, GPM 34 / 48 and two-stage 17 / 24 (stage 2
"hp" and the paper's "global") on the level and the 30 per-mille route, with the solve-time ratios
measured in the same run.

Library code: :func:`run_study` takes the loaded train and routes (the command line and
``benchmarks/ocp_study.py`` load the files, :data:`~locoplan.ocp.registry.STUDY_ROUTES` names the
defaults) and returns a :class:`Study`; :mod:`locoplan.reporting.ocp_study` renders and writes it.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field
from typing import Callable

from ..errors import InputError, Problem
from .min_time import exact_minimum_time, train_problem
from .min_time_run import SOURCE, solve_ocp
from .registry import OCP_METHODS
from .solve import solve_min_time

__all__ = ["PAPER_CLAIMS", "PAPER_TABLES", "STUDY_RUNS", "Study", "run_study"]


# --------------------------------------------------------------------------------------------------
# the two-stage Gauss paper's Tables 2-3
# --------------------------------------------------------------------------------------------------

STUDY_RUNS: tuple[tuple[str, int, str | None], ...] = (
    ("cvp", 20, None), ("cvp", 40, None),
    ("gpm", 34, None), ("gpm", 48, None),
    ("two-stage", 17, "hp"), ("two-stage", 24, "hp"),
    ("two-stage", 17, "global"), ("two-stage", 24, "global"),
)
"""(method, control nodes, stage 2) of every row, per experiment, in the paper's order."""

PAPER_TABLES: dict[int, dict[tuple[str, int], tuple[float, float, tuple[int, int] | None]]] = {
    # table -> (method, nodes) -> (objective [s], solve time [s], stage-2 (control, state) nodes)
    2: {("cvp", 20): (142.25, 50.41, None), ("cvp", 40): (141.81, 210.63, None),
        ("gpm", 34): (141.81, 8.12, None), ("gpm", 48): (141.62, 19.19, None),
        ("two-stage", 17): (141.74, 5.77, (15, 34)), ("two-stage", 24): (141.59, 12.09, (17, 48))},
    3: {("cvp", 20): (142.26, 63.01, None), ("cvp", 40): (141.83, 238.79, None),
        ("gpm", 34): (141.97, 8.10, None), ("gpm", 48): (141.76, 21.47, None),
        ("two-stage", 17): (141.75, 5.66, (15, 34)), ("two-stage", 24): (141.67, 12.60, (15, 48))},
}
"""The two-stage Gauss paper's Tables 2 (level, test 1) and 3 (30 per mille, test 2) as printed."""

PAPER_CLAIMS = {"cvp": 91.93, "gpm": 33.88}
"""The paper's abstract / conclusion: two-stage solve time lower than CVP / GPM by this many per cent."""

@dataclass(frozen=True)
class Study:
    """Result of :func:`run_study`: ``rows`` (one SPEC object per run, with ``table``, ``test``,
    ``label``, the paper's values and the median ``solve_time_s``), ``ratios`` (solve-time reductions
    of two-stage vs CVP / GPM, measured and as in the paper), ``exact`` (table -> exact minimum [s]),
    ``runs`` ((table, method, nodes, stage2) -> :class:`OcpRun`, for plots), ``repeats``."""

    rows: list[dict]
    ratios: list[dict]
    exact: dict[int, float]
    repeats: int
    runs: dict = field(repr=False, default_factory=dict)

    def to_dict(self) -> dict:
        return {"results": self.rows, "solve_time_ratios": self.ratios,
                "exact_minimum_s": {f"table {k}": round(v, 4) for k, v in self.exact.items()},
                "repeats": self.repeats}


def _label(method: str, stage2: str | None) -> str:
    spec = OCP_METHODS[method]
    return f"{spec.label} {stage2}" if spec.has_stage2 else spec.label


def _reduction(ts: float, other: float) -> float:
    return 100.0 * (1.0 - ts / other)


def run_study(train, routes: dict, *, runs=STUDY_RUNS, repeats: int = 1, warmup: bool = True,
              progress: Callable[[str], None] | None = None) -> Study:
    """Reproduce the two-stage Gauss paper's Tables 2-3 on this machine.

    ``train``: the loaded consist (the paper's HXD1 + C64); ``routes``: table number -> loaded
    :class:`~locoplan.model.route.Route`, or ``(route, name)`` where ``name`` (its file) labels error
    messages (the defaults: :data:`~locoplan.ocp.registry.STUDY_ROUTES`). Each of ``runs``
    ((method, control nodes, stage 2)) is solved ``repeats`` times and its ``solve_time_s`` is the
    median; the objective and re-simulation are those of the first solve (the solves are
    deterministic). ``warmup`` solves once untimed first, so loading IPOPT is not charged to the first
    row. ``progress(text)`` is called before each run (e.g. to drive a progress bar).

    Ratios: for each table and test (CVP 20 / GPM 34 / two-stage 17 is test 1, CVP 40 / GPM 48 /
    two-stage 24 test 2) the reduction ``1 - t_two-stage / t_other`` in per cent, and their mean over
    the four pairs; the same from the paper's printed times, and the paper's claimed 91.93 % / 33.88 %.
    """
    if not isinstance(repeats, int) or repeats < 1:
        raise InputError(Problem(SOURCE, "--repeats", f"must be a whole number >= 1, got {repeats!r}"))
    loaded = {k: (v if isinstance(v, tuple) else (v, None)) for k, v in routes.items()}
    problems = {k: train_problem(r, train, p) for k, (r, p) in loaded.items()}
    if warmup:
        solve_min_time(next(iter(problems.values())), "two-stage", 4)
    rows, store, exact = [], {}, {}
    for table, (route, path) in loaded.items():
        problem = problems[table]
        exact[table] = exact_minimum_time(problem)
        seen: dict[tuple, int] = {}
        for method, nodes, stage2 in runs:
            key = (method, stage2)
            seen[key] = seen.get(key, 0) + 1
            test = seen[key]
            if progress:
                progress(f"table {table}: {_label(method, stage2)} {nodes}")
            first = solve_ocp(route, train, method, nodes, stage2=stage2 or "hp", route_file=path, problem=problem)
            times = [first.solution.solve_time_s]
            for _ in range(repeats - 1):  # timing only: the solves are deterministic, re-simulate once
                kwargs = {"stage2": stage2} if stage2 else {}
                times.append(solve_min_time(problem, method, nodes, **kwargs).solve_time_s)
            row = dict(first.summary)
            row.pop("sequence", None)
            seed = PAPER_TABLES.get(table, {}).get((method, nodes))
            row.update({
                "table": table, "test": test, "label": _label(method, stage2),
                "solve_time_s": round(statistics.median(times), 4),
                "solve_times_s": [round(t, 4) for t in times],
                "seed_objective_s": seed[0] if seed else None,
                "seed_solve_time_s": seed[1] if seed else None,
                "seed_stage2_nodes": list(seed[2]) if seed and seed[2] else None,
            })
            rows.append(row)
            store[table, method, nodes, stage2] = first
    return Study(rows, _ratios(rows), exact, repeats, store)


def _ratios(rows: list[dict]) -> list[dict]:
    by = {(r["table"], r["algorithm"], r["control_nodes"], r["stage2"]): r for r in rows}
    out = []
    for stage2 in ("hp", "global"):
        for other, pairs in (("cvp", ((17, 20), (24, 40))), ("gpm", ((17, 34), (24, 48)))):
            per_test = []
            for table in sorted({r["table"] for r in rows}):
                for test, (n_ts, n_other) in enumerate(pairs, start=1):
                    a = by.get((table, "two-stage", n_ts, stage2))
                    b = by.get((table, other, n_other, None))
                    if a is None or b is None:
                        continue
                    seed_t = PAPER_TABLES.get(table, {})
                    seed_pct = None
                    if ("two-stage", n_ts) in seed_t and (other, n_other) in seed_t:
                        seed_pct = round(_reduction(seed_t["two-stage", n_ts][1], seed_t[other, n_other][1]), 2)
                    per_test.append({"table": table, "test": test, "two_stage_nodes": n_ts, "other_nodes": n_other,
                                     "two_stage_s": a["solve_time_s"], "other_s": b["solve_time_s"],
                                     "percent": round(_reduction(a["solve_time_s"], b["solve_time_s"]), 2),
                                     "seed_percent": seed_pct})
            if not per_test:
                continue
            seeds = [p["seed_percent"] for p in per_test if p["seed_percent"] is not None]
            out.append({
                "two_stage": stage2, "versus": other,
                "per_test": per_test,
                "mean_percent": round(statistics.fmean(p["percent"] for p in per_test), 2),
                "seed_tables_mean_percent": round(statistics.fmean(seeds), 2) if seeds else None,
                "seed_claim_percent": PAPER_CLAIMS[other],
            })
    return out
