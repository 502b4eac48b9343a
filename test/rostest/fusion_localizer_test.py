#!/usr/bin/env python3
"""Rostest of the NDT localizer nodelet with fusion/mode sliding_window (see fusion_localizer.test): a synthetic
drive with scans and a noisy, biased 200 Hz IMU whose mounting (turned 90 deg, off-centre) comes from TF,
replayed with `rosbag play --clock`; both localizers' tracks are compared with the ground truth."""

from __future__ import annotations

import subprocess
import tempfile
import time
import unittest
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack, angle_between
from fixtures.synthetic_bag import write_drive_bag, xyz_cloud
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

START = 1000.0  # bag time of the first scan [s]
OFFSET = ss.pose_matrix(np.array([0.8, 0.6, 0.0]), np.deg2rad(5.0))  # 1 m, 5 deg


class FusionLocalizerTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("fusion_localizer_test")
        cls.scene = ss.make_scene()
        cls.drive = ss.Drive(duration=5.0, x0=-8.0)
        cls.tmp = tempfile.TemporaryDirectory()
        bag = Path(cls.tmp.name) / "drive.bag"
        write_drive_bag(bag, cls.scene, cls.drive, start=START, imu_rate=200.0)
        map_points = ss.sample_map(cls.scene)
        cls.tracks = {name: OdometryTrack(f"/{name}/odom") for name in ("window", "offset")}
        cls.statuses: list[NdtStatus] = []
        rospy.Subscriber("/window/ndt_localizer/status", NdtStatus, cls.statuses.append)
        map_pub = rospy.Publisher("/map_cloud", type(xyz_cloud(map_points[:1], Header())), queue_size=1, latch=True)
        map_pub.publish(xyz_cloud(map_points, Header(frame_id="map")))
        pose_pub = rospy.Publisher("/offset/initialpose", PoseWithCovarianceStamped, queue_size=1, latch=True)
        start = OFFSET @ cls.drive.pose(0.0)
        init = PoseWithCovarianceStamped(header=Header(frame_id="map"))
        init.pose.pose.position.x, init.pose.pose.position.y = start[0, 3], start[1, 3]
        o = init.pose.pose.orientation
        o.x, o.y, o.z, o.w = Rotation.from_matrix(start[:3, :3]).as_quat()
        pose_pub.publish(init)
        deadline = time.monotonic() + 60.0

        def connected() -> bool:  # one connection per topic: the localizers share the manager's process
            return all(p.get_num_connections() for p in (map_pub, pose_pub))

        while time.monotonic() < deadline and not connected():
            time.sleep(0.2)
        if not connected():
            raise RuntimeError("the localizers did not subscribe within 60 s; see the manager's log")
        time.sleep(3.0)  # let the map be built in the background
        subprocess.run(["rosbag", "play", "--clock", "-q", "-d", "2", "-r", "0.25", str(bag)], check=True, timeout=200)
        time.sleep(2.0)

    @classmethod
    def tearDownClass(cls) -> None:
        cls.tmp.cleanup()

    def truth(self, stamp: float) -> np.ndarray:
        return self.drive.pose(stamp - START)

    def assert_within(self, poses: dict, metres: float, radians: float) -> None:
        errors = {t: float(np.linalg.norm(m[:3, 3] - self.truth(t)[:3, 3])) for t, m in poses.items()}
        t = max(errors, key=errors.get)
        where = f"at t = {t - START:.1f} s: {np.round(poses[t][:3, 3], 3)} vs {np.round(self.truth(t)[:3, 3], 3)}"
        self.assertLess(errors[t], metres, f"worst translation error {errors[t]:.3f} m {where}")
        self.assertLess(max(angle_between(m, self.truth(t)) for t, m in poses.items()), radians)

    def test_window_follows_ground_truth_within_5cm(self) -> None:
        poses = self.tracks["window"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        self.assert_within(poses, 0.05, np.deg2rad(0.5))
        self.assertTrue(self.statuses and all(s.match_accepted for s in self.statuses))

    def test_recovers_from_1m_5deg_initial_offset(self) -> None:
        poses = self.tracks["offset"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        late = {t: m for t, m in poses.items() if t >= START + 1.0}
        self.assertTrue(late)
        self.assert_within(late, 0.05, np.deg2rad(0.5))


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "fusion_localizer", FusionLocalizerTest)
