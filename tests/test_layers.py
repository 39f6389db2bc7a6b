"""The layering of docs/architecture.md, checked: import-linter's contracts in pyproject.toml (a package
imports only the ones below it; no import cycle among the modules of any package), and every module of
locoplan in some layer, so that a new package cannot slip past the check."""

from __future__ import annotations

import pkgutil
from pathlib import Path

import pytest

try:
    import tomllib
except ImportError:  # Python 3.10
    tomllib = pytest.importorskip("tomli")

import locoplan

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "pyproject.toml"


def _contracts() -> list[dict]:
    return tomllib.loads(CONFIG.read_text())["tool"]["importlinter"]["contracts"]


def test_the_import_contracts_hold(capsys):
    from importlinter.cli import lint_imports

    code = lint_imports(config_filename=str(CONFIG), no_cache=True)
    out = capsys.readouterr().out
    assert code == 0, out[out.find("Broken contracts"):] if "Broken contracts" in out else out
    assert "2 kept, 0 broken" in out


def test_every_top_level_module_has_a_layer():
    layers = next(c for c in _contracts() if c["type"] == "layers")["layers"]
    named = {m.strip() for layer in layers for m in layer.replace(":", "|").split("|")}
    data_only = {"locoplan.catalogue"}  # shipped files, no code to import
    top = {f"locoplan.{m.name}" for m in pkgutil.iter_modules(locoplan.__path__)}
    assert top - named - data_only == set(), "add the new package to the layers in pyproject.toml (docs/architecture.md)"


@pytest.mark.parametrize("low, high", [("physics", "model"), ("model", "sim"), ("sim", "strategy"), ("io", "reporting")])
def test_the_layers_run_downwards(low, high):
    """The contract's order is the documented one: a formula's package under the data's, the data under the
    calculator, the calculator under the strategies; reading under rendering."""
    layers = [set(x.replace(":", "|").replace(" ", "").split("|")) for x in
              next(c for c in _contracts() if c["type"] == "layers")["layers"]]
    where = {m: i for i, layer in enumerate(layers) for m in layer}
    assert where[f"locoplan.{high}"] < where[f"locoplan.{low}"]
