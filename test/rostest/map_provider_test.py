#!/usr/bin/env python3
"""Runs a grid puzzle provider (the rospy node, or the nodelet standalone: the .test file's ~provider) on a small
tiled map written into a temp dir and drives poses along a path with turns. Checks the deltas (tiles by
reference), the merged map_cloud (switched on here) and the status against a brute-force selection over the
directory listing, and the standing start, a corrupt tile (named in the deltas, left out of map_cloud: the localizer
reports it), late subscribers, ~resend, a pose far off the map, the window grown for a lost localizer's search, a
tile directory rewritten under the node, a missing tile directory (the rospy node exits, the nodelet keeps
retrying and serves the directory once it exists) and a negative window n."""

import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import unittest

import numpy as np
import rospkg
import rospy
import rostest
from fixtures.synthetic_tiles import write_tiles
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus, ProviderStatus, TileDelta
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger

from grid_puzzle_localization.pcd import read_pcd
from grid_puzzle_localization.ros.msgs.cloud import cloud_to_array
from grid_puzzle_localization.tiles.grid import parse_tile_stem, tile_filename, tile_stem

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from tile_truth import brute_force_window_files

PKG = "grid_puzzle_localization"
S, N, K = 2.0, 1, 2
CORRUPT = (8, 2)  # on the first leg of the path
WAIT = 30.0  # [s] upper bound on waiting for a message (never asserted as a time)
LATE_SUBSCRIBER = """
import rospy
from grid_puzzle_localization.msg import TileDelta
rospy.init_node("late_subscriber", anonymous=True)
m = rospy.wait_for_message("/tile_delta", TileDelta, 30.0)
print(m.reset)
print(m.revision)
print(" ".join(m.added_ids))
"""


def provider_command(provider, name):
    """The command that starts the rospy provider node or the provider nodelet standalone, named ``name``."""
    if provider == "rospy":
        return [
            sys.executable,
            os.path.join(rospkg.RosPack().get_path(PKG), "scripts", "grid_puzzle_map_provider"),
            f"__name:={name}",
        ]
    return ["rosrun", "nodelet", "nodelet", "standalone", f"{PKG}/GridPuzzleProviderNodelet", f"__name:={name}"]


def expected_bounds(x, y, heading_deg):
    """The window written out from Table I by hand: Δ per axis in units of k, heading in degrees."""
    i, j = math.floor(x / S), math.floor(y / S)
    if heading_deg is None:
        return (i - N, i + N, j - N, j + N)
    d = (heading_deg + 20.0) % 360.0 - 20.0
    table = [(20, 1, 0, 0, 0), (70, 1, 0, 1, 0), (110, 0, 0, 1, 0), (160, 0, -1, 1, 0)]
    table += [(200, 0, -1, 0, 0), (250, 0, -1, 0, -1), (290, 0, 0, 0, -1), (340, 1, 0, 0, -1)]
    for hi, du_max, du_min, dv_max, dv_min in table:
        if d < hi:
            return (i - N + du_min * K, i + N + du_max * K, j - N + dv_min * K, j + N + dv_max * K)
    raise AssertionError(d)


def initial_pose(x, y):
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = "map"
    msg.header.stamp = rospy.Time.now()
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.w = 1.0
    return msg


