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


TRIM_PROGRAM = """
from grid_puzzle_localization.malloc_tuning import limit_arenas, pin_mmap_threshold, trim_heap

def rss_kib():
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))

assert pin_mmap_threshold() and limit_arenas(1)
chunks = [bytearray(16000) for _ in range(5000)]  # 80 MB of heap chunks (below the mmap threshold)
del chunks[::2]  # every other one freed: 16 kB holes between live chunks, nothing free at the heap's top
# 40 MB freed; free() only gives back what lies past the last live chunk, so the holes stay resident.
held = rss_kib()
assert trim_heap()
released = held - rss_kib()
assert released > 25 * 1024, f"malloc_trim gave back only {released} KiB of 40 MB of holes"
"""


def test_trim_gives_the_holes_in_the_heap_back_to_the_os():
    result = subprocess.run([sys.executable, "-c", TRIM_PROGRAM], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
