"""Regenerative braking: the energy the locomotives' electric brake returns to the line.

One physics function (``physics.energy.recovered_energy_kwh``) and one vehicle field
(``regen_efficiency``); the calculator reports it beside the traction energy. Checked against the
physics: with the electric brake alone, what it returns is the efficiency times the braking work, and
that work is the train's kinetic energy at the start of braking less the resistance on the way down.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from locoplan.errors import InputError
from locoplan.io.load import load_train, load_vehicle
from locoplan.physics.units import G_MS2, KJ_PER_KWH, kinetic_e
from locoplan.sim.calculator import ModelOptions, TractionCalculator
from routes import hand_made_route

ROOT = Path(__file__).resolve().parents[1]
STOCK = ROOT / "configs" / "rolling_stock"


def _stock(tmp_path: Path, regen: float | None) -> Path:
    """The shipped HXD1 + 50 x C80 with the locomotive's regen_efficiency set (None: without the field)."""
    d = tmp_path / "stock"
    d.mkdir()
    for f in ("HXD1.yaml", "C80.yaml"):
        text = (STOCK / f).read_text()
        if f == "HXD1.yaml":
            text = re.sub(r"(?m)^regen_efficiency:.*\n", "", text)
            assert "regen_efficiency:" not in text
            if regen is not None:
                text += f"\nregen_efficiency: {regen}\n"
        (d / f).write_text(text)
    shutil.copy(ROOT / "configs" / "consists" / "HXD1-C80x50.yaml", tmp_path / "consist.yaml")
    return d


def _without_regen(tmp_path: Path) -> tuple[Path, Path]:
    """(stock folder, consist file) of the shipped train with no regen_efficiency, beside the others."""
    d = tmp_path / "plain"
    d.mkdir()
    return _stock(d, None), d / "consist.yaml"


def _level_line():
    return hand_made_route([(8000.0, 80.0)], [(8000.0, 0.0)])


PLAN = (("T", "C", "B"), np.array([[3000.0, np.nan]]))  # up to speed, coast, brake on the stop's braking curve


def _run(tmp_path, regen, air_brake, route=None):
    stock = _stock(tmp_path, regen)
    train = load_train(tmp_path / "consist.yaml", stock)
    calc = TractionCalculator(route or _level_line(), train, ModelOptions(air_brake=air_brake))
    return calc, calc.evaluate(*PLAN, profile=True)


def test_without_the_field_nothing_is_recovered(tmp_path):
    calc, res = _run(tmp_path, None, air_brake=True)
    assert calc.train.regen_efficiency == 0.0
    assert res.feasible[0] and res.recovered_energy_kwh[0] == 0.0


def test_electric_brake_alone_returns_efficiency_times_its_work(tmp_path):
    """--no-air-brake: every kN of braking is electric, so recovered = eta x sum B ds exactly; and that work
    is the kinetic energy where braking began less the basic resistance's work while braking (level line),
    within the calculator's discretisation (0.5 %)."""
    calc, res = _run(tmp_path, 0.8, air_brake=False)
    p = res.profile
    brake_work_kwh = float(np.sum(p.brake_kn[0] * np.diff(p.s_m))) / KJ_PER_KWH
    assert brake_work_kwh > 10.0  # it did brake to the stop
    # (1e-5: the cell's electric share is capped at B_e,max of the mean of its node speeds, while the
    # calculator took the force at its own mid-cell speed estimate: a few cells clip by far below 0.1 kN)
    assert res.recovered_energy_kwh[0] == pytest.approx(0.8 * brake_work_kwh, rel=1e-5)
    braking = np.flatnonzero(p.brake_kn[0] > 0)
    k0 = braking[0]
    v0 = p.v_kmh[0, k0]
    mid = 0.5 * (p.v_kmh[0, 1:] + p.v_kmh[0, :-1])
    a, b, c = calc.train.resistance_kn
    resist_kwh = float(np.sum((a + b * mid[braking] + c * mid[braking] ** 2) * np.diff(p.s_m)[braking])) / KJ_PER_KWH
    kinetic_kwh = calc.m_eff_t * kinetic_e(v0) / KJ_PER_KWH  # t x m^2/s^2 = kJ
    assert brake_work_kwh == pytest.approx(kinetic_kwh - resist_kwh, rel=5e-3)
    assert res.traction_energy_kwh[0] > res.recovered_energy_kwh[0] > 0


