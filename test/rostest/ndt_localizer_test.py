#!/usr/bin/env python3
"""Rostest of the NDT localizer nodelet on a synthetic drive (see ndt_localizer.test).

Writes the bag with the rosbag API, publishes the map (latched map_cloud), writes the same map as tile files
and publishes tile deltas by reference (tile names and their directory, as grid_puzzle_map_provider does)
around the ground-truth position (with one deliberately skipped revision, to exercise the resend service),
replays the bag with `rosbag play --clock` and compares the trajectories."""

from __future__ import annotations

import subprocess
import tempfile
import threading
import time
import unittest
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack, angle_between
from fixtures.synthetic_bag import write_drive_bag, xyz_cloud
from fixtures.synthetic_tiles import write_map_tiles
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus, TileDelta
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header
from std_srvs.srv import Trigger, TriggerResponse

from grid_puzzle_localization.tiles import grid

START = 1000.0  # bag time of the first scan [s]
TILE = 10.0  # tile side [m]
WINDOW = 7  # tiles on each side of the vehicle's tile
OFFSET = ss.pose_matrix(np.array([0.8, 0.6, 0.0]), np.deg2rad(5.0))  # 1 m, 5 deg


class TileDeltaPublisher:
    """A minimal tile provider: tile files in ``tile_dir``, a square window around the ground-truth position,
    incremental deltas by reference, a reset on `resend`. Skips one revision on purpose (the second window
    change)."""

    def __init__(self, points: np.ndarray, tile_dir: Path) -> None:
        self.tiles = write_map_tiles(points, tile_dir, TILE)
        self.tile_dir = tile_dir
        self.loaded: set[tuple[int, int]] = set()
        self.revision = 0
        self.changes = 0
        self.resend_calls = 0
        self.lock = threading.Lock()
        self.pub = rospy.Publisher("/tile_delta", TileDelta, queue_size=100)
        self.srv = rospy.Service("/tile_provider/resend", Trigger, self._resend)

    def _msg(self, reset: bool, added: list, removed: list) -> TileDelta:
        self.revision += 1
        header = Header(stamp=rospy.Time.now(), frame_id="map")
        return TileDelta(
            header=header,
            revision=self.revision,
            reset=reset,
            grid_size=TILE,
            tile_dir=str(self.tile_dir),
            index_revision="1",
            added_ids=[grid.tile_stem(i, j, TILE) for i, j in added],
            removed_ids=[grid.tile_stem(i, j, TILE) for i, j in removed],
        )

    def _resend(self, _req: object) -> TriggerResponse:
        with self.lock:
            self.resend_calls += 1
            self.pub.publish(self._msg(True, sorted(self.loaded), []))
        return TriggerResponse(success=True, message="window resent")

    def follow(self, x: float, y: float) -> None:
        ci, cj = int(np.floor(x / TILE)), int(np.floor(y / TILE))
        want = {
            (i, j)
            for i in range(ci - WINDOW, ci + WINDOW + 1)
            for j in range(cj - WINDOW, cj + WINDOW + 1)
            if (i, j) in self.tiles
        }
        with self.lock:
            if want == self.loaded:
                return
            reset = not self.loaded
            msg = self._msg(reset, sorted(want - self.loaded), sorted(self.loaded - want))
            self.loaded = want
            self.changes += 1
            if self.changes == 2:
                return  # lost on purpose: the localizer must notice the gap and ask for a resend
            self.pub.publish(msg)


class NdtLocalizerTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("ndt_localizer_test")
        cls.scene = ss.make_scene()
        cls.drive = ss.Drive(duration=5.0, x0=-8.0)
        cls.tmp = tempfile.TemporaryDirectory()
        bag = Path(cls.tmp.name) / "drive.bag"
        write_drive_bag(bag, cls.scene, cls.drive, start=START)
        map_points = ss.sample_map(cls.scene)
        cls.tracks = {name: OdometryTrack(f"/{name}/odom") for name in ("cloud", "tiles", "offset")}
        cls.statuses: list[NdtStatus] = []
        rospy.Subscriber("/tiles/ndt_localizer/status", NdtStatus, cls.statuses.append)
        cls.tiles = TileDeltaPublisher(map_points, Path(cls.tmp.name) / "tiles")
        map_pub = rospy.Publisher("/map_cloud", type(xyz_cloud(map_points[:1], Header())), queue_size=1, latch=True)
        map_pub.publish(xyz_cloud(map_points, Header(frame_id="map")))
        pose_pub = rospy.Publisher("/offset/initialpose", PoseWithCovarianceStamped, queue_size=1, latch=True)
        start = OFFSET @ cls.drive.pose(0.0)
        init = PoseWithCovarianceStamped(header=Header(frame_id="map"))
        init.pose.pose.position.x, init.pose.pose.position.y = start[0, 3], start[1, 3]
        q = Rotation.from_matrix(start[:3, :3]).as_quat()
        o = init.pose.pose.orientation
        o.x, o.y, o.z, o.w = q
        pose_pub.publish(init)
        truth_sub = rospy.Subscriber(
            "/ground_truth", PoseStamped, lambda m: cls.tiles.follow(m.pose.position.x, m.pose.position.y)
        )
        # Every localizer is loaded and subscribed before the bag starts.
        deadline = time.monotonic() + 60.0

        def connected() -> bool:  # one connection per topic: the localizers share the manager's process
            return all(p.get_num_connections() for p in (map_pub, pose_pub, cls.tiles.pub))

        while time.monotonic() < deadline and not connected():
            time.sleep(0.2)
        if not connected():
            counts = {p.resolved_name: p.get_num_connections() for p in (map_pub, pose_pub, cls.tiles.pub)}
            raise RuntimeError(f"the three localizers did not subscribe within 60 s ({counts}); see the manager's log")
        first = cls.drive.pose(0.0)
        cls.tiles.follow(first[0, 3], first[1, 3])
        time.sleep(3.0)  # let the map and the first window be built in the background
        subprocess.run(["rosbag", "play", "--clock", "-q", "-d", "2", "-r", "0.25", str(bag)], check=True, timeout=300)
        time.sleep(2.0)
        truth_sub.unregister()

    @classmethod
    def tearDownClass(cls) -> None:
        cls.tmp.cleanup()

    def truth(self, stamp: float) -> np.ndarray:
        return self.drive.pose(stamp - START)

    def worst(self, poses: dict, reference) -> tuple[float, str]:
        """Largest translation error against ``reference(stamp)`` and a description of where it is."""
        errors = {t: float(np.linalg.norm(m[:3, 3] - reference(t)[:3, 3])) for t, m in poses.items()}
        t = max(errors, key=errors.get)
        where = f"at t = {t - START:.1f} s: {np.round(poses[t][:3, 3], 3)} vs {np.round(reference(t)[:3, 3], 3)}"
        return errors[t], where

    def assert_most_scans(self, poses: dict) -> None:
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")

    def test_cloud_mode_follows_ground_truth_within_5cm(self) -> None:
        poses = self.tracks["cloud"].poses
        self.assert_most_scans(poses)
        error, where = self.worst(poses, self.truth)
        self.assertLess(error, 0.05, f"worst translation error {error:.3f} m {where}")
        self.assertLess(max(angle_between(m, self.truth(t)) for t, m in poses.items()), np.deg2rad(0.5))

    def test_recovers_from_1m_5deg_initial_offset(self) -> None:
        poses = self.tracks["offset"].poses
        self.assert_most_scans(poses)
        late = {t: m for t, m in poses.items() if t >= START + 1.0}
        self.assertTrue(late)
        error, where = self.worst(late, self.truth)
        self.assertLess(error, 0.05, f"worst translation error after 1 s {error:.3f} m {where}")
        self.assertLess(max(angle_between(m, self.truth(t)) for t, m in late.items()), np.deg2rad(0.5))

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
