#!/usr/bin/env python3
"""A start from a wrong pose under CPU load (issue 31, see wrong_start_hog.test).

The grid puzzle stack with the provider nodelet is given a start pose 20 m ahead of the true start and turned by
90 deg, while a busy loop runs on core 1 for the whole drive. The window (n 1, k 1, 10 m tiles) around the wrong
pose leaves the true start out, so the localizer can only recover once the provider's window has grown to hold the
search region the localizer reports in its ~status.

What must happen:
- the first scans are refused: ~status lost, nothing published (no odometry), since the wrong pose matches
  nothing;
- the first pose within 1 m of the ground truth comes within RECOVERY s of bag time after the first scan (below);
- every pose ever published is within 1 m of the ground truth (the wrong start pose is never published).

RECOVERY, derived from the defaults (config/ndt_localizer.yaml): the window around the wrong start does not hold the
square of lost/initial_pose_search_size (60 m) around it, so that square is not searched (a look-alike place inside
the window could win over the true one outside it). The search region around the last accepted pose (the wrong
start) has a radius of prediction/min_radius + margin x max_speed x elapsed = 1 + 22.5 t m, so it holds the vehicle
(20 m behind it, driving towards it at 5 m/s) after about 0.7 s; it covers every yaw only after
prediction/max_extrapolation (2 s; before that the yaw range grows 0.75 rad/s, 90 deg after 2.1 s); a search runs at
most every lost/search_period (1 s); so the first search that can succeed is due about 3 s after the first scan. The
window's growth is applied by the map worker (niced) in the time the scans leave, and the hog takes one of the two
cores: the issue's figure for the whole recovery under a hog is 10 s of bag time, which is the bound here. The drive
is played at RATE 0.25 (4 s of wall time per s of bag time), as the other stack tests on a busy 2-core CI machine.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack, angle_between
from fixtures.synthetic_tiles import write_map_tiles
from grid_puzzle_localization.msg import NdtStatus, ProviderStatus

from grid_puzzle_localization.experiment.cpu_hog import start_cpu_hog, stop_cpu_hog

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from fault_report import record

S = 10.0  # [m] tile side, as the .test file sets it
START = replay.START
DURATION = 10.0  # [s] of drive
RATE = 0.25  # playback rate
OFFSET = 20.0  # [m] the wrong start lies this far ahead along the street ...
TURN = np.pi / 2  # [rad] ... and turned by this much
RECOVERY = 10.0  # [s of bag time] from the first scan to the first accepted match (see the module docstring)
TOLERANCE = 1.0  # [m] no published pose farther from the ground truth
YAW_TOLERANCE = np.deg2rad(5.0)  # [rad] nor turned more than this


def tile_of(x: float, y: float) -> tuple[int, int]:
    return int(np.floor(x / S)), int(np.floor(y / S))


def holds(status: ProviderStatus, tile: tuple[int, int]) -> bool:
    return status.i_min <= tile[0] <= status.i_max and status.j_min <= tile[1] <= status.j_max


def area(status: ProviderStatus) -> int:
    """Tiles in the window's bounds."""
    return (status.i_max - status.i_min + 1) * (status.j_max - status.j_min + 1)


