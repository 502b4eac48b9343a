"""Runs one experiment: for each run of a mode (the modes interleaved when each runs more than once) a fresh
roscore and roslaunch, the resource monitor on the mode's processes, the bag played with clock, the localizer's
odometry recorded as TUM, and a clean shutdown; then the evaluation report."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import rosbag
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.config import ExperimentConfig
from grid_puzzle_localization.experiment.maps import write_empty_map
from grid_puzzle_localization.experiment.modes import (
    EMPTY_MAP_MODES,
    GRID_PUZZLE_MODES,
    LAUNCH_MODES,
    interleaved_runs,
)
from grid_puzzle_localization.experiment.processes import ManagedProcess, wait_for
from grid_puzzle_localization.experiment.ros_stack import RosCore, rosbag_play, roslaunch, run_node
from grid_puzzle_localization.experiment.start import Start, start_from
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
    run_dir,
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
    repeat: int = 1  # the mode's run number (--repeats)


def initial_pose_from(trajectory_path: Path) -> list[float]:
    """x y z roll pitch yaw [m, rad] of the first pose of a TUM trajectory."""
    gt = read_tum(trajectory_path)
    if len(gt) == 0:
        raise UserError(f"ground truth {trajectory_path} has no pose")
    yaw, pitch, roll = Rotation.from_quat(gt.quat[0]).as_euler("ZYX")
    return [*map(float, gt.xyz[0]), float(roll), float(pitch), float(yaw)]


def first_scan_stamp(bag: str | os.PathLike, topic: str = "points") -> float | None:
    """Header stamp [s] of the first message on ``topic`` (with or without its leading slash) in ``bag``: the first
    played scan; None when the bag holds none."""
    with rosbag.Bag(str(bag)) as b:
        for _, msg, _ in b.read_messages(topics=[topic.lstrip("/"), "/" + topic.lstrip("/")]):
            return msg.header.stamp.to_sec()
    return None


def launch_args(
    cfg: ExperimentConfig, mode: str, global_map: Path, tiles: Path | str | None, initial_pose: list[float] | None
) -> dict[str, object]:
    """roslaunch arguments of a mode; ``initial_pose`` None: the localizer gets none."""
    launch = LAUNCH_MODES[mode]
    pose = [] if initial_pose is None else initial_pose
    args: dict[str, object] = {
        "mode": launch.mode,
        "use_sim_time": "true",
        "initial_pose": "[" + ", ".join(f"{v:.9g}" for v in pose) + "]",
        "map": global_map.resolve(),
        "n": cfg.window.n,
        "k": cfg.window.k,
    }
    if cfg.search_timeout_s() is not None:  # else the localizer's own default
        args["global_search_timeout"] = cfg.search_timeout_s()
    if cfg.ndt_threads is not None:  # else the localizer's own default
        args["ndt_threads"] = cfg.ndt_threads
    if cfg.fusion is not None:  # else the localizer's own default
        args["fusion"] = cfg.fusion
    if launch.provider is not None:
        args["provider"] = launch.provider
    if tiles is not None:
        args["tiles"] = tiles if isinstance(tiles, str) else tiles.resolve()  # a directory, or a map store's URL
    if mode == "block_map":
        args["blocks"] = cfg.blocks.resolve()
    return args


def mode_roles(cfg: ExperimentConfig, mode: str) -> dict[str, str]:
    """The node whose process plays each role. The provider nodelet runs in the localizer's process
    (localization_node, /localizer_manager), so in grid_puzzle mode that one process plays both roles."""
    roles = {"localizer": cfg.roles.localizer}
    if mode == "grid_puzzle":
        roles["map_provider"] = cfg.roles.localizer
    elif mode == "grid_puzzle_rospy":
        roles["map_provider"] = cfg.roles.map_provider
    elif mode == "block_map":
        roles["map_provider"] = cfg.roles.block_server
    return roles


def required_nodes(cfg: ExperimentConfig, mode: str) -> set[str]:
    """The nodes to wait for before playing: the role processes'. The provider nodelet (grid_puzzle mode) has
    no node of its own: the localizer's process loads it before the localizer, so the runner's wait for a
    subscriber of points covers it."""
    return set(mode_roles(cfg, mode).values())


def say(mode: str, text: str) -> None:
    print(f"gpm experiment [{mode}]: {text}", file=sys.stderr, flush=True)


def _stop_all(processes: list[ManagedProcess]) -> tuple[list[int], list[int]]:
    """Stops in reverse start order; returns (pids that needed SIGKILL, pids still alive)."""
    killed: list[int] = []
    for proc in reversed(processes):
        killed += proc.stop()
    stray = [pid for proc in processes for pid in proc.alive_pids()]
    return killed, stray


def recorder_args(cfg: ExperimentConfig, out: Path, start: Start) -> list[str]:
    """The trajectory recorder's arguments: its outputs, and what it publishes, latched, for the start: the initial
    pose on initialpose, or the hint on cfg.hint_topic (which the localizer and the provider both receive)."""
    argv = [
        f"__name:={cfg.roles.recorder.lstrip('/')}",
        f"_output:={(out / TRAJECTORY).resolve()}",
        f"_scan_times:={(out / SCAN_TIMES).resolve()}",
        f"status:={cfg.localizer_status_topic}",
    ]
    if start.initial_pose is not None:
        x, y, z, roll, pitch, yaw = start.initial_pose
        pose = [x, y, z, *map(float, Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat())]
        argv.append(f"_initial_pose:={pose}")
    if start.hint_xy is not None:
        argv += [f"_hint:={[*start.hint_xy, start.hint_sigma_m]}", f"initialpose_hint:={cfg.hint_topic}"]
    return argv


def start_recorder(cfg: ExperimentConfig, core: RosCore, out: Path, start: Start) -> ManagedProcess:
    """The trajectory recorder node, subscribed to odom and publishing the start (recorder_args)."""
    argv = recorder_args(cfg, out, start)
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
    tiles: Path | str | None  # the grid puzzle modes' tile directory, or a map store's URL
    out: Path  # the run's directory (emptied first)
    duration_s: float | None = None  # seconds of the bag to play; None: all of it
    record: bool = True  # record the trajectory (and require one)


def run_mode(cfg: ExperimentConfig, mode: str, inputs: ModeInputs, start: Start) -> ModeOutcome:
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
        args = launch_args(cfg, mode, inputs.global_map, inputs.tiles, start.initial_pose)
        launch = roslaunch(cfg.launch_file, args, core.env, out / "logs" / "roslaunch.log")
        started.append(launch)
        wanted = required_nodes(cfg, mode)
        wait_for(lambda: wanted <= core.nodes(), cfg.startup_timeout_s, f"the nodes {sorted(wanted)}", launch)
        wait_for(lambda: core.subscribers("/points"), cfg.startup_timeout_s, "a subscriber of /points", launch)
        if inputs.record:
            started.append(start_recorder(cfg, core, out, start))
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


def run_empty_map(cfg: ExperimentConfig, mode: str, start: Start) -> ModeOutcome:
    """The mode's launch against an empty map (written to a temporary directory) for the first
    ``cfg.empty_map_s`` seconds of the bag, into OUT/<mode>/empty_map/: the floor that the report subtracts to
    get each process's map memory."""
    with tempfile.TemporaryDirectory(prefix="gpm_empty_map_") as tmp:
        global_map, tiles = write_empty_map(tmp, cfg.window.grid_size_m)
        inputs = ModeInputs(global_map, tiles, cfg.out_dir / mode / EMPTY_MAP_DIR, cfg.empty_map_s, record=False)
        return run_mode(cfg, mode, inputs, start)


