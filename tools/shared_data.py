"""Where the team's larger real data sets are: $GPL_SHARED_DATA, else ../shared/data/real beside the clone."""

from __future__ import annotations

import os
from pathlib import Path

SHARED_REAL_DATA = Path(os.environ.get("GPL_SHARED_DATA") or Path(__file__).resolve().parents[2] / "shared/data/real")