class WrongStartHogTest(replay.DriveReplayTest):
    hog: subprocess.Popen | None = None

    @classmethod
    def setUpClass(cls) -> None:
        bag = cls.write_drive("wrong_start_hog_test", ss.Drive(duration=DURATION, x0=-8.0))
        cls.tile_dir = rospy.get_param("~tiles")
        write_map_tiles(ss.sample_map(cls.scene), cls.tile_dir, S)
        cls.track = OdometryTrack("/odom")
        cls.statuses: dict[float, NdtStatus] = {}  # by stamp [s from the first scan]
        cls.provider: list[tuple[float, ProviderStatus]] = []  # (bag time received [s from the first scan], status)
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, cls._on_status, queue_size=100)
        rospy.Subscriber("/grid_puzzle_map_provider/status", ProviderStatus, cls._on_provider, queue_size=100)
        truth = cls.drive.pose(0.0)
        wrong = ss.pose_matrix(truth[:3, 3] + [OFFSET, 0.0, 0.0], np.arctan2(truth[1, 0], truth[0, 0]) + TURN)
        cls.wrong = wrong
        try:
            cls.hog = start_cpu_hog()
            pose_pub = replay.publish_initial_pose("/initialpose", wrong)
            replay.wait_until_subscribed([pose_pub], "the localizer and the provider nodelet (one manager)")
            replay.play_bag(bag, rate=RATE, timeout=DURATION / RATE + replay.WAIT, linger=3.0)
        except BaseException:
            cls.stop_hog()
            raise

    @classmethod
    def stop_hog(cls) -> None:
        if cls.hog is not None:
            stop_cpu_hog(cls.hog)

    @classmethod
    def tearDownClass(cls) -> None:
        cls.stop_hog()
        shutil.rmtree(cls.tile_dir, ignore_errors=True)
        super().tearDownClass()

    @classmethod
    def _on_status(cls, msg: NdtStatus) -> None:
        cls.statuses[replay.since_start(msg.header.stamp.to_sec())] = msg

    @classmethod
    def _on_provider(cls, msg: ProviderStatus) -> None:
        cls.provider.append((rospy.Time.now().to_sec() - START, msg))

    def first_accepted(self) -> float:
        accepted = [t for t, s in self.statuses.items() if s.match_accepted]
        self.assertTrue(accepted, f"no match accepted in {len(self.statuses)} scans: the localizer never recovered")
        return min(accepted)

    def first_right(self) -> float:
        """Stamp [s from the first scan] from which every published pose is within TOLERANCE of the ground truth (a
        wrong track that crosses the true one is not a recovery)."""
        poses = self.track.poses
        self.assertTrue(poses, "no pose published: the localizer never recovered")
        wrong = [t for t, m in poses.items() if np.linalg.norm(m[:3, 3] - self.truth(t)[:3, 3]) >= TOLERANCE]
        right = [t for t in poses if not wrong or t > max(wrong)]
        error, where = self.worst(poses, self.truth)
        self.assertTrue(
            right, f"never recovered: the last pose is more than {TOLERANCE} m off (worst {error:.1f} m {where})"
        )
        return replay.since_start(min(right))

    def test_the_hog_ran_for_the_whole_drive(self) -> None:
        self.assertIsNotNone(self.hog)
        self.assertIsNone(self.hog.poll(), "the CPU hog ended before the drive did")

    def test_the_true_start_lies_outside_the_wrong_poses_window(self) -> None:
        self.assertTrue(self.provider, "no status from the provider nodelet")
        first = self.provider[0][1]
        start = tile_of(*self.drive.pose(0.0)[:2, 3])
        self.assertTrue(holds(first, tile_of(*self.wrong[:2, 3])), "the first window is not the wrong pose's")
        self.assertFalse(
            holds(first, start), f"the true start's tile {start} is in the first window: it does not matter"
        )

    def test_first_scans_are_reported_lost_and_not_published(self) -> None:
        self.assertTrue(self.statuses, "no status from the localizer")
        t0 = min(self.statuses)
        recovered = self.first_accepted()
        first = self.statuses[t0]
        self.assertGreater(
            recovered,
            t0,
            f"the first scan was accepted at the wrong start pose (NVTL {first.nvtl:.2f}, inliers "
            f"{first.inlier_fraction:.2f}, {first.target_points} target points)",
        )
        before = [t for t in self.statuses if t < recovered]
        self.assertTrue(all(self.statuses[t].lost for t in before), "a scan before the recovery was not reported lost")
        published = [t for t in before if self.statuses[t].published]
        self.assertEqual(published, [], "poses published before the first accepted match")
        odom = [t for t in map(replay.since_start, self.track.poses) if t < recovered]
        self.assertEqual(odom, [], "odometry published before the first accepted match")

    def test_recovers_within_10s_of_bag_time(self) -> None:
        t0 = 0.0  # the first scan's stamp
        recovered = self.first_right()
        lost = [s for t, s in self.statuses.items() if t < recovered and s.lost]
        first = self.provider[0][1] if self.provider else None
        grown = [t for t, s in self.provider if first and area(s) > area(first)]
        record(
            "start 20 m and 90 deg off, CPU hog on core 1, grid puzzle stack (provider nodelet, n 1 k 1, 10 m tiles)",
            f"{len(lost)} scans reported lost before the first right pose",
            round(recovered - t0, 2),
            data_lost=f"{self.statuses[max(self.statuses)].scans_dropped} scans dropped by the localizer",
            window_grew_at_s=round(min(grown), 2) if grown else None,
            rate=RATE,
        )
        rospy.loginfo(
            "recovered %.2f s (bag time) after the first scan, %d scans lost, window grew at %s s",
            recovered - t0,
            len(lost),
            f"{min(grown):.2f}" if grown else "never",
        )
        self.assertLessEqual(
            recovered - t0,
            RECOVERY,
            f"first pose within {TOLERANCE} m of the truth {recovered - t0:.2f} s after the first scan",
        )

    def test_every_published_pose_within_1m_of_the_ground_truth(self) -> None:
        recovered = self.first_accepted()
        poses = self.track.poses
        after = [t for t in self.statuses if t >= recovered]
        self.assertGreaterEqual(len(poses), 0.5 * len(after), f"{len(poses)} poses for {len(after)} scans")
        error, where = self.worst(poses, self.truth)
        self.assertLess(error, TOLERANCE, f"worst translation error {error:.3f} m {where}")
        yaw = max(angle_between(m, self.truth(t)) for t, m in poses.items())
        self.assertLess(yaw, YAW_TOLERANCE, f"worst rotation error {np.rad2deg(yaw):.1f} deg")


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "wrong_start_hog", WrongStartHogTest)
