"""Runs one experiment: for each mode a fresh roscore and roslaunch, the resource monitor on the
mode's processes, the bag played with clock, the localizer's odometry recorded as TUM, and a clean
shutdown; then the evaluation report."""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.config import ExperimentConfig
from grid_puzzle_localization.experiment.maps import write_empty_map
from grid_puzzle_localization.experiment.modes import EMPTY_MAP_MODES, GRID_PUZZLE_MODES, LAUNCH_MODES
from grid_puzzle_localization.experiment.processes import ManagedProcess, wait_for
from grid_puzzle_localization.experiment.ros_stack import RosCore, rosbag_play, roslaunch, run_node
from grid_puzzle_localization.monitor.log import write_csv
from grid_puzzle_localization.monitor.sampler import Monitor
from grid_puzzle_localization.monitor.stats import summarize
from grid_puzzle_localization.report.build import (
    EMPTY_MAP_DIR,
    MONITOR_CSV,
    MONITOR_JSON,
    SCAN_TIMES,
    TRAJECTORY,
    RunInfo,
    build_report,
    write_json,
    write_run_info,
)
from grid_puzzle_localization.ros.node_pids import node_target


@dataclass
class ModeOutcome:
    mode: str
    master_uri: str
    roles: dict[str, str]
    processes: list[str]
    killed_pids: list[int]  # needed SIGKILL at shutdown (should be empty)
    stray_pids: list[int]  # still alive after shutdown (must be empty)


def initial_pose_from(trajectory_path: Path) -> list[float]:
    """x y z roll pitch yaw [m, rad] of the first pose of a TUM trajectory."""
    gt = read_tum(trajectory_path)
    if len(gt) == 0:
        raise UserError(f"ground truth {trajectory_path} has no pose")
    yaw, pitch, roll = Rotation.from_quat(gt.quat[0]).as_euler("ZYX")
    return [*map(float, gt.xyz[0]), float(roll), float(pitch), float(yaw)]


def launch_args(
    cfg: ExperimentConfig, mode: str, global_map: Path, tiles: Path | None, initial_pose: list[float]
) -> dict[str, object]:
    launch = LAUNCH_MODES[mode]
    args: dict[str, object] = {
        "mode": launch.mode,
        "use_sim_time": "true",
        "initial_pose": "[" + ", ".join(f"{v:.9g}" for v in initial_pose) + "]",
        "map": global_map.resolve(),
        "n": cfg.window.n,
        "k": cfg.window.k,
    }
    if cfg.ndt_threads is not None:  # else the localizer's own default
        args["ndt_threads"] = cfg.ndt_threads
    if cfg.fusion is not None:  # else the localizer's own default
        args["fusion"] = cfg.fusion
    if launch.provider is not None:
        args["provider"] = launch.provider
    if tiles is not None:
        args["tiles"] = tiles.resolve()
    if mode == "block_map":
        args["blocks"] = cfg.blocks.resolve()
    return args


def mode_roles(cfg: ExperimentConfig, mode: str) -> dict[str, str]:
    """The node whose process plays each role. The provider nodelet runs in the localizer's manager, so in
    grid_puzzle mode that one process plays both roles."""
    roles = {"localizer": cfg.roles.localizer}
    if mode == "grid_puzzle":
        roles["map_provider"] = cfg.roles.localizer
    elif mode == "grid_puzzle_rospy":
        roles["map_provider"] = cfg.roles.map_provider
    elif mode == "block_map":
        roles["map_provider"] = cfg.roles.block_server
    return roles


def required_nodes(cfg: ExperimentConfig, mode: str) -> set[str]:
    """The nodes to wait for before playing: the role processes' and the tile provider's (in grid_puzzle
    mode, the loader of its nodelet)."""
    nodes = set(mode_roles(cfg, mode).values())
    if mode in GRID_PUZZLE_MODES:
        nodes.add(cfg.roles.map_provider)
    return nodes


