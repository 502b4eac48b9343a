"""Builds summary.json, report.md and plots/ from an experiment directory:

OUT/run.json                    scenario, modes, roles per mode, ground truth and map paths, storage figures,
                                the start and the first played scan's stamp (extra)
OUT/<mode>/trajectory.tum       the localizer's odometry (TUM)
OUT/<mode>/monitor.csv, .json   the resource monitor's samples and summary (with events)
OUT/<mode>/scan_times.csv       the localizer's per-scan times (optional)
OUT/<mode>/empty_map/monitor.csv  the same launch against an empty map, for the map memory (optional)
OUT/<mode>/repeat_<r>/          the mode's r-th run (r >= 2) with --repeats: the same files as OUT/<mode>/, which
                                holds its first
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.resources import protocol_processes
from grid_puzzle_localization.evaluation.scan_times import read_scan_times
from grid_puzzle_localization.evaluation.summary import ModeRun, summarize_experiment
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.monitor.log import Event, MonitorLog, read_csv
from grid_puzzle_localization.report import plots
from grid_puzzle_localization.report.map_view import map_top_view
from grid_puzzle_localization.report.markdown import render_report
from grid_puzzle_localization.util.atomic import atomic_write

RUN_FILE = "run.json"
TRAJECTORY = "trajectory.tum"
MONITOR_CSV = "monitor.csv"
MONITOR_JSON = "monitor.json"
SCAN_TIMES = "scan_times.csv"
EMPTY_MAP_DIR = "empty_map"
REPEAT_DIR = "repeat_{}"  # the r-th run of a mode, r >= 2; the first keeps OUT/<mode>/


@dataclass
class RunInfo:
    """What run.json holds: everything besides the per-mode outputs that the report needs."""

    scenario: dict
    modes: list[str]
    roles: dict[str, dict[str, str]]  # mode -> role -> monitored process name
    ground_truth: str | None = None
    global_map: str | None = None  # the map PCD the trajectory plot draws under the trajectories
    storage: dict | None = None
    max_diff_s: float = 0.05
    extra: dict = field(default_factory=dict)
    repeats: int = 1  # runs of each mode (run_dir)


def write_json(path: str | os.PathLike, data) -> None:
    with atomic_write(path) as f:
        json.dump(data, f, indent=2)
        f.write("\n")


def read_json(path: str | os.PathLike):
    try:
        with open(path) as f:
            return json.load(f)
    except OSError as err:
        raise UserError(f"cannot read {path}: {err.strerror}") from err
    except json.JSONDecodeError as err:
        raise UserError(f"{path} is not valid JSON ({err})") from err


def write_run_info(out_dir: str | os.PathLike, info: RunInfo) -> None:
    write_json(Path(out_dir) / RUN_FILE, asdict(info))


def read_run_info(out_dir: str | os.PathLike) -> RunInfo:
    data = read_json(Path(out_dir) / RUN_FILE)
    try:
        return RunInfo(**data)
    except TypeError as err:
        raise UserError(f"{Path(out_dir) / RUN_FILE} does not describe an experiment ({err})") from err


def run_dir(out_dir: str | os.PathLike, mode: str, repeat: int = 1) -> Path:
    """The directory of a mode's ``repeat``-th run (from 1): OUT/<mode>/ for the first, as without repeats."""
    d = Path(out_dir) / mode
    return d if repeat == 1 else d / REPEAT_DIR.format(repeat)


def load_monitor(d: Path) -> MonitorLog:
    """A run's monitor log with the events from its summary."""
    log = read_csv(d / MONITOR_CSV)
    if (d / MONITOR_JSON).exists():
        log.events = [Event(**e) for e in read_json(d / MONITOR_JSON).get("events", [])]
    return log


def load_mode(out_dir: Path, mode: str, roles: dict[str, str], repeats: int = 1) -> ModeRun:
    """The mode's first run in full, and the monitor logs of its later repeats."""
    d = run_dir(out_dir, mode)
    scan_times = read_scan_times(d / SCAN_TIMES) if (d / SCAN_TIMES).exists() else None
    empty_csv = d / EMPTY_MAP_DIR / MONITOR_CSV
    empty_map = read_csv(empty_csv) if empty_csv.exists() else None
    later = tuple(load_monitor(run_dir(out_dir, mode, r)) for r in range(2, repeats + 1))
    return ModeRun(mode, read_tum(d / TRAJECTORY), load_monitor(d), roles, scan_times, empty_map, later)


def build_report(out_dir: str | os.PathLike) -> dict:
    """Evaluates the experiment in ``out_dir`` and writes summary.json, report.md and plots/*.png.
    Returns the summary."""
    out = Path(out_dir)
    info = read_run_info(out)
    runs = [load_mode(out, mode, info.roles.get(mode, {}), info.repeats) for mode in info.modes]
    gt = read_tum(info.ground_truth) if info.ground_truth else None
    start, first_scan = info.extra.get("start"), info.extra.get("first_scan_stamp_s")
    summary = summarize_experiment(runs, gt, info.storage, info.max_diff_s, info.scenario, start, first_scan)
    write_json(out / "summary.json", summary)
    with atomic_write(out / "report.md") as f:
        f.write(render_report(summary))
    logs = {r.mode: r.monitor for r in runs}
    processes = {
        r.mode: {p: protocol_processes(r.mode, r.roles, r.monitor, p) for p in ("paper", "total")} for r in runs
    }
    trajectories = {r.mode: r.trajectory for r in runs}
    plots.plot_cpu(out / "plots" / "cpu.png", logs, processes)
    plots.plot_memory(out / "plots" / "memory.png", logs, processes)
    # The map may be gone when a report is rebuilt elsewhere: the trajectories are then drawn alone.
    map_xy = map_top_view(info.global_map) if info.global_map and Path(info.global_map).is_file() else None
    plots.plot_trajectories(out / "plots" / "trajectories.png", trajectories, gt, map_xy)
    plots.plot_errors(out / "plots" / "errors.png", trajectories, gt, info.max_diff_s)
    return summary