def test_blended_braking_returns_only_the_electric_share(tmp_path):
    """With the wagons' air brake, full braking is electric + air: the electric brake takes its share first
    (at most its curve at each speed), the rest is air and returns nothing."""
    calc, res = _run(tmp_path, 1.0, air_brake=True)
    p = res.profile
    total_kwh = float(np.sum(p.brake_kn[0] * np.diff(p.s_m))) / KJ_PER_KWH
    mid = 0.5 * (p.v_kmh[0, 1:] + p.v_kmh[0, :-1])
    e_max = np.interp(mid, calc.electric_brake_speed_kmh, calc.electric_brake_kn)
    expect = float(np.sum(np.minimum(p.brake_kn[0], e_max) * np.diff(p.s_m))) / KJ_PER_KWH
    assert res.recovered_energy_kwh[0] == pytest.approx(expect, rel=1e-12)
    assert 0 < res.recovered_energy_kwh[0] < total_kwh  # the air brake took part


def test_no_regeneration_where_the_catenary_is_off(tmp_path):
    """In a neutral section's span the main breaker is open: no electric brake, nothing returned; the same
    braking outside it returns energy."""
    base = _level_line().model_dump(by_alias=True)
    base["neutral_sections"] = [{"from_m": 7400.0, "to_m": 7450.0}]
    from locoplan.model.route import Route

    calc, res = _run(tmp_path, 1.0, air_brake=True, route=Route.model_validate(base))
    p = res.profile
    off = calc.traction_allowed == 0
    assert off.any() and np.any(p.brake_kn[0][off] > 0)  # it brakes there ...
    mid = 0.5 * (p.v_kmh[0, 1:] + p.v_kmh[0, :-1])
    e_max = np.interp(mid, calc.electric_brake_speed_kmh, calc.electric_brake_kn) * calc.traction_allowed
    per_cell = np.minimum(p.brake_kn[0], e_max) * np.diff(p.s_m)
    assert np.all(per_cell[off] == 0)  # ... and returns nothing there
    assert res.recovered_energy_kwh[0] == pytest.approx(float(per_cell.sum()) / KJ_PER_KWH, rel=1e-12)


def test_the_field_is_checked(tmp_path):
    wagon = (STOCK / "C80.yaml").read_text() + "\nregen_efficiency: 0.8\n"
    (tmp_path / "C80.yaml").write_text(wagon)
    with pytest.raises(InputError, match="regen_efficiency: a wagon has no electric brake"):
        load_vehicle(tmp_path / "C80.yaml")
    loco = (STOCK / "HXD1.yaml").read_text() + "\nregen_efficiency: 1.2\n"
    (tmp_path / "HXD1.yaml").write_text(loco)
    with pytest.raises(InputError, match="regen_efficiency"):
        load_vehicle(tmp_path / "HXD1.yaml")
    assert G_MS2 == 9.81


