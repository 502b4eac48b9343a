"""The monitor's record: one row per sample, per-process and summed columns, and process events.

CSV layout (one header row, then one row per sample; an empty cell means the process was not
running at that sample, or the value is unavailable, e.g. USS without permission):

    t_s, wall_time_s, <name>/pid, <name>/cpu_percent, <name>/rss_bytes, <name>/uss_bytes,
    <name>/pss_bytes, ..., total/processes, total/cpu_percent, total/rss_bytes, total/uss_bytes,
    total/pss_bytes

``t_s`` is seconds since the monitor started (monotonic clock), ``wall_time_s`` the Unix time.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.util.atomic import atomic_write

# Sampled per process: CPU in percent of one core, memory in bytes.
METRICS = ("cpu_percent", "rss_bytes", "uss_bytes", "pss_bytes")
TOTAL = "total"


@dataclass(frozen=True)
class Event:
    """A change in a monitored process: ``attach`` (first seen), ``exit``, or ``respawn`` (seen again
    under a new PID after an exit)."""

    t_s: float
    name: str
    kind: str
    pid: int


@dataclass
class MonitorLog:
    """Samples of named processes. ``pid[name]`` is -1 where the process was absent; metric values
    are NaN where absent or unavailable."""

    names: list[str]
    t_s: np.ndarray
    wall_time_s: np.ndarray
    pid: dict[str, np.ndarray]
    values: dict[str, dict[str, np.ndarray]]  # metric -> name -> (N,) float64
    events: list[Event] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t_s)

    def sum(self, metric: str, names: list[str] | None = None) -> np.ndarray:
        """Per-sample sum of ``metric`` over ``names`` (all processes when None), skipping absent
        processes; NaN at samples where none of them has a value."""
        chosen = self.names if names is None else names
        missing = [n for n in chosen if n not in self.values[metric]]
        if missing:
            raise UserError(f"monitor log has no process named {missing} (it has {self.names})")
        if not chosen:
            return np.full(len(self), np.nan)
        stack = np.vstack([self.values[metric][n] for n in chosen])
        present = ~np.isnan(stack)
        return np.where(present.any(axis=0), np.nansum(stack, axis=0), np.nan)

    def processes_alive(self) -> np.ndarray:
        if not self.names:
            return np.zeros(len(self), dtype=np.int64)
        return np.sum([self.pid[n] >= 0 for n in self.names], axis=0).astype(np.int64)


def _cell(value: float) -> str:
    return "" if math.isnan(value) else repr(float(value))


def write_csv(path: str | os.PathLike, log: MonitorLog) -> None:
    """Writes ``log`` as CSV (layout in the module docstring), atomically."""
    header = ["t_s", "wall_time_s"]
    for name in log.names:
        header += [f"{name}/pid"] + [f"{name}/{m}" for m in METRICS]
    header += [f"{TOTAL}/processes"] + [f"{TOTAL}/{m}" for m in METRICS]
    totals = {m: log.sum(m) for m in METRICS}
    alive = log.processes_alive()
    with atomic_write(path, newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        for i in range(len(log)):
            row = [repr(float(log.t_s[i])), repr(float(log.wall_time_s[i]))]
            for name in log.names:
                pid = int(log.pid[name][i])
                row.append(str(pid) if pid >= 0 else "")
                row += [_cell(log.values[m][name][i]) for m in METRICS]
            row.append(str(int(alive[i])))
            row += [_cell(totals[m][i]) for m in METRICS]
            writer.writerow(row)


def read_csv(path: str | os.PathLike) -> MonitorLog:
    """Reads a CSV written by :func:`write_csv` (events are not part of the CSV; they live in the JSON
    summary)."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as err:
        raise UserError(f"cannot read monitor CSV {path}: {err.strerror}") from err
    if not rows or rows[0][:2] != ["t_s", "wall_time_s"]:
        raise UserError(f"{path} is not a monitor CSV (its header must start with t_s,wall_time_s)")
    header = rows[0]
    if any(len(r) != len(header) for r in rows[1:]):
        raise UserError(f"{path}: some rows do not have the {len(header)} columns of the header (truncated?)")
    names = [h[: -len("/pid")] for h in header if h.endswith("/pid")]
    cells = np.array(rows[1:], dtype=object).reshape(len(rows) - 1, len(header))

    def column(key: str) -> np.ndarray:
        if key not in header:
            raise UserError(f"{path}: column {key} is missing")
        return np.array([float(c) if c else np.nan for c in cells[:, header.index(key)]], dtype=np.float64)

    pid = {n: np.nan_to_num(column(f"{n}/pid"), nan=-1.0).astype(np.int64) for n in names}
    values = {m: {n: column(f"{n}/{m}") for n in names} for m in METRICS}
    return MonitorLog(names, column("t_s"), column("wall_time_s"), pid, values)
