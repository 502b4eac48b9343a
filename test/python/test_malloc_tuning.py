"""The mmap threshold pin: a freed multi-megabyte buffer leaves the resident set (glibc).

Checked in a fresh interpreter: in the pytest process, earlier tests (matplotlib rendering, large
arrays) leave big free chunks in the heap, and glibc serves a large request from them before it
considers mmap, whatever the threshold."""

import subprocess
import sys

CHECK = """
import numpy as np
from grid_puzzle_localization.malloc_tuning import pin_mmap_threshold

def rss_kib():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))

assert pin_mmap_threshold()
for _ in range(3):  # without the pin, glibc would raise its threshold after the first free
    buffer = np.ones(8 * 2**20, dtype=np.uint8)
    held = rss_kib()
    del buffer
    print(held - rss_kib())
"""


def test_freed_large_buffers_go_back_to_the_os():
    out = subprocess.run([sys.executable, "-c", CHECK], capture_output=True, text=True, check=True).stdout
    released_kib = [int(v) for v in out.split()]
    assert len(released_kib) == 3 and all(v > 6 * 1024 for v in released_kib)
