"""The strategy registry: strategies as data, known in every process.

A library script that runs ``drivers`` (seed 004) on a process pool or a Dask cluster must work without
importing ``locoplan.learn`` itself: the workers are fresh processes that import only what unpickling a
task needs, so a strategy that registered itself on import was unknown there. The scripts run in a fresh
``python -c`` (no ``__main__`` file that a spawned worker would re-import) and their records must equal
the same run done in this process. Small on purpose: two drivers on the 6 km learning line, no E_min.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from locoplan.errors import InputError
from locoplan.strategy import registry

ROOT = Path(__file__).resolve().parents[1]
LINE = ROOT / "tests/data/learn/line-6km.yaml"


def test_every_entry_names_an_importable_function():
    for entry in registry.BUILT_IN:
        assert callable(entry.function()), entry.name
        assert all(callable(registry._resolve(reader)) for _, reader in entry.inputs), entry.name
    assert list(registry.STRATEGIES) == ["time-saving", "energy-saving", "four-stage", "proposed", "mpoc", "mpoc-n",
                                         "mpoc-c", "sfs", "drivers", "advice"]


def test_traits_are_the_ones_the_runs_used_to_retype():
    assert registry.names(timetabled=True) == ("four-stage", "proposed", "mpoc", "mpoc-n", "mpoc-c", "sfs", "advice")
    assert registry.names(needs_time=False) == ("time-saving", "energy-saving")
    assert registry.names(needs_e_min=True) == registry.names(seeded=True) == ("proposed",)
    assert registry.names(refuses_impossible_time=True) == ("four-stage", "proposed")
    assert registry.names(source=registry.ISSA_PAPER) == ("time-saving", "energy-saving", "four-stage", "proposed")
    assert [n for n, _ in registry.STRATEGIES["drivers"].inputs] == ["logs"]
    assert [n for n, _ in registry.STRATEGIES["advice"].inputs] == ["patterns"]
    from locoplan.runs.pareto import ENDS, PLANNED

    assert PLANNED == ("four-stage", "proposed") and ENDS == ("time-saving", "energy-saving")


def test_unknown_strategy_names_the_field_and_the_known_names():
    with pytest.raises(InputError) as exc:
        registry.get("fastest", field="strategies")
    text = str(exc.value)
    assert "strategies" in text and "unknown strategy 'fastest'" in text and "drivers, advice" in text
    assert not registry.is_timetabled("sequence") and registry.is_timetabled("proposed")


def _fresh(code: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_a_fresh_process_knows_every_strategy_without_importing_its_module():
    res = _fresh("""
        import sys
        from locoplan.strategy import registry
        assert "drivers" in registry.STRATEGIES and "locoplan.learn" not in sys.modules
        import locoplan.cli  # the command line lists every strategy, and loads none of the seed 001 / 004 code
        assert "locoplan.learn.strategies" not in sys.modules and "locoplan.strategy.optimal" not in sys.modules
        assert "mpoc" in sys.modules["locoplan.cli"].STRATEGIES
        fn = registry.get("drivers").function()
        assert fn.__module__ == "locoplan.learn.strategies"
    """)
    assert res.returncode == 0, res.stderr


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    from locoplan.io.load import load_consist, load_route
    from locoplan.learn.drivers import SimulationSpec
    from locoplan.reporting.logs import simulate_drivers

    consist, vehicles, files, _, _ = load_consist(ROOT / "configs/consists/HXD1-C80x50.yaml")
    out = tmp_path_factory.mktemp("registry") / "logs"
    simulate_drivers(SimulationSpec(LINE, load_route(LINE), consist, vehicles, files, masses_t=(5200,), times_s=(520,),
                                    n_drivers=2, n_runs=1, seed=1), out)
    return out


SETTINGS = dict(strategy="drivers", fitness=False)
"""The run: the drivers' logs for the 6 km line at 520 s (no E_min, so no optimiser: a second or two)."""


def _spec_code(logs) -> str:
    return (f"RunSpec({str(LINE)!r}, 'HXD1-C80x50', inputs=(('logs', ({str(logs)!r},)),), "
            f"settings=RunSettings(time_s=520.0), **{SETTINGS!r})")


@pytest.fixture(scope="module")
def in_process(logs):
    from locoplan import RunSettings, RunSpec, run_many

    batch = run_many([RunSpec(str(LINE), "HXD1-C80x50", inputs=(("logs", (str(logs),)),),
                              settings=RunSettings(time_s=520.0), **SETTINGS)])
    record = batch.records[0]
    assert record.summary["feasible"] and record.summary["drivers_runs"] == 2
    return json.loads(json.dumps(record.comparable()))


def _records(stdout: str) -> list[dict]:
    return json.loads(stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_process_pool_workers_run_drivers_from_a_library_script(logs, in_process):
    res = _fresh(f"""
        import json, os
        from locoplan import RunSettings, RunSpec, run_many, make_executor
        executor = make_executor(2)
        try:
            batch = run_many([{_spec_code(logs)}], executor)
        finally:
            executor.close()
        record = batch.records[0]
        assert record.worker.rsplit(":", 1)[1] != str(os.getpid()), "ran in the parent, not in a worker"
        print(json.dumps([r.comparable() for r in batch.records]))
    """)
    assert res.returncode == 0, res.stderr[-3000:]
    assert _records(res.stdout) == [in_process]


@pytest.mark.slow
def test_dask_workers_run_drivers_from_a_library_script(logs, in_process):
    pytest.importorskip("distributed")
    res = _fresh(f"""
        import json, os
        from distributed import Client, LocalCluster
        from locoplan import RunSettings, RunSpec, run_many, DaskExecutor
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \\
                Client(cluster) as client:
            batch = run_many([{_spec_code(logs)}], DaskExecutor(client))
        record = batch.records[0]
        assert record.worker.rsplit(":", 1)[1] != str(os.getpid()), "ran in the client, not on a worker"
        print(json.dumps([r.comparable() for r in batch.records]))
    """)
    assert res.returncode == 0, res.stderr[-3000:]
    assert _records(res.stdout) == [in_process]
