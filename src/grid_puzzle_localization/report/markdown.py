"""report.md from the experiment summary (see evaluation.summary)."""

from __future__ import annotations

from collections.abc import Mapping

from grid_puzzle_localization.evaluation.scan_times import SLOW_OVER_MEDIAN
from grid_puzzle_localization.experiment.modes import GRID_PUZZLE_MODES
from grid_puzzle_localization.report.format import MIB, change, mib, mode_title, num, times
from grid_puzzle_localization.report.headline import headline_section

PLOTS = {
    "cpu.png": "CPU over time per mode (100 % = one core)",
    "memory.png": "Memory (RSS) over time per mode",
    "trajectories.png": "Top-down trajectories over the map, with ground truth",
    "errors.png": "Position error over time",
}


def _paper_change(before: float, after: float, unit: str) -> str:
    return f"{after - before:+.1f}{unit} ({100 * (after - before) / before:+.1f} %)"


def comparison_table(summary: Mapping) -> list[str]:
    """Our figures (paper protocol, means), one column per grid puzzle mode run (the provider nodelet first,
    then the paper's setup), next to the paper's two datasets."""
    paper = summary["paper"]
    modes = summary["modes"]
    ours_modes = [m for m in GRID_PUZZLE_MODES if m in modes] or [GRID_PUZZLE_MODES[0]]
    base = modes.get("global", {}).get("resources", {}).get("paper", {})
    storage = summary.get("storage") or {}
    tiles = storage.get("tiles") or {}
    global_map = storage.get("global_map") or {}
    c, u = paper["courtyard"], paper["urban"]

    def mean(section: Mapping, metric: str) -> float | None:
        return (section.get(metric) or {}).get("mean")

    def mode_paper(mode: str) -> Mapping:
        return modes.get(mode, {}).get("resources", {}).get("paper", {})

    def reduction(mode: str, metric: str) -> Mapping | None:
        return summary.get("reductions", {}).get(mode, {}).get("paper", {}).get(metric, {}).get("mean")

    def rmse(mode: str) -> float | None:
        between = summary.get("between_modes", {}).get(f"{mode}_vs_global")
        return between["translation_m"]["rmse"] if between else None

    def row(figure: str, ours: list[str], courtyard: str, urban: str) -> str:
        return f"| {figure} | {' | '.join(ours)} | {courtyard} | {urban} |"

    def same(text: str) -> list[str]:
        return [text] * len(ours_modes)

    cpu, mem = c["cpu_percent_mean"], c["memory_mb_mean"]
    ucpu, umem = u["cpu_percent_mean"], u["memory_mb_mean"]
    lines = [
        row("figure (means; paper protocol)", [f"ours: {mode_title(m)}" for m in ours_modes], "paper courtyard",
            "paper urban"),
        "|---|" + "---:|" * (len(ours_modes) + 2),
        row("CPU, global map [% of one core]", same(num(mean(base, "cpu_percent"))), f"{cpu['global']:.1f}",
            f"{ucpu['global']:.1f}"),
        row("CPU, grid puzzle [% of one core]", [num(mean(mode_paper(m), "cpu_percent")) for m in ours_modes],
            f"{cpu['grid_puzzle']:.1f}", f"{ucpu['grid_puzzle']:.1f}"),
        row("CPU change", [change(reduction(m, "cpu_percent"), unit=" pts") for m in ours_modes],
            _paper_change(cpu["global"], cpu["grid_puzzle"], " pts"),
            _paper_change(ucpu["global"], ucpu["grid_puzzle"], " pts")),
        row("Memory, global map [MiB ours RSS; MB paper]", same(mib(mean(base, "rss_bytes"))), f"{mem['global']:.1f}",
            f"{umem['global']:.1f}"),
        row("Memory, grid puzzle [MiB ours RSS; MB paper]", [mib(mean(mode_paper(m), "rss_bytes")) for m in ours_modes],
            f"{mem['grid_puzzle']:.1f}", f"{umem['grid_puzzle']:.1f}"),
        row("Memory change", [change(reduction(m, "rss_bytes"), MIB, " MiB") for m in ours_modes],
            _paper_change(mem["global"], mem["grid_puzzle"], " MB"),
            _paper_change(umem["global"], umem["grid_puzzle"], " MB")),
        row("Trajectory RMSE, grid puzzle vs global [m]", [num(rmse(m), ".4f") for m in ours_modes],
            f"{c['rmse_between_modes_m']:.4f}", f"{u['rmse_between_modes_m']:.4f}"),
        row("Storage overhead (tile data bytes minus map data bytes)",
            same(num(tiles.get("data_overhead_bytes"), ",.0f")), str(c["storage_overhead_bytes"]),
            str(u["storage_overhead_bytes"])),
        row("Tile files", same(num(tiles.get("files"), ",.0f")), f"{c['tile_files']:,}", f"{u['tile_files']:,}"),
        row("Global map size [MB]", same(num(None if not global_map else global_map["bytes"] / 1e6, ",.1f")),
            f"{c['global_map_mb']:,.1f}", f"{u['global_map_mb']:,.1f}"),
    ]  # fmt: skip
    return lines


