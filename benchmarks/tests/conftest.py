"""The benchmarks' tests (apart from the product's suite in tests/, run with it by `make test`):
the project's config and a resolved demo campaign."""
from pathlib import Path

import pytest

from stringcast.core import load_config, resolve_campaign

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def config():
    return load_config(ROOT / "config" / "config.yaml")


@pytest.fixture(scope="session")
def campaign(config):
    return resolve_campaign({"string": 1, "target": 1}, config, "bench-test")
