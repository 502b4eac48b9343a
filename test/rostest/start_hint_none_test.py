#!/usr/bin/env python3
"""Starts without a pose (issue 31, see start_hint_none.test): two grid puzzle stacks on one small map and one drive.

- hint: no initial pose; an initialpose_hint HINT_OFFSET off the true start with sigma HINT_SIGMA (3 sigma = 24 m
  holds the 15 m offset). The provider serves the window of the search around the hint, the localizer searches
  that square at the first scan.
- none: no initial pose and no hint; localization.launch global_search_timeout 1 s: the provider serves the whole
  map 1 s (wall time) after start-up, which is long before the bag plays, and the localizer searches its whole map
  1 s (bag time) after the first scan.

Each must publish its first pose within 1 m (and 5 deg) of the ground truth and within its bound of bag time after
the first scan, and no pose more than 1 m off afterwards. The bounds: hint, the search is due at the first scan and
is repeated every lost/search_period (1 s) on failure: HINT_BOUND 3 s allows the first search and two more. none: the
search is due global_search_timeout (1 s) after the first scan, repeated after another timeout on failure:
NONE_BOUND 4 s allows it and two more. The drive is played at RATE 0.25 (4 s of wall time per s of bag time), so a
search has 4 s of wall time per s of bag time on a busy 2-core machine (the search of the whole 100 m x 60 m map
takes well below that)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack, angle_between
from fixtures.synthetic_bag import write_drive_bag
from fixtures.synthetic_tiles import write_map_tiles
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus, ProviderStatus
from std_msgs.msg import Header

START = replay.START
S = 10.0  # [m] tile side, as the .test file sets it
LENGTH = 60.0  # [m] of street: the map is 100 m x 60 m (make_scene's ground reaches 10 m past the end, 30 m behind)
DURATION = 8.0  # [s] of drive, from x = -8 m to 32 m
RATE = 0.25
HINT_OFFSET = (12.0, 9.0)  # [m] the hint is 15 m off the true start
HINT_SIGMA = 8.0  # [m]
HINT_BOUND = 3.0  # [s of bag time] after the first scan (module docstring)
NONE_BOUND = 4.0  # [s of bag time] after the first scan (module docstring)
TOLERANCE = 1.0  # [m]
YAW_TOLERANCE = np.deg2rad(5.0)
STACKS = ("hint", "none")


def hint_msg(x: float, y: float, sigma: float, frame: str = "map") -> PoseWithCovarianceStamped:
    """An initialpose_hint at (x, y) [m] with variance sigma^2 in x and y."""
    msg = PoseWithCovarianceStamped(header=Header(frame_id=frame))
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance[0] = msg.pose.covariance[7] = sigma * sigma
    return msg


class Stack:
    """What one stack published: poses, the localizer's statuses by stamp, the provider's statuses."""

    def __init__(self, ns: str) -> None:
        self.track = OdometryTrack(f"/{ns}/odom")
        self.statuses: dict[float, NdtStatus] = {}
        self.provider: list[ProviderStatus] = []
        rospy.Subscriber(f"/{ns}/ndt_localizer/status", NdtStatus, self._on_status, queue_size=100)
        rospy.Subscriber(f"/{ns}/grid_puzzle_map_provider/status", ProviderStatus, self.provider.append)

    def _on_status(self, msg: NdtStatus) -> None:
        self.statuses[replay.since_start(msg.header.stamp.to_sec())] = msg


class StartHintNoneTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("start_hint_none_test")
        cls.scene = ss.make_scene(length=LENGTH)
        cls.drive = ss.Drive(duration=DURATION, x0=-8.0)
        cls.tmp = tempfile.TemporaryDirectory()
        bag = Path(cls.tmp.name) / "drive.bag"
        write_drive_bag(bag, cls.scene, cls.drive, start=START)
        cls.tile_dir = rospy.get_param("~tiles")
        write_map_tiles(ss.sample_map(cls.scene), cls.tile_dir, S)
        cls.stacks = {ns: Stack(ns) for ns in STACKS}
        truth = cls.drive.pose(0.0)[:2, 3]
        cls.hint = truth + HINT_OFFSET
        hint_pub = rospy.Publisher("/hint/initialpose_hint", PoseWithCovarianceStamped, queue_size=1, latch=True)
        hint_pub.publish(hint_msg(*cls.hint, HINT_SIGMA))
        # The localizer and the provider of the hint stack (two connections with the rospy provider, one per
        # process; one with the nodelet, which shares the localizer's manager).
        connections = 2 if rospy.get_param("~provider") == "rospy" else 1
        replay.wait_until_subscribed([hint_pub], "the hint stack's localizer and provider", connections)
        replay.play_bag(bag, rate=RATE, timeout=DURATION / RATE + replay.WAIT, linger=3.0)

    @classmethod
    def tearDownClass(cls) -> None:
        shutil.rmtree(cls.tile_dir, ignore_errors=True)
        super().tearDownClass()

    def assert_starts(self, ns: str, bound: float) -> None:
        stack = self.stacks[ns]
        poses = {replay.since_start(t): m for t, m in stack.track.poses.items()}
        self.assertTrue(poses, f"{ns}: no pose published ({len(stack.statuses)} statuses)")
        first = min(poses)  # [s] after the first scan (bag time START)
        truth = self.drive.pose(first)
        error = float(np.linalg.norm(poses[first][:3, 3] - truth[:3, 3]))
        rospy.loginfo("%s: first pose %.2f s (bag time) after the first scan, %.3f m off", ns, first, error)
        self.assertLess(error, TOLERANCE, f"{ns}: first pose {np.round(poses[first][:3, 3], 2)} at {first:.1f} s")
        self.assertLess(angle_between(poses[first], truth), YAW_TOLERANCE, f"{ns}: first pose turned")
        self.assertLessEqual(first, bound, f"{ns}: first pose {first:.2f} s after the first scan")
        worst = max(poses, key=lambda t: float(np.linalg.norm(poses[t][:3, 3] - self.drive.pose(t)[:3, 3])))
        worst_error = float(np.linalg.norm(poses[worst][:3, 3] - self.drive.pose(worst)[:3, 3]))
        self.assertLess(worst_error, TOLERANCE, f"{ns}: {worst_error:.3f} m off at {worst:.1f} s")
        # It tracks on: most scans after the first pose have one (a busy machine drops a few).
        later = [t for t in stack.statuses if t >= first]
        self.assertGreaterEqual(len(poses), 0.5 * len(later), f"{ns}: {len(poses)} poses for {len(later)} scans")

    def test_hint_15m_off_first_pose_within_1m_and_3s(self) -> None:
        self.assert_starts("hint", HINT_BOUND)

    def test_hint_window_holds_the_search_around_the_hint(self) -> None:
        provider = self.stacks["hint"].provider
        self.assertTrue(provider, "no status from the hint stack's provider")
        first = provider[0]
        # The first window is the search's: it holds the square of 3 sigma around the hint, whatever tiles exist.
        i0, j0 = np.floor((self.hint - 3 * HINT_SIGMA) / S).astype(int)
        i1, j1 = np.floor((self.hint + 3 * HINT_SIGMA) / S).astype(int)
        bounds = (first.i_min, first.i_max, first.j_min, first.j_max)
        self.assertTrue(first.i_min <= i0 and first.i_max >= i1 and first.j_min <= j0 and first.j_max >= j1, bounds)

    def test_none_first_pose_within_1m_and_4s(self) -> None:
        self.assert_starts("none", NONE_BOUND)

    def test_none_provider_served_the_whole_map_first(self) -> None:
        provider = self.stacks["none"].provider
        self.assertTrue(provider, "no status from the none stack's provider")
        tiles = {p.name for p in Path(self.tile_dir).glob("*.pcd")}
        self.assertEqual(provider[0].tiles_loaded, len(tiles), "the first window is not the whole map")


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "start_hint_none", StartHintNoneTest)
