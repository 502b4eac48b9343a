"""Ordered parallel map with bounded look-ahead, for simulating sweeps while the caller writes them.

Sweep simulation is numpy and Embree work, most of which releases the GIL, so worker threads use the
cores while the calling thread serializes and writes the previous sweeps. Results come back in index
order, so the output does not depend on the number of threads.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")


def ordered_map(fn: Callable[[int], T], count: int, threads: int, ahead: int = 2) -> Iterator[T]:
    """``fn(0), fn(1), ..., fn(count - 1)`` computed by ``threads`` workers; at most ``ahead * threads``
    results are computed ahead of the consumer, which bounds memory. Abandoning the iterator cancels
    the queued calls (those already running finish)."""
    pending: deque[Future[T]] = deque()
    with ThreadPoolExecutor(max(1, threads)) as pool:
        try:
            for k in range(count):
                pending.append(pool.submit(fn, k))
                if len(pending) > ahead * max(1, threads):
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for job in pending:
                job.cancel()
