"""The localizer's per-scan times, as the experiment's recorder writes them (``OUT/<mode>/scan_times.csv``):
one row per scan with its stamp [s], the whole scan's time and the matching's [ms] (NdtStatus
``scan_time_ms`` and ``align_time_ms``), and whether its match was accepted (``match_accepted``, 1 or 0).
Tables written before the last column existed are read too; their ``match_accepted`` is NaN (unknown)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.util.atomic import atomic_write

HEADER = "stamp_s,scan_time_ms,align_time_ms,match_accepted"
HEADER_WITHOUT_ACCEPTED = "stamp_s,scan_time_ms,align_time_ms"
COLUMNS = 4


def write_scan_times(path: str | os.PathLike, rows: Sequence[tuple[float, float, float, bool]]) -> None:
    with atomic_write(path) as f:
        f.write(HEADER + "\n")
        for stamp, scan_ms, align_ms, accepted in rows:
            f.write(f"{stamp:.9f},{scan_ms:.4f},{align_ms:.4f},{int(bool(accepted))}\n")


def read_scan_times(path: str | os.PathLike) -> np.ndarray:
    """An (n, 4) array of the rows (stamp, scan ms, align ms, accepted); raises UserError naming the file when it is
    not such a table."""
    try:
        with open(path) as f:
            header = f.readline().strip()
            if header not in (HEADER, HEADER_WITHOUT_ACCEPTED):
                raise UserError(f"{path}: first line is {header!r}, expected {HEADER!r}: not a scan-time table")
            columns = len(header.split(","))
            rows = [line for line in f if line.strip()]
            data = np.loadtxt(rows, delimiter=",", ndmin=2) if rows else np.empty((0, columns))
    except OSError as err:
        raise UserError(f"cannot read {path}: {err.strerror}") from err
    except ValueError as err:
        raise UserError(f"{path}: a row is not {columns} numbers ({err})") from err
    if data.size and data.shape[1] != columns:
        raise UserError(f"{path}: rows have {data.shape[1]} columns, expected {columns} ({header})")
    data = data.reshape(-1, columns)
    if columns < COLUMNS:
        data = np.hstack([data, np.full((len(data), 1), np.nan)])
    return data


def accepted_stamps(data: np.ndarray) -> np.ndarray | None:
    """Stamps [s] of the scans whose match was accepted; None when the table does not say (an older table)."""
    accepted = data[:, 3]
    if np.isnan(accepted).any():
        return None
    return data[accepted > 0.5, 0]


def summarize_scan_times(data: np.ndarray) -> dict:
    """Mean, median, 95th and 99th percentile (linear interpolation between order statistics, numpy's default)
    and maximum of the whole scan's time [ms], and the scans counted."""
    times = data[:, 1]
    if times.size == 0:
        return {"scans": 0, "mean": None, "median": None, "p95": None, "p99": None, "max": None}
    return {
        "scans": int(times.size),
        "mean": float(times.mean()),
        "median": float(np.median(times)),
        "p95": float(np.percentile(times, 95)),
        "p99": float(np.percentile(times, 99)),
        "max": float(times.max()),
    }
