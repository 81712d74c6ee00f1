"""Shared test fixtures: the test data committed under tests/data (see its README)."""

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """``tests/data``: small third-party files, each case in its own folder."""
    return DATA
