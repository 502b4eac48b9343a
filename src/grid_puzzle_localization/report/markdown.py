"""report.md from the experiment summary (see evaluation.summary)."""

from __future__ import annotations

from collections.abc import Mapping

MIB = 1024.0 * 1024.0
MODE_TITLES = {"global": "global map", "grid_puzzle": "grid puzzle", "block_map": "block map"}
PLOTS = {
    "cpu.png": "CPU over time per mode (100 % = one core)",
    "memory.png": "Memory (RSS) over time per mode",
    "trajectories.png": "Top-down trajectories with ground truth",
    "errors.png": "Position error over time",
}


def _num(value: float | None, fmt: str = ".1f", suffix: str = "") -> str:
    return "–" if value is None else f"{value:{fmt}}{suffix}"


def _mib(value: float | None) -> str:
    return _num(None if value is None else value / MIB, ".1f")


def _change(change: Mapping | None, scale: float = 1.0, unit: str = "") -> str:
    if not change or change.get("absolute") is None:
        return "–"
    rel = change.get("relative_percent")
    rel_text = "" if rel is None else f" ({rel:+.1f} %)"
    return f"{change['absolute'] / scale:+.1f}{unit}{rel_text}"


def _paper_change(before: float, after: float, unit: str) -> str:
    return f"{after - before:+.1f}{unit} ({100 * (after - before) / before:+.1f} %)"


def comparison_table(summary: Mapping, mode: str = "grid_puzzle") -> list[str]:
    """Our figures (paper protocol, means) next to the paper's two datasets."""
    paper = summary["paper"]
    modes = summary["modes"]
    ours_base = modes.get("global", {}).get("resources", {}).get("paper", {})
    ours_mode = modes.get(mode, {}).get("resources", {}).get("paper", {})
    change = summary.get("reductions", {}).get(mode, {}).get("paper", {})
    between = summary.get("between_modes", {}).get(f"{mode}_vs_global")
    storage = summary.get("storage") or {}
    tiles = storage.get("tiles") or {}
    global_map = storage.get("global_map") or {}

    def ours(section: Mapping, metric: str) -> float | None:
        return (section.get(metric) or {}).get("mean")

    c, u = paper["courtyard"], paper["urban"]
    lines = [
        "| figure (means; paper protocol) | ours | paper courtyard | paper urban |",
        "|---|---:|---:|---:|",
    ]
    for m, title in (("global", "global map"), ("grid_puzzle", "grid puzzle")):
        value = ours(ours_base if m == "global" else ours_mode, "cpu_percent")
        lines.append(
            f"| CPU, {title} [% of one core] | {_num(value)} "
            f"| {c['cpu_percent_mean'][m]:.1f} | {u['cpu_percent_mean'][m]:.1f} |"
        )
    lines.append(
        f"| CPU change | {_change((change or {}).get('cpu_percent', {}).get('mean'), unit=' pts')} | "
        f"{_paper_change(c['cpu_percent_mean']['global'], c['cpu_percent_mean']['grid_puzzle'], ' pts')} | "
        f"{_paper_change(u['cpu_percent_mean']['global'], u['cpu_percent_mean']['grid_puzzle'], ' pts')} |"
    )
    lines.append(
        f"| Memory, global map [MiB ours RSS; MB paper] | {_mib(ours(ours_base, 'rss_bytes'))} | "
        f"{c['memory_mb_mean']['global']:.1f} | {u['memory_mb_mean']['global']:.1f} |"
    )
    lines.append(
        f"| Memory, grid puzzle [MiB ours RSS; MB paper] | {_mib(ours(ours_mode, 'rss_bytes'))} | "
        f"{c['memory_mb_mean']['grid_puzzle']:.1f} | {u['memory_mb_mean']['grid_puzzle']:.1f} |"
    )
    lines.append(
        f"| Memory change | {_change((change or {}).get('rss_bytes', {}).get('mean'), MIB, ' MiB')} | "
        f"{_paper_change(c['memory_mb_mean']['global'], c['memory_mb_mean']['grid_puzzle'], ' MB')} | "
        f"{_paper_change(u['memory_mb_mean']['global'], u['memory_mb_mean']['grid_puzzle'], ' MB')} |"
    )
    rmse = between["translation_m"]["rmse"] if between else None
    lines.append(
        f"| Trajectory RMSE, grid puzzle vs global [m] | {_num(rmse, '.4f')} | "
        f"{c['rmse_between_modes_m']:.4f} | {u['rmse_between_modes_m']:.4f} |"
    )
    lines.append(
        f"| Storage overhead (tile data bytes minus map data bytes) "
        f"| {_num(tiles.get('data_overhead_bytes'), ',.0f')} | "
        f"{c['storage_overhead_bytes']} | {u['storage_overhead_bytes']} |"
    )
    lines.append(f"| Tile files | {_num(tiles.get('files'), ',.0f')} | {c['tile_files']:,} | {u['tile_files']:,} |")
    lines.append(
        f"| Global map size [MB] | {_num(None if not global_map else global_map['bytes'] / 1e6, ',.1f')} | "
        f"{c['global_map_mb']:,.1f} | {u['global_map_mb']:,.1f} |"
    )
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
                f"| {MODE_TITLES.get(mode, mode)} | {protocol} | {', '.join(r['processes'])} "
                f"| {_num(r['cpu_percent']['mean'])} | {_num(r['cpu_percent']['p95'])} "
                f"| {_mib(r['rss_bytes']['mean'])} | {_mib(r['rss_bytes']['p95'])} "
                f"| {_mib(r['pss_bytes']['mean'])} | {_mib(r['pss_bytes']['p95'])} |"
            )
    return lines


