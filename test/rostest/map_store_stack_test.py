#!/usr/bin/env python3
"""The grid puzzle stack on a tiled map served over HTTP (see map_store_stack.test). nginx serves the output of
`gpm tile`; the stack (localization.launch, the provider nodelet or the rospy provider: ~provider) gets
tiles:=http://127.0.0.1:PORT/map. nginx is stopped in the middle of the drive and started again: tiles entering the
window meanwhile cannot be fetched (the localizer names each by its URL) and are fetched with a later delta, the
localizer tracks within 5 cm throughout, the provider says the store is unreachable naming the URL, in its log and
its ~status, and then that it is back, and it serves the index revision of the served index.json."""

from __future__ import annotations

import hashlib
import os
import subprocess
import threading
import time
import unittest
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import nginx_server
from fixtures import synthetic_scene as ss
from fixtures.launch_group import stop_launch_group
from fixtures.odometry_track import OdometryTrack
from grid_puzzle_localization.msg import NdtStatus, ProviderStatus
from rosgraph_msgs.msg import Log

from grid_puzzle_localization.pcd import write_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.tiling import TileConfig, tile_map

S = 10.0  # tile side [m], as test/launch/map_store_stack.launch sets it
RATE = 0.5  # bag playback rate
OUTAGE_START = 7.0  # [s] wall time after play_bag starts (map build 3 s, play delay 2 s, then 1 s of drive)
OUTAGE = 5.0  # [s] wall time nginx is down (2.5 s of drive: 12.5 m, the window moves on)


class MapStoreStackTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        if nginx_server.binary() is None:
            raise unittest.SkipTest("nginx is not installed (apt-get install nginx-light)")
        bag = cls.write_drive("map_store_stack_test", ss.Drive(duration=6.0, x0=-8.0))
        provider = rospy.get_param("~provider")  # nodelet | rospy
        tmp = Path(cls.tmp.name)
        points = ss.sample_map(cls.scene).astype(np.float32)
        records = np.zeros(len(points), dtype=XYZ_DTYPE)
        for axis, name in enumerate("xyz"):
            records[name] = points[:, axis]
        write_pcd(tmp / "map.pcd", records)
        (tmp / "www").mkdir()
        tile_map([tmp / "map.pcd"], tmp / "www" / "map", TileConfig(grid_size=S, progress=False, sync=False))
        cls.index_revision = "sha256:" + hashlib.sha256((tmp / "www/map/index.json").read_bytes()).hexdigest()[:16]
        cls.server = nginx_server.NginxServer(tmp / "www")
        cls.server.start()
        cls.url = cls.server.url("/map")
        cls.logs: list[Log] = []
        cls.track = OdometryTrack("/odom")
        cls.statuses: list[NdtStatus] = []
        cls.provider: list[ProviderStatus] = []
        rospy.Subscriber("/rosout", Log, cls.logs.append, queue_size=1000)
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, cls.statuses.append)
        rospy.Subscriber("/grid_puzzle_map_provider/status", ProviderStatus, cls.provider.append)
        env = dict(os.environ, XDG_CACHE_HOME=str(tmp / "cache"))  # the stores' disk cache
        cls.stack_log = open(tmp / "stack.log", "wb")  # noqa: SIM115 (closed in tearDownClass)
        cls.stack = subprocess.Popen(
            [
                "roslaunch",
                "grid_puzzle_localization",
                "map_store_stack.launch",
                f"tiles:={cls.url}",
                f"provider:={provider}",
            ],
            env=env,
            stdout=cls.stack_log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        pose_pub = replay.publish_initial_pose("/initialpose", cls.drive.pose(0.0))
        replay.wait_until_subscribed([pose_pub], f"the localizer and the provider ({provider})")
        cls.outage: list[float] = []  # wall times nginx went down and came back
        timer = threading.Thread(target=cls.interrupt_server, daemon=True)
        timer.start()
        replay.play_bag(bag, rate=RATE, timeout=200)
        timer.join()

    @classmethod
    def interrupt_server(cls) -> None:
        time.sleep(OUTAGE_START)
        cls.server.stop()
        cls.outage.append(time.monotonic())
        time.sleep(OUTAGE)
        cls.server.start()
        cls.outage.append(time.monotonic())

    @classmethod
    def tearDownClass(cls) -> None:
        stop_launch_group(cls.stack)
        cls.stack_log.close()
        cls.server.close()
        super().tearDownClass()

    def test_tracks_within_5cm_through_the_outage(self) -> None:
        poses = self.track.poses
        self.assertGreaterEqual(len(poses), 0.9 * len(self.drive.stamps), f"only {len(poses)} poses came out")
        self.assert_within(poses, 0.05, np.deg2rad(0.5))
        tiled = [s for s in self.statuses if s.map_source == "tiles"]
        self.assertTrue(tiled and all(s.match_accepted for s in tiled))

    def test_the_provider_says_the_store_was_unreachable_and_is_back(self) -> None:
        self.assertEqual(len(self.outage), 2, "nginx was not stopped and started")
        texts = [m.msg for m in self.logs]
        down = [t for t in texts if f"map store {self.url} unreachable" in t]
        self.assertTrue(down, "no warning that the map store is unreachable")
        self.assertIn(self.url + "/index.json", down[0])  # the last error names what failed
        self.assertTrue(any(f"map store {self.url} reachable" in t for t in texts), "no message that it is back")
        # ~status says so too: unreachable with the last error naming the URL, then reachable again.
        down_status = [s for s in self.provider if not s.store_reachable]
        self.assertTrue(down_status, "no ~status with store_reachable false")
        self.assertIn(self.url + "/index.json", down_status[0].store_error)
        self.assertTrue(self.provider[-1].store_reachable, "the last ~status still says unreachable")
        # Tiles entered the window while nginx was down: the localizer named each it could not fetch by its URL.
        failed = [t for t in texts if "map update failed" in t]
        self.assertTrue(failed, "no tile entered the window during the outage: lengthen it")
        self.assertTrue(all(f"{self.url}/" in t for t in failed), failed[:3])

    def test_the_provider_serves_the_url_at_the_served_index_revision(self) -> None:
        self.assertTrue(self.provider, "no status from the provider nodelet")
        last = self.provider[-1]
        self.assertEqual(last.tile_dir, self.url)
        self.assertEqual(last.index_revision, self.index_revision)
        self.assertGreater(last.tiles_loaded, 0)


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "map_store_stack", MapStoreStackTest)
