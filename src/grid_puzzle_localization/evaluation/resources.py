"""CPU and memory per mode under two accounting protocols, and reductions between modes.

- ``paper``: the processes the grid puzzle paper summed: the NDT localizer alone in global-map mode,
  the localizer plus the map provider in the grid puzzle (and block-map) modes. Each process counts once:
  with the provider nodelet (grid_puzzle mode) that is the localizer's nodelet manager alone; with the
  rospy provider (grid_puzzle_rospy, the paper's setup) the manager plus the provider's process.
- ``total``: every process of the mode (the localization process or a nodelet manager with its loaders, provider,
  helpers).

CPU is in percent of one core; memory in bytes (RSS as psutil reports it, the paper's figure; PSS
where available, which does not double-count pages shared between the summed processes).

Map memory is what the map costs a process: its mean RSS minus its mean RSS in a run of the same launch
against an empty map (the process's floor: libraries, ROS, scan buffers)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.monitor.log import MonitorLog
from grid_puzzle_localization.monitor.stats import describe

PROTOCOLS = ("paper", "total")
# Roles whose processes the paper summed, per mode. The block map server plays the provider's role.
PAPER_ROLES: dict[str, tuple[str, ...]] = {
    "global": ("localizer",),
    "grid_puzzle": ("localizer", "map_provider"),
    "grid_puzzle_rospy": ("localizer", "map_provider"),
    "block_map": ("localizer", "map_provider"),
}
RESOURCE_METRICS = ("cpu_percent", "rss_bytes", "pss_bytes", "uss_bytes")


def protocol_processes(mode: str, roles: Mapping[str, str], log: MonitorLog, protocol: str) -> list[str]:
    """Names of the monitored processes counted under ``protocol`` for ``mode``, each once. ``roles`` maps
    a role (``localizer``, ``map_provider``) to the process name in the log; two roles may name the same
    process (a nodelet provider in the localizer's manager)."""
    if protocol == "total":
        return list(log.names)
    if protocol != "paper":
        raise UserError(f"unknown accounting protocol '{protocol}' (use one of {PROTOCOLS})")
    if mode not in PAPER_ROLES:
        raise UserError(f"unknown mode '{mode}' (use one of {sorted(PAPER_ROLES)})")
    missing = [r for r in PAPER_ROLES[mode] if r not in roles]
    if missing:
        raise UserError(f"mode {mode} needs the process of role(s) {missing} for the paper protocol")
    return list(dict.fromkeys(roles[r] for r in PAPER_ROLES[mode]))


def resource_stats(log: MonitorLog, names: Sequence[str]) -> dict[str, dict]:
    """mean/median/p95/max of each metric summed over ``names`` per sample."""
    return {m: describe(log.sum(m, list(names))) for m in RESOURCE_METRICS}


def mode_resources(mode: str, roles: Mapping[str, str], log: MonitorLog) -> dict[str, dict]:
    """Both protocols for one mode: {protocol: {"processes": [...], metric: stats}}."""
    out = {}
    for protocol in PROTOCOLS:
        names = protocol_processes(mode, roles, log, protocol)
        out[protocol] = {"processes": names} | resource_stats(log, names)
    return out


def reduction(baseline: float | None, value: float | None) -> dict[str, float | None]:
    """Change from ``baseline`` to ``value``: absolute (value - baseline, in the figure's unit) and
    relative [% of the baseline]; negative means a reduction."""
    if baseline is None or value is None:
        return {"absolute": None, "relative_percent": None}
    return {
        "absolute": value - baseline,
        "relative_percent": 100.0 * (value - baseline) / baseline if baseline else None,
    }


def compare_to_baseline(resources: Mapping[str, Mapping], baseline: str = "global") -> dict[str, dict]:
    """For each non-baseline mode, protocol and metric: the reduction of the mean and of the p95."""
    if baseline not in resources:
        raise UserError(f"the comparison needs the {baseline} mode's resources (have {sorted(resources)})")
    out: dict[str, dict] = {}
    for mode, by_protocol in resources.items():
        if mode == baseline:
            continue
        out[mode] = {
            protocol: {
                m: {
                    stat: reduction(resources[baseline][protocol][m][stat], by_protocol[protocol][m][stat])
                    for stat in ("mean", "p95")
                }
                for m in RESOURCE_METRICS
            }
            for protocol in PROTOCOLS
        }
    return out


def map_memory(mode: str, roles: Mapping[str, str], log: MonitorLog, empty_map: MonitorLog) -> dict:
    """Per process and per protocol: mean RSS, mean RSS of the empty-map run, and their difference
    (``map_bytes``; None for a process the empty-map run did not see)."""
    processes = {}
    for name in log.names:
        full = describe(log.sum("rss_bytes", [name]))["mean"]
        empty = describe(empty_map.sum("rss_bytes", [name]))["mean"] if name in empty_map.names else None
        processes[name] = {
            "rss_bytes_mean": full,
            "empty_map_rss_bytes_mean": empty,
            "map_bytes": None if full is None or empty is None else full - empty,
        }
    out: dict = {"processes": processes}
    for protocol in PROTOCOLS:
        names = protocol_processes(mode, roles, log, protocol)
        parts = [processes[n]["map_bytes"] for n in names]
        out[protocol] = {"processes": names, "map_bytes": None if None in parts else sum(parts)}
    return out


def map_memory_ratios(map_memories: Mapping[str, Mapping], baseline: str = "global") -> dict[str, dict]:
    """For each non-baseline mode and protocol: its map memory over the baseline's (None when either is
    missing or the baseline's is not positive)."""
    base = map_memories.get(baseline)
    out: dict[str, dict] = {}
    for mode, mem in map_memories.items():
        if mode == baseline:
            continue
        out[mode] = {}
        for protocol in PROTOCOLS:
            b = None if base is None else base[protocol]["map_bytes"]
            v = mem[protocol]["map_bytes"]
            out[mode][protocol] = v / b if b is not None and v is not None and b > 0 else None
    return out
