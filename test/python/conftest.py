"""Shared pytest fixtures: where the real data sets live.

``real_data`` is test/data, the small real files committed with the tests. ``shared_real_data`` is the team's
larger store ($GPL_SHARED_DATA, else ../shared/data/real beside the clone); a test that needs it is skipped,
saying so, when it is absent.
"""

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TEST_DATA = ROOT / "test" / "data"
sys.path.insert(0, str(ROOT / "tools"))
from shared_data import SHARED_REAL_DATA  # noqa: E402


@pytest.fixture(scope="session")
def real_data() -> Path:
    return TEST_DATA


@pytest.fixture(scope="session")
def shared_real_data() -> Path:
    if not SHARED_REAL_DATA.is_dir():
        pytest.skip(f"needs the larger real data sets at {SHARED_REAL_DATA} (absent; set GPL_SHARED_DATA)")
    return SHARED_REAL_DATA
