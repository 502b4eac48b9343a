#!/usr/bin/env python3
"""Rostest of the NDT localizer nodelet with fusion/mode sliding_window (see fusion_localizer.test): a synthetic
drive with scans and a noisy, biased 200 Hz IMU whose mounting (turned 90 deg, off-centre) comes from TF,
replayed with `rosbag play --clock`; the localizers' tracks are compared with the ground truth, and the window
sizes they report with the map changes they saw."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack
from fixtures.tile_delta_publisher import TileDeltaPublisher
from geometry_msgs.msg import PoseStamped
from grid_puzzle_localization.msg import NdtStatus

OFFSET = ss.pose_matrix(np.array([0.8, 0.6, 0.0]), np.deg2rad(5.0))  # 1 m, 5 deg
RESET_STATES = 5  # fusion/window/reset_states: N_r, the block map paper's value and the default


def shrinks(statuses: list[NdtStatus]) -> list[tuple[int, int]]:
    """(before, after) window sizes of the consecutive statuses where the window lost states."""
    sizes = [s.window_states for s in statuses]
    return [(a, b) for a, b in zip(sizes, sizes[1:]) if b < a]


class FusionLocalizerTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        bag = cls.write_drive("fusion_localizer_test", ss.Drive(duration=5.0, x0=-8.0), imu_rate=200.0)
        map_points = ss.sample_map(cls.scene)
        cls.tracks = {name: OdometryTrack(f"/{name}/odom") for name in ("window", "offset", "tiles")}
        cls.statuses: dict[str, list[NdtStatus]] = {"window": [], "tiles": []}
        for name, received in cls.statuses.items():
            rospy.Subscriber(f"/{name}/ndt_localizer/status", NdtStatus, received.append)
        cls.tiles = TileDeltaPublisher(map_points, Path(cls.tmp.name) / "tiles")
        map_pub = replay.publish_map(map_points)
        pose_pub = replay.publish_initial_pose("/offset/initialpose", OFFSET @ cls.drive.pose(0.0))
        truth_sub = rospy.Subscriber(
            "/ground_truth", PoseStamped, lambda m: cls.tiles.follow(m.pose.position.x, m.pose.position.y)
        )
        replay.wait_until_subscribed([map_pub, pose_pub, cls.tiles.pub], "the localizers")
        first = cls.drive.pose(0.0)
        cls.tiles.follow(first[0, 3], first[1, 3])  # the first window, before the bag
        replay.play_bag(bag, rate=0.25, timeout=200)
        truth_sub.unregister()

    def test_window_follows_ground_truth_within_5cm(self) -> None:
        poses = self.tracks["window"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        self.assert_within(poses, 0.05, np.deg2rad(0.5))
        statuses = self.statuses["window"]
        self.assertTrue(statuses and all(s.match_accepted for s in statuses))
        # One map for the whole drive: the window fills up and never shrinks.
        self.assertGreater(max(s.window_states for s in statuses), RESET_STATES)
        self.assertEqual(shrinks(statuses), [])

    def test_a_reset_of_the_tiles_shrinks_the_window_and_tracking_goes_on(self) -> None:
        poses = self.tracks["tiles"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        self.assert_within(poses, 0.05, np.deg2rad(0.5))
        self.assertGreaterEqual(self.tiles.resend_calls, 1, "the skipped revision must trigger a reset delta")
        # The first delta (a reset too) only starts the map; the resent window is a reset of the map source.
        self.assertEqual([after for _, after in shrinks(self.statuses["tiles"])], [RESET_STATES])

    def test_recovers_from_1m_5deg_initial_offset(self) -> None:
        poses = self.tracks["offset"].poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        late = {t: m for t, m in poses.items() if t >= replay.START + 1.0}
        self.assertTrue(late)
        self.assert_within(late, 0.05, np.deg2rad(0.5))


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "fusion_localizer", FusionLocalizerTest)
