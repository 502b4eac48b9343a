"""The experiment's summary (what summary.json holds), computed from each mode's trajectory and
monitor log, the ground truth and the storage figures. Pure: no ROS, no plotting."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.evaluation.first_pose import start_figures
from grid_puzzle_localization.evaluation.metrics import PairedErrors, interpolated_errors, paired_errors
from grid_puzzle_localization.evaluation.paper import PAPER_FIGURES
from grid_puzzle_localization.evaluation.repeats import median_resources, repeat_spread
from grid_puzzle_localization.evaluation.resources import (
    compare_to_baseline,
    map_memory,
    map_memory_ratios,
    mode_resources,
)
from grid_puzzle_localization.evaluation.scan_times import accepted_stamps, summarize_scan_times
from grid_puzzle_localization.evaluation.trajectory import Trajectory
from grid_puzzle_localization.monitor.log import MonitorLog
from grid_puzzle_localization.util.iteration import zip_equal

BASELINE_MODE = "global"


@dataclass(frozen=True)
class ModeRun:
    """One mode's outputs: its trajectory, its monitor log, and which monitored process plays which
    role (``localizer``, ``map_provider``)."""

    mode: str
    trajectory: Trajectory
    monitor: MonitorLog
    roles: Mapping[str, str]
    scan_times: np.ndarray | None = None  # (n, 4) rows of evaluation.scan_times, when recorded
    empty_map: MonitorLog | None = None  # the monitor log of the same launch against an empty map, when run
    later_monitors: tuple[MonitorLog, ...] = ()  # the monitor logs of the mode's runs 2, 3, ... (--repeats)


def _errors(errors: PairedErrors) -> dict:
    return {
        "translation_m": dataclasses.asdict(errors.translation),
        "rotation_deg": dataclasses.asdict(errors.rotation),
    }


def summarize_experiment(
    runs: Sequence[ModeRun],
    ground_truth: Trajectory | None,
    storage: Mapping | None,
    max_diff_s: float,
    scenario: Mapping,
    start: Mapping | None = None,
    first_scan_stamp_s: float | None = None,
) -> dict:
    """The summary dictionary: per-mode resources (both protocols), map memory (when an empty-map run was
    made), APE and the start (when the first played scan's stamp is known: evaluation.first_pose), the paper's
    RMSE between the baseline (global) and every other mode, reductions and map memory ratios against the
    baseline, storage, and the paper's figures. ``start`` is what the localizer was given (experiment.start).

    With repeated runs (``later_monitors``), ``resources`` holds each figure's median over the runs (and so do the
    reductions computed from it), ``per_repeat`` each run's resources and events, and ``repeats`` their count and
    spread (evaluation.repeats); everything else comes from the first run."""
    counts = {1 + len(run.later_monitors) for run in runs}
    if len(counts) > 1:
        raise ValueError(f"every mode needs the same number of runs (got {sorted(counts)})")
    logs = {run.mode: [run.monitor, *run.later_monitors] for run in runs}
    per_repeat = {run.mode: [mode_resources(run.mode, run.roles, log) for log in logs[run.mode]] for run in runs}
    modes = {}
    for run in runs:
        memory = None if run.empty_map is None else map_memory(run.mode, run.roles, run.monitor, run.empty_map)
        ape = None if ground_truth is None else interpolated_errors(ground_truth, run.trajectory, max_diff_s)
        accepted = None if run.scan_times is None else accepted_stamps(run.scan_times)
        modes[run.mode] = {
            "poses": len(run.trajectory),
            "duration_s": float(run.trajectory.t[-1] - run.trajectory.t[0]) if len(run.trajectory) else 0.0,
            "roles": dict(run.roles),
            "resources": median_resources(per_repeat[run.mode]),
            "per_repeat": [
                {"repeat": k, "resources": resources, "events": [dataclasses.asdict(e) for e in log.events]}
                for k, (resources, log) in enumerate(zip_equal(per_repeat[run.mode], logs[run.mode]), 1)
            ],
            "ape": None if ape is None else _errors(ape),
            "events": [dataclasses.asdict(e) for e in run.monitor.events],
            "scan_time_ms": None if run.scan_times is None else summarize_scan_times(run.scan_times),
            "start": start_figures(run.trajectory, first_scan_stamp_s, ground_truth, accepted, max_diff_s),
            "map_memory": memory,
        }
    by_mode = {run.mode: run for run in runs}
    between = {}
    if BASELINE_MODE in by_mode:
        base = by_mode[BASELINE_MODE].trajectory
        for run in runs:
            if run.mode != BASELINE_MODE:
                between[f"{run.mode}_vs_{BASELINE_MODE}"] = _errors(paired_errors(base, run.trajectory, max_diff_s))
    resources = {mode: m["resources"] for mode, m in modes.items()}
    map_memories = {mode: m["map_memory"] for mode, m in modes.items() if m["map_memory"] is not None}
    return {
        "scenario": dict(scenario),
        "max_time_diff_s": max_diff_s,
        "start": None if start is None else dict(start),
        "baseline_mode": BASELINE_MODE,
        "modes": modes,
        "between_modes": between,
        "repeats": {"count": max(counts, default=1), "spread": repeat_spread(per_repeat, BASELINE_MODE)},
        "reductions": compare_to_baseline(resources, BASELINE_MODE) if BASELINE_MODE in resources else {},
        "map_memory_ratios": map_memory_ratios(map_memories, BASELINE_MODE),
        "storage": dict(storage) if storage is not None else None,
        "paper": PAPER_FIGURES,
    }
