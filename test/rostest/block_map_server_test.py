#!/usr/bin/env python3
"""Writes a block directory (a grid of blocks with known centroids), launches block_map_server with
launch/block_map_server.launch, and drives it with poses: every ~status selection, every map_cloud and
every ~query_blocks answer must equal the brute-force nearest blocks."""

from __future__ import annotations

import os
import shutil
import tempfile
import unittest

import numpy as np
import roslaunch
import rospkg
import rospy
import rostest
from geometry_msgs.msg import Point
from grid_puzzle_localization.msg import BlockMapStatus
from grid_puzzle_localization.srv import QueryBlocks
from nav_msgs.msg import Odometry
from sensor_msgs.msg import PointCloud2

from grid_puzzle_localization.blocks.store import write_block_dir
from grid_puzzle_localization.ros.msgs.cloud import cloud_to_array

NUM_BLOCKS = 2
TIMEOUT = 20.0  # [s] for any one expected message
INITIAL_POSE = [47.0, 31.0, 0.5, 0.0, 0.0, 1.0]  # [x y z roll pitch yaw]: blocks served before any pose


def make_blocks(directory: str) -> tuple[np.ndarray, list[np.ndarray]]:
    rng = np.random.default_rng(5)
    centres = [
        (30.0 * i + rng.uniform(-3, 3), 30.0 * j + rng.uniform(-3, 3), rng.uniform(-1, 1))
        for i in range(4)
        for j in range(3)
    ]
    clouds = [np.round(rng.uniform(-20, 20, size=(200, 3)) * [1, 1, 0.1] + c, 2) for c in centres]
    write_block_dir(directory, ((c, c.mean(axis=0), {}) for c in clouds), "keyframe_blocks", {}, 0)
    return np.array([c.mean(axis=0) for c in clouds]), clouds


def xyz_rows(points: np.ndarray) -> np.ndarray:
    return np.unique(np.stack([points[n] for n in "xyz"], axis=1).astype(np.float32), axis=0)


class BlockMapServerTest(unittest.TestCase):
    def setUp(self):
        rospy.init_node("block_map_server_test")
        self.tmp = tempfile.mkdtemp(prefix="gpm_block_map_server_test_")
        self.block_dir = os.path.join(self.tmp, "blocks")
        self.centroids, self.clouds = make_blocks(self.block_dir)
        launch_file = os.path.join(
            rospkg.RosPack().get_path("grid_puzzle_localization"), "launch", "block_map_server.launch"
        )
        uuid = roslaunch.rlutil.get_or_generate_uuid(None, False)
        self.launch = roslaunch.parent.ROSLaunchParent(
            uuid, [(launch_file, [f"block_dir:={self.block_dir}", f"initial_pose:={INITIAL_POSE}", "output:=log"])]
        )
        self.launch.start()
        self.statuses, self.clouds_received = {}, {}
        rospy.Subscriber(
            "block_map_server/status", BlockMapStatus, lambda m: self.statuses.__setitem__(m.header.stamp, m)
        )
        rospy.Subscriber("map_cloud", PointCloud2, lambda m: self.clouds_received.__setitem__(m.header.stamp, m))
        self.odom = rospy.Publisher("odom", Odometry, queue_size=10)

    def tearDown(self):
        self.launch.shutdown()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def brute_force(self, position: np.ndarray) -> np.ndarray:
        return np.argsort(np.linalg.norm(self.centroids - position, axis=1))[:NUM_BLOCKS]

    def wait_for(self, table: dict, stamp: rospy.Time):
        deadline = rospy.get_time() + TIMEOUT
        while stamp not in table and rospy.get_time() < deadline and not rospy.is_shutdown():
            rospy.sleep(0.02)
        self.assertIn(stamp, table, f"nothing received for stamp {stamp.to_sec()}")
        return table[stamp]

    def send_pose(self, position: np.ndarray, stamp: rospy.Time, frame: str = "map") -> None:
        msg = Odometry()
        msg.header.stamp, msg.header.frame_id = stamp, frame
        msg.pose.pose.position = Point(*position)
        msg.pose.pose.orientation.w = 1.0
        self.odom.publish(msg)

    def assert_cloud_holds(self, cloud: PointCloud2, blocks: tuple) -> None:
        self.assertEqual(cloud.header.frame_id, "map")
        union = np.concatenate([self.clouds[i] for i in blocks])
        np.testing.assert_array_equal(xyz_rows(cloud_to_array(cloud)), np.unique(union.astype(np.float32), axis=0))

    def test_selection_cloud_and_query_match_brute_force(self):
        rospy.wait_for_service("block_map_server/query_blocks", timeout=TIMEOUT)
        while self.odom.get_num_connections() == 0 and not rospy.is_shutdown():
            rospy.sleep(0.05)
        rng = np.random.default_rng(11)
        # A path through the grid (many switches) with some repeated positions (no switch).
        path = np.concatenate([np.linspace([-10, -10, 0], [100, 70, 0], 25), np.repeat([[45.0, 30.0, 0.0]], 3, axis=0)])
        path[:, 2] = rng.uniform(-1, 1, len(path))
        # The blocks around ~initial_pose are published at startup, before any pose.
        deadline = rospy.get_time() + TIMEOUT
        while not self.clouds_received and rospy.get_time() < deadline:
            rospy.sleep(0.02)
        self.assertEqual(len(self.clouds_received), 1, "expected exactly the startup map_cloud")
        previous = tuple(sorted(self.brute_force(np.array(INITIAL_POSE[:3])).tolist()))
        self.assert_cloud_holds(next(iter(self.clouds_received.values())), previous)
        switches = 1
        for k, position in enumerate(path):
            stamp = rospy.Time(1000 + k)
            self.send_pose(position, stamp)
            status = self.wait_for(self.statuses, stamp)
            expected = tuple(sorted(self.brute_force(position).tolist()))
            self.assertEqual(tuple(status.selected_ids), expected)
            if expected != previous:
                switches += 1
                self.assert_cloud_holds(self.wait_for(self.clouds_received, stamp), expected)
            else:
                self.assertNotIn(stamp, self.clouds_received)
            self.assertEqual(status.switch_count, switches)
            self.assertLessEqual(status.blocks_in_memory, NUM_BLOCKS)
            previous = expected
        self.assertGreater(switches, 3)
        # A pose in another frame is ignored: no status for it.
        self.send_pose(path[0], rospy.Time(5000), frame="odom")
        self.send_pose(path[0], rospy.Time(5001))
        self.wait_for(self.statuses, rospy.Time(5001))
        self.assertNotIn(rospy.Time(5000), self.statuses)
        query = rospy.ServiceProxy("block_map_server/query_blocks", QueryBlocks)
        for position in rng.uniform(-20, 110, size=(30, 3)):
            answer = query(Point(*position))
            order = self.brute_force(position)
            self.assertEqual(list(answer.block_ids), order.tolist())
            np.testing.assert_allclose(
                answer.distances, np.linalg.norm(self.centroids[order] - position, axis=1), rtol=1e-9
            )


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "block_map_server_check", BlockMapServerTest)