def say(mode: str, text: str) -> None:
    print(f"gpm experiment [{mode}]: {text}", file=sys.stderr, flush=True)


def _stop_all(processes: list[ManagedProcess]) -> tuple[list[int], list[int]]:
    """Stops in reverse start order; returns (pids that needed SIGKILL, pids still alive)."""
    killed: list[int] = []
    for proc in reversed(processes):
        killed += proc.stop()
    stray = [pid for proc in processes for pid in proc.alive_pids()]
    return killed, stray


def start_recorder(cfg: ExperimentConfig, core: RosCore, out: Path, initial_pose: list[float]) -> ManagedProcess:
    """The trajectory recorder node, subscribed to odom and publishing the initial pose (latched)."""
    x, y, z, roll, pitch, yaw = initial_pose
    pose = [x, y, z, *map(float, Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat())]
    argv = [
        f"__name:={cfg.roles.recorder.lstrip('/')}",
        f"_output:={(out / TRAJECTORY).resolve()}",
        f"_scan_times:={(out / SCAN_TIMES).resolve()}",
        f"_initial_pose:={pose}",
        f"status:={cfg.localizer_status_topic}",
    ]
    recorder = run_node("trajectory_recorder", "trajectory_recorder", argv, core.env, out / "logs" / "recorder.log")
    try:
        recording = lambda: cfg.roles.recorder in core.subscribers("/odom")  # noqa: E731
        wait_for(recording, cfg.startup_timeout_s, "the trajectory recorder", recorder)
    except BaseException:
        recorder.stop()
        raise
    return recorder


def wait_for_playback(player: ManagedProcess, launch: ManagedProcess, bag: Path) -> None:
    """Waits until rosbag play ends; raises UserError if it fails or roslaunch dies meanwhile."""
    while player.wait(1.0) is None:
        if not launch.running():
            raise UserError(f"roslaunch exited during playback; see {launch.log_path}")
        launch.remember_descendants()
    if player.popen.returncode != 0:
        raise UserError(f"rosbag play failed on {bag}; see {player.log_path}")


@dataclass(frozen=True)
class ModeInputs:
    """What one run of a mode plays against, and for how long."""

    global_map: Path
    tiles: Path | None  # the grid puzzle modes' tile directory
    out: Path  # the run's directory (emptied first)
    duration_s: float | None = None  # seconds of the bag to play; None: all of it
    record: bool = True  # record the trajectory (and require one)


def run_mode(cfg: ExperimentConfig, mode: str, inputs: ModeInputs, initial_pose: list[float]) -> ModeOutcome:
    """One run of a mode, start to clean shutdown; writes OUT/{trajectory.tum, monitor.csv, monitor.json, logs}
    (the trajectory only when recording)."""
    out = inputs.out
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    roles = mode_roles(cfg, mode)
    started: list[ManagedProcess] = []
    monitor: Monitor | None = None
    try:
        say(mode, "starting roscore and roslaunch")
        core = RosCore(out / "logs", cfg.startup_timeout_s)
        started.append(core.process)
        args = launch_args(cfg, mode, inputs.global_map, inputs.tiles, initial_pose)
        launch = roslaunch(cfg.launch_file, args, core.env, out / "logs" / "roslaunch.log")
        started.append(launch)
        wanted = required_nodes(cfg, mode)
        wait_for(lambda: wanted <= core.nodes(), cfg.startup_timeout_s, f"the nodes {sorted(wanted)}", launch)
        wait_for(lambda: core.subscribers("/points"), cfg.startup_timeout_s, "a subscriber of /points", launch)
        if inputs.record:
            started.append(start_recorder(cfg, core, out, initial_pose))
        time.sleep(cfg.settle_s)
        launch.remember_descendants()
        processes = sorted(core.nodes() - {"/rosout", cfg.roles.recorder})
        monitor = Monitor([node_target(name, core.master_uri) for name in processes], cfg.monitor_interval_s)
        monitor.start()
        say(mode, f"monitoring {', '.join(processes)}; playing {cfg.bag.name} at {cfg.rate}x")
        log_path = out / "logs" / "rosbag_play.log"
        started.append(rosbag_play(cfg.bag.resolve(), cfg.rate, core.env, log_path, duration_s=inputs.duration_s))
        wait_for_playback(started[-1], launch, cfg.bag)
        time.sleep(cfg.settle_s)  # the last scans are still being matched
        log = monitor.stop()
        monitor = None
        write_csv(out / MONITOR_CSV, log)
        write_json(out / MONITOR_JSON, summarize(log, cfg.monitor_interval_s))
        say(mode, "playback done; shutting down")
    finally:
        if monitor is not None:
            monitor.stop()
        killed, stray = _stop_all(started)
    if stray:
        raise UserError(f"mode {mode}: processes {stray} survived SIGKILL; stop them by hand")
    if inputs.record and (not (out / TRAJECTORY).is_file() or len(read_tum(out / TRAJECTORY)) == 0):
        raise UserError(f"mode {mode}: the localizer published no odometry; see {out / 'logs' / 'roslaunch.log'}")
    return ModeOutcome(mode, core.master_uri, roles, processes, killed, stray)


