"""Shared test fixtures: where the shared data lives."""

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def data_root() -> Path:
    env = os.environ.get("SKINRS_DATA")
    return Path(env) if env else ROOT.parent / "shared" / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    d = data_root()
    if not d.is_dir():
        pytest.fail(f"shared test data not found at {d}; set SKINRS_DATA")
    return d
