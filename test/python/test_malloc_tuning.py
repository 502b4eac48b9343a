"""The mmap threshold pin: a freed multi-megabyte buffer leaves the resident set (glibc)."""

import numpy as np

from grid_puzzle_localization.malloc_tuning import pin_mmap_threshold


def rss_kib():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))


def test_freed_large_buffers_go_back_to_the_os():
    assert pin_mmap_threshold()
    for _ in range(3):  # without the pin, glibc would raise its threshold after the first free
        buffer = np.ones(8 * 2**20, dtype=np.uint8)
        held = rss_kib()
        del buffer
        assert held - rss_kib() > 6 * 1024
