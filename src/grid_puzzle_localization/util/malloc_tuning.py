"""glibc malloc tuning for long-running processes that build large transient buffers and churn many
small ones (the provider's tiles), and for batch jobs that reuse large temporaries (the simulator).

- glibc raises its mmap threshold each time a large mmapped block is freed (up to 32 MiB), so after
  the first few multi-megabyte messages, new ones come from the heap and their memory stays resident
  after being freed. Pinning the threshold (:func:`pin_mmap_threshold`) keeps every large buffer
  mmapped, so it goes back to the OS when freed: the resident set then tracks the loaded tiles instead
  of the largest past messages.
- Every thread that meets contention gets an arena of its own (up to 8 per core), each keeping freed
  memory for itself; rospy runs a dozen threads. One arena (:func:`limit_arenas`) keeps the freed
  tiles of every thread in one place for reuse.
- Freed small chunks inside a heap stay resident until malloc_trim (:func:`trim_heap`) hands their
  pages back.
- The opposite need: a batch job that allocates and frees the same multi-megabyte numpy temporaries
  thousands of times, where mmapping each one costs a page fault per 4 KiB on first touch
  (:func:`reuse_large_buffers`).
"""

from __future__ import annotations

import ctypes
import functools

M_TRIM_THRESHOLD = -1  # mallopt parameter numbers (glibc malloc.h)
M_MMAP_THRESHOLD = -3
M_ARENA_MAX = -8
MMAP_THRESHOLD_BYTES = 128 * 1024  # glibc's initial value, pinned
REUSE_MMAP_THRESHOLD_BYTES = 32 * 2**20  # glibc's largest mmap threshold on 64-bit
REUSE_TRIM_THRESHOLD_BYTES = 256 * 2**20  # free heap kept for reuse before it goes back to the OS


@functools.lru_cache(maxsize=None)
def _libc():
    """The C library when it is glibc (has mallopt and malloc_trim), else None."""
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
    except (OSError, AttributeError):
        return None
    return libc


def _mallopt(settings: dict[int, int]) -> bool:
    libc = _libc()
    return libc is not None and all([bool(libc.mallopt(param, value)) for param, value in settings.items()])


def pin_mmap_threshold() -> bool:
    """Pins glibc's mmap threshold; False when the C library is not glibc."""
    return _mallopt({M_MMAP_THRESHOLD: MMAP_THRESHOLD_BYTES})


def limit_arenas(count: int = 1) -> bool:
    """Caps the number of malloc arenas (call before starting threads); False when not glibc."""
    return _mallopt({M_ARENA_MAX: count})


def trim_heap() -> bool:
    """Returns the free pages of every arena to the OS; True when memory was released."""
    libc = _libc()
    return libc is not None and bool(libc.malloc_trim(0))


def reuse_large_buffers() -> bool:
    """Serves buffers up to 32 MiB from the heap and keeps up to 256 MiB of freed heap for reuse, so
    repeated large temporaries stop faulting in fresh pages; False when not glibc. Memory stays bounded
    by the peak working set plus that reserve."""
    return _mallopt({M_MMAP_THRESHOLD: REUSE_MMAP_THRESHOLD_BYTES, M_TRIM_THRESHOLD: REUSE_TRIM_THRESHOLD_BYTES})
