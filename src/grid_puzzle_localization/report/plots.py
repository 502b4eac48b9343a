"""PNG plots of an experiment with matplotlib's object API on the Agg canvas (no display, no pyplot
global state)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from grid_puzzle_localization.evaluation.metrics import interpolated_errors, paired_errors
from grid_puzzle_localization.evaluation.trajectory import Trajectory
from grid_puzzle_localization.monitor.log import MonitorLog
from grid_puzzle_localization.report.format import MIB, mode_title
from grid_puzzle_localization.util.atomic import atomic_write
from grid_puzzle_localization.util.iteration import zip_equal

COLORS = {"global": "tab:blue", "grid_puzzle": "tab:orange", "grid_puzzle_rospy": "tab:red", "block_map": "tab:green"}
MAP_COLOR = "0.82"  # light grey: the map stays under the trajectories


def new_figure(width: float, height: float) -> Figure:
    """A figure of ``width`` x ``height`` inches with constrained layout (the keyword matplotlib has had since 3.1,
    Ubuntu 20.04's; ``layout=`` came with 3.5)."""
    return Figure(figsize=(width, height), constrained_layout=True)


def save_png(fig: Figure, path: str | os.PathLike) -> None:
    """Renders ``fig`` on the Agg canvas and writes it to ``path`` atomically."""
    FigureCanvasAgg(fig)
    with atomic_write(path, "wb") as f:
        fig.savefig(f, format="png", dpi=110)


def plot_resource(
    path: str | os.PathLike,
    logs: Mapping[str, MonitorLog],
    processes: Mapping[str, Mapping[str, Sequence[str]]],
    metric: str,
    ylabel: str,
    scale: float = 1.0,
) -> None:
    """One panel per protocol: ``metric`` summed over the protocol's processes, per mode, over time.
    ``processes[mode][protocol]`` lists the process names."""
    protocols = list(next(iter(processes.values())))
    fig = new_figure(9, 3.2 * len(protocols))
    axes = fig.subplots(len(protocols), 1, squeeze=False)[:, 0]
    for ax, protocol in zip_equal(axes, protocols):
        for mode, log in logs.items():
            values = log.sum(metric, list(processes[mode][protocol])) / scale
            ax.plot(log.t_s, values, color=COLORS.get(mode), label=mode_title(mode), lw=1.2)
        ax.set_title(f"{protocol} protocol")
        ax.set_xlabel("time since monitoring started [s]")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    save_png(fig, path)


def plot_cpu(path, logs, processes) -> None:
    plot_resource(path, logs, processes, "cpu_percent", "CPU [% of one core]")


def plot_memory(path, logs, processes) -> None:
    plot_resource(path, logs, processes, "rss_bytes", "RSS [MiB]", MIB)


def trajectory_figure(
    trajectories: Mapping[str, Trajectory], ground_truth: Trajectory | None, map_xy: np.ndarray | None = None
) -> Figure:
    """Top-down (x, y) view of every mode's trajectory over the ground truth, over the map's points
    (``map_xy``, (N, 2) [m], e.g. report.map_view.map_top_view) when given."""
    fig = new_figure(7, 7)
    ax = fig.subplots()
    if map_xy is not None and len(map_xy):
        ax.scatter(map_xy[:, 0], map_xy[:, 1], s=0.3, c=MAP_COLOR, linewidths=0, rasterized=True, label="map")
    if ground_truth is not None:
        ax.plot(ground_truth.xyz[:, 0], ground_truth.xyz[:, 1], color="black", lw=3, alpha=0.35, label="ground truth")
    for mode, traj in trajectories.items():
        ax.plot(traj.xyz[:, 0], traj.xyz[:, 1], color=COLORS.get(mode), lw=1.0, label=mode_title(mode))
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", markerscale=10)  # the map's dots visible in the legend
    return fig


def plot_trajectories(
    path: str | os.PathLike,
    trajectories: Mapping[str, Trajectory],
    ground_truth: Trajectory | None,
    map_xy: np.ndarray | None = None,
) -> None:
    save_png(trajectory_figure(trajectories, ground_truth, map_xy), path)


def plot_errors(
    path: str | os.PathLike,
    trajectories: Mapping[str, Trajectory],
    ground_truth: Trajectory | None,
    max_diff_s: float,
    baseline: str = "global",
) -> None:
    """Position error over time: each mode against the ground truth (when given), and each mode
    against the baseline mode's trajectory (the paper's comparison)."""
    panels = (["ground truth"] if ground_truth is not None else []) + (
        [baseline] if baseline in trajectories and len(trajectories) > 1 else []
    )
    fig = new_figure(9, 3.2 * max(1, len(panels)))
    axes = fig.subplots(max(1, len(panels)), 1, squeeze=False)[:, 0]
    t0 = min(float(tr.t[0]) for tr in trajectories.values() if len(tr))
    for ax, panel in zip(axes, panels):
        reference = ground_truth if panel == "ground truth" else trajectories[baseline]
        for mode, traj in trajectories.items():
            if panel == baseline and mode == baseline:
                continue
            e = (interpolated_errors if panel == "ground truth" else paired_errors)(reference, traj, max_diff_s)
            ax.plot(e.t - t0, e.translation_m, color=COLORS.get(mode), lw=1.0, label=mode_title(mode))
        ax.set_title(f"position error against {'the ' + mode_title(baseline) + ' run' if panel == baseline else panel}")
        ax.set_xlabel("time since the first pose [s]")
        ax.set_ylabel("error [m]")
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
        ax.legend(loc="best")
    save_png(fig, path)
