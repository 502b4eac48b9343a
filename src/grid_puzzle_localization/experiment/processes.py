"""Child processes that are always cleaned up: each runs in its own session (process group);
stopping sends SIGINT, then SIGTERM, then SIGKILL, to the group and to every descendant seen while
it ran (roslaunch starts each node in a session of its own)."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import psutil

from grid_puzzle_localization.errors import UserError


def free_port() -> int:
    """A TCP port on the loopback interface that was free a moment ago."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ManagedProcess:
    """A child process with its output in a log file. Use as a context manager or call :meth:`stop`."""

    def __init__(
        self,
        name: str,
        argv: Sequence[str],
        env: Mapping[str, str],
        log_path: str | os.PathLike,
        cwd: str | os.PathLike | None = None,
    ):
        self.name = name
        self.argv = list(argv)
        self.log_path = Path(log_path)
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "ab")  # noqa: SIM115 (closed in stop)
        try:
            self.popen = subprocess.Popen(
                self.argv,
                env=dict(env),
                cwd=cwd,
                stdin=subprocess.DEVNULL,
                stdout=self._log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        except OSError as err:
            self._log.close()
            raise UserError(f"cannot start {name} ({self.argv[0]}): {err.strerror}; is it installed?") from err
        self._seen: dict[int, psutil.Process] = {}
        self.remember_descendants()

    @property
    def pid(self) -> int:
        return self.popen.pid

    def remember_descendants(self) -> list[psutil.Process]:
        """Records the current descendants, so they are stopped even if their parent dies first."""
        try:
            procs = [psutil.Process(self.pid), *psutil.Process(self.pid).children(recursive=True)]
        except psutil.NoSuchProcess:
            procs = []
        for p in procs:
            self._seen.setdefault(p.pid, p)
        return procs

    def running(self) -> bool:
        return self.popen.poll() is None

    def wait(self, timeout_s: float | None = None) -> int | None:
        """Exit status, or None when still running after ``timeout_s``."""
        try:
            return self.popen.wait(timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def _alive(self) -> list[psutil.Process]:
        alive = []
        for p in self._seen.values():
            try:
                if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                    alive.append(p)
            except psutil.NoSuchProcess:
                pass
        return alive

    def _wait_alive(self, timeout_s: float) -> None:
        """Waits until nothing is alive. The main process is reaped through Popen (not psutil), so its
        exit status is kept."""
        deadline = time.monotonic() + timeout_s
        while self._alive() and time.monotonic() < deadline:
            self.popen.poll()
            time.sleep(0.05)

    def alive_pids(self) -> list[int]:
        """PIDs of this process and its remembered descendants that are still running."""
        return [p.pid for p in self._alive()]

    def _signal_all(self, sig: int) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.pid, sig)
        for p in self._alive():
            with contextlib.suppress(psutil.NoSuchProcess):
                p.send_signal(sig)

    def stop(self, sigint_timeout_s: float = 10.0, sigterm_timeout_s: float = 3.0) -> list[int]:
        """SIGINT to the main process, then SIGTERM, then SIGKILL to everything still alive. Returns
        the PIDs that needed SIGKILL (empty after a clean shutdown)."""
        if self.running():
            self.remember_descendants()
        killed: list[int] = []
        for sig, timeout in ((signal.SIGINT, sigint_timeout_s), (signal.SIGTERM, sigterm_timeout_s)):
            if not self._alive():
                break
            if sig == signal.SIGINT:
                # Only the main process: it shuts its own children down in order (roslaunch does).
                if self.running():
                    self.popen.send_signal(sig)
            else:
                self._signal_all(sig)
            self._wait_alive(timeout)
        leftover = self._alive()
        if leftover:
            killed = [p.pid for p in leftover]
            self._signal_all(signal.SIGKILL)
            self._wait_alive(5.0)
        if self.running():
            self.popen.wait(5.0)
        self._log.close()
        return killed

    def __enter__(self) -> ManagedProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def wait_for(condition, timeout_s: float, what: str, process: ManagedProcess | None = None, poll_s: float = 0.1):
    """Polls ``condition()`` until it returns a true value, which is returned. Raises UserError
    naming ``what`` on timeout, or earlier when ``process`` exits (pointing at its log)."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if process is not None and not process.running():
            raise UserError(f"{process.name} exited while waiting for {what}; see its log {process.log_path}")
        if time.monotonic() > deadline:
            hint = f"; see {process.log_path}" if process is not None else ""
            raise UserError(f"timed out after {timeout_s:.0f} s waiting for {what}{hint}")
        if process is not None:
            process.remember_descendants()
        time.sleep(poll_s)
