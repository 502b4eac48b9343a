#!/usr/bin/env python3
"""Cost of one monitor sample (CPU times + memory_full_info per process) against the number of
watched processes, each holding 64 MiB. Prints one JSON line per process count: the median over
repeats of the time per sample, per process, and the monitor's own CPU share at a 1 s interval.
--quick: one process, 3 repeats (checks that it runs)."""

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np
from hardware import cpu_model

from grid_puzzle_localization.monitor import Monitor, Target

HOLDER = "import sys, time; block = b'\\x01' * (64 << 20); print('ready', flush=True); time.sleep(3600)"
REPEATS = 40


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one process, 3 repeats: checks that it runs")
    args = parser.parse_args()
    counts, repeats = ((1,), 3) if args.quick else ((1, 4, 16), REPEATS)
    for count in counts:
        children = [subprocess.Popen([sys.executable, "-c", HOLDER], stdout=subprocess.PIPE) for _ in range(count)]
        try:
            for c in children:
                c.stdout.readline()
            monitor = Monitor([Target.from_pid(c.pid) for c in children], interval=1.0)
            monitor.sample()
            wall, cpu = [], []
            for _ in range(repeats):
                w0, c0 = time.perf_counter(), time.process_time()
                monitor.sample()
                wall.append(time.perf_counter() - w0)
                cpu.append(time.process_time() - c0)
        finally:
            for c in children:
                c.kill()
                c.wait()
        sample_ms = 1e3 * float(np.median(wall))
        print(
            json.dumps(
                {
                    "bench": "monitor_sample",
                    "processes": count,
                    "rss_per_process_mib": 64,
                    "sample_ms": round(sample_ms, 3),
                    "per_process_ms": round(sample_ms / count, 3),
                    "monitor_cpu_percent_at_1s_interval": round(100 * float(np.median(cpu)), 3),
                    "repeats": repeats,
                    "cpu_model": cpu_model(),
                    "cores": os.cpu_count(),
                    "threads_used": 1,
                }
            )
        )


if __name__ == "__main__":
    main()
