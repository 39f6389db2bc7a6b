"""The disk caches keyed by code (E*, the air brake's cycle optimum) are keyed by every module they import:
a change to any of them, in a copy of the package, is a cache miss; a module they do not import is not."""

from __future__ import annotations

import shutil

import pytest

from locoplan.ocp import bound
from locoplan.strategy import cycle_start


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A copy of the locoplan sources that E*'s cache key is computed from, and a cache folder of its own."""
    copy = tmp_path / "locoplan"
    shutil.copytree(bound.PACKAGE_DIR, copy, ignore=shutil.ignore_patterns("__pycache__", "*.so", "*.pyc"))
    monkeypatch.setattr(bound, "PACKAGE_DIR", copy)
    monkeypatch.setenv("LOCOPLAN_CACHE_DIR", str(tmp_path / "cache"))
    bound.code_digest.cache_clear()
    yield copy
    bound.code_digest.cache_clear()


def _edit(path):
    path.write_text(path.read_text() + "\n# edited\n")
    bound.code_digest.cache_clear()  # as in a new process


@pytest.mark.parametrize("rel", ["sim/calculator.py", "sim/constants.py", "model/route.py", "physics/resistance.py",
                                 "ocp/cells.py", "errors.py"])
def test_an_edit_to_what_estar_imports_is_a_cache_miss(package, rel):
    key = ("a case",)
    bound.cache_store(key, {"e_star_kwh": 1.0})
    assert bound.cache_load(key) == {"e_star_kwh": 1.0}
    _edit(package / rel)
    assert bound.cache_load(key) is None


@pytest.mark.parametrize("rel", ["cli.py", "reporting/tables.py", "runs/store.py"])
def test_an_edit_elsewhere_keeps_estar_cached(package, rel):
    key = ("a case",)
    bound.cache_store(key, {"e_star_kwh": 1.0})
    _edit(package / rel)
    assert bound.cache_load(key) == {"e_star_kwh": 1.0}


def test_estar_sources_are_what_it_imports():
    found = set(bound.code_sources(bound.E_STAR_SOURCES))
    for rel in ("ocp/bound.py", "ocp/cells.py", "sim/calculator.py", "sim/constants.py", "model/route.py",
                "model/train.py", "physics/resistance.py", "errors.py"):
        assert rel in found, rel
    assert not any(f.startswith(("cli", "runs/", "reporting/", "strategy/")) for f in found)


def test_the_cycle_optimum_sources_include_the_builder_and_estar():
    found = set(bound.code_sources(("strategy/cycle_start.py",)))
    for rel in ("strategy/general_builder.py", "optimize/problem.py", "optimize/cycle_dp.py", "optimize/dp_kernel.py",
                "sim/calculator.py", "ocp/bound.py", "ocp/cells.py", "model/plan.py"):
        assert rel in found, rel


def test_relative_and_absolute_imports_are_followed(tmp_path):
    pkg = tmp_path / "pkg"
    for rel, text in {"__init__.py": "", "a/__init__.py": "", "b/__init__.py": "", "c.py": "", "d/__init__.py": "",
                      "d/e.py": "", "f.py": "",
                      "a/x.py": "from ..b import y\n\ndef g():\n    from .. import c\n",
                      "b/y.py": "from locoplan.d.e import thing  # a comment\nfrom numpy import array\n",
                      }.items():
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(text)
    found = bound.code_sources(("a/x.py",), pkg)
    assert found == ["__init__.py", "a/__init__.py", "a/x.py", "b/__init__.py", "b/y.py", "c.py", "d/__init__.py",
                     "d/e.py"]
    before = bound.code_digest.__wrapped__(("a/x.py",), pkg)
    (pkg / "d/e.py").write_text("thing = 1\n")
    assert bound.code_digest.__wrapped__(("a/x.py",), pkg) != before


def test_cycle_optimum_key_moves_with_its_code(package):
    before = cycle_start._code_digest()
    _edit(package / "strategy/general_builder.py")
    assert cycle_start._code_digest() != before
