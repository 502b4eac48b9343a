"""Samples CPU and memory of named processes with psutil, following exits and respawns."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import psutil

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.monitor.log import METRICS, Event, MonitorLog
from grid_puzzle_localization.util.iteration import zip_equal


@dataclass(frozen=True)
class Target:
    """A process to watch. ``resolve`` returns its current PID, or None while it does not exist (it
    may raise OSError, e.g. when a ROS master is gone: treated as None). With ``respawns`` the PID is
    resolved again after the process exits, so a restarted node is followed under the same name."""

    name: str
    resolve: Callable[[], int | None]
    respawns: bool = True

    @classmethod
    def from_pid(cls, pid: int, name: str | None = None) -> Target:
        """A fixed PID: once it exits it is not followed again (the PID may be reused by another process)."""
        return cls(name or f"pid_{pid}", lambda: pid, respawns=False)


@dataclass
class _Reading:
    pid: int
    cpu_percent: float
    rss_bytes: float
    uss_bytes: float
    pss_bytes: float


class _Tracker:
    """State of one target: the attached psutil.Process and its last CPU time."""

    def __init__(self, target: Target):
        self.target = target
        self.proc: psutil.Process | None = None
        self.ever_attached = False
        self.last_cpu_s = 0.0
        self.last_t = 0.0

    def _attach(self, t: float, events: list[Event], t0: float) -> None:
        if self.ever_attached and not self.target.respawns:
            return
        try:
            pid = self.target.resolve()
        except OSError:
            pid = None
        if pid is None:
            return
        try:
            proc = psutil.Process(pid)
            if proc.status() == psutil.STATUS_ZOMBIE:
                return
            cpu = proc.cpu_times()
        except (psutil.NoSuchProcess, psutil.ZombieProcess):
            return
        kind = "respawn" if self.ever_attached else "attach"
        self.proc, self.ever_attached = proc, True
        self.last_cpu_s, self.last_t = cpu.user + cpu.system, t
        events.append(Event(t - t0, self.target.name, kind, pid))

    def read(self, events: list[Event], t0: float) -> _Reading | None:
        """One reading, or None when the process is absent. The first reading after an attach has no
        CPU figure (NaN): CPU% needs two CPU-time readings. An exit is recorded and, for a respawning
        target, the PID is resolved again at once (once per sample)."""
        for _ in range(2):
            t = time.monotonic()
            fresh = self.proc is None
            if fresh:
                self._attach(t, events, t0)
                if self.proc is None:
                    return None
            proc = self.proc
            try:
                with proc.oneshot():
                    if proc.status() == psutil.STATUS_ZOMBIE:
                        raise psutil.ZombieProcess(proc.pid)
                    cpu = proc.cpu_times()
                    try:
                        mem = proc.memory_full_info()
                        uss, pss = float(mem.uss), float(getattr(mem, "pss", np.nan))
                    except psutil.AccessDenied:
                        mem, uss, pss = proc.memory_info(), np.nan, np.nan
            except (psutil.NoSuchProcess, psutil.ZombieProcess):
                events.append(Event(t - t0, self.target.name, "exit", proc.pid))
                self.proc = None
                if not self.target.respawns:
                    return None
                continue
            cpu_s = cpu.user + cpu.system
            dt = t - self.last_t
            cpu_percent = np.nan if fresh or dt <= 0 else 100.0 * (cpu_s - self.last_cpu_s) / dt
            self.last_cpu_s, self.last_t = cpu_s, t
            return _Reading(proc.pid, cpu_percent, float(mem.rss), uss, pss)
        return None


DEFAULT_INTERVAL_S = 1.0  # [s] between samples


class Monitor:
    """Samples ``targets`` every ``interval`` seconds into a :class:`MonitorLog`.

    Use :meth:`run` to sample in the calling thread, or :meth:`start` / :meth:`stop` to sample in a
    background thread (what the experiment runner does)."""

    def __init__(self, targets: Sequence[Target], interval: float = DEFAULT_INTERVAL_S):
        names = [t.name for t in targets]
        if len(set(names)) != len(names):
            raise UserError(f"monitor targets must have distinct names (got {names})")
        if not interval > 0:
            raise UserError(f"monitor interval must be a positive number of seconds (got {interval})")
        self.interval = float(interval)
        self._trackers = [_Tracker(t) for t in targets]
        self._names = names
        self._t: list[float] = []
        self._wall: list[float] = []
        self._rows: list[list[_Reading | None]] = []
        self._events: list[Event] = []
        self._t0 = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def sample(self) -> None:
        """Takes one sample of every target now."""
        t, wall = time.monotonic(), time.time()
        readings = [tr.read(self._events, self._t0) for tr in self._trackers]
        with self._lock:
            self._t.append(t - self._t0)
            self._wall.append(wall)
            self._rows.append(readings)

    def run(self, duration: float | None = None) -> MonitorLog:
        """Samples until ``duration`` seconds have passed (or forever when None) or :meth:`stop`."""
        self._t0 = time.monotonic()
        k = 0
        while not self._stop.is_set():
            self.sample()
            k += 1
            next_t = self._t0 + k * self.interval
            if duration is not None and next_t - self._t0 > duration + 1e-9:
                break
            self._stop.wait(max(0.0, next_t - time.monotonic()))
        return self.log()

    def start(self) -> None:
        """Starts sampling in a background thread."""
        if self._thread is not None:
            raise RuntimeError("monitor already started")
        self._thread = threading.Thread(target=self.run, name="gpm-monitor", daemon=True)
        self._thread.start()

    def stop(self) -> MonitorLog:
        """Stops the background thread (or a :meth:`run` in another thread) and returns the log."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        return self.log()

    def log(self) -> MonitorLog:
        """The samples so far as arrays."""
        with self._lock:
            rows, t, wall, events = list(self._rows), list(self._t), list(self._wall), list(self._events)
        n = len(rows)
        pid = {name: np.full(n, -1, dtype=np.int64) for name in self._names}
        values = {m: {name: np.full(n, np.nan) for name in self._names} for m in METRICS}
        for i, readings in enumerate(rows):
            for name, r in zip_equal(self._names, readings):
                if r is None:
                    continue
                pid[name][i] = r.pid
                for m in METRICS:
                    values[m][name][i] = getattr(r, m)
        return MonitorLog(list(self._names), np.array(t), np.array(wall), pid, values, events)
