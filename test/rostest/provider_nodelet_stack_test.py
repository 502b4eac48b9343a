#!/usr/bin/env python3
"""The grid puzzle stack with the provider nodelet (see provider_nodelet_stack.test): the localizer tracks the
synthetic drive within 5 cm of the ground truth on the tiles the nodelet serves, the window holds exactly the tile
files inside its bounds, the localizer's target holds only part of the map, and the stack is one process,
`/localizer_manager` (localization_node: it publishes the tile deltas and the odometry), with no `nodelet load`
process, no rospy provider and no relay process. With ~one_process false (provider_nodelet_stack_loaders.test, the
manager-and-loader form) the stack is the nodelet manager process plus one `nodelet load` process per nodelet."""

from __future__ import annotations

import os
import shutil
import sys
import xmlrpc.client

import numpy as np
import psutil
import rosgraph
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.odometry_track import OdometryTrack
from fixtures.synthetic_tiles import write_map_tiles
from grid_puzzle_localization.msg import NdtStatus, ProviderStatus

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from tile_truth import brute_force_window_files

S = 10.0  # tile side [m], as the .test file sets it
MANAGER = "/localizer_manager"


class ProviderNodeletStackTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        bag = cls.write_drive("provider_nodelet_stack_test", ss.Drive(duration=5.0, x0=-8.0))
        map_points = ss.sample_map(cls.scene)
        cls.map_size = len(map_points)
        cls.tile_dir = rospy.get_param("~tiles")
        write_map_tiles(map_points, cls.tile_dir, S)
        cls.track = OdometryTrack("/odom")
        cls.statuses: list[NdtStatus] = []
        cls.provider: list[ProviderStatus] = []
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, cls.statuses.append)
        rospy.Subscriber("/grid_puzzle_map_provider/status", ProviderStatus, cls.provider.append)
        pose_pub = replay.publish_initial_pose("/initialpose", cls.drive.pose(0.0))
        replay.wait_until_subscribed([pose_pub], "the localizer and the provider nodelet (one manager)")
        replay.play_bag(bag, rate=0.25, timeout=200)

    @classmethod
    def tearDownClass(cls) -> None:
        shutil.rmtree(cls.tile_dir, ignore_errors=True)
        super().tearDownClass()

    def test_tracks_within_5cm_on_the_nodelets_tiles(self) -> None:
        poses = self.track.poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        self.assert_within(poses, 0.05, np.deg2rad(0.5))
        tiled = [s for s in self.statuses if s.map_source == "tiles"]
        self.assertTrue(tiled and all(s.match_accepted for s in tiled))

    def test_only_the_windows_tiles_are_loaded(self) -> None:
        self.assertTrue(self.provider, "no status from the provider nodelet")
        last = self.provider[-1]
        window = brute_force_window_files(self.tile_dir, (last.i_min, last.i_max, last.j_min, last.j_max), S)
        all_tiles = brute_force_window_files(self.tile_dir, (-(10**6), 10**6, -(10**6), 10**6), S)
        self.assertEqual(last.tiles_loaded, len(window))
        self.assertLess(len(window), len(all_tiles), "the window must leave part of the map out")
        self.assertEqual(last.tile_dir, self.tile_dir)
        self.assertLess(self.statuses[-1].target_points, self.map_size)

    def test_the_stack_is_one_process_or_the_manager_plus_the_loaders(self) -> None:
        master = rosgraph.Master(rospy.get_name())
        publishers, _, _ = master.getSystemState()
        by_topic = dict(publishers)
        self.assertEqual(by_topic["/tile_delta"], [MANAGER])
        self.assertEqual(by_topic["/odom"], [MANAGER])
        self.assertEqual(by_topic["/grid_puzzle_map_provider/status"], [MANAGER])
        self.assertEqual(by_topic["/ndt_localizer/status"], [MANAGER])
        nodes = {n for _, names in publishers for n in names}
        ours = {n for n in nodes if n != rospy.get_name() and not n.startswith(("/rosout", "/play_"))}
        self.assertNotIn("/last_pose_hint", nodes)
        pids = {n: self.pid_of(n) for n in ours}
        loaders = self.nodelet_loaders()
        rss = sum(psutil.Process(pid).memory_info().rss for pid in set(pids.values()) | set(loaders))
        rospy.loginfo("stack processes %s, nodelet loaders %s, RSS %.1f MiB", pids, loaders, rss / 2**20)
        if rospy.get_param("~one_process", True):
            self.assertEqual(ours, {MANAGER})
            self.assertIn("localization_node", " ".join(psutil.Process(pids[MANAGER]).cmdline()))
            self.assertEqual(loaders, [])
        else:
            self.assertEqual(ours, {MANAGER, "/ndt_localizer", "/grid_puzzle_map_provider"})
            self.assertEqual(len(set(pids.values())), 3, pids)  # the two nodes are the manager's loaders
            self.assertEqual(sorted(loaders), sorted([pids["/ndt_localizer"], pids["/grid_puzzle_map_provider"]]))

    @staticmethod
    def nodelet_loaders() -> list[int]:
        """Pids of the `nodelet load` processes that rostest started (this test's siblings)."""
        loaders = []
        for proc in psutil.Process(os.getppid()).children(recursive=True):
            try:
                cmd = proc.cmdline()
            except psutil.NoSuchProcess:
                continue
            if cmd[:1] and os.path.basename(cmd[0]) == "nodelet" and cmd[1:2] == ["load"]:
                loaders.append(proc.pid)
        return loaders

    @staticmethod
    def pid_of(node: str) -> int:
        uri = rosgraph.Master(rospy.get_name()).lookupNode(node)
        code, _, pid = xmlrpc.client.ServerProxy(uri).getPid(rospy.get_name())
        assert code == 1, node
        return pid


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "provider_nodelet_stack", ProviderNodeletStackTest)
