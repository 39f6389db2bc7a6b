"""Batch runs (issue 11): results independent of executor and split, a store that survives a kill,
study-file errors, export and summary from the store, the energy-time front.

One small batch (a 2.6 km real line, 6 runs) serves every test: it is run one by one in this process
(the reference), on a pool of 2 processes killed at a random moment and restarted, and on a Dask
LocalCluster; every record must equal the reference, timing fields aside.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from locoplan.cli import app
from locoplan.runs import RunSpec, Store, run_many
from locoplan.runs.study import load_study

ROOT = Path(__file__).resolve().parents[1]
ROUTE = ROOT / "routes/real/CN_Songjiazhuang_Yizhuang-leg1.yaml"
cli = CliRunner()

STUDY = f"""schema: locoplan/study@1
routes: [{ROUTE}]
consists: [HXD1-C80x30]
times: [1.2x]
algorithms: [issa, pso]
seeds: [1, 2, 3]
"""


@pytest.fixture(scope="module")
def study_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("study") / "small.yaml"
    path.write_text(STUDY)
    return path


@pytest.fixture(scope="module")
def reference(study_file):
    """The study's runs one by one, as `locoplan optimize` does them (make_context + run_strategy)."""
    from locoplan.io.load import load_route, load_train
    from locoplan.runner import make_context, run_strategy
    from locoplan.settings import RunSettings

    specs = load_study(study_file).specs
    route, train = load_route(ROUTE), load_train("HXD1-C80x30")
    out = []
    for s in specs:
        ctx = make_context(route, train, RunSettings(time_s=s.time_s, algorithm=s.algorithm, seed=s.seed,
                                                     yardstick=False))
        summary = run_strategy(ctx, "proposed").summary
        summary.pop("solve_time_s")
        out.append(summary)
    return specs, out


def _comparable(records):
    return [r.comparable() for r in records]


def _store_keys(path: Path) -> set[str]:
    if not path.exists():
        return set()
    with sqlite3.connect(path, timeout=30) as conn:
        try:
            return {k for (k,) in conn.execute("SELECT key FROM runs")}
        except sqlite3.OperationalError:  # the batch has not made its tables yet
            return set()


def test_study_expands_to_the_product_with_factor_times(study_file):
    from locoplan.io.load import load_route, load_train
    from locoplan.sim.calculator import TractionCalculator

    specs = load_study(study_file).specs
    fastest = TractionCalculator(load_route(ROUTE), load_train("HXD1-C80x30")).fastest_time_s
    assert [(s.algorithm, s.seed) for s in specs] == [(a, k) for a in ("issa", "pso") for k in (1, 2, 3)]
    # 1.2 x the fastest run, rounded up to 0.1 s (never below 1.2 x)
    assert all(s.time_s == pytest.approx(np.ceil(12 * fastest) / 10) for s in specs)
    assert all(1.2 * fastest <= s.time_s < 1.2 * fastest + 0.1 for s in specs)


