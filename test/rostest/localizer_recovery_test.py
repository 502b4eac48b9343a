#!/usr/bin/env python3
"""Rostest of the localizer's bounded prediction, lost state and global search (see localizer_recovery.test).

One synthetic drive along the street with an 8 s gap in the scans, played with `rosbag play --clock` to three
localizers: one started at the true pose (the gap), one started 30 m and 90 deg off, one with no initial pose
that searches by itself around a coarse centre."""

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from grid_puzzle_localization.msg import NdtStatus
from nav_msgs.msg import Odometry
from scipy.spatial.transform import Rotation

GAP = (4.0, 12.0)  # no scans in between [s from the start]
MAX_COAST_TIME = 2.0  # lost/max_coast_time, the core's default
START_SEARCH_BOUND = 1.0  # [s of the drive] from the first scan to the first pose published
NAMES = ("gap", "offset", "global")


class Track:
    """Odometry and status of one localizer, keyed by stamp [s from the start]."""

    def __init__(self, name: str) -> None:
        self.poses: dict[float, np.ndarray] = {}
        self.statuses: dict[float, NdtStatus] = {}
        rospy.Subscriber(f"/{name}/odom", Odometry, self._on_odom)
        rospy.Subscriber(f"/{name}/ndt_localizer/status", NdtStatus, self._on_status)

    def _on_odom(self, msg: Odometry) -> None:
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat([o.x, o.y, o.z, o.w]).as_matrix()
        m[:3, 3] = [p.x, p.y, p.z]
        self.poses[replay.since_start(msg.header.stamp.to_sec())] = m

    def _on_status(self, msg: NdtStatus) -> None:
        self.statuses[replay.since_start(msg.header.stamp.to_sec())] = msg


class LocalizerRecoveryTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        drive = ss.Drive(duration=16.0, x0=-8.0)
        stamps = drive.stamps[(drive.stamps < GAP[0]) | (drive.stamps >= GAP[1])]
        object.__setattr__(drive, "stamps", stamps)  # the gap: scans dropped, the motion goes on
        bag = cls.write_drive("localizer_recovery_test", drive)
        cls.tracks = {name: Track(name) for name in NAMES}
        map_pub = replay.publish_map(ss.sample_map(cls.scene))
        replay.wait_until_subscribed([map_pub], "the localizers")
        # The gap holds no message: the clock jumps over it (the localizers see it in the scans' stamps).
        replay.play_bag(bag, rate=0.25, timeout=400, linger=3.0, skip_empty=1.0)

    def error(self, t: float, m: np.ndarray) -> float:
        return float(np.linalg.norm(m[:3, 3] - self.drive.pose(t)[:3, 3]))

    def assert_never_stale(self, track: Track) -> None:
        """Every published pose is a match or at most MAX_COAST_TIME after the last accepted one (or after the
        initial pose, taken at the first scan)."""
        last_good = min(track.statuses) if track.statuses else None
        for t in sorted(track.statuses):
            s = track.statuses[t]
            if s.match_accepted:
                last_good = t
            elif t in track.poses:
                self.assertLessEqual(t - last_good, MAX_COAST_TIME + 1e-6, f"stale pose published at {t:.1f} s")
            self.assertEqual(s.published, t in track.poses, f"status.published disagrees with odom at {t:.1f} s")

    def assert_tracks_after(self, track: Track, since: float, label: str) -> None:
        good = {t: m for t, m in track.poses.items() if t >= since and track.statuses.get(t, None) is not None}
        good = {t: m for t, m in good.items() if track.statuses[t].match_accepted}
        self.assertTrue(good, f"{label}: no accepted pose after {since:.1f} s")
        worst = max(good, key=lambda t: self.error(t, good[t]))
        self.assertLess(self.error(worst, good[worst]), 0.05, f"{label}: worst error at {worst:.1f} s")
        # Scans the localizer processed (a busy manager drops some from its queue of 2: not a tracking failure).
        later = [t for t in track.statuses if t >= min(good)]
        self.assertGreaterEqual(len(good), 0.9 * len(later), f"{label}: {len(good)} of {len(later)} scans matched")

    def test_gap_of_8s_is_bridged_within_2s(self) -> None:
        track = self.tracks["gap"]
        self.assert_never_stale(track)
        after = [t for t, s in track.statuses.items() if t >= GAP[1] and s.match_accepted]
        self.assertTrue(after, "no match after the gap")
        self.assertLessEqual(min(after) - GAP[1], 2.0, f"first match {min(after) - GAP[1]:.1f} s after the gap")
        self.assert_tracks_after(track, 0.0, "gap")

    def test_start_30m_90deg_off_is_found_by_the_start_search(self) -> None:
        """The wrong start fits no scan, so the first scan starts the search of the square of
        lost/initial_pose_search_size (60 m) around it over every yaw, on its own thread (lost/background_search), and
        is not published; the first scan after the search takes its pose up and is matched from it (or, farther from
        it than the NDT reaches, searches the little region around it first): the wrong start itself is never
        published."""
        track = self.tracks["offset"]
        stamps = sorted(track.statuses)
        self.assertTrue(stamps, "no status")
        first_status = track.statuses[stamps[0]]
        self.assertTrue(first_status.search_started, "the first scan started no search around the wrong start")
        self.assertFalse(first_status.published, "the wrong start was published")
        answered = [t for t in stamps if track.statuses[t].global_search]
        self.assertTrue(answered, "the start search never answered")
        reason = track.statuses[answered[0]].global_search_reason
        self.assertEqual(reason, "", f"the start search refused: {reason}")
        self.assertTrue(track.poses, "no pose published")
        first = min(track.poses)
        self.assertGreaterEqual(first, answered[0], "a pose was published before the search answered")
        # Played at a quarter of real time: 1 s of the drive is 4 s of wall time, loaded machine or not.
        self.assertLessEqual(first - stamps[0], START_SEARCH_BOUND, "the first pose came late")
        self.assertLess(self.error(first, track.poses[first]), 0.05, "the first pose is off")
        self.assert_never_stale(track)
        self.assert_tracks_after(track, first, "offset")

    def test_no_initial_pose_finds_itself_and_tracks_within_5cm(self) -> None:
        track = self.tracks["global"]
        self.assertTrue(track.poses, "no pose published")
        self.assert_tracks_after(track, min(track.poses), "global")


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "localizer_recovery", LocalizerRecoveryTest)
