from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", default=False,
                     help="also run the tests marked slow (the documentation's # slow examples)")


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def freight():
    from locoplan.io.load import load_route, load_train
    return load_route(ROOT / "routes/freight-20km.yaml"), load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")


@pytest.fixture(scope="session")
def heavy_haul():
    """The heavy-haul line (30.5 km at -12 per mille) and HXD1 x 2 + 100 x C80, whose electric brake cannot hold it."""
    from locoplan.io.load import load_route, load_train
    return load_route(ROOT / "routes/heavy-haul-60km.yaml"), load_train(ROOT / "configs/consists/HXD1x2-C80x100.yaml")


@pytest.fixture(scope="session")
def seed000():
    from locoplan.io.load import load_route, load_train
    train = load_train(ROOT / "configs/consists/HXD1-C64-seed000.yaml")
    return load_route(ROOT / "routes/seed000-flat.yaml"), load_route(ROOT / "routes/seed000-grade30.yaml"), train


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory):
    """Tests never read or write the user's cache of optima (~/.cache/locoplan): one of their own."""
    import os

    old = os.environ.get("LOCOPLAN_CACHE_DIR")
    os.environ["LOCOPLAN_CACHE_DIR"] = str(tmp_path_factory.mktemp("locoplan-cache"))
    # the ahead-of-time kernels (locoplan.sim.native): built once per session, shared by every test and the
    # commands they run (a README example's own cache folder included), unless the caller gave a folder
    # (parallel workers share one folder: one builds each kernel under a file lock, the others wait for it)
    native_set = "LOCOPLAN_NATIVE_DIR" in os.environ
    if not native_set:
        base = tmp_path_factory.getbasetemp()
        shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
        native = shared / "locoplan-native"
        native.mkdir(exist_ok=True)
        os.environ["LOCOPLAN_NATIVE_DIR"] = str(native)
    yield
    if not native_set:
        os.environ.pop("LOCOPLAN_NATIVE_DIR", None)
    if old is None:
        os.environ.pop("LOCOPLAN_CACHE_DIR", None)
    else:
        os.environ["LOCOPLAN_CACHE_DIR"] = old


def pytest_collection_modifyitems(items):
    """The documentation's examples (each a process of its own) are among the slow tests, left out of the quick
    subset (``-m "not slow"``)."""
    for item in items:
        if item.path.name == "test_readme_examples.py" and item.originalname in ("test_readme_example", "test_example"):
            item.add_marker(pytest.mark.slow)
