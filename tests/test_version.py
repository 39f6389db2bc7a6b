"""One version, written once (``locoplan.__version__``): the installed package's metadata, the JSON
outputs' ``locoplan_version``, a store's version check and the CHANGELOG all read it."""

from __future__ import annotations

import importlib.metadata
import re
from pathlib import Path

import pytest

import locoplan

ROOT = Path(__file__).resolve().parents[1]


def test_the_package_metadata_is_the_version():
    assert importlib.metadata.version("locoplan") == locoplan.__version__


def test_pyproject_writes_no_version_of_its_own():
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" not in config["project"] and "version" in config["project"]["dynamic"]
    assert config["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "locoplan.__version__"}


def test_the_changelog_names_this_version_first():
    text = (ROOT / "CHANGELOG.md").read_text()
    assert re.findall(r"^## (\S+)", text, re.M)[0] == locoplan.__version__


def test_a_store_of_another_version_is_refused(tmp_path, monkeypatch):
    from locoplan.errors import InputError
    from locoplan.runs import store as store_mod

    path = tmp_path / "runs.sqlite"
    store = store_mod.Store(path)
    store.check_writer()  # this version's own store
    store.close()
    monkeypatch.setattr(store_mod, "__version__", "9.9.9")
    with pytest.raises(InputError, match=f"store begun by locoplan {re.escape(locoplan.__version__)}, this is 9.9.9"):
        store_mod.Store(path).check_writer()