def tile_file_points(directory, key):
    """x, y, z of a tile file (map_cloud carries only those, as float32)."""
    points = read_pcd(os.path.join(directory, tile_filename(*key, S))).points
    out = np.empty(len(points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    for name in "xyz":
        out[name] = points[name]
    return out


def xyz_sorted(points):
    xyz = np.stack([points["x"], points["y"], points["z"]], axis=1).astype(np.float64)
    return xyz[np.lexsort(xyz.T[::-1])]


class Recorder:
    def __init__(self, topic, kind):
        self.messages = []
        self.cond = threading.Condition()
        self.sub = rospy.Subscriber(topic, kind, self._on, queue_size=100)

    def _on(self, msg):
        with self.cond:
            self.messages.append(msg)
            self.cond.notify_all()

    def wait_for(self, predicate, what):
        with self.cond:
            ok = self.cond.wait_for(lambda: any(predicate(m) for m in self.messages), WAIT)
        if not ok:
            raise AssertionError(f"no message {what} within {WAIT} s")
        return next(m for m in reversed(self.messages) if predicate(m))


class MapProviderTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("map_provider_test")
        cls.dir = tempfile.mkdtemp(prefix="gpm_tiles_")
        rng = np.random.default_rng(4)
        keys = [(i, j) for i in range(20) for j in range(20) if rng.random() > 0.2 or (i, j) == CORRUPT]
        write_tiles(cls.dir, keys, S, count=30, seed=7)
        corrupt = os.path.join(cls.dir, tile_filename(*CORRUPT, S))
        with open(corrupt, "r+b") as f:
            f.truncate(os.path.getsize(corrupt) - 5)
        params = {"tiles/dir": cls.dir, "tiles/grid_size": S, "window/n": N, "window/k": K, "publish_map_cloud": True}
        for name, value in params.items():
            rospy.set_param(f"/provider/{name}", value)
        cls.deltas = Recorder("/tile_delta", TileDelta)
        cls.clouds = Recorder("/map_cloud", PointCloud2)
        cls.status = Recorder("/provider/status", ProviderStatus)
        cls.provider = rospy.get_param("~provider")
        cls.proc = subprocess.Popen([*provider_command(cls.provider, "provider"), "odom:=/odom"])
        cls.odom = rospy.Publisher("/odom", Odometry, queue_size=100)
        cls.localizer_status = rospy.Publisher("/localizer_status", NdtStatus, queue_size=10)
        cls.initialpose = rospy.Publisher("/initialpose", PoseWithCovarianceStamped, queue_size=10)
        deadline = time.monotonic() + WAIT
        publishers = (cls.odom, cls.localizer_status, cls.initialpose)
        while (
            any(p.get_num_connections() == 0 for p in publishers) or cls.deltas.sub.get_num_connections() == 0
        ) and time.monotonic() < deadline:
            rospy.sleep(0.1)
        cls.mirror = set()
        cls.last_revision = 0
        cls.prefetched = 0

    @classmethod
    def tearDownClass(cls):
        cls.proc.terminate()
        cls.proc.wait(timeout=WAIT)
        shutil.rmtree(cls.dir, ignore_errors=True)

    def send(self, x, y):
        msg = Odometry()
        msg.header.frame_id = "map"
        msg.header.stamp = rospy.Time.now()
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        msg.pose.pose.orientation.w = 1.0
        self.odom.publish(msg)

    def apply_new_deltas(self):
        """Replays unseen deltas into the mirror, checking revision order and each delta's tiles."""
        with self.deltas.cond:
            new = [d for d in self.deltas.messages if d.revision > MapProviderTest.last_revision]
        for d in new:
            self.assertEqual(d.revision, MapProviderTest.last_revision + 1)
            MapProviderTest.last_revision = d.revision
            self.assertEqual((d.tile_dir, len(d.added_clouds)), (self.dir, 0), "by reference: names, no points")
            self.assertTrue(d.index_revision)
            if d.reset:
                self.mirror.clear()
            for tile_id in d.removed_ids:
                self.mirror.remove(parse_tile_stem(tile_id, S))
            for tile_id in d.added_ids:
                key = parse_tile_stem(tile_id, S)
                self.assertNotIn(key, self.mirror)
                self.mirror.add(key)
            bounds = (d.i_min, d.i_max, d.j_min, d.j_max)
            self.assertEqual(self.mirror, brute_force_window_files(self.dir, bounds, S), f"delta {d.revision}")
            prefetch = {parse_tile_stem(t, S) for t in d.prefetch_ids}
            self.assertFalse(prefetch & self.mirror, "prefetch names tiles outside the window")
            self.assertTrue(all(os.path.exists(os.path.join(self.dir, tile_filename(*k, S))) for k in prefetch))
            MapProviderTest.prefetched += len(prefetch)
        return new

    def assert_map_cloud_is(self, keys):
        expected = [tile_file_points(self.dir, k) for k in sorted(keys - {CORRUPT})]
        want = xyz_sorted(np.concatenate(expected)) if expected else np.empty((0, 3))

        def matches(cloud):
            return cloud.header.frame_id == "map" and np.array_equal(xyz_sorted(cloud_to_array(cloud)), want)

        self.clouds.wait_for(matches, f"map_cloud holding exactly the {len(keys)} tiles of the window")

    def test_1_standing_start_is_one_plain_square(self):
        for _ in range(10):
            self.send(5.3, 5.3)
            rospy.sleep(0.1)
        first = self.deltas.wait_for(lambda d: d.revision == 1, "revision 1")
        rospy.sleep(1.0)  # give a wrong second delta the chance to show up
        self.assertTrue(first.reset)
        self.assertEqual((first.i_min, first.i_max, first.j_min, first.j_max), expected_bounds(5.3, 5.3, None))
        self.assertEqual(len(self.apply_new_deltas()), 1)
        status = self.status.wait_for(lambda m: True, "status")
        self.assertEqual(status.sector, -1)
        self.assertTrue(math.isnan(status.theta))
        self.assertEqual(status.tiles_loaded, len(self.mirror))
        self.assert_map_cloud_is(set(self.mirror))

    def test_2_drive_with_turns(self):
        legs = [((5.3, 5.3), (25.3, 5.3)), ((25.3, 5.3), (25.3, 21.3)), ((25.3, 21.3), (9.3, 37.3))]
        for (x0, y0), (x1, y1) in legs:
            steps = int(math.hypot(x1 - x0, y1 - y0) / 1.5)
            for t in range(1, steps + 1):
                self.send(x0 + (x1 - x0) * t / steps, y0 + (y1 - y0) * t / steps)
                rospy.sleep(0.1)
        final = expected_bounds(9.3, 37.3, 135.0)
        self.deltas.wait_for(lambda d: (d.i_min, d.i_max, d.j_min, d.j_max) == final, f"final window {final}")
        self.assertGreater(len(self.apply_new_deltas()), 5)
        self.assert_map_cloud_is(set(self.mirror))
        status = self.status.wait_for(lambda m: (m.i_min, m.i_max, m.j_min, m.j_max) == final, "final status")
        self.assertEqual(status.sector, 3)
        self.assertAlmostEqual(math.degrees(status.theta), 135.0, places=6)
        self.assertEqual(status.tiles_loaded, len(self.mirror))
        self.assertEqual(status.tile_dir, self.dir)
        self.assertGreater(MapProviderTest.prefetched, 0, "a heading was known: tiles ahead must be named")

    def test_3_late_subscriber_gets_a_reset_and_resend_broadcasts_one(self):
        # A subscriber in another process: rospy shares one connection among a process's subscribers.
        late = subprocess.run([sys.executable, "-c", LATE_SUBSCRIBER], capture_output=True, text=True, timeout=WAIT)
        self.assertEqual(late.returncode, 0, late.stderr)
        reset, revision, ids = late.stdout.split("\n")[:3]
        self.assertEqual(reset, "True")
        self.assertEqual(int(revision), MapProviderTest.last_revision)
        self.assertEqual({parse_tile_stem(t, S) for t in ids.split()}, set(self.mirror))
        rospy.wait_for_service("/provider/resend", WAIT)
        reply = rospy.ServiceProxy("/provider/resend", Trigger)()
        self.assertTrue(reply.success, reply.message)
        resent = self.deltas.wait_for(lambda d: d.revision == MapProviderTest.last_revision + 1, "resend")
        self.assertTrue(resent.reset)
        self.apply_new_deltas()

    def test_4_far_off_the_map_gives_an_empty_window_then_recovers(self):
        self.send(5000.0, 5000.0)
        self.deltas.wait_for(lambda d: d.i_min > 2000 and not d.added_ids, "an empty window far away")
        self.apply_new_deltas()
        self.assertEqual(self.mirror, set())
        self.assert_map_cloud_is(set())
        self.send(5.3, 5.3)
        back = expected_bounds(5.3, 5.3, 225.0)
        self.deltas.wait_for(lambda d: (d.i_min, d.i_max, d.j_min, d.j_max) == back, "the window back home")
        self.apply_new_deltas()
        self.assertTrue(self.mirror)
        self.assert_map_cloud_is(set(self.mirror))

    def test_4b_a_lost_localizer_gets_its_search_region_then_the_window_follows_the_pose_again(self):
        self.apply_new_deltas()
        home = expected_bounds(5.3, 5.3, 225.0)
        self.assertEqual(self.mirror, brute_force_window_files(self.dir, home, S))
        status = NdtStatus(lost=True, search_x=5.3, search_y=5.3, search_radius=7.0)
        status.header.stamp = rospy.Time.now()
        self.localizer_status.publish(status)
        # Half side: radius 7 m + n s (2 m), rounded up to 10 m; the union with the window it had.
        grown = (math.floor(-4.7 / S), math.floor(15.3 / S), math.floor(-4.7 / S), math.floor(15.3 / S))
        self.deltas.wait_for(lambda d: (d.i_min, d.i_max, d.j_min, d.j_max) == grown, f"the search's window {grown}")
        self.apply_new_deltas()
        # The pose published while lost is a prediction: the window does not follow it.
        self.send(9.3, 5.3)
        rospy.sleep(1.0)
        self.assertEqual(self.apply_new_deltas(), [])
        self.localizer_status.publish(NdtStatus(match_accepted=True))
        rospy.sleep(0.3)
        self.send(5.3, 5.3)
        seen = MapProviderTest.last_revision
        self.deltas.wait_for(
            lambda d: d.revision > seen and (d.i_min, d.i_max, d.j_min, d.j_max) == home, "the window back at the pose"
        )
        self.apply_new_deltas()
        self.assertEqual(self.mirror, brute_force_window_files(self.dir, home, S))
        # Lost again; this time a pose given by hand (rviz's initialpose) takes the window back to it. The wait is
        # for a new delta: the first search's window is in the history, and an initialpose sent before the status
        # is handled would be overtaken by it.
        seen = MapProviderTest.last_revision
        status.header.stamp = rospy.Time.now()
        self.localizer_status.publish(status)
        self.deltas.wait_for(
            lambda d: d.revision > seen and (d.i_min, d.i_max, d.j_min, d.j_max) == grown, "the search's window again"
        )
        self.apply_new_deltas()
        seen = MapProviderTest.last_revision
        self.initialpose.publish(initial_pose(5.3, 5.3))
        self.deltas.wait_for(
            lambda d: d.revision > seen and (d.i_min, d.i_max, d.j_min, d.j_max) == home, "the window at initialpose"
        )
        self.apply_new_deltas()

    def test_4c_the_window_goes_with_a_start_the_localizer_carries_while_its_map_arrives(self):
        self.apply_new_deltas()
        seen = MapProviderTest.last_revision
        status = NdtStatus(state="waiting_for_map", start_pending=True, start_x=25.3, start_y=5.3, start_yaw=0.0)
        status.header.stamp = rospy.Time.now()
        self.localizer_status.publish(status)
        ahead = expected_bounds(25.3, 5.3, 0.0)  # moved east from the window at (5.3, 5.3)
        self.deltas.wait_for(
            lambda d: d.revision > seen and (d.i_min, d.i_max, d.j_min, d.j_max) == ahead, f"the window at {ahead}"
        )
        self.apply_new_deltas()
        seen = MapProviderTest.last_revision
        self.send(5.3, 5.3)
        home = expected_bounds(5.3, 5.3, 180.0)
        self.deltas.wait_for(
            lambda d: d.revision > seen and (d.i_min, d.i_max, d.j_min, d.j_max) == home, "the window back home"
        )
        self.apply_new_deltas()

    def test_5_a_rewritten_directory_is_sent_again_as_a_reset_with_a_new_revision(self):
        self.apply_new_deltas()
        with self.deltas.cond:
            old = self.deltas.messages[-1].index_revision
        key = sorted(self.mirror - {CORRUPT})[0]
        write_tiles(self.dir, [key], S, count=31, seed=8)  # written by rename: the directory changes
        self.send(5.3, 5.3)
        fresh = self.deltas.wait_for(lambda d: d.index_revision != old, "a delta of the new revision")
        self.assertTrue(fresh.reset)
        self.assertIn(tile_stem(*key, S), fresh.added_ids)
        self.apply_new_deltas()
        self.assert_map_cloud_is(set(self.mirror))

    def test_6_missing_tile_directory_is_named(self):
        missing = os.path.join(self.dir, "nope")
        rospy.set_param("/broken_provider/tiles/dir", missing)
        rospy.set_param("/broken_provider/tiles/grid_size", S)
        command = [*provider_command(self.provider, "broken_provider"), "tile_delta:=/broken_delta"]
        if self.provider == "rospy":
            done = subprocess.run(command, capture_output=True, text=True, timeout=WAIT)
            self.assertEqual(done.returncode, 2)
            self.assertIn("does not exist", done.stdout + done.stderr)
            return
        # The nodelet shares the localizer's process: it names the directory, keeps running and retries.
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            deadline = time.monotonic() + WAIT
            line = ""
            while "does not exist" not in line and time.monotonic() < deadline:
                line = proc.stdout.readline()
            self.assertIn(f"{missing} does not exist", line)
            self.assertIsNone(proc.poll())
            shutil.copytree(self.dir, missing)
            deltas = Recorder("/broken_delta", TileDelta)
            publisher = rospy.Publisher("/odom", Odometry, queue_size=10)
            for _ in range(int(WAIT / 0.2)):
                self.send(5.3, 5.3)
                if deltas.messages:
                    break
                rospy.sleep(0.2)
            first = deltas.wait_for(lambda d: d.reset, "a first window once the directory exists")
            self.assertEqual(first.tile_dir, missing)
            publisher.unregister()
        finally:
            proc.terminate()
            proc.wait(timeout=WAIT)

    def test_7_a_negative_window_n_is_named(self):
        # In a manager, the nodelet's loader exits with the error and the manager (the localizer) keeps running.
        rospy.set_param("/bad_n_provider/tiles/dir", self.dir)
        rospy.set_param("/bad_n_provider/tiles/grid_size", S)
        rospy.set_param("/bad_n_provider/window/n", -1)
        command = [*provider_command(self.provider, "bad_n_provider"), "tile_delta:=/bad_n_delta"]
        done = subprocess.run(command, capture_output=True, text=True, timeout=WAIT)
        self.assertNotEqual(done.returncode, 0)
        self.assertIn("window n and k must be integers >= 0 (got n=-1", done.stdout + done.stderr)


if __name__ == "__main__":
    rostest.rosrun(PKG, "map_provider", MapProviderTest)
