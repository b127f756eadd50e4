"""Shared fixtures: the project's config and a resolved demo campaign."""
import os
from pathlib import Path

import pytest

from stringcast.config import load_config, resolve_campaign

ROOT = Path(__file__).resolve().parents[1]
# the real camera data: $STRINGCAST_REAL_DATA, else ../shared/real beside the clone
SHARED_REAL = Path(os.environ.get("STRINGCAST_REAL_DATA", ROOT.parent / "shared" / "real"))


@pytest.fixture(scope="session")
def config():
    return load_config(ROOT / "config" / "config.yaml")


@pytest.fixture(scope="session")
def campaign(config):
    return resolve_campaign({"string": 1, "target": 1}, config, "test")
