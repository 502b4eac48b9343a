"""Summary statistics of a monitor log: mean, median, p95 and max per process and in total."""

from __future__ import annotations

import dataclasses

import numpy as np

from grid_puzzle_localization.monitor.log import METRICS, TOTAL, MonitorLog


def describe(values: np.ndarray) -> dict[str, float | int | None]:
    """mean, median, p95 (linear interpolation) and max over the finite values, and their count;
    the statistics are None when there is no finite value."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return {"mean": None, "median": None, "p95": None, "max": None, "samples": 0}
    return {
        "mean": float(np.mean(v)),
        "median": float(np.median(v)),
        "p95": float(np.percentile(v, 95)),
        "max": float(np.max(v)),
        "samples": int(v.size),
    }


def summarize(log: MonitorLog, interval_s: float | None = None) -> dict:
    """The JSON summary: per process (its PIDs in order of appearance) and the total over all
    processes, for every metric; plus the exit/respawn events."""
    processes = {}
    for name in log.names:
        pids = list(dict.fromkeys(int(p) for p in log.pid[name] if p >= 0))
        processes[name] = {"pids": pids} | {m: describe(log.values[m][name]) for m in METRICS}
    duration = float(log.t_s[-1] - log.t_s[0]) if len(log) else 0.0
    return {
        "cpu_percent_basis": "100 = one core fully busy",
        "memory_unit": "bytes",
        "interval_s": interval_s,
        "samples": len(log),
        "duration_s": duration,
        "processes": processes,
        TOTAL: {m: describe(log.sum(m)) for m in METRICS},
        "events": [dataclasses.asdict(e) for e in log.events],
    }
