"""The experiment runner end to end with a stand-in localizer (topic_tools relays that echo the bag's
ground truth as odom): every output exists and parses, the figures follow from the known inputs,
and no process of the run is left."""

import json
from pathlib import Path

import numpy as np
import pytest
import rosbag
import rospy
from nav_msgs.msg import Odometry
from process_check import processes_on
from sensor_msgs import point_cloud2
from sensor_msgs.msg import PointField
from std_msgs.msg import Header

from grid_puzzle_localization.evaluation.trajectory import make_trajectory, read_tum, write_tum
from grid_puzzle_localization.experiment.config import ExperimentConfig
from grid_puzzle_localization.experiment.runner import initial_pose_from, run_experiment
from grid_puzzle_localization.monitor.log import read_csv
from grid_puzzle_localization.pcd.writer import write_pcd
from grid_puzzle_localization.report.build import read_json

RELAY_LAUNCH = str(Path(__file__).resolve().parents[1] / "launch" / "relay_localizer.launch")
FIELDS = [PointField(name, 4 * i, PointField.FLOAT32, 1) for i, name in enumerate("xyz")]


def write_scenario(d, seconds: float = 4.0):
    """A bag with points and ground_truth at 10 Hz along a circle, its TUM file and a tiny map."""
    t = 1.7e9 + np.arange(int(seconds * 10)) * 0.1
    yaw = 0.2 * (t - t[0])
    xyz = np.stack([5 * np.cos(yaw), 5 * np.sin(yaw), 0 * t], axis=1)
    quat = np.stack([0 * t, 0 * t, np.sin((yaw + np.pi / 2) / 2), np.cos((yaw + np.pi / 2) / 2)], axis=1)
    gt = make_trajectory(t, xyz, quat)
    write_tum(d / "ground_truth.tum", gt)
    with rosbag.Bag(str(d / "scenario.bag"), "w") as bag:
        for i, ti in enumerate(t):
            stamp = rospy.Time.from_sec(ti)
            cloud = point_cloud2.create_cloud(Header(stamp=stamp, frame_id="lidar"), FIELDS, [(1.0, 2.0, 3.0)] * 100)
            bag.write("points", cloud, stamp)
            odom = Odometry()
            odom.header.stamp, odom.header.frame_id, odom.child_frame_id = stamp, "map", "base_link"
            p, q = odom.pose.pose.position, odom.pose.pose.orientation
            p.x, p.y, p.z = xyz[i]
            q.x, q.y, q.z, q.w = quat[i]
            bag.write("ground_truth", odom, stamp)
    points = np.zeros(1000, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    points["x"] = np.linspace(-10, 10, 1000)
    write_pcd(d / "global_map.pcd", points)
    return gt


@pytest.fixture(scope="module")
def experiment(tmp_path_factory):
    d = tmp_path_factory.mktemp("runner")
    gt = write_scenario(d)
    cfg = ExperimentConfig(
        out_dir=d / "out",
        bag=d / "scenario.bag",
        global_map=d / "global_map.pcd",
        ground_truth=d / "ground_truth.tum",
        modes=["global", "grid_puzzle", "grid_puzzle_rospy"],
        rate=2.0,
        monitor_interval_s=0.2,
        settle_s=1.0,
        empty_map_s=0.0,  # the empty-map runs are the integration test's (test_experiment_integration.py)
        launch_file=RELAY_LAUNCH,
        scenario_name="relay",
    )
    summary = run_experiment(cfg, tiles=None, storage=None)
    return cfg, gt, summary


def test_every_output_exists_and_parses(experiment):
    cfg, gt, summary = experiment
    out = cfg.out_dir
    assert read_json(out / "summary.json") == json.loads(json.dumps(summary))
    assert (out / "report.md").read_text().startswith("# Grid puzzle map experiment")
    for name in ("cpu", "memory", "trajectories", "errors"):
        assert (out / "plots" / f"{name}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for mode in cfg.modes:
        traj = read_tum(out / mode / "trajectory.tum")
        # The relay echoes the ground truth: the recorded trajectory is the ground truth, pose for pose
        # (a few may be missed at the very start while the subscription connects).
        assert len(traj) >= len(gt) - 5
        idx = np.searchsorted(gt.t, traj.t)
        np.testing.assert_allclose(gt.t[idx], traj.t, atol=1e-6)
        np.testing.assert_allclose(gt.xyz[idx], traj.xyz, atol=1e-9)
        log = read_csv(out / mode / "monitor.csv")
        assert "/localizer_manager" in log.names and len(log) >= 5
        assert np.all(log.pid["/localizer_manager"] > 0)
        assert json.loads((out / mode / "monitor.json").read_text())["samples"] == len(log)
    assert "/grid_puzzle_map_provider" in read_csv(out / "grid_puzzle_rospy" / "monitor.csv").names
    assert "/grid_puzzle_map_provider" not in read_csv(out / "grid_puzzle" / "monitor.csv").names


def test_figures_follow_from_the_inputs(experiment):
    _cfg, _gt, summary = experiment
    between = summary["between_modes"]["grid_puzzle_vs_global"]["translation_m"]
    assert between["rmse"] < 1e-9 and between["pairs"] >= 30
    for mode in ("global", "grid_puzzle", "grid_puzzle_rospy"):
        assert summary["modes"][mode]["ape"]["translation_m"]["max"] < 1e-9
        paper = summary["modes"][mode]["resources"]["paper"]
        assert paper["rss_bytes"]["mean"] > 1e6 and paper["cpu_percent"]["samples"] >= 4
    resources = {mode: summary["modes"][mode]["resources"] for mode in summary["modes"]}
    # The provider nodelet runs in the localizer's process: both protocols count that process alone (besides the
    # relay standing for the rest of the stack in the total protocol).
    assert resources["global"]["paper"]["processes"] == ["/localizer_manager"]
    assert resources["grid_puzzle"]["paper"]["processes"] == ["/localizer_manager"]
    assert resources["grid_puzzle_rospy"]["paper"]["processes"] == [
        "/localizer_manager",
        "/grid_puzzle_map_provider",
    ]
    assert set(resources["grid_puzzle"]["total"]["processes"]) == {"/localizer_manager", "/points_sink"}
    assert set(resources["grid_puzzle_rospy"]["total"]["processes"]) == {
        "/localizer_manager",
        "/grid_puzzle_map_provider",
        "/points_sink",
    }


def test_no_process_is_left_running(experiment):
    cfg, _gt, _summary = experiment
    outcomes = read_json(cfg.out_dir / "run.json")["extra"]["outcomes"]
    assert [o["mode"] for o in outcomes] == ["global", "grid_puzzle", "grid_puzzle_rospy"]
    for o in outcomes:
        assert o["stray_pids"] == [] and o["killed_pids"] == []
        assert processes_on(o["master_uri"]) == []


def test_initial_pose_is_the_first_ground_truth_pose(experiment):
    cfg, gt, _summary = experiment
    x, y, z, roll, pitch, yaw = initial_pose_from(cfg.ground_truth)
    assert [x, y, z] == pytest.approx(gt.xyz[0].tolist())
    assert (roll, pitch, yaw) == pytest.approx((0.0, 0.0, np.pi / 2))