def reductions_table(summary: Mapping) -> list[str]:
    lines = [
        "| mode vs global | protocol | CPU mean | CPU p95 | RSS mean | RSS p95 | PSS mean | PSS p95 |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for mode, by_protocol in summary.get("reductions", {}).items():
        for protocol, r in by_protocol.items():
            cells = [_change(r["cpu_percent"][s], unit=" pts") for s in ("mean", "p95")]
            cells += [_change(r[m][s], MIB, " MiB") for m in ("rss_bytes", "pss_bytes") for s in ("mean", "p95")]
            lines.append(f"| {MODE_TITLES.get(mode, mode)} | {protocol} | " + " | ".join(cells) + " |")
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
        title = MODE_TITLES.get(mode, mode)
        for name, p in memory["processes"].items():
            lines.append(
                f"| {title} | {name} | {_mib(p['rss_bytes_mean'])} | {_mib(p['empty_map_rss_bytes_mean'])} "
                f"| {_mib(p['map_bytes'])} | |"
            )
        for protocol in ("paper", "total"):
            ratio = 1.0 if mode == summary["baseline_mode"] else ratios.get(mode, {}).get(protocol)
            lines.append(
                f"| {title} | {protocol} protocol | | | {_mib(memory[protocol]['map_bytes'])} "
                f"| {_num(ratio, '.2f', ' x')} |"
            )
    return lines if len(lines) > 2 else []


def accuracy_table(summary: Mapping) -> list[str]:
    lines = [
        "| trajectory | reference | pairs | transl. RMSE [m] | transl. median [m] | transl. max [m] "
        "| rot. RMSE [deg] | rot. median [deg] | rot. max [deg] |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    entries = [(MODE_TITLES.get(mode, mode), "ground truth", m["ape"]) for mode, m in summary["modes"].items()]
    entries += [
        (MODE_TITLES.get(key.split("_vs_")[0], key), "global map run", e) for key, e in summary["between_modes"].items()
    ]
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
        "| mode | fusion | scans | mean [ms] | median [ms] | p95 [ms] |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for mode, t in rows:
        if t:
            lines.append(
                f"| {MODE_TITLES.get(mode, mode)} | {fusion} | {t['scans']} | {_num(t['mean'])} "
                f"| {_num(t['median'])} | {_num(t['p95'])} |"
            )
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
        "### Map memory",
        "",
        *table,
        "",
        "A process's map memory is its mean RSS minus its mean RSS when the same launch plays the start of the",
        "bag against an empty map (its floor: libraries, ROS, scan buffers).",
        "",
    ]


def render_report(summary: Mapping) -> str:
    """The whole report.md."""
    sc = summary["scenario"]
    setting = ", ".join(f"{k} = {v}" for k, v in sc.items() if not isinstance(v, (Mapping, list)))
    lines = [
        "# Grid puzzle map experiment",
        "",
        f"Setting: {setting}.",
        "",
        "## Our figures next to the paper's",
        "",
        *comparison_table(summary),
        "",
        "The paper protocol counts the NDT localizer process alone in global-map mode and the localizer plus the",
        "map provider in grid-puzzle mode, as the paper did. CPU is in percent of one core (200 % = two cores",
        'busy); "pts" are percentage points. Our memory is psutil\'s RSS in MiB; the paper printed MB.',
        "",
        "## CPU and memory per mode",
        "",
        *resources_table(summary),
        "",
        "The total protocol counts every process of the mode's launch file. PSS splits shared pages between",
        "the processes that share them, so it does not double-count libraries when processes are summed.",
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
        "## Time per scan",
        "",
        *scan_time_table(summary),
        "",
        "The localizer's own time for each scan (NdtStatus scan_time_ms): preprocessing, the NDT match with any",
        "hypotheses or search, and the sliding window's update when fusion is on.",
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
