"""The localizer's per-scan times, as the experiment's recorder writes them (``OUT/<mode>/scan_times.csv``):
one row per scan with its stamp [s], the whole scan's time and the matching's [ms] (NdtStatus
``scan_time_ms`` and ``align_time_ms``)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.util.atomic import atomic_write

HEADER = "stamp_s,scan_time_ms,align_time_ms"


def write_scan_times(path: str | os.PathLike, rows: Sequence[tuple[float, float, float]]) -> None:
    with atomic_write(path) as f:
        f.write(HEADER + "\n")
        for stamp, scan_ms, align_ms in rows:
            f.write(f"{stamp:.9f},{scan_ms:.4f},{align_ms:.4f}\n")


def read_scan_times(path: str | os.PathLike) -> np.ndarray:
    """An (n, 3) array of the rows; raises UserError naming the file when it is not such a table."""
    try:
        with open(path) as f:
            header = f.readline().strip()
            if header != HEADER:
                raise UserError(f"{path}: first line is {header!r}, expected {HEADER!r}: not a scan-time table")
            rows = [line for line in f if line.strip()]
            data = np.loadtxt(rows, delimiter=",", ndmin=2) if rows else np.empty((0, 3))
    except OSError as err:
        raise UserError(f"cannot read {path}: {err.strerror}") from err
    except ValueError as err:
        raise UserError(f"{path}: a row is not three numbers ({err})") from err
    if data.size and data.shape[1] != 3:
        raise UserError(f"{path}: rows have {data.shape[1]} columns, expected 3 ({HEADER})")
    return data.reshape(-1, 3)


def summarize_scan_times(data: np.ndarray) -> dict:
    """Mean, median and 95th percentile of the whole scan's time [ms], and the scans counted."""
    times = data[:, 1]
    if times.size == 0:
        return {"scans": 0, "mean": None, "median": None, "p95": None}
    return {
        "scans": int(times.size),
        "mean": float(times.mean()),
        "median": float(np.median(times)),
        "p95": float(np.percentile(times, 95)),
    }
