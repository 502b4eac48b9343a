"""Test helper: which processes still belong to a ROS master (by their ROS_MASTER_URI)."""

from __future__ import annotations

import psutil


def processes_on(master_uri: str) -> list[int]:
    """PIDs of processes whose environment points at ``master_uri``."""
    pids = []
    for p in psutil.process_iter():
        try:
            if p.environ().get("ROS_MASTER_URI") == master_uri:
                pids.append(p.pid)
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            pass
    return pids
