"""The mmap threshold pin: a freed multi-megabyte buffer leaves the resident set (glibc).

Runs in a fresh interpreter: the allocator state of the pytest process depends on every test that
ran before (arenas, earlier mallopt calls), which is not what this test is about."""

import subprocess
import sys

PROGRAM = """
import numpy as np
from grid_puzzle_localization.util.malloc_tuning import pin_mmap_threshold

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


REUSE_PROGRAM = """
import resource
import sys
import numpy as np
from grid_puzzle_localization.util.malloc_tuning import reuse_large_buffers

if sys.argv[1] == "tuned":
    assert reuse_large_buffers()
faults = []
for _ in range(5):  # three 8 MiB temporaries at a time, as a sweep's numpy maths makes them
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    buffers = [np.ones(8 * 2**20, dtype=np.uint8) for _ in range(3)]
    del buffers
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(max(faults[1:]))
"""


def _faults_after_warm_up(mode: str) -> int:
    result = subprocess.run([sys.executable, "-c", REUSE_PROGRAM, mode], capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stderr
    return int(result.stdout)


def test_reused_large_buffers_do_not_fault_pages_in_again():
    # glibc's default trims the freed 24 MiB and faults it in again on the next round (about 1000 faults
    # of 4 KiB pages per round).
    assert _faults_after_warm_up("tuned") < 64
    assert _faults_after_warm_up("default") > 4 * 64


TRIM_PROGRAM = """
from grid_puzzle_localization.util.malloc_tuning import limit_arenas, pin_mmap_threshold, trim_heap

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
