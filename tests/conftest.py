"""Shared test fixtures: the test data committed under tests/data (see its README)."""

from pathlib import Path

import pytest

DATA = Path(__file__).resolve().parent / "data"


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """``tests/data``: small third-party files, each case in its own folder."""
    return DATA


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "slow: takes 10 s or more; CI runs it, `make quicktest` leaves it out"
    )
