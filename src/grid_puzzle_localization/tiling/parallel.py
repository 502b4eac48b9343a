"""Running one job in a forked child while the caller goes on, so both cores work.

The tiler creates tens of thousands of small files (system-call bound) in a child while the parent
builds and writes the index. The child shares the parent's buffers copy-on-write: nothing is copied
or pickled.
"""

from __future__ import annotations

import contextlib
import os
import sys
import traceback
from collections.abc import Callable, Iterator


@contextlib.contextmanager
def in_background(job: Callable[[], None], fork: bool) -> Iterator[None]:
    """Runs ``job`` in a forked child during the with-block (or, with ``fork`` False, right away in
    this process). Leaving the block waits for the child, even when the block raised, so no child
    outlives its caller; a failed child raises OSError."""
    if not (fork and hasattr(os, "fork")):
        job()
        yield
        return
    pid = os.fork()
    if pid == 0:  # child: never return into the caller's stack
        status = 1
        try:
            job()
            status = 0
        except BaseException:
            traceback.print_exc(file=sys.stderr)
        finally:
            os._exit(status)
    try:
        yield
    finally:
        code = os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])
    if code != 0:
        raise OSError(f"the tile writer process failed (exit status {code}); see the error above")
