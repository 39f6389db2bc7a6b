"""locoplan.api: the command line's decisions (checks, exit codes, tolerances) as a script gets them."""

from __future__ import annotations

from pathlib import Path

import pytest

from locoplan import api
from locoplan.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


def test_model_request_defaults_and_checks():
    opts = api.ModelRequest().options()
    assert (opts.point_mass, opts.air_brake, opts.strict_limits, opts.rotating_mass) == (False, True, False, None)
    assert api.ModelRequest(point_mass=True).options().air_brake is False  # air brakes off with the point mass
    assert api.ModelRequest(point_mass=True, air_brake=True).options().air_brake is True
    with pytest.raises(InputError, match=r"--rotating-mass: must be in \[0, 1\) \(got 1\)"):
        api.ModelRequest(rotating_mass=1.0).options()
    with pytest.raises(InputError, match="--step"):
        api.ModelRequest(step_m=0.01).options()


def test_verdicts_and_exit_codes():
    assert api.verdict([None, ""]).exit_code == api.EXIT_OK
    v = api.verdict(["four-stage: late", "proposed: late", "four-stage: late"])
    assert v.failures == ["four-stage, proposed: late"] and v.exit_code == api.EXIT_FAILED
    rows = [{"strategy": "proposed", "feasible": True, "punctual": True},
            {"strategy": "four-stage", "feasible": False, "punctual": False}]
    # the default list: one timetabled strategy on time, so the failed one is a note (exit 0)
    quiet = api.compare_verdict(rows, ["four-stage: infeasible"], named=False, timetabled={"proposed", "four-stage"})
    assert quiet.exit_code == 0 and quiet.notes == ["four-stage: infeasible"]
    # named by the user: its failure is exit 1
    named = api.compare_verdict(rows, ["four-stage: infeasible"], named=True, timetabled={"proposed", "four-stage"})
    assert named.exit_code == 1 and named.failures == ["four-stage: infeasible"]
    assert api.confirmed_verdict(False, "overspeed").exit_code == 1
    assert api.VERDICTS[api.EXIT_INVALID] == "invalid input"


def test_option_values():
    assert api.value_grid("0.1:0.3:0.1", "--weight-grid") == pytest.approx([0.1, 0.2, 0.3])
    assert api.weights("0.3,0.7") == (0.3, 0.7)
    assert api.seed_list("1,2") == (1, 2)
    with pytest.raises(InputError, match="expected whole numbers"):
        api.seed_list("1,x")
    with pytest.raises(InputError, match="name at least one"):
        api.names(" , ", "--strategies")
    with pytest.raises(InputError, match="expected positive numbers"):
        api.positive_numbers("0", "--masses")
    with pytest.raises(InputError, match="give exactly one"):
        api.one_of(None, None, "--weight-grid", "give exactly one of --weight-grid or --times", exactly=True)
    assert api.planned_time("1500", None).time_s == 1500.0
    assert api.planned_time(None, None).time_s is None
    assert api.window_half_width({"window_s": [1470.0, 1530.0]}) == 30.0
    assert api.window_half_width({}) is None


def test_energy_ocp_checks_collect_every_problem():
    with pytest.raises(InputError) as info:
        api.check_energy_ocp(17, None, 2.0, 50)
    assert [p.field for p in info.value.problems] == ["--nodes", "--mesh-tol", "--max-phase-degree"]
    assert api.planned_times(api.bound_times(None, "1400,1500")).times_s == [1400.0, 1500.0]
    assert api.bound_times(None, "1400,1.1x") == [("s", 1400.0), ("x", 1.1)]
    with pytest.raises(InputError, match="not both"):
        api.bound_times("1500", "1400,1500")


def test_validate_files_as_a_script():
    good = ROOT / "routes" / "freight-20km.yaml"
    bad = ROOT / "tests" / "data" / "bad" / "route_gap.yaml"
    report = api.validate_files([good, bad])
    assert report.exit_code == api.EXIT_INVALID
    assert [r["valid"] for r in report.results] == [True, False]
    assert report.results[0]["kind"] == "route" and report.problems
    assert api.validate_files([good]).to_dict()["valid"] is True
