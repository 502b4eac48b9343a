"""Outcome records of the fault tests for `make reliability`: one JSON line per fault, appended to the file
named by $GPL_FAULT_REPORT (nothing is written when it is unset, as in `make test`)."""

from __future__ import annotations

import json
import os


def record(fault: str, outcome: str, recovery_s: float | None, data_lost: str = "none", **details) -> None:
    """``outcome``: what the component did; ``recovery_s``: seconds from the fault until it was back to
    a clean state (process exited with its error, or the next good update); ``data_lost``: "none" or what."""
    path = os.environ.get("GPL_FAULT_REPORT")
    if not path:
        return
    line = {"fault": fault, "outcome": outcome, "recovery_s": recovery_s, "data_lost": data_lost, **details}
    with open(path, "a") as f:
        f.write(json.dumps(line) + "\n")
