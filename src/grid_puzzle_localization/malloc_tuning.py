"""glibc malloc tuning for long-running processes that build large transient buffers.

glibc raises its mmap threshold each time a large mmapped block is freed (up to 32 MiB), so after the
first few multi-megabyte messages, new ones come from the heap and their memory stays resident after
being freed. Pinning the threshold keeps every large buffer mmapped, so it goes back to the OS when
freed: the provider's resident set then tracks its loaded tiles instead of its largest past messages.
"""

from __future__ import annotations

import ctypes

M_MMAP_THRESHOLD = -3  # mallopt parameter number (glibc malloc.h)
MMAP_THRESHOLD_BYTES = 128 * 1024  # glibc's initial value, pinned


def pin_mmap_threshold() -> bool:
    """Pins glibc's mmap threshold; False when the C library has no mallopt (not glibc)."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES))
