#!/usr/bin/env python3
"""Rostest of the NDT localizer nodelet with fusion/mode sliding_window (see fusion_localizer.test): a synthetic
drive with scans and a noisy, biased 200 Hz IMU whose mounting (turned 90 deg, off-centre) comes from TF,
replayed with `rosbag play --clock`; both localizers' tracks are compared with the ground truth."""

from __future__ import annotations

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack
from grid_puzzle_localization.msg import NdtStatus

OFFSET = ss.pose_matrix(np.array([0.8, 0.6, 0.0]), np.deg2rad(5.0))  # 1 m, 5 deg


class FusionLocalizerTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        bag = cls.write_drive("fusion_localizer_test", ss.Drive(duration=5.0, x0=-8.0), imu_rate=200.0)
        cls.tracks = {name: OdometryTrack(f"/{name}/odom") for name in ("window", "offset")}
        cls.statuses: list[NdtStatus] = []
        rospy.Subscriber("/window/ndt_localizer/status", NdtStatus, cls.statuses.append)
        map_pub = replay.publish_map(ss.sample_map(cls.scene))
        pose_pub = replay.publish_initial_pose("/offset/initialpose", OFFSET @ cls.drive.pose(0.0))
        replay.wait_until_subscribed([map_pub, pose_pub], "the localizers")
        replay.play_bag(bag, rate=0.25, timeout=200)

    def test_window_follows_ground_truth_within_5cm(self) -> None:
        poses = self.tracks["window"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        self.assert_within(poses, 0.05, np.deg2rad(0.5))
        self.assertTrue(self.statuses and all(s.match_accepted for s in self.statuses))

    def test_recovers_from_1m_5deg_initial_offset(self) -> None:
        poses = self.tracks["offset"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        late = {t: m for t, m in poses.items() if t >= replay.START + 1.0}
        self.assertTrue(late)
        self.assert_within(late, 0.05, np.deg2rad(0.5))


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "fusion_localizer", FusionLocalizerTest)
