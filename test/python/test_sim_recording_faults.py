"""The simulator's hand-held walk (yaw swing), reduced scan rate and recording gaps against closed forms."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import rosbag
from scipy.spatial.transform import Rotation

from grid_puzzle_localization import cli
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.sim.recording_faults import YawSwing, in_gaps, with_yaw_swing
from grid_puzzle_localization.sim.scenario import ScenarioConfig, generate, scan_every
from grid_puzzle_localization.sim.trajectory import RATE, Trajectory


def straight_walk(seconds: float) -> Trajectory:
    """Walking along x at 1 m/s, heading 40 deg off x, on a 5 deg slope (a tilted z axis)."""
    t = np.arange(int(seconds * RATE) + 1) / RATE
    position = np.column_stack([t, np.zeros_like(t), 0.1 * t])
    quat = Rotation.from_euler("ZYX", np.column_stack([np.full_like(t, 0.7), np.full_like(t, -0.09), 0 * t])).as_quat()
    return Trajectory(position, quat, np.array([0, 1]))


def test_yaw_swing_turns_each_pose_about_its_own_z_axis_by_the_closed_form():
    walk, swing = straight_walk(3.0), YawSwing(swing_deg=60.0, half_period_s=0.5)
    swung = with_yaw_swing(walk, swing)
    np.testing.assert_array_equal(swung.position, walk.position)
    relative = (Rotation.from_quat(walk.quat).inv() * Rotation.from_quat(swung.quat)).as_rotvec()
    expected = math.radians(30.0) * np.cos(np.pi * walk.times / 0.5)
    np.testing.assert_allclose(relative[:, :2], 0.0, atol=1e-12)  # about base_link's z axis only
    np.testing.assert_allclose(relative[:, 2], expected, atol=1e-12)
    # Scans half a period apart see the whole swing, reversing each time: +60, -60, +60 ... deg.
    at_scans = expected[:: int(0.5 * RATE)]
    np.testing.assert_allclose(np.degrees(np.diff(at_scans)), 60.0 * (-1.0) ** np.arange(1, len(at_scans)), atol=1e-9)
    assert np.all(np.sum(swung.quat[1:] * swung.quat[:-1], axis=1) > 0)  # sign-continuous


def test_scan_rate_must_divide_the_sensor_rate_and_gaps_are_half_open():
    assert scan_every(10.0, None) == 1 and scan_every(10.0, 2.0) == 5 and scan_every(10.0, 10.0) == 1
    with pytest.raises(UserError, match=r"--scan-rate 3\.0 Hz must divide the sensor.s 10 Hz"):
        scan_every(10.0, 3.0)
    np.testing.assert_array_equal(in_gaps([0.99, 1.0, 2.99, 3.0], ((1.0, 2.0),)), [False, True, True, False])
    with pytest.raises(UserError, match=r"swing must be in \(0, 180\] deg"):
        ScenarioConfig(yaw_swing=YawSwing(swing_deg=0.0)).resolved()


HANDHELD = ScenarioConfig(
    world="courtyard", seed=3, scale=0.25, duration=5.0, map_leaf=0.3, movers=0, yaw_swing=YawSwing(), scan_rate=2.0
)


@pytest.fixture(scope="module")
def handheld(tmp_path_factory):
    base = tmp_path_factory.mktemp("handheld")
    generate(replace(HANDHELD, gaps=((1.0, 2.0),)), base / "swing_gap", progress=False)
    generate(replace(HANDHELD, yaw_swing=None, scan_rate=None), base / "smooth", progress=False)
    return base


def bag_stamps(path, topic: str) -> np.ndarray:
    with rosbag.Bag(str(path)) as bag:
        return np.array([m.header.stamp.to_nsec() for _, m, _ in bag.read_messages(topics=[topic])], dtype=np.int64)


def test_bag_holds_2_hz_scans_and_nothing_inside_the_gap(handheld):
    t0 = round(HANDHELD.start_time * 1e9)
    scans = (bag_stamps(handheld / "swing_gap" / "scenario.bag", "points") - t0) * 1e-9
    expected = [0.5 * k for k in range(10) if not 1.0 <= 0.5 * k < 3.0]  # sweeps start every 0.5 s
    np.testing.assert_allclose(scans, expected, atol=1e-9)
    imu = (bag_stamps(handheld / "swing_gap" / "scenario.bag", "imu") - t0) * 1e-9
    samples = np.arange(int(5.0 * RATE) + 1) / RATE
    np.testing.assert_allclose(imu, samples[~((samples >= 1.0) & (samples < 3.0))], atol=1e-9)
    smooth = (bag_stamps(handheld / "smooth" / "scenario.bag", "points") - t0) * 1e-9
    np.testing.assert_allclose(smooth, 0.1 * np.arange(50), atol=1e-9)  # the sensor's 10 Hz


def test_ground_truth_is_the_smooth_walk_turned_by_the_swing(handheld):
    swung, smooth = (
        read_tum(handheld / "swing_gap" / "ground_truth.tum"),
        read_tum(handheld / "smooth" / "ground_truth.tum"),
    )
    np.testing.assert_array_equal(swung.t, smooth.t)  # complete at 100 Hz, gap included
    np.testing.assert_allclose(swung.xyz, smooth.xyz, atol=1e-9)
    relative = (Rotation.from_quat(smooth.quat).inv() * Rotation.from_quat(swung.quat)).as_rotvec()
    t = swung.t - swung.t[0]
    np.testing.assert_allclose(relative[:, 2], math.radians(30.0) * np.cos(np.pi * t / 0.5), atol=1e-6)


def test_simulate_command_line_options(tmp_path, capsys):
    args = ["simulate", "courtyard", "-o", str(tmp_path / "s"), "--scale", "0.25", "--duration", "2", "--quiet"]
    assert cli.main([*args, "--yaw-swing", "--scan-rate", "2", "--gap", "0.5", "0.5", "--map-density", "0.3"]) == 0
    assert "3 sweeps" in capsys.readouterr().out  # 0, 1.0 and 1.5 s: the one at 0.5 s falls in the gap
    assert cli.main([*args, "--no-imu", "--force"]) == 0
    with rosbag.Bag(str(tmp_path / "s" / "scenario.bag")) as bag:
        assert set(bag.get_type_and_topic_info().topics) == {"points", "ground_truth", "/tf_static"}
    assert cli.main([*args, "--gap", "5", "1", "--force"]) == 2
    assert "--gap 5.0 1.0: the gap must start inside the run" in capsys.readouterr().err
