"""Resource monitor: CPU and memory of a set of processes, sampled at a fixed interval.

CPU is in percent of one core (100 = one core fully busy, 253 = about 2.5 cores), as in the grid
puzzle paper; memory is in bytes (RSS, and USS/PSS where the kernel exposes them). No ROS here:
PIDs come from a resolver callable, which ``grid_puzzle_localization.ros.node_pids`` provides for ROS
node names.
"""

from grid_puzzle_localization.monitor.log import METRICS, Event, MonitorLog, read_csv, write_csv
from grid_puzzle_localization.monitor.sampler import Monitor, Target
from grid_puzzle_localization.monitor.stats import describe, summarize

__all__ = [
    "METRICS",
    "Event",
    "Monitor",
    "MonitorLog",
    "Target",
    "describe",
    "read_csv",
    "summarize",
    "write_csv",
]
