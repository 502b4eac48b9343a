"""The mmap threshold pin: a freed multi-megabyte buffer leaves the resident set (glibc).

Runs in a fresh interpreter: the allocator state of the pytest process depends on every test that
ran before (arenas, earlier mallopt calls), which is not what this test is about."""

import subprocess
import sys

PROGRAM = """
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
    released = held - rss_kib()
    assert released > 6 * 1024, f"only {released} KiB of an 8 MiB buffer went back to the OS"
"""


def test_freed_large_buffers_go_back_to_the_os():
    result = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
