"""The report's first section: the grid puzzle modes against the global map, CPU and memory under both
protocols and the map memory per process. What a user gets (the provider nodelet, grid_puzzle) comes
first, then the paper's setup (the rospy provider, grid_puzzle_rospy)."""

from __future__ import annotations

from collections.abc import Mapping

from grid_puzzle_localization.evaluation.repeats import ratio
from grid_puzzle_localization.evaluation.resources import PROTOCOLS
from grid_puzzle_localization.experiment.modes import GRID_PUZZLE_MODES
from grid_puzzle_localization.report.format import mib, mode_title, num, times


def headline_modes(summary: Mapping) -> list[str]:
    """The baseline and the grid puzzle modes that the summary holds, in that order."""
    return [m for m in (summary["baseline_mode"], *GRID_PUZZLE_MODES) if m in summary["modes"]]


def repeat_count(summary: Mapping) -> int:
    """Runs of each mode (1 when the summary has no repeats section)."""
    return (summary.get("repeats") or {}).get("count", 1)


def _x(value: float) -> str:
    return f"{value:.2f}"


def _range(spread: Mapping | None, fmt) -> str:
    """A spread entry's "min–max"; "–" when missing."""
    if not spread or spread.get("min") is None:
        return "–"
    return f"{fmt(spread['min'])}–{fmt(spread['max'])}"


def resources_vs_global_table(summary: Mapping) -> list[str]:
    """Per protocol and mode: mean CPU and mean RSS, each with its ratio to the baseline's. With repeated runs the
    figures are medians, and the CPU means' range and each figure's range of per-round ratios are added."""
    modes = summary["modes"]
    base = modes.get(summary["baseline_mode"], {}).get("resources", {})
    repeated = repeat_count(summary) > 1
    spread = (summary.get("repeats") or {}).get("spread", {})
    if repeated:
        lines = [
            "| protocol | mode | processes | CPU mean [% of one core], median | runs, min–max | vs global "
            "| per round, min–max | RSS mean [MiB], median | vs global | per round, min–max |",
            "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
        ]
    else:
        lines = [
            "| protocol | mode | processes | CPU mean [% of one core] | vs global | RSS mean [MiB] | vs global |",
            "|---|---|---|---:|---:|---:|---:|",
        ]
    for protocol in PROTOCOLS:
        for mode in headline_modes(summary):
            r = modes[mode]["resources"][protocol]
            b = base.get(protocol)
            cpu, rss = r["cpu_percent"]["mean"], r["rss_bytes"]["mean"]
            cpu_ratio = ratio(cpu, b["cpu_percent"]["mean"]) if b else None
            rss_ratio = ratio(rss, b["rss_bytes"]["mean"]) if b else None
            if repeated:
                s = spread.get(mode, {}).get(protocol, {})
                cpu_s, rss_s = s.get("cpu_percent", {}), s.get("rss_bytes", {})
                lines.append(
                    f"| {protocol} | {mode_title(mode)} | {', '.join(r['processes'])} | {num(cpu)} "
                    f"| {_range(cpu_s, num)} | {times(cpu_ratio)} | {_range(cpu_s.get('vs_baseline'), _x)} "
                    f"| {mib(rss)} | {times(rss_ratio)} | {_range(rss_s.get('vs_baseline'), _x)} |"
                )
            else:
                lines.append(
                    f"| {protocol} | {mode_title(mode)} | {', '.join(r['processes'])} | {num(cpu)} "
                    f"| {times(cpu_ratio)} | {mib(rss)} | {times(rss_ratio)} |"
                )
    return lines


def repeats_note(summary: Mapping) -> list[str]:
    """What the figures of repeated runs are (markdown lines); none for a single run of each mode."""
    n = repeat_count(summary)
    if n <= 1:
        return []
    return [
        f"Each mode ran {n} times, interleaved: every mode once per round, then the next round. CPU and memory",
        f"figures are the medians of the {n} runs (the reductions too, computed from them). Runs: the range of the",
        "runs' CPU means. Per round: the range of each run's figure over the global map's run of the same round,",
        "which shares the state of the machine. Map memory, accuracy, start, time per scan and the plots come from",
        "each mode's first run.",
        "",
    ]


def map_memory_split_table(summary: Mapping) -> list[str]:
    """Per mode: the map memory of the localizer's nodelet manager (which also holds the provider nodelet in
    grid_puzzle mode) and of a provider process of its own (the paper's setup), then each protocol's sum and
    its ratio to the baseline's. Empty when no empty-map run was made."""
    ratios = summary.get("map_memory_ratios", {})
    lines = [
        "| mode | localizer's nodelet manager [MiB] | provider process [MiB] | paper protocol [MiB] | vs global "
        "| total protocol [MiB] | vs global |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for mode in headline_modes(summary):
        m = summary["modes"][mode]
        memory = m.get("map_memory")
        if memory is None:
            continue
        manager = m["roles"]["localizer"]
        provider = m["roles"].get("map_provider", manager)
        cells = [mib(memory["processes"].get(manager, {}).get("map_bytes"))]
        cells.append("–" if provider == manager else mib(memory["processes"].get(provider, {}).get("map_bytes")))
        for protocol in PROTOCOLS:
            r = 1.0 if mode == summary["baseline_mode"] else ratios.get(mode, {}).get(protocol)
            cells += [mib(memory[protocol]["map_bytes"]), times(r)]
        lines.append(f"| {mode_title(mode)} | " + " | ".join(cells) + " |")
    return lines if len(lines) > 2 else []


def headline_section(summary: Mapping) -> list[str]:
    """Both tables with what they count (markdown lines)."""
    lines = [
        *repeats_note(summary),
        *resources_vs_global_table(summary),
        "",
        "The paper protocol counts the NDT localizer's nodelet manager alone in global-map mode, and the processes",
        "that localize and serve the tiles in the grid puzzle modes: the same manager alone with the provider",
        "nodelet (grid puzzle), the manager plus the rospy provider in the paper's setup. The total protocol counts",
        "every process of the stack. CPU is in percent of one core; memory is RSS.",
        "",
    ]
    split = map_memory_split_table(summary)
    if split:
        lines += [
            *split,
            "",
            "Map memory: a process's mean RSS minus its mean RSS when the same launch plays the start of the bag",
            "against an empty map. With the provider nodelet, the provider's map memory is in the manager's column.",
            "",
        ]
    return lines
