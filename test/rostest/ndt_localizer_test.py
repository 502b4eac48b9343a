#!/usr/bin/env python3
"""Rostest of the NDT localizer nodelet on a synthetic drive (see ndt_localizer.test).

Writes the bag with the rosbag API, publishes the map (latched map_cloud), writes the same map as tile files
and publishes tile deltas by reference (tile names and their directory, as grid_puzzle_map_provider does)
around the ground-truth position (with one deliberately skipped revision, to exercise the resend service),
replays the bag with `rosbag play --clock` and compares the trajectories. Meanwhile it polls the pose the cloud
localizer saves on the parameter server (~last_pose, default save_pose_rate) and checks it against the poses
published and the ground truth; the offset localizer (save_pose_rate 0) must save nothing."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import rosgraph
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack, angle_between
from fixtures.saved_pose import SavedPoseSampler, read_saved_pose
from fixtures.tile_delta_publisher import TileDeltaPublisher
from geometry_msgs.msg import PoseStamped
from grid_puzzle_localization.msg import NdtStatus

OFFSET = ss.pose_matrix(np.array([0.8, 0.6, 0.0]), np.deg2rad(5.0))  # 1 m, 5 deg
NAME = "/ndt_localizer_test"


class NdtLocalizerTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        bag = cls.write_drive(NAME.lstrip("/"), ss.Drive(duration=5.0, x0=-8.0))
        map_points = ss.sample_map(cls.scene)
        cls.tracks = {name: OdometryTrack(f"/{name}/odom") for name in ("cloud", "tiles", "offset")}
        cls.statuses: list[NdtStatus] = []
        rospy.Subscriber("/tiles/ndt_localizer/status", NdtStatus, cls.statuses.append)
        cls.tiles = TileDeltaPublisher(map_points, Path(cls.tmp.name) / "tiles")
        map_pub = replay.publish_map(map_points)
        pose_pub = replay.publish_initial_pose("/offset/initialpose", OFFSET @ cls.drive.pose(0.0))
        truth_sub = rospy.Subscriber(
            "/ground_truth", PoseStamped, lambda m: cls.tiles.follow(m.pose.position.x, m.pose.position.y)
        )
        # Every localizer is loaded and subscribed before the bag starts.
        replay.wait_until_subscribed([map_pub, pose_pub, cls.tiles.pub], "the three localizers")
        first = cls.drive.pose(0.0)
        cls.tiles.follow(first[0, 3], first[1, 3])  # the first window, built with the map before the bag
        cls.saved = SavedPoseSampler("/cloud/ndt_localizer", NAME)
        try:
            replay.play_bag(bag, rate=0.25, timeout=300)
            cls.last_saved = cls.wait_for_last_pose_saved()
        finally:
            cls.saved.stop()
        truth_sub.unregister()

    @classmethod
    def wait_for_last_pose_saved(cls) -> tuple[float, np.ndarray] | None:
        """The cloud localizer's ~last_pose once it holds the last pose published (a save period, 2 s at the
        default rate, after it); what it holds after replay.WAIT s otherwise."""
        master = rosgraph.Master(NAME)
        deadline = time.monotonic() + replay.WAIT
        while True:
            saved = read_saved_pose(master, "/cloud/ndt_localizer")
            poses = cls.tracks["cloud"].poses
            if (saved and poses and round(saved[0], 3) == max(poses)) or time.monotonic() > deadline:
                return saved
            time.sleep(0.2)

    def assert_most_scans(self, poses: dict) -> None:
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")

    def test_cloud_mode_follows_ground_truth_within_5cm(self) -> None:
        poses = self.tracks["cloud"].poses
        self.assert_most_scans(poses)
        self.assert_within(poses, 0.05, np.deg2rad(0.5))

    def test_recovers_from_1m_5deg_initial_offset(self) -> None:
        poses = self.tracks["offset"].poses
        self.assert_most_scans(poses)
        late = {t: m for t, m in poses.items() if t >= replay.START + 1.0}
        self.assertTrue(late)
        self.assert_within(late, 0.05, np.deg2rad(0.5))

    def test_saved_pose_follows_the_published_pose(self) -> None:
        poses = self.tracks["cloud"].poses
        self.assertIsNotNone(self.last_saved, "the cloud localizer never wrote ~last_pose")
        samples = [(stamp, pose) for _, stamp, pose in self.saved.samples]
        saved = [*samples, self.last_saved]
        # At 0.5 Hz over the drive (20 s of wall time at 0.25x) about 10 writes; 3 show that it follows.
        self.assertGreaterEqual(len(samples), 3, f"~last_pose changed only {len(samples)} times during the drive")
        for stamp, pose in saved:
            published = poses.get(round(stamp, 3))
            self.assertIsNotNone(published, f"~last_pose/stamp {stamp:.3f} is not the stamp of a published pose")
            self.assertLess(float(np.linalg.norm(pose[:3, 3] - published[:3, 3])), 1e-6)
            self.assertLess(angle_between(pose, published), 1e-6)
        self.assertEqual(round(self.last_saved[0], 3), max(poses), "~last_pose never held the last pose published")
        self.assert_within(dict(saved), 0.05, np.deg2rad(0.5))

    def test_save_pose_rate_0_saves_nothing(self) -> None:
        self.assert_most_scans(self.tracks["offset"].poses)  # it published, and had as long as cloud to save
        self.assertIsNotNone(self.last_saved)
        self.assertFalse(rospy.has_param("/offset/ndt_localizer/last_pose"), "save_pose_rate 0 wrote ~last_pose")

    def test_tiles_mode_matches_cloud_mode_within_1cm(self) -> None:
        cloud, tiles = self.tracks["cloud"].poses, self.tracks["tiles"].poses
        self.assert_most_scans(tiles)
        common = sorted(set(cloud) & set(tiles))
        self.assertGreaterEqual(len(common), 0.9 * len(self.drive.stamps))
        error, where = self.worst({t: tiles[t] for t in common}, cloud.get)
        self.assertLess(error, 0.01, f"worst tiles vs cloud difference {error:.4f} m {where}")
        self.assertGreaterEqual(self.tiles.changes, 3, "the drive must cross tile boundaries")
        self.assertGreaterEqual(self.tiles.resend_calls, 1, "the skipped revision must trigger a resend")
        self.assertTrue(all(s.map_source == "tiles" for s in self.statuses))
        self.assertTrue(all(s.match_accepted for s in self.statuses))


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "ndt_localizer", NdtLocalizerTest)