def run_experiment(cfg: ExperimentConfig, tiles: Path | str | None, storage: dict | None) -> dict:
    """Every mode in turn, ``cfg.repeats`` rounds of them (the empty-map runs in the first), then the report.
    Returns the summary."""
    cfg.check()
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    # Where the run really starts; the localizer is given it, moved, a hint near it, or nothing (cfg.start).
    true_start = cfg.initial_pose if cfg.initial_pose is not None else None
    if true_start is None and cfg.ground_truth is not None:
        true_start = initial_pose_from(cfg.ground_truth)
    start = start_from(cfg.start, true_start)
    if start.initial_pose is not None:
        say("start", "initial pose " + " ".join(f"{v:.3f}" for v in start.initial_pose))
    elif start.hint_xy is not None:
        say("start", f"no pose; hint ({start.hint_xy[0]:.2f}, {start.hint_xy[1]:.2f}) on {cfg.hint_topic}")
    else:
        say("start", "no pose and no hint: the localizer's global search")
    outcomes = []
    # The first round empties OUT/<mode>/, which holds the later rounds' directories, before any of them is written.
    for repeat, mode in interleaved_runs(cfg.modes, cfg.repeats):
        if cfg.repeats > 1:
            say(mode, f"run {repeat} of {cfg.repeats}")
        out = run_dir(cfg.out_dir, mode, repeat)
        inputs = ModeInputs(cfg.global_map, tiles if mode in GRID_PUZZLE_MODES else None, out)
        outcomes.append(dataclasses.replace(run_mode(cfg, mode, inputs, start), repeat=repeat))
        if repeat == 1 and cfg.empty_map_s > 0 and mode in EMPTY_MAP_MODES:
            outcomes.append(run_empty_map(cfg, mode, start))
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
        repeats=cfg.repeats,
        extra={
            "outcomes": [asdict(o) for o in outcomes],
            "initial_pose": start.initial_pose,
            "start": {
                **dataclasses.asdict(cfg.start),
                **start.as_dict(),
                "true_start_pose": None if true_start is None else [float(v) for v in true_start],
                "global_search_timeout_s": cfg.search_timeout_s(),
                "hint_topic": cfg.hint_topic,
            },
            "first_scan_stamp_s": first_scan_stamp(cfg.bag),
        },
    )
    write_run_info(cfg.out_dir, info)
    summary = build_report(cfg.out_dir)
    json.dumps(summary)  # must be plain JSON
    return summary