def test_reported_beside_the_traction_energy(tmp_path):
    """`simulate --json` carries recovered_energy_kwh right after traction_energy_kwh, equal to the
    calculator's number, and net_energy_kwh, their difference; a train without the field recovers 0."""
    import json

    from typer.testing import CliRunner

    from locoplan.cli import app

    stock = _stock(tmp_path, 0.85)
    line = str(ROOT / "routes" / "freight-20km.yaml")
    out = CliRunner().invoke(app, ["simulate", line, "--strategy", "time-saving", "--consist",
                                   str(tmp_path / "consist.yaml"), "--stock-dir", str(stock), "--json"])
    assert out.exit_code == 0, out.output
    d = json.loads(out.output)
    keys = list(d)
    assert keys[keys.index("traction_energy_kwh") + 1] == "recovered_energy_kwh"
    from locoplan.io.load import load_route

    train = load_train(tmp_path / "consist.yaml", stock)
    calc = TractionCalculator(load_route(line), train)
    res = calc.evaluate(("T",), np.zeros((1, 0)), profile=True)  # time-saving: full traction, braking curves
    assert d["recovered_energy_kwh"] == pytest.approx(float(res.recovered_energy_kwh[0]), abs=0.006)
    assert 0 < d["recovered_energy_kwh"] < d["traction_energy_kwh"]
    assert keys[keys.index("recovered_energy_kwh") + 1] == "net_energy_kwh"
    assert d["net_energy_kwh"] == pytest.approx(d["traction_energy_kwh"] - d["recovered_energy_kwh"], abs=0.011)
    plain_stock, plain_consist = _without_regen(tmp_path)
    plain = json.loads(CliRunner().invoke(app, ["simulate", line, "--strategy", "time-saving", "--consist",
                                                str(plain_consist), "--stock-dir", str(plain_stock), "--json"]).output)
    assert plain["recovered_energy_kwh"] == 0.0 and plain["net_energy_kwh"] == plain["traction_energy_kwh"]


def test_the_table_names_it(tmp_path):
    from typer.testing import CliRunner

    from locoplan.cli import app

    stock = _stock(tmp_path, 0.85)
    line = str(ROOT / "routes" / "freight-20km.yaml")
    args = ["simulate", line, "--strategy", "time-saving", "--consist", str(tmp_path / "consist.yaml"), "--stock-dir", str(stock)]
    text = CliRunner().invoke(app, args).output
    js = __import__("json").loads(CliRunner().invoke(app, args + ["--json"]).output)
    assert f"recovered energy  │ {js['recovered_energy_kwh']:.2f} kWh by the electric brake" in text
    assert f"net energy        │ {js['net_energy_kwh']:.2f} kWh, traction less recovered" in text


def test_locomotives_are_weighted_by_their_electric_brake(tmp_path):
    """Two equal locomotives, one regenerating at 0.8 and one not: the train's share is half of 0.8; a
    third, twice as many of the regenerating one: (2 x 0.8) / 3."""
    stock = _stock(tmp_path, 0.8)
    plain = (stock / "HXD1.yaml").read_text()
    plain = re.sub(r"(?m)^regen_efficiency:.*\n", "", plain).replace("name: HXD1\n", "name: HXD1-old\n")
    assert "name: HXD1-old" in plain
    (stock / "HXD1-old.yaml").write_text(plain)
    for n_new, expect in ((1, 0.4), (2, 1.6 / 3)):
        (tmp_path / f"c{n_new}.yaml").write_text(
            "schema: locoplan/consist@1\nname: two HXD1\nvehicles:\n"
            f"  - {{type: HXD1, count: {n_new}}}\n  - {{type: HXD1-old, count: 1}}\n  - {{type: C80, count: 50, load_t: 80}}\n")
        assert load_train(tmp_path / f"c{n_new}.yaml", stock).regen_efficiency == pytest.approx(expect, rel=1e-12)


def test_store_keys_tell_a_regenerating_train_apart(tmp_path):
    """A batch store keys runs by the train's numbers: regeneration is one of them, while a train without
    it keeps the identity it had before the field existed (no regen_efficiency key at all)."""
    from locoplan.runs.spec import _train_identity

    plain_stock, plain_consist = _without_regen(tmp_path)
    plain = load_train(plain_consist, plain_stock)
    regen = load_train(tmp_path / "consist.yaml", _stock(tmp_path, 0.8))
    assert "regen_efficiency" not in _train_identity(plain)
    assert _train_identity(regen)["regen_efficiency"] == 0.8
    assert {k: v for k, v in _train_identity(regen).items() if k != "regen_efficiency"} == _train_identity(plain)