@pytest.mark.slow
def test_killed_batch_resumes_without_a_run_twice_or_lost_and_equals_one_by_one(study_file, reference, tmp_path):
    """Kill the batch (SIGKILL to its process group: parent and workers) a random moment after its
    first commit, restart it: the restart runs exactly the runs the store lacked, and every stored
    record equals the same run done alone."""
    specs, ref = reference
    store = tmp_path / "runs.sqlite"
    cmd = [sys.executable, "-m", "locoplan", "batch", str(study_file), "--store", str(store), "--workers", "2", "--quiet"]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    rng = np.random.default_rng()
    deadline = time.monotonic() + 120
    try:
        while not _store_keys(store) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(float(rng.uniform(0.0, 0.8)))
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read().decode()
    proc.stderr.close()
    before = _store_keys(store)
    assert 1 <= len(before) < len(specs), "kill the batch while it still has runs to do"
    with sqlite3.connect(store) as conn:  # whole rows only: every committed record parses
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        for (text,) in conn.execute("SELECT record FROM runs"):
            assert json.loads(text)["summary"]["feasible"] is True

    res = subprocess.run(cmd[:-1] + ["--json"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    report = json.loads(res.stdout)
    ran = set(report["ran_keys"])
    assert report["from_store"] == len(before) and len(ran) == len(report["ran_keys"])
    assert not ran & before, "a run stored before the kill was run again"
    assert ran | before == _store_keys(store) and len(_store_keys(store)) == len(specs), "a run was lost"

    with Store(store) as s:
        records = run_many(specs, store=s).records  # everything comes from the store now
    assert _comparable(records) == ref


@pytest.mark.slow
def test_dask_local_cluster_gives_identical_records(reference):
    distributed = pytest.importorskip("distributed")
    from locoplan.runs import DaskExecutor

    specs, ref = reference
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        executor = DaskExecutor(cluster.scheduler_address)
        try:
            records = run_many(specs, executor).records
        finally:
            executor.close()
    assert _comparable(records) == ref
    assert len({r.worker for r in records}) == 2  # the runs really were split between the two workers


@pytest.mark.parametrize("text,where", [
    ("routes: [{route}]\nstrategies: [proposed, fastest]\ntimes: [1.1x]\n", "small.yaml:2: strategies[1]: unknown strategy 'fastest'"),
    ("routes: [nowhere/*.yaml]\ntimes: [1.1x]\n", "small.yaml:1: routes[0]: 'nowhere/*.yaml' matches no route file"),
    ("routes: [{route}]\ntimes:\n  - 1.1x\n  - 0.95x\n", "small.yaml:4: times[1]: a factor of the fastest run must be >= 1"),
    ("routes: [{route}]\ntimes: [1.1x]\nseed: [1]\n", "small.yaml:3: seed: unknown key; did you mean 'seeds'?"),
    ("routes: [{route}]\ntimes: [1.1x]\nalgorithms: [ga]\n", "small.yaml:3: algorithms[0]: unknown optimiser 'ga'"),
    ("routes: [{route}]\n", "small.yaml:1: times: route"),  # a real line has no schedule: times are needed
    ("routes: [{route}]\ntimes: [1.1x]\nobjective: power\n", "small.yaml:3: objective: unknown objective 'power'"),
])
def test_bad_study_files_exit_2_naming_line_and_field(tmp_path, text, where):
    path = tmp_path / "small.yaml"
    path.write_text(text.format(route=ROUTE))
    res = cli.invoke(app, ["batch", str(path), "--store", str(tmp_path / "s.sqlite"), "--workers", "1"])
    assert res.exit_code == 2, res.output
    assert where in res.stderr, res.stderr
    assert not (tmp_path / "s.sqlite").exists() or not Store(tmp_path / "s.sqlite").keys()


def test_store_of_another_format_or_not_a_store_is_refused(tmp_path):
    path = tmp_path / "old.sqlite"
    Store(path).close()
    with sqlite3.connect(path) as conn:
        conn.execute("UPDATE meta SET value = '0' WHERE name = 'format'")
    res = cli.invoke(app, ["results", str(path)])
    assert res.exit_code == 2 and "old.sqlite: format: store format '0'" in res.stderr, res.stderr
    junk = tmp_path / "junk.sqlite"
    junk.write_text("not a database at all, just text" * 10)
    res = cli.invoke(app, ["results", str(junk)])
    assert res.exit_code == 2 and "not a locoplan result store" in res.stderr, res.stderr
    res = cli.invoke(app, ["results", str(tmp_path / "none.sqlite")])
    assert res.exit_code == 2 and "no such store" in res.stderr


@pytest.fixture(scope="module")
def filled_store(reference, tmp_path_factory):
    """A store holding the reference runs (run in this process) plus one time-saving run."""
    specs, _ = reference
    path = tmp_path_factory.mktemp("store") / "runs.sqlite"
    extra = RunSpec(str(ROUTE), "HXD1-C80x30", strategy="time-saving", fitness=False)
    with Store(path) as s:
        run_many(specs + [extra], store=s)
    return path


@pytest.mark.slow
def test_results_export_csv_json_parquet_and_where(filled_store, tmp_path):
    import csv
    import io

    res = cli.invoke(app, ["results", str(filled_store), "--format", "csv"])
    assert res.exit_code == 0, res.stderr
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    assert len(rows) == 7
    for field in ("planned_time_s", "algorithm", "seed", "running_time_s", "traction_energy_kwh", "fitness", "key"):
        assert field in rows[0]
    res = cli.invoke(app, ["results", str(filled_store), "--format", "json", "--where", "algorithm=pso",
                           "--where", "seed>=2"])
    got = json.loads(res.stdout)["results"]
    assert sorted(r["seed"] for r in got) == [2, 3] and {r["algorithm"] for r in got} == {"pso"}
    res = cli.invoke(app, ["results", str(filled_store), "--where", "energy<3"])
    assert res.exit_code == 2 and "--where: unknown field 'energy'" in res.stderr
    pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    out = tmp_path / "runs.parquet"
    res = cli.invoke(app, ["results", str(filled_store), "--format", "parquet", "--out", str(out)])
    assert res.exit_code == 0, res.stderr
    table = pq.read_table(out)
    assert table.num_rows == 7 and "traction_energy_kwh" in table.column_names


@pytest.mark.slow
def test_results_summary_is_the_stores_statistics_and_plots(filled_store, reference, tmp_path):
    _, ref = reference
    png, box = tmp_path / "et.png", tmp_path / "box.png"
    res = cli.invoke(app, ["results", str(filled_store), "--json", "--plot", str(png), "--boxplot", str(box)])
    assert res.exit_code == 0, res.stderr
    summary = json.loads(res.stdout)["summary"]
    for alg in ("issa", "pso"):
        row = next(r for r in summary if r["algorithm"] == alg)
        e = [x["traction_energy_kwh"] for x in ref if x["algorithm"] == alg]
        assert row["runs"] == 3 and row["energy_best_kwh"] == pytest.approx(min(e))
        assert row["energy_mean_kwh"] == pytest.approx(np.mean(e), abs=1e-3)
        assert row["energy_sd_kwh"] == pytest.approx(np.std(e, ddof=1), abs=1e-3)
        assert row["gap_mean_percent"] is None  # no optimum provider registered: no gap is invented
    assert png.stat().st_size > 10_000 and box.stat().st_size > 5_000
    # a bad plot name fails before anything is written (all outputs or none)
    res = cli.invoke(app, ["results", str(filled_store), "--format", "csv", "--out", str(tmp_path / "x.csv"),
                           "--plot", str(tmp_path / "p.jpg")])
    assert res.exit_code == 2 and not (tmp_path / "x.csv").exists()


@pytest.mark.slow
def test_pareto_front_is_nondominated_and_slower_plans_use_less_energy(tmp_path):
    from locoplan.runs.pareto import pareto
    from locoplan.runs.optimum import optimum_providers

    base = RunSpec(str(ROUTE), "HXD1-C80x30")
    front = pareto(base, factors=[1.15, 1.4], strategies=("four-stage", "proposed"), optimum=False)
    grid = front["grid"]
    assert [g["factor"] for g in grid] == [1.15, 1.4]
    assert all(g["best_energy_kwh"] is not None for g in grid)
    assert grid[1]["best_energy_kwh"] < grid[0]["best_energy_kwh"]  # more time, less energy
    f = front["front"]
    assert all(a["running_time_s"] < b["running_time_s"] and a["traction_energy_kwh"] > b["traction_energy_kwh"]
               for a, b in zip(f, f[1:]))
    for q in f:  # no plan found is as fast as a front point with less energy
        assert not any(p["running_time_s"] <= q["running_time_s"] and p["traction_energy_kwh"] < q["traction_energy_kwh"]
                       for p in front["points"])
    assert f[0]["strategy"] == "time-saving" and f[0]["running_time_s"] == pytest.approx(front["fastest_time_s"], abs=0.1)
    assert "no optimum E*" in front["front_kind"] and all(g["optimum_kwh"] is None for g in grid)
    assert optimum_providers(), "seed 001's bound is registered as the optimum"


def test_pareto_with_the_optimum_never_beats_it():
    """E*(T0) (seed 001's bound) is a lower bound: the best on-time plan uses at least E* minus the
    bound's own tolerance (a plan may run a little later than T0 and so need a little less)."""
    from locoplan.runs.pareto import pareto

    front = pareto(RunSpec(str(ROUTE), "HXD1-C80x30"), factors=[1.3], strategies=("four-stage",))
    g = front["grid"][0]
    assert g["optimum_kwh"] is not None and "minimum-energy optimal control" in front["front_kind"]
    assert g["best_energy_kwh"] >= 0.98 * g["optimum_kwh"] and g["gap_to_optimum_percent"] > -2.0


def test_library_errors_name_arguments_and_the_cli_names_flags(freight):
    from locoplan.errors import InputError
    from locoplan.runner import make_context
    from locoplan.settings import RunSettings

    route, train = freight
    with pytest.raises(InputError) as exc:
        make_context(route, train, RunSettings(time_s=-3))
    assert exc.value.problems[0].field == "time_s" and "--" not in str(exc.value)
    res = cli.invoke(app, ["compare", str(ROOT / "routes/freight-20km.yaml"), "--time", "-3"])
    assert res.exit_code == 2 and "<command line>: --time: must be in [1, 604,800] s (got -3)" in res.stderr, res.stderr


def test_public_api_is_lazy_and_complete():
    code = ("import sys, locoplan; assert 'locoplan.runs' not in sys.modules; "
            "from locoplan import RunSpec, run_many, Store, load_study, make_executor, pareto, compare_specs; "
            "print('ok')")
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert res.stdout.strip() == "ok", res.stderr


def test_ocp_study_routes_resolve_outside_the_checkout(tmp_path, monkeypatch):
    """ocp-study's default routes come from the package catalogue when the folder has no routes/."""
    from locoplan.io.load import load_route
    from locoplan.ocp.registry import STUDY_ROUTES, study_route_file as _default_path

    monkeypatch.chdir(tmp_path)
    for rel in STUDY_ROUTES.values():
        path = _default_path(rel)
        assert "catalogue" in str(path) and load_route(path).length_m == 1500


def test_results_plots_as_pdf_and_svg(filled_store, tmp_path):
    plot, box = tmp_path / "e.pdf", tmp_path / "b.svg"
    res = cli.invoke(app, ["results", str(filled_store), "--plot", str(plot), "--boxplot", str(box)])
    assert res.exit_code == 0, res.output
    assert plot.read_bytes()[:5] == b"%PDF-" and b"<svg" in box.read_bytes()[:400]


def test_results_csv_is_read_as_numbers_and_booleans(filled_store):
    """``results --format csv``: a spreadsheet's and pandas' CSV (true/false, numbers, empty cells, the
    weights and the window as columns of their own), never Python's 'True' or '[0.5, 0.5]'."""
    import csv
    import io

    res = cli.invoke(app, ["results", str(filled_store), "--format", "csv"])
    assert res.exit_code == 0, res.stderr
    rows = list(csv.DictReader(io.StringIO(res.stdout)))
    text = res.stdout
    assert "True" not in text and "False" not in text and "None" not in text and "nan" not in text.lower()
    assert {"w_time", "w_energy", "window_from_s", "window_to_s"} <= set(rows[0]) and "weights" not in rows[0]
    assert {r["feasible"] for r in rows} <= {"true", "false"}
    weighted = [r for r in rows if r["w_time"] != ""]
    assert weighted and all(float(r["w_time"]) + float(r["w_energy"]) == pytest.approx(1) for r in weighted)
    for col in ("planned_time_s", "traction_energy_kwh", "seed", "window_from_s"):
        [float(r[col]) for r in rows if r[col] != ""]  # every value a number


def test_results_exports_are_written_a_row_at_a_time_as_made_whole(filled_store, tmp_path):
    """An export is written in a second pass over the store, a row at a time (memory does not grow with the
    store): the same text as the whole export made at once, the same Parquet table; rows that differ from the
    first pass (a run replaced meanwhile) are refused, and nothing is written."""
    import csv
    import io

    from locoplan.errors import InputError
    from locoplan.reporting.writers import csv_row, to_json
    from locoplan.runs.results import ExportShape, export_to_file, rows_of, write_export

    with Store(filled_store, create=False) as s:
        rows = rows_of(s.records())
    flat = [csv_row(r) for r in rows]
    whole_csv = io.StringIO()
    writer = csv.DictWriter(whole_csv, fieldnames=list(dict.fromkeys(k for f in flat for k in f)), lineterminator="\n",
                            restval="")
    writer.writeheader()
    writer.writerows(flat)
    for fmt, whole in (("csv", whole_csv.getvalue()), ("json", to_json({"results": rows}) + "\n")):
        shape = ExportShape(fmt, str(filled_store))
        for r in rows:
            shape.add(r)
        streamed = io.StringIO()
        write_export(iter(rows), shape, streamed)
        assert streamed.getvalue() == whole
        with pytest.raises(InputError, match="the store changed while it was exported") as err:
            export_to_file(iter(rows[1:]), shape, tmp_path / f"changed.{fmt}")
        assert str(filled_store) in str(err.value) and not list(tmp_path.iterdir())
    empty = ExportShape("json", "s")
    out = io.StringIO()
    write_export(iter([]), empty, out)
    assert out.getvalue() == to_json({"results": []}) + "\n"
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    from locoplan.runs.results import _flat, clean

    shape = ExportShape("parquet", str(filled_store))
    for r in rows:
        shape.add(r)
    export_to_file(iter(rows), shape, tmp_path / "r.parquet")
    whole = pa.table({c: [_flat(clean(r.get(c))) for r in rows] for c in shape.columns})
    assert pq.read_table(tmp_path / "r.parquet").equals(whole)


def test_a_route_edited_between_batches_is_summarised_apart(tmp_path):
    """Runs are grouped by what they ran, not by its name: a route file edited between two batches into one store
    (a limit lowered) gives two groups, each named with its content hash, and a note says why; the store keeps
    every run (one per content), and the unedited route's summary has no such note."""
    route = tmp_path / "line.yaml"
    text = ROUTE.read_text()
    route.write_text(text)
    study = tmp_path / "study.yaml"
    study.write_text(f"schema: locoplan/study@1\nroutes: [{route}]\nconsists: [HXD1-C80x30]\ntimes: [1.2x]\n"
                     "algorithms: [issa]\nseeds: [1]\n")
    store = tmp_path / "runs.sqlite"
    first = cli.invoke(app, ["batch", str(study), "--store", str(store), "--workers", "1", "--quiet"])
    assert first.exit_code == 0, first.output
    assert "different contents" not in first.stderr
    lowered = text.replace("kmh: 80", "kmh: 70", 1)
    assert lowered != text  # the premise: the line has an 80 km/h limit to lower
    route.write_text(lowered)
    second = cli.invoke(app, ["batch", str(study), "--store", str(store), "--workers", "1", "--quiet"])
    assert second.exit_code == 0, second.output
    res = cli.invoke(app, ["results", str(store), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)["summary"]
    assert len(summary) == 2 and all(g["runs"] == 1 for g in summary)
    names = sorted(g["route"] for g in summary)
    assert names[0] != names[1] and all(" @ " in n for n in names)
    assert "names 2 different contents" in " ".join(res.stderr.split())


def test_a_route_glob_passes_over_study_files(tmp_path):
    """A route glob takes route files only: the study file itself, which the glob matches, and a journey file beside
    it are passed over (a study lists its own folder's routes with '*.yaml')."""
    (tmp_path / "line.yaml").write_text(ROUTE.read_text())
    (tmp_path / "trip-journey.yaml").write_text((ROOT / "routes/journeys/CH_Stadelhofen_Altstetten-journey.yaml").read_text())
    study = tmp_path / "study.yaml"
    study.write_text("schema: locoplan/study@1\nroutes: ['*.yaml']\nconsists: [HXD1-C80x30]\ntimes: [1.2x]\n"
                     "algorithms: [issa]\nseeds: [1]\n")
    specs = load_study(study).specs
    assert [Path(s.route).name for s in specs] == ["line.yaml"]
