"""The file system's share of a tiling run: the time to create a set of files (given names and sizes)
in a fresh directory and make them durable, with nothing else to do. Forked workers create their
share of the files (one open, write and close each) while the parent flushes the file system every
10 ms, as the tiler does; a last syncfs ends it. It is independent of the package, so that the tiler's
time can be compared with the least that this disk allows."""

from __future__ import annotations

import ctypes
import os
import time
from pathlib import Path

from grid_puzzle_localization.util.iteration import exit_code

FLUSH_PAUSE_S = 0.01


def create_files(directory: Path, files: list[tuple[str, int]], workers: int) -> float:
    """Seconds to create ``files`` (name, bytes) durably in the new directory ``directory``."""
    syncfs = ctypes.CDLL(None, use_errno=True).syncfs
    payload = b"\0" * max((size for _, size in files), default=0)
    start = time.perf_counter()
    directory.mkdir()
    dir_fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        pids = [_fork_worker(dir_fd, files[k::workers], payload) for k in range(workers)]
        running = set(pids)
        while True:
            for pid in list(running):
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    running.discard(pid)
                    if exit_code(status) != 0:
                        raise OSError(f"file creation worker failed in {directory}")
            if syncfs(dir_fd) != 0:
                raise OSError(ctypes.get_errno(), "syncfs failed", str(directory))
            if not running:
                break
            time.sleep(FLUSH_PAUSE_S)
    finally:
        os.close(dir_fd)
    return time.perf_counter() - start


def _fork_worker(dir_fd: int, files: list[tuple[str, int]], payload: bytes) -> int:
    pid = os.fork()
    if pid != 0:
        return pid
    status = 1
    try:
        view = memoryview(payload)
        for name, size in files:
            fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644, dir_fd=dir_fd)
            try:
                os.write(fd, view[:size])
            finally:
                os.close(fd)
        status = 0
    finally:
        os._exit(status)
