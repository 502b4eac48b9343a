"""Using both cores: chunks grouped on a thread pool while the next one is read (the grouping runs in
C++ through ctypes, which releases the GIL), and jobs run in forked children while the caller goes on.

The tiler creates tens of thousands of small files (system-call bound) in children while the parent
builds and writes the index. The children share the parent's buffers copy-on-write: nothing is
copied or pickled. They take their work in batches from a shared queue (SharedBatches), so that they
finish together however unevenly the work is spread.
"""

from __future__ import annotations

import collections
import contextlib
import os
import select
import signal
import struct
import sys
import traceback
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from grid_puzzle_localization.util.iteration import exit_code

T = TypeVar("T")
R = TypeVar("R")

WAIT_PAUSE_S = 0.01  # longest pause between calls of while_waiting
MAX_REASON_BYTES = select.PIPE_BUF  # a failed child's reason: one atomic write into its empty exit pipe
_BATCH = struct.Struct("<q")  # a batch in the queue: the index of its first item
_MAX_BATCHES = select.PIPE_BUF // _BATCH.size  # the whole queue is one atomic pipe write
_MIN_BATCH_ITEMS = 64


class SharedBatches:
    """The items 0 .. total-1 in consecutive batches, handed out on demand to whoever iterates: the
    caller and the children it forks afterwards share one queue, a pipe filled at creation, so each
    batch goes to exactly one of them and faster workers take more. At most _MAX_BATCHES batches (one
    atomic pipe write, so filling never blocks); use as a context manager to close the pipe."""

    def __init__(self, total: int):
        self.total = total
        self.size = max(_MIN_BATCH_ITEMS, -(-total // _MAX_BATCHES))
        self._read_end, write_end = os.pipe()
        try:
            os.write(write_end, b"".join(_BATCH.pack(start) for start in range(0, total, self.size)))
        finally:
            os.close(write_end)  # once the batches are taken, readers see the end of the pipe

    def __iter__(self) -> Iterator[range]:
        while item := os.read(self._read_end, _BATCH.size):
            (start,) = _BATCH.unpack(item)
            yield range(start, min(start + self.size, self.total))

    def __enter__(self) -> SharedBatches:
        return self

    def __exit__(self, *exc_info) -> None:
        os.close(self._read_end)


def map_ahead(fn: Callable[[T], R], items: Iterable[T], threads: int) -> Iterator[R]:
    """``fn`` of each item, in order, computed on ``threads`` threads while the caller consumes earlier
    results and ``items`` yields the next ones. At most ``threads`` items are in flight, so memory stays
    bounded; with ``threads`` < 2 it is plain ``map``."""
    if threads < 2:
        yield from map(fn, items)
        return
    with ThreadPoolExecutor(threads) as pool:
        pending: collections.deque = collections.deque()
        for item in items:
            pending.append(pool.submit(fn, item))
            if len(pending) >= threads:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


@contextlib.contextmanager
def in_background(
    jobs: Sequence[Callable[[], None]], fork: bool, while_waiting: Callable[[], None] | None = None
) -> Iterator[None]:
    """Runs each job in its own forked child during the with-block (or, with ``fork`` False, all of
    them right away in this process). Leaving the block waits for every child, even when the block
    raised (then after stopping them with SIGTERM), so no child outlives its caller; a failed child
    raises OSError. ``while_waiting`` is called again and again while the children are still running
    after the block, with a pause of up to WAIT_PAUSE_S that ends early when a child exits (the tiler
    flushes the files they have written so far, so that little is left to flush at the end)."""
    if not (fork and hasattr(os, "fork")):
        for job in jobs:
            job()
        yield
        return
    # pid -> read end of a pipe whose write end only the child holds: readable (end of file) once it exited, after
    # the reason it failed, if it did. A pipe rather than os.pidfd_open, which Python 3.8 lacks.
    children: dict[int, int] = {}
    try:
        # SIGINT is blocked while forking: Python runs its at-fork handlers (logging's lock release) with
        # signals live and prints and drops a KeyboardInterrupt raised there, so a Ctrl-C that hit a
        # fork was lost and the tiler ran to completion. Unblocked here, the pending signal is raised.
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            for job in jobs:
                read_end, write_end = os.pipe()
                pid = os.fork()
                if pid == 0:  # child: never return into the caller's stack
                    os.close(read_end)
                    _run_child(job, mask, write_end)
                os.close(write_end)
                children[pid] = read_end
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        yield
    except BaseException:
        # The caller failed or was interrupted (SIGINT sent to this process alone reaches no child): its
        # output is discarded, so the children are stopped rather than left to write every tile first.
        for pid in children:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGTERM)
        raise
    finally:
        try:
            codes = _wait_for(children, while_waiting)
            reasons = [os.read(exit_fd, MAX_REASON_BYTES).decode(errors="replace") for exit_fd in children.values()]
        finally:
            for exit_fd in children.values():
                os.close(exit_fd)
    failed = [(code, reason) for code, reason in zip(codes, reasons) if code != 0]
    if failed:
        named = "; ".join(dict.fromkeys(reason for _, reason in failed if reason))  # each distinct reason once
        raise OSError(
            f"a tile writer process failed: {named}"
            if named
            else f"a tile writer process failed (exit status {failed[0][0]}); see the error above"
        )


def _wait_for(children: dict[int, int], while_waiting: Callable[[], None] | None) -> list[int]:
    """Exit codes of the children (pid -> exit pipe), calling ``while_waiting`` between waits while any runs."""
    codes: dict[int, int] = {}
    while len(codes) < len(children):
        for pid in children:
            if pid in codes:
                continue
            done, status = os.waitpid(pid, os.WNOHANG if while_waiting else 0)
            if done:
                codes[pid] = exit_code(status)
        running = [exit_fd for pid, exit_fd in children.items() if pid not in codes]
        if while_waiting is not None and running:
            while_waiting()
            select.select(running, [], [], WAIT_PAUSE_S)
    return [codes[pid] for pid in children]


def _run_child(job: Callable[[], None], mask: Iterable[signal.Signals], exit_fd: int) -> None:
    """Runs ``job`` and exits; an OSError's text (disk full, permissions) goes to ``exit_fd``: the parent's error
    names it, so it is not printed here too."""
    status = 1
    try:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        job()
        status = 0
    except KeyboardInterrupt:  # Ctrl-C reaches the whole process group: the parent reports it
        pass
    except OSError as err:
        with contextlib.suppress(OSError):
            os.write(exit_fd, str(err).encode()[:MAX_REASON_BYTES])
    except BaseException:
        traceback.print_exc(file=sys.stderr)
    finally:
        os._exit(status)
