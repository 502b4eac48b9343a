#!/usr/bin/env python3
"""The map provider killed with SIGKILL mid-drive (the rospy node, or with the nodelet the manager process that holds
it; the .test file's ~provider): roslaunch respawns it (respawn="true"), and the new process
re-syncs its subscribers with a reset delta of the current window. A mirror of the tiles, built from the deltas
(by reference: tile names and their directory) as the localizer builds its map, must equal the window's existing
tile files before the kill and again after the reset; the time from the kill to that reset is the recovery time."""

import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest

import rospy
import rostest
from fixtures.synthetic_tiles import write_tiles
from grid_puzzle_localization.msg import TileDelta
from nav_msgs.msg import Odometry

from grid_puzzle_localization.tiles.grid import parse_tile_stem, tile_filename

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from fault_report import record
from ros_process import node_pid
from tile_truth import brute_force_window_files

PKG = "grid_puzzle_localization"
S, N, K = 2.0, 1, 2
WAIT = 60.0  # [s] upper bound on waiting for a message (never asserted as a time)
NODES = {
    "rospy": """<node pkg="grid_puzzle_localization" type="grid_puzzle_map_provider" name="provider" respawn="true"
        respawn_delay="0" output="log">""",
    "nodelet": """<node pkg="nodelet" type="nodelet" name="provider_manager" args="manager" respawn="true"
        respawn_delay="0" output="log"/>
  <node pkg="nodelet" type="nodelet" name="provider" respawn="true" respawn_delay="0" output="log"
        args="load grid_puzzle_localization/GridPuzzleProviderNodelet provider_manager">""",
}
# The process that holds the provider: the one killed.
HOLDER = {"rospy": "/provider", "nodelet": "/provider_manager"}
LAUNCH = """<launch>
  {node}
    <param name="tiles/dir" value="{dir}"/>
    <param name="tiles/grid_size" value="{s}"/>
    <param name="window/n" value="{n}"/>
    <param name="window/k" value="{k}"/>
    <param name="publish_map_cloud" value="false"/>
    <remap from="odom" to="/odom"/>
  </node>
</launch>
"""


class Mirror:
    """The tiles as a subscriber sees them: deltas applied in order; a reset starts over (a respawned
    provider counts its revisions from 1 again)."""

    def __init__(self, directory):
        self.directory = directory
        self.tiles = {}
        self.revision = 0
        self.deltas = []
        self.gaps = []  # (revision, next revision) of deltas that skipped revisions without a reset
        self.cond = threading.Condition()
        self.sub = rospy.Subscriber("/tile_delta", TileDelta, self._on, queue_size=100)

    def _on(self, d):
        with self.cond:
            if d.reset:
                self.tiles.clear()
            elif d.revision != self.revision + 1:
                self.gaps.append((self.revision, d.revision))
            self.revision = d.revision
            for tile_id in d.removed_ids:
                del self.tiles[parse_tile_stem(tile_id, S)]
            for tile_id in d.added_ids:
                self.tiles[parse_tile_stem(tile_id, S)] = d.tile_dir
            self.deltas.append((time.monotonic(), d, set(self.tiles)))
            self.cond.notify_all()

    def wait_for(self, predicate, what):
        with self.cond:
            if not self.cond.wait_for(lambda: any(predicate(t, d) for t, d, _ in self.deltas), WAIT):
                raise AssertionError(f"no tile delta {what} within {WAIT} s")
            return next((t, d, keys) for t, d, keys in self.deltas if predicate(t, d))

    def check_against_files(self, d, keys):
        truth = brute_force_window_files(self.directory, (d.i_min, d.i_max, d.j_min, d.j_max), S)
        assert keys == truth, f"revision {d.revision}: mirror {sorted(keys)} != window {sorted(truth)}"
        with self.cond:
            for key, tile_dir in self.tiles.items():
                assert os.path.samefile(tile_dir, self.directory), f"tile {key} names directory {tile_dir}"
                assert os.path.isfile(os.path.join(tile_dir, tile_filename(*key, S))), f"tile {key} has no file"


class ProviderRespawnTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("provider_respawn_test")
        self.provider = rospy.get_param("~provider")
        if self._testMethodName == "test_without_map_cloud_the_node_never_loads_numpy" and self.provider != "rospy":
            self.skipTest("the rospy node's memory floor; the nodelet has no Python")
        self.dir = tempfile.mkdtemp(prefix="gpm_tiles_")
        write_tiles(self.dir, [(i, j) for i in range(40) for j in range(-4, 5)], S, count=30, seed=3)
        self.launch_file = os.path.join(self.dir, "provider.launch")
        with open(self.launch_file, "w") as f:
            f.write(LAUNCH.format(node=NODES[self.provider], dir=self.dir, s=S, n=N, k=K))
        self.mirror = Mirror(self.dir)
        self.launch = subprocess.Popen(
            ["roslaunch", self.launch_file], stdout=subprocess.DEVNULL, start_new_session=True
        )
        self.odom = rospy.Publisher("/odom", Odometry, queue_size=10)
        self.x = 1.3
        self.stop = threading.Event()
        self.driver = threading.Thread(target=self.drive, daemon=True)
        self.driver.start()

    def tearDown(self):
        self.stop.set()
        self.driver.join()
        self.launch.send_signal(signal.SIGINT)
        try:
            self.launch.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:  # a loaded machine: what is checked here is not how roslaunch ends
            os.killpg(self.launch.pid, signal.SIGKILL)
            self.launch.wait()
        shutil.rmtree(self.dir, ignore_errors=True)

    def drive(self):
        """Along +x at 1 m/s, 10 odometry messages a second."""
        while not self.stop.is_set() and self.x < 70.0:
            msg = Odometry()
            msg.header.frame_id = "map"
            msg.header.stamp = rospy.Time.now()
            msg.pose.pose.position.x, msg.pose.pose.position.y = self.x, 0.7
            msg.pose.pose.orientation.w = 1.0
            self.odom.publish(msg)
            self.x += 0.1
            time.sleep(0.1)

    def test_without_map_cloud_the_node_never_loads_numpy(self):
        # Tiles travel by reference and map_cloud is off: the node's memory stays at rospy's floor without numpy.
        self.mirror.wait_for(lambda t, d: d.revision >= 3, "revision 3 (driving)")
        with open(f"/proc/{node_pid('/provider', '/provider_respawn_test', WAIT)}/maps") as f:
            mapped = f.read()
        self.assertIn("python3", mapped)  # the right process
        self.assertNotIn("numpy", mapped)

    def test_sigkill_mid_drive_is_respawned_and_resynced(self):
        _, before, keys = self.mirror.wait_for(lambda t, d: d.revision >= 5, "revision 5 (driving)")
        self.mirror.check_against_files(before, keys)
        pid = node_pid(HOLDER[self.provider], "/provider_respawn_test", WAIT)
        killed = time.monotonic()
        os.kill(pid, signal.SIGKILL)
        t, reset, keys = self.mirror.wait_for(lambda t, d: t > killed and d.reset, "reset after the kill")
        recovery = t - killed
        node_pid(HOLDER[self.provider], "/provider_respawn_test", WAIT, other_than=pid)  # respawned
        self.assertTrue(math.isfinite(recovery))
        self.mirror.check_against_files(reset, keys)
        # The drive goes on: later deltas keep the mirror equal to the window.
        _, after, keys = self.mirror.wait_for(lambda t, d: t > killed and d.revision >= reset.revision + 3, "3 more")
        self.mirror.check_against_files(after, keys)
        self.assertEqual(self.mirror.gaps, [])
        record(
            f"provider ({self.provider}) SIGKILL mid-drive",
            "respawned by roslaunch; reset delta of the current window",
            round(recovery, 2),
        )


if __name__ == "__main__":
    rostest.rosrun(PKG, "provider_respawn", ProviderRespawnTest)