def resources_table(summary: Mapping) -> list[str]:
    lines = [
        "| mode | protocol | processes | CPU mean [%] | CPU p95 [%] | RSS mean [MiB] | RSS p95 [MiB] "
        "| PSS mean [MiB] | PSS p95 [MiB] |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for mode, m in summary["modes"].items():
        for protocol, r in m["resources"].items():
            lines.append(
                f"| {mode_title(mode)} | {protocol} | {', '.join(r['processes'])} "
                f"| {num(r['cpu_percent']['mean'])} | {num(r['cpu_percent']['p95'])} "
                f"| {mib(r['rss_bytes']['mean'])} | {mib(r['rss_bytes']['p95'])} "
                f"| {mib(r['pss_bytes']['mean'])} | {mib(r['pss_bytes']['p95'])} |"
            )
    return lines


def reductions_table(summary: Mapping) -> list[str]:
    lines = [
        "| mode vs global | protocol | CPU mean | CPU p95 | RSS mean | RSS p95 | PSS mean | PSS p95 |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for mode, by_protocol in summary.get("reductions", {}).items():
        for protocol, r in by_protocol.items():
            cells = [change(r["cpu_percent"][s], unit=" pts") for s in ("mean", "p95")]
            cells += [change(r[m][s], MIB, " MiB") for m in ("rss_bytes", "pss_bytes") for s in ("mean", "p95")]
            lines.append(f"| {mode_title(mode)} | {protocol} | " + " | ".join(cells) + " |")
    return lines


def map_memory_table(summary: Mapping) -> list[str]:
    """Per mode and process: mean RSS, mean RSS against an empty map, their difference (the map's memory),
    then each protocol's sum and its ratio to the global map's. Empty when no empty-map run was made."""
    ratios = summary.get("map_memory_ratios", {})
    lines = [
        "| mode | process | RSS mean [MiB] | RSS with an empty map [MiB] | map memory [MiB] | vs global map |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for mode, m in summary["modes"].items():
        memory = m.get("map_memory")
        if memory is None:
            continue
        title = mode_title(mode)
        for name, p in memory["processes"].items():
            lines.append(
                f"| {title} | {name} | {mib(p['rss_bytes_mean'])} | {mib(p['empty_map_rss_bytes_mean'])} "
                f"| {mib(p['map_bytes'])} | |"
            )
        for protocol in ("paper", "total"):
            ratio = 1.0 if mode == summary["baseline_mode"] else ratios.get(mode, {}).get(protocol)
            lines.append(
                f"| {title} | {protocol} protocol | | | {mib(memory[protocol]['map_bytes'])} | {times(ratio)} |"
            )
    return lines if len(lines) > 2 else []


def accuracy_table(summary: Mapping) -> list[str]:
    lines = [
        "| trajectory | reference | pairs | transl. RMSE [m] | transl. median [m] | transl. max [m] "
        "| rot. RMSE [deg] | rot. median [deg] | rot. max [deg] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    entries = [(mode_title(mode), "ground truth", m["ape"]) for mode, m in summary["modes"].items()]
    entries += [(mode_title(key.split("_vs_")[0]), "global map run", e) for key, e in summary["between_modes"].items()]
    for name, ref, e in entries:
        if e is None:
            lines.append(f"| {name} | {ref} | – | – | – | – | – | – | – |")
            continue
        t, r = e["translation_m"], e["rotation_deg"]
        lines.append(
            f"| {name} | {ref} | {t['pairs']} | {t['rmse']:.4f} | {t['median']:.4f} | {t['max']:.4f} "
            f"| {r['rmse']:.3f} | {r['median']:.3f} | {r['max']:.3f} |"
        )
    return lines


def scan_time_table(summary: Mapping) -> list[str]:
    """The localizer's time per scan (the paper's Table III), when the run recorded it."""
    rows = [(mode, m.get("scan_time_ms")) for mode, m in summary["modes"].items()]
    if not any(t for _, t in rows):
        return ["No per-scan times were recorded."]
    fusion = summary["scenario"].get("fusion", "–")
    lines = [
        "| mode | fusion | scans | mean [ms] | median [ms] | p95 [ms] | p99 [ms] | max [ms] "
        f"| over {SLOW_OVER_MEDIAN:g}x median | of them with hypotheses / search "
        "| NDT iterations, median of them / of all |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for mode, t in rows:
        if t:
            slow = t.get("slow_scans")
            what = (
                "– | – | –"
                if not slow
                else f"{slow['scans']} | {slow['with_hypotheses']} / {slow['with_search']} "
                f"| {num(slow['median_iterations'])} / {num(slow['median_iterations_all'])}"
            )
            lines.append(
                f"| {mode_title(mode)} | {fusion} | {t['scans']} | {num(t['mean'])} "
                f"| {num(t['median'])} | {num(t.get('p95'))} | {num(t.get('p99'))} | {num(t.get('max'))} | {what} |"
            )
    return lines


def start_setting(start: Mapping | None) -> str:
    """What the localizer was given at the start, in words."""
    if not start:
        return "the start pose (initial_pose and initialpose)"
    mode = start.get("mode")
    if mode == "hint":
        x, y = start["hint_xy"]
        return f"no pose; a hint at ({x:.1f}, {y:.1f}) m (sigma {start['hint_sigma_m']:g} m) on initialpose_hint"
    if mode == "none":
        return "no pose and no hint: the localizer's global search over its map"
    text = "the start pose (initial_pose and initialpose)"
    if start.get("offset_m") or start.get("offset_deg"):
        text += f", moved {start['offset_m']:g} m and turned {start['offset_deg']:g} deg from the first reference pose"
    return text


def start_table(summary: Mapping) -> list[str]:
    """Per mode: the first published pose and the first from an accepted match, after the first played scan, with
    their errors then."""
    rows = [(mode, m.get("start")) for mode, m in summary["modes"].items()]
    if not any(s for _, s in rows):
        return ["The first played scan's stamp was not recorded: no start figures."]

    def cells(pose: Mapping | None) -> str:
        if pose is None:
            return "never | – | –"
        after, error = num(pose["after_s"], ".2f"), num(pose["translation_error_m"], ".2f")
        return f"{after} | {error} | {num(pose['yaw_error_deg'])}"

    lines = [
        f"Start: {start_setting(summary.get('start'))}.",
        "",
        "| mode | first pose after [s] | its error [m] | its yaw error [deg] "
        "| first accepted pose after [s] | its error [m] | its yaw error [deg] |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for mode, s in rows:
        if s:
            accepted = cells(s["first_accepted_pose"]) if "first_accepted_pose" in s else "– | – | –"
            lines.append(f"| {mode_title(mode)} | {cells(s['first_pose'])} | {accepted} |")
    return lines


def storage_table(summary: Mapping) -> list[str]:
    storage = summary.get("storage")
    if not storage:
        return ["No storage figures (no map or tiles were given)."]
    lines = [
        "| map | files | bytes | point data bytes | header bytes | filesystem-block overhead bytes "
        "| overlap factor | mean bytes per file |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    labels = {
        "global_map": "global map",
        "tiles": "grid puzzle tiles",
        "block_maps": "keyframe-stitched block maps",
        "fixed_submaps": "fixed-size overlapping submaps",
    }
    for key, label in labels.items():
        s = storage.get(key)
        if s:
            overlap = f"{s['overlap_factor']:.3f}" if "overlap_factor" in s else "–"
            mean = f"{s['mean_bytes_per_file']:,.0f}" if "mean_bytes_per_file" in s else "–"
            lines.append(
                f"| {label} | {s['files']:,} | {s['bytes']:,} | {s['data_bytes']:,} "
                f"| {s['header_bytes']:,} | {s['disk_bytes'] - s['bytes']:,} | {overlap} | {mean} |"
            )
    lines += [
        "",
        "Overlap factor: stored points / map points (the map the files represent; for the block maps, the",
        "union of the blocks). 1 means no point is stored twice.",
    ]
    return lines


def map_memory_section(summary: Mapping) -> list[str]:
    table = map_memory_table(summary)
    if not table:
        return []
    return [
        "### Map memory per process",
        "",
        *table,
        "",
        "A process's map memory is its mean RSS minus its mean RSS when the same launch plays the start of the",
        "bag against an empty map (its floor: libraries, ROS, scan buffers).",
        "",
    ]


def printed_tables(summary: Mapping) -> list[str]:
    """What `gpm experiment` and `gpm report` print: the grid puzzle modes against the global map, then our
    figures next to the paper's."""
    return [*headline_section(summary), *comparison_table(summary)]


def render_report(summary: Mapping) -> str:
    """The whole report.md."""
    sc = summary["scenario"]
    setting = ", ".join(f"{k} = {v}" for k, v in sc.items() if not isinstance(v, (Mapping, list)))
    lines = [
        "# Grid puzzle map experiment",
        "",
        f"Setting: {setting}.",
        "",
        "## Grid puzzle against the global map",
        "",
        *headline_section(summary),
        "## Our figures next to the paper's",
        "",
        *comparison_table(summary),
        "",
        "Paper protocol, as the paper summed: the NDT localizer's process alone in global-map mode, plus the map",
        "provider's process when it has one (the paper's setup). CPU is in percent of one core (200 % = two cores",
        'busy); "pts" are percentage points. Our memory is psutil\'s RSS in MiB; the paper printed MB.',
        "",
        "## CPU and memory per mode",
        "",
        *resources_table(summary),
        "",
        "The total protocol counts every process of the mode's launch (with the loaders when it has any). PSS splits",
        "shared pages between the processes that share them, so it does not double-count libraries when",
        "processes are summed.",
        "",
        "### Change against the global map",
        "",
        *reductions_table(summary),
        "",
        *map_memory_section(summary),
        "## Accuracy",
        "",
        *accuracy_table(summary),
        "",
        "Against ground truth, the ground truth is interpolated at each estimated pose's time (linear in",
        "position, slerp in rotation). Between runs, each pose of the shorter trajectory is paired with the",
        f"nearest pose of the other within {summary['max_time_diff_s']} s, as evo does. No alignment is applied",
        '(all trajectories are in the map frame). "global map run" is the paper\'s figure: the grid puzzle',
        "trajectory against the global map trajectory.",
        "",
        "## Start",
        "",
        *start_table(summary),
        "",
        "Times are bag time from the first played scan's stamp. The first pose is the first one published (with a",
        "start pose, the localizer may publish its prediction from it before a match is accepted); the first",
        "accepted pose is the first published for a scan whose match the localizer accepted (its ~status). Errors",
        "are against the reference at that pose's stamp: position, and yaw alone.",
        "",
        "## Time per scan",
        "",
        *scan_time_table(summary),
        "",
        "The localizer's own time for each scan (NdtStatus scan_time_ms): preprocessing, the NDT match with any",
        "hypotheses or search, and the sliding window's update when fusion is on. The scans that took more than",
        f"{SLOW_OVER_MEDIAN:g} times the median: how many ran the hypotheses (candidates tried after a poor match) or",
        "the search, and their NDT iterations against every scan's.",
        "",
        "## Storage",
        "",
        *storage_table(summary),
        "",
        "## Plots",
        "",
    ]
    for name, caption in PLOTS.items():
        lines += [f"![{caption}](plots/{name})", ""]
    return "\n".join(lines)
