from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def freight():
    from locoplan.io.load import load_route, load_train
    return load_route(ROOT / "routes/freight-20km.yaml"), load_train(ROOT / "configs/consists/HXD1-C80x50.yaml")


@pytest.fixture(scope="session")
def seed000():
    from locoplan.io.load import load_route, load_train
    train = load_train(ROOT / "configs/consists/HXD1-C64-seed000.yaml")
    return load_route(ROOT / "routes/seed000-flat.yaml"), load_route(ROOT / "routes/seed000-grade30.yaml"), train
