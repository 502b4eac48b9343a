"""Splitting independent file writes over two processes (fork), so both cores create tiles.

Creating tens of thousands of small files is system-call bound; a forked child shares the parent's
buffers copy-on-write (nothing is copied or pickled) and takes every other item.
"""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable

MIN_ITEMS_TO_FORK = 2000  # below this a fork costs more than it saves


def run_split(n_items: int, work: Callable[[range], None], processes: int) -> None:
    """Calls ``work(range(k, n_items, processes))`` for each k, k > 0 in forked children. Raises
    OSError when a child failed (after every child has ended), so no child outlives a failure."""
    processes = max(1, min(processes, 2)) if n_items >= MIN_ITEMS_TO_FORK and hasattr(os, "fork") else 1
    children = []
    try:
        for k in range(1, processes):
            pid = os.fork()
            if pid == 0:  # child: never return into the caller's stack
                status = 1
                try:
                    work(range(k, n_items, processes))
                    status = 0
                except BaseException:
                    traceback.print_exc(file=sys.stderr)
                finally:
                    os._exit(status)
            children.append(pid)
        work(range(0, n_items, processes))
    finally:
        failed = [pid for pid in children if os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) != 0]
    if failed:
        raise OSError(f"{len(failed)} tile writer process(es) failed; see the error above")
