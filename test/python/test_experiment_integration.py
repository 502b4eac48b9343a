"""gpm experiment end to end with the real pieces: a tiny simulated courtyard (6 s of bag), the NDT
localizer nodelet in global (its own PCD) and grid puzzle modes (tiles from the provider nodelet in the
localizer's manager, and from the rospy provider, the paper's setup)."""

import contextlib
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from matplotlib.image import imread
from process_check import processes_on

from grid_puzzle_localization.cli import main
from grid_puzzle_localization.evaluation.scan_times import read_scan_times
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.modes import DEFAULT_MODES
from grid_puzzle_localization.monitor.log import read_csv
from grid_puzzle_localization.report.build import read_json

GPM = Path(__file__).resolve().parents[2] / "scripts" / "gpm"


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("integration")
    scenario, out = d / "scenario", d / "out"
    # In a child process: the ray caster's libraries stay out of the test process.
    sim = ["simulate", "courtyard", "--scale", "0.2", "--duration", "6", "--seed", "2", "-o", str(scenario), "--quiet"]
    subprocess.run([sys.executable, str(GPM), *sim], check=True)
    argv = ["experiment", str(scenario), "-o", str(out), "--preset", "demo", "--interval", "0.25", "--settle", "1.5"]
    argv += ["--empty-map-seconds", "3"]
    assert main(argv) == 0
    return scenario, out


def test_every_output_exists_and_parses(run):
    scenario, out = run
    summary = read_json(out / "summary.json")
    assert list(summary["modes"]) == ["global", "grid_puzzle", "grid_puzzle_rospy"] == list(DEFAULT_MODES)
    assert "| Trajectory RMSE, grid puzzle vs global [m] |" in (out / "report.md").read_text()
    for name in ("cpu", "memory", "trajectories", "errors"):
        assert imread(out / "plots" / f"{name}.png").ndim == 3
    # The trajectory plot draws the map the run played against under the trajectories.
    assert read_json(out / "run.json")["global_map"] == str((scenario / "global_map.pcd").resolve())
    gt = read_tum(scenario / "ground_truth.tum")
    for mode in DEFAULT_MODES:
        traj = read_tum(out / mode / "trajectory.tum")
        assert len(traj) >= 40  # 10 Hz scans over 6 s, a few lost while starting
        assert gt.t[0] - 0.2 <= traj.t[0] and traj.t[-1] <= gt.t[-1] + 0.2
        log = read_csv(out / mode / "monitor.csv")
        assert "/localizer_manager" in log.names and len(log) >= 10
        assert json.loads((out / mode / "monitor.json").read_text())["samples"] == len(log)
        # One status per scan matched, with the time it took: every published pose has one.
        times = read_scan_times(out / mode / "scan_times.csv")
        assert len(times) >= len(traj) and np.all(times[:, 1] >= times[:, 2]) and np.all(times[:, 2] > 0)
        # What each match did: an accepted match ran at least one NDT iteration.
        assert np.all(times[times[:, 3] > 0.5, 4] >= 1) and np.all(times[:, 5:] >= 0)
        assert summary["modes"][mode]["scan_time_ms"]["scans"] == len(times)
    assert "## Time per scan" in (out / "report.md").read_text()
    storage = summary["storage"]["tiles"]
    assert storage["data_overhead_bytes"] == 0 and storage["points_tiles"] == storage["points_map"]


def test_modes_agree_within_5_cm_and_track_ground_truth(run):
    _scenario, out = run
    summary = read_json(out / "summary.json")
    for mode in ("grid_puzzle", "grid_puzzle_rospy"):
        between = summary["between_modes"][f"{mode}_vs_global"]["translation_m"]
        assert between["rmse"] < 0.05 and between["pairs"] >= 40, mode
    for mode in DEFAULT_MODES:
        ape = summary["modes"][mode]["ape"]["translation_m"]
        # The prior map is built with a few centimetres of drift (simulator): 0.3 m bounds a lost track.
        assert ape["max"] < 0.3, mode
    resources = {mode: summary["modes"][mode]["resources"] for mode in summary["modes"]}
    # The provider nodelet is in the localizer's manager: that one process; the paper's setup adds the provider's.
    assert resources["grid_puzzle"]["paper"]["processes"] == ["/localizer_manager"]
    assert resources["grid_puzzle_rospy"]["paper"]["processes"] == ["/localizer_manager", "/grid_puzzle_map_provider"]
    for mode in ("grid_puzzle", "grid_puzzle_rospy"):
        paper = resources[mode]["paper"]
        assert np.isfinite(paper["cpu_percent"]["mean"]) and paper["rss_bytes"]["mean"] > 10e6
    # The total protocol counts every process of the stack: the grid puzzle stack is one process, no nodelet loaders.
    assert resources["grid_puzzle"]["total"]["processes"] == ["/localizer_manager"]
    assert {"/localizer_manager", "/grid_puzzle_map_provider"} <= set(
        resources["grid_puzzle_rospy"]["total"]["processes"]
    )


def test_map_memory_is_measured_against_an_empty_map(run):
    _scenario, out = run
    summary = read_json(out / "summary.json")
    for mode in DEFAULT_MODES:
        log = read_csv(out / mode / "empty_map" / "monitor.csv")
        assert "/localizer_manager" in log.names and len(log) >= 4
        memory = summary["modes"][mode]["map_memory"]["processes"]["/localizer_manager"]
        # The same process with the map's voxels holds more than with none; its floor is a roscpp process.
        assert memory["empty_map_rss_bytes_mean"] > 10e6 and memory["map_bytes"] > 0.5e6, mode
        # The empty map's localizer matched nothing: no odometry was recorded.
        assert not (out / mode / "empty_map" / "trajectory.tum").exists()
    for mode in ("grid_puzzle", "grid_puzzle_rospy"):
        ratio = summary["map_memory_ratios"][mode]["paper"]
        assert ratio is not None and ratio > 0, mode
    assert "### Map memory" in (out / "report.md").read_text()


def test_no_process_is_left_running(run):
    _scenario, out = run
    for outcome in read_json(out / "run.json")["extra"]["outcomes"]:
        assert outcome["stray_pids"] == []
        assert processes_on(outcome["master_uri"]) == []


def test_a_terminated_experiment_stops_the_ros_processes_it_started(run, tmp_path):
    """SIGTERM (kill, a CI timeout) in the middle of playback: gpm stops roscore, roslaunch, the nodes and rosbag
    play as on Ctrl-C, instead of dying and leaving them running."""
    scenario, _ = run
    argv = [sys.executable, str(GPM), "experiment", str(scenario), "-o", str(tmp_path / "out"), "--modes", "global"]
    gpm = subprocess.Popen([*argv, "--empty-map-seconds", "0"], stderr=subprocess.PIPE, text=True)
    started: list[psutil.Process] = []
    try:
        for line in gpm.stderr:
            if "monitoring" in line:
                break
        time.sleep(2.0)  # rosbag play starts after that line
        started = psutil.Process(gpm.pid).children(recursive=True)
        assert any("rosbag" in " ".join(p.cmdline()) for p in started)
        assert len(started) >= 3, [p.name() for p in started]  # roscore's master, roslaunch, the nodes, ...
        gpm.send_signal(signal.SIGTERM)
        assert gpm.wait(timeout=120) == 130
        _, alive = psutil.wait_procs(started, timeout=5)
        assert alive == [], [p.pid for p in alive]
    finally:
        for p in [gpm, *started]:
            with contextlib.suppress(psutil.NoSuchProcess, ProcessLookupError):
                p.kill()
        gpm.stderr.close()
