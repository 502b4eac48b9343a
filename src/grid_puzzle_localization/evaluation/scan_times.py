"""The localizer's per-scan times, as the experiment's recorder writes them (``OUT/<mode>/scan_times.csv``):
one row per scan with its stamp [s], the whole scan's time and the matching's [ms] (NdtStatus
``scan_time_ms`` and ``align_time_ms``), whether its match was accepted (``match_accepted``, 1 or 0), and what the
match did: its NDT iterations, the candidates the hypotheses tried, whether the branch-and-bound search ran, and
the NVTL of the match taken (``iterations``, ``hypotheses``, ``global_search``, ``nvtl``), and the CPU time the map
worker thread had used by then (``map_worker_cpu_s``, since the localizer started). Tables written before the later
columns existed are read too; the columns they lack are NaN (unknown)."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.util.atomic import atomic_write

HEADER = "stamp_s,scan_time_ms,align_time_ms,match_accepted,iterations,hypotheses,global_search,nvtl,map_worker_cpu_s"
COLUMN = {name: index for index, name in enumerate(HEADER.split(","))}
COLUMNS = len(COLUMN)
# Older tables have the header's first columns: as many as these.
OLDER_COLUMNS = (3, 4, 7, 8)
# Scans slower than this many times the median are the tail the issue bounds (p95 <= 2x the median).
SLOW_OVER_MEDIAN = 2.0


def write_scan_times(
    path: str | os.PathLike, rows: Sequence[tuple[float, float, float, bool, int, int, bool, float, float]]
) -> None:
    with atomic_write(path) as f:
        f.write(HEADER + "\n")
        for stamp, scan_ms, align_ms, accepted, iterations, hypotheses, searched, nvtl, worker_cpu_s in rows:
            f.write(
                f"{stamp:.9f},{scan_ms:.4f},{align_ms:.4f},{int(bool(accepted))},{int(iterations)},"
                f"{int(hypotheses)},{int(bool(searched))},{nvtl:.4f},{worker_cpu_s:.6f}\n"
            )


def read_scan_times(path: str | os.PathLike) -> np.ndarray:
    """An (n, 9) array of the rows (stamp, scan ms, align ms, accepted, iterations, hypotheses, search, NVTL, map
    worker CPU s);
    raises UserError naming the file when it is not such a table."""
    try:
        with open(path) as f:
            header = f.readline().strip()
            columns = len(header.split(","))
            if columns not in (*OLDER_COLUMNS, COLUMNS) or header != ",".join(HEADER.split(",")[:columns]):
                raise UserError(f"{path}: first line is {header!r}, expected {HEADER!r}: not a scan-time table")
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
        data = np.hstack([data, np.full((len(data), COLUMNS - columns), np.nan)])
    return data


def accepted_stamps(data: np.ndarray) -> np.ndarray | None:
    """Stamps [s] of the scans whose match was accepted; None when the table does not say (an older table)."""
    accepted = data[:, COLUMN["match_accepted"]]
    if np.isnan(accepted).any():
        return None
    return data[accepted > 0.5, 0]


def map_worker_cpu_s(data: np.ndarray) -> float | None:
    """CPU time [s] the map worker spent from the first scan of the table to its last; None when it does not say."""
    cpu = data[:, COLUMN["map_worker_cpu_s"]] if data.size else np.empty(0)
    return None if cpu.size == 0 or np.isnan(cpu).any() else float(cpu[-1] - cpu[0])


def summarize_scan_times(data: np.ndarray) -> dict:
    """Mean, median, 95th and 99th percentile (linear interpolation between order statistics, numpy's default)
    and maximum of the whole scan's time [ms], the scans counted, what the slow scans did (slow_scans), and the map
    worker's CPU time over the table [s] (map_worker_cpu_s)."""
    times = data[:, 1]
    if times.size == 0:
        return {
            "scans": 0,
            "mean": None,
            "median": None,
            "p95": None,
            "p99": None,
            "max": None,
            "slow_scans": None,
            "map_worker_cpu_s": None,
        }
    return {
        "scans": int(times.size),
        "mean": float(times.mean()),
        "median": float(np.median(times)),
        "p95": float(np.percentile(times, 95)),
        "p99": float(np.percentile(times, 99)),
        "max": float(times.max()),
        "slow_scans": slow_scans(data),
        "map_worker_cpu_s": map_worker_cpu_s(data),
    }


def slow_scans(data: np.ndarray) -> dict | None:
    """The scans over SLOW_OVER_MEDIAN times the median scan time: how many, how many of them ran the hypotheses or
    the search, and their median NDT iterations against all scans'; None when the table does not say (older)."""
    iterations, hypotheses, search = COLUMN["iterations"], COLUMN["hypotheses"], COLUMN["global_search"]
    if data.size == 0 or np.isnan(data[:, [iterations, hypotheses, search]]).any():
        return None
    times = data[:, COLUMN["scan_time_ms"]]
    slow = data[times > SLOW_OVER_MEDIAN * np.median(times)]
    return {
        "over_median": SLOW_OVER_MEDIAN,
        "scans": len(slow),
        "with_hypotheses": int(np.count_nonzero(slow[:, hypotheses] > 0)),
        "with_search": int(np.count_nonzero(slow[:, search] > 0.5)),
        "median_iterations": float(np.median(slow[:, iterations])) if len(slow) else None,
        "median_iterations_all": float(np.median(data[:, iterations])),
    }
