"""Rendering and writing of the optimal-control results of the two-stage Gauss paper: the study's table cells and
markdown, and the files of ``ocp --out`` and ``ocp-study --out``.

The library (:mod:`locoplan.ocp.min_time_run`, :mod:`locoplan.ocp.min_time_study`) computes and returns
objects; this module turns them into text and files (written whole or not at all).
"""

from __future__ import annotations

from pathlib import Path

from .files import atomic_write_text, check_output_path
from .writers import rows_csv, to_json, with_provenance
from ..ocp.min_time_run import PROFILE_COLUMNS, OcpRun
from ..ocp.min_time_study import Study

__all__ = ["STUDY_COLUMNS", "check_output_path", "study_cells", "study_markdown", "write_ocp_output",
           "write_study_output"]


def write_ocp_output(path: str | Path, run: OcpRun) -> None:
    """``--out``: ``.csv`` the re-simulated profile (:data:`PROFILE_COLUMNS`), ``.json`` the summary
    plus the profile's columns. Written whole or not at all."""
    check_output_path(path, "--out", (".csv", ".json"))
    rows = run.profile_rows()
    if Path(path).suffix.lower() == ".csv":
        atomic_write_text(path, rows_csv(rows, PROFILE_COLUMNS))
    else:
        data = dict(run.summary)
        data["profile"] = {c: [r[c] for r in rows] for c in PROFILE_COLUMNS}
        atomic_write_text(path, to_json(with_provenance(data)) + "\n")


STUDY_COLUMNS = ("table", "method", "test", "u / x nodes", "stage 2 u / x", "objective", "re-simulated",
                 "- exact", "solve time", "confirmed", "paper's objective", "paper's solve time")
"""Column heads of :func:`study_cells` (times in s)."""


def study_cells(row: dict) -> list[str]:
    """One study row as the strings of :data:`STUDY_COLUMNS` (shared by the CLI table and markdown)."""
    def f(x, nd):
        return "-" if x is None else f"{x:.{nd}f}"

    nodes = f"{row['control_nodes']}" + (f" / {row['state_nodes']}" if row["state_nodes"] else "")
    st2 = "-"
    if row["algorithm"] == "two-stage":
        st2 = f"{row['final_control_nodes']} / {row['final_state_nodes']}, {row['segments']} seg."
    seed_n = row.get("seed_stage2_nodes")
    if seed_n:
        st2 += f" (paper {seed_n[0]} / {seed_n[1]})"
    return [
        str(row["table"]), row["label"], str(row["test"]), nodes, st2,
        f(row["objective"], 3), f(row["resimulated_running_time_s"], 3),
        "-" if row["gap_to_exact_s"] is None else f"{row['gap_to_exact_s']:+.3f}",
        f(row["solve_time_s"], 3),
        "yes" if row["feasible"] else "no",
        f(row.get("seed_objective_s"), 2), f(row.get("seed_solve_time_s"), 2),
    ]


def study_markdown(study: Study) -> str:
    """The study as markdown: the table, the exact minima, the ratios, and why rows are unconfirmed."""
    heads = ["Table", "method", "test", "u / x nodes", "stage-2 u / x nodes", "objective [s]",
             "re-simulated [s]", "objective - exact [s]", "solve time [s]", "confirmed",
             "paper's objective [s]", "paper's solve time [s]"]
    lines = ["| " + " | ".join(heads) + " |", "|" + "|".join(["---"] * len(heads)) + "|"]
    for row in study.rows:
        lines.append("| " + " | ".join(study_cells(row)) + " |")
    lines.append("")
    lines.append("Exact minimum (accelerate / cruise / brake, `scipy.integrate.quad`): "
                 + ", ".join(f"Table {k}: {v:.4f} s" for k, v in study.exact.items()) + ".")
    lines.append("")
    lines.append("| two-stage | faster than | per pair (Table-test: measured % / the paper's %) | mean measured | "
                 "mean of the paper's tables | the paper's claim |")
    lines.append("|---|---|---|---|---|---|")
    for r in study.ratios:
        pairs = ", ".join(f"{p['table']}-{p['test']}: {p['percent']:.1f} / {p['seed_percent']:.1f}"
                          if p["seed_percent"] is not None else f"{p['table']}-{p['test']}: {p['percent']:.1f}"
                          for p in r["per_test"])
        lines.append(f"| {r['two_stage']} | {r['versus'].upper()} | {pairs} | {r['mean_percent']:.1f} % | "
                     f"{r['seed_tables_mean_percent']:.2f} % | {r['seed_claim_percent']:.2f} % |")
    rejected = [r for r in study.rows if not r["feasible"]]
    if rejected:
        lines.append("")
        lines.append("Unconfirmed rows (re-simulation of the clipped control):")
        lines.append("")
        for r in rejected:
            lines.append(f"- Table {r['table']}, {r['label']} {r['control_nodes']}: {r['reason']}")
    return "\n".join(lines) + "\n"


def write_study_output(path: str | Path, study: Study) -> None:
    """``ocp-study --out``: ``.json`` the whole study, ``.csv`` one line per row, ``.md`` the markdown."""
    check_output_path(path, "--out", (".json", ".csv", ".md"))
    suffix = Path(path).suffix.lower()
    if suffix == ".json":
        atomic_write_text(path, to_json(with_provenance(study.to_dict())) + "\n")
    elif suffix == ".md":
        atomic_write_text(path, study_markdown(study))
    else:
        cols = ["table", "test", "label", "algorithm", "stage2", "control_nodes", "state_nodes",
                "final_control_nodes", "final_state_nodes", "segments", "objective", "resimulated_running_time_s",
                "exact_minimum_s", "gap_to_exact_s", "solve_time_s", "feasible", "max_limit_violation_kmh",
                "seed_objective_s", "seed_solve_time_s", "reason"]
        atomic_write_text(path, rows_csv(study.rows, cols))
