"""Shared pytest fixtures: where the real data sets live (../shared/data/real, never copied here)."""

from pathlib import Path

import pytest

REAL_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real"


@pytest.fixture(scope="session")
def real_data() -> Path:
    if not REAL_DATA.is_dir():
        pytest.fail(f"real data not found at {REAL_DATA}: the repo must sit beside ../shared")
    return REAL_DATA
