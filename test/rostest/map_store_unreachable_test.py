#!/usr/bin/env python3
"""Both providers on a map store that does not answer, with nothing of it in the cache (map_store_unreachable.test):
each stops at start-up with a fatal error naming the URL's index.json and what failed, and the rospy node's process
ends, while a directory would be waited for. Nothing listens on the port (nginx_server.free_port)."""

from __future__ import annotations

import re
import subprocess
import tempfile
import time
import unittest
from pathlib import Path

import rospy
import rostest
from fixtures import nginx_server
from fixtures.launch_group import stop_launch_group

WAIT = 60.0  # [s] upper bound on waiting for both providers to stop (never asserted as a time)


class MapStoreUnreachableTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("map_store_unreachable_test")
        cls.tmp = tempfile.TemporaryDirectory()
        cls.url = f"http://127.0.0.1:{nginx_server.free_port()}/map"
        log_path = Path(cls.tmp.name) / "launch.log"
        with open(log_path, "wb") as log:
            launch = subprocess.Popen(
                [
                    "roslaunch",
                    "grid_puzzle_localization",
                    "map_store_unreachable.launch",
                    f"url:={cls.url}",
                    f"cache_dir:={cls.tmp.name}/cache",
                ],
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            deadline = time.monotonic() + WAIT
            while time.monotonic() < deadline and not cls.both_stopped(log_path.read_text(errors="replace")):
                time.sleep(0.5)
            stop_launch_group(launch)
        cls.log = log_path.read_text(errors="replace")

    @classmethod
    def tearDownClass(cls) -> None:
        cls.tmp.cleanup()

    @staticmethod
    def died(log: str, node: str) -> bool:
        return re.search(rf"\[{node}-\d+\] process has died", log) is not None

    @staticmethod
    def fatal_lines(log: str, text: str) -> list[str]:
        return [line for line in log.splitlines() if "FATAL" in line and text in line]

    @classmethod
    def both_stopped(cls, log: str) -> bool:
        return cls.died(log, "provider_rospy") and bool(cls.fatal_lines(log, "/provider_nodelet:"))

    def test_the_nodelet_stops_naming_the_url(self) -> None:
        lines = self.fatal_lines(self.log, "/provider_nodelet:")
        self.assertTrue(lines, f"no fatal error from the provider nodelet:\n{self.log[-3000:]}")
        self.assertIn(f"cannot fetch {self.url}/index.json", lines[0])
        self.assertNotIn("serving no tiles until", self.log, "the nodelet kept retrying instead of stopping")

    def test_the_rospy_provider_stops_naming_the_url(self) -> None:
        self.assertTrue(self.died(self.log, "provider_rospy"), f"the rospy provider kept running:\n{self.log[-3000:]}")
        lines = self.fatal_lines(self.log, f"grid_puzzle_map_provider: cannot fetch {self.url}/index.json")
        self.assertTrue(lines, f"no fatal error naming the URL from the rospy provider:\n{self.log[-3000:]}")


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "map_store_unreachable", MapStoreUnreachableTest)
