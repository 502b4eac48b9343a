"""The load of the runs "with a CPU hog on one of the two cores": a busy loop pinned to core 1.

It runs in a session of its own: with the kernel's autogroup scheduling CPU is shared between sessions first, so a
busy loop in the caller's session would compete only with the caller."""

from __future__ import annotations

import shutil
import subprocess

CPU_HOG = ["taskset", "-c", "1", "python3", "-c", "while True: pass"]


def start_cpu_hog() -> subprocess.Popen:
    if shutil.which("taskset") is None:
        raise RuntimeError("a CPU hog needs taskset; install util-linux")
    return subprocess.Popen(CPU_HOG, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)


def stop_cpu_hog(hog: subprocess.Popen) -> None:
    if hog.poll() is None:
        hog.kill()
    hog.wait()
