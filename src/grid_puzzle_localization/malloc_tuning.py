"""glibc malloc tuning for long-running processes that build large transient buffers.

Two opposite needs, one function each: a server that must give memory back (:func:`pin_mmap_threshold`)
and a batch job that allocates and frees the same multi-megabyte numpy temporaries thousands of times,
where mmapping each one costs a page fault per 4 KiB on first touch (:func:`reuse_large_buffers`).

glibc raises its mmap threshold each time a large mmapped block is freed (up to 32 MiB), so after the
first few multi-megabyte messages, new ones come from the heap and their memory stays resident after
being freed. Pinning the threshold keeps every large buffer mmapped, so it goes back to the OS when
freed: the provider's resident set then tracks its loaded tiles instead of its largest past messages.
"""

from __future__ import annotations

import ctypes

M_TRIM_THRESHOLD = -1  # mallopt parameter numbers (glibc malloc.h)
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 128 * 1024  # glibc's initial value, pinned
REUSE_MMAP_THRESHOLD_BYTES = 32 * 2**20  # glibc's largest mmap threshold on 64-bit
REUSE_TRIM_THRESHOLD_BYTES = 256 * 2**20  # free heap kept for reuse before it goes back to the OS


def _mallopt(settings: dict[int, int]) -> bool:
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return all([bool(mallopt(param, value)) for param, value in settings.items()])


def pin_mmap_threshold() -> bool:
    """Pins glibc's mmap threshold; False when the C library has no mallopt (not glibc)."""
    return _mallopt({M_MMAP_THRESHOLD: MMAP_THRESHOLD_BYTES})


def reuse_large_buffers() -> bool:
    """Serves buffers up to 32 MiB from the heap and keeps up to 256 MiB of freed heap for reuse, so
    repeated large temporaries stop faulting in fresh pages; False when not glibc. Memory stays bounded
    by the peak working set plus that reserve."""
    return _mallopt({M_MMAP_THRESHOLD: REUSE_MMAP_THRESHOLD_BYTES, M_TRIM_THRESHOLD: REUSE_TRIM_THRESHOLD_BYTES})