def run_empty_map(cfg: ExperimentConfig, mode: str, initial_pose: list[float]) -> ModeOutcome:
    """The mode's launch against an empty map (written to a temporary directory) for the first
    ``cfg.empty_map_s`` seconds of the bag, into OUT/<mode>/empty_map/: the floor that the report subtracts to
    get each process's map memory."""
    with tempfile.TemporaryDirectory(prefix="gpm_empty_map_") as tmp:
        global_map, tiles = write_empty_map(tmp, cfg.window.grid_size_m)
        inputs = ModeInputs(global_map, tiles, cfg.out_dir / mode / EMPTY_MAP_DIR, cfg.empty_map_s, record=False)
        return run_mode(cfg, mode, inputs, initial_pose)


def run_experiment(cfg: ExperimentConfig, tiles: Path | None, storage: dict | None) -> dict:
    """Every mode in turn, then the report. Returns the summary."""
    cfg.check()
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    initial_pose = cfg.initial_pose if cfg.initial_pose is not None else initial_pose_from(cfg.ground_truth)
    outcomes = []
    for mode in cfg.modes:
        inputs = ModeInputs(cfg.global_map, tiles if mode in GRID_PUZZLE_MODES else None, cfg.out_dir / mode)
        outcomes.append(run_mode(cfg, mode, inputs, initial_pose))
        if cfg.empty_map_s > 0 and mode in EMPTY_MAP_MODES:
            outcomes.append(run_empty_map(cfg, mode, initial_pose))
    scenario = {
        "name": cfg.scenario_name,
        "preset": cfg.preset,
        "n": cfg.window.n,
        "k": cfg.window.k,
        "grid_size_m": cfg.window.grid_size_m,
        "rate": cfg.rate,
        "ndt_threads": cfg.ndt_threads,
        "fusion": cfg.fusion if cfg.fusion is not None else "localizer default",
        "monitor_interval_s": cfg.monitor_interval_s,
        "bag": str(cfg.bag),
    }
    info = RunInfo(
        scenario=scenario,
        modes=list(cfg.modes),
        roles={o.mode: o.roles for o in outcomes},
        ground_truth=str(cfg.ground_truth.resolve()) if cfg.ground_truth else None,
        global_map=str(cfg.global_map.resolve()),
        storage=storage,
        max_diff_s=cfg.max_time_diff_s,
        extra={"outcomes": [asdict(o) for o in outcomes], "initial_pose": list(np.asarray(initial_pose, float))},
    )
    write_run_info(cfg.out_dir, info)
    summary = build_report(cfg.out_dir)
    json.dumps(summary)  # must be plain JSON
    return summary
