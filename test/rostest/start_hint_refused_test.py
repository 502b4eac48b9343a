#!/usr/bin/env python3
"""Bad initialpose_hint messages against the running grid puzzle stack (issue 31, see start_hint_refused.test).

The stack has no pose and no global search timeout, so nothing but a hint can make the provider serve a window. Each
bad hint is sent on /initialpose_hint and must be refused:
- in frame odom: the localizer and the provider each log an error naming initialpose_hint and the frame;
- with a NaN x: both log an error naming initialpose_hint and the non-finite position;
- 5 km outside the map: the provider logs an error naming initialpose_hint and the map's extent (in tiles mode the
  localizer's map is only the provider's window, so only the provider can check it, docs/localizer.md);
and the provider serves no window for any of them (no ~status), the localizer publishes no pose. A good hint at the
end is the control: its window comes, so a window served for a bad hint would have been seen."""

from __future__ import annotations

import math
import shutil
import time
import unittest

import rospy
import rostest
from fixtures import synthetic_scene as ss
from fixtures.synthetic_tiles import write_map_tiles
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import ProviderStatus
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Log
from std_msgs.msg import Header

S = 10.0  # [m] tile side, as the .test file sets it
WAIT = 60.0  # [s] upper bound on waiting for a connection or a log line (never asserted as a time)
SETTLE = 3.0  # [s] after a refused hint, for a window served anyway to arrive
LOCALIZER_FILE = "ndt_localizer_nodelet.cpp"
GOOD = (10.0, 0.0, 5.0)  # x, y, sigma [m] of the control hint, on the street


def hint_msg(x: float, y: float, sigma: float, frame: str = "map") -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped(header=Header(frame_id=frame, stamp=rospy.Time.now()))
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.w = 1.0
    msg.pose.covariance[0] = msg.pose.covariance[7] = sigma * sigma
    return msg


class StartHintRefusedTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node("start_hint_refused_test")
        cls.tile_dir = rospy.get_param("~tiles")
        write_map_tiles(ss.sample_map(ss.make_scene(length=60.0)), cls.tile_dir, S)
        cls.logs: list[Log] = []
        cls.provider: list[ProviderStatus] = []
        cls.odom: list[Odometry] = []
        rospy.Subscriber("/rosout", Log, cls.logs.append, queue_size=100)
        rospy.Subscriber("/grid_puzzle_map_provider/status", ProviderStatus, cls.provider.append)
        rospy.Subscriber("/odom", Odometry, cls.odom.append)
        cls.pub = rospy.Publisher("/initialpose_hint", PoseWithCovarianceStamped, queue_size=10)
        connections = 2 if rospy.get_param("~provider") == "rospy" else 1
        deadline = time.monotonic() + WAIT
        while time.monotonic() < deadline and cls.pub.get_num_connections() < connections:
            time.sleep(0.2)
        assert cls.pub.get_num_connections() >= connections, "the localizer and the provider did not subscribe"
        # The provider opens the tile directory (retried every 0.5 s) before it can check a hint against the map.
        time.sleep(2.0)

    @classmethod
    def tearDownClass(cls) -> None:
        shutil.rmtree(cls.tile_dir, ignore_errors=True)

    def errors_naming_the_hint(self, since: int) -> tuple[list[Log], list[Log]]:
        """ERROR lines naming initialpose_hint after the first ``since`` log lines: (localizer's, provider's)."""
        errors = [m for m in self.logs[since:] if m.level == Log.ERROR and "initialpose_hint" in m.msg]
        localizer = [m for m in errors if m.file.endswith(LOCALIZER_FILE)]
        return localizer, [m for m in errors if not m.file.endswith(LOCALIZER_FILE)]

    def send(self, msg: PoseWithCovarianceStamped, localizer_too: bool) -> tuple[list[Log], list[Log]]:
        """Sends ``msg`` and waits for the errors it must cause; returns them."""
        since = len(self.logs)
        self.pub.publish(msg)
        deadline = time.monotonic() + WAIT
        while time.monotonic() < deadline:
            localizer, provider = self.errors_naming_the_hint(since)
            if provider and (localizer or not localizer_too):
                break
            time.sleep(0.1)
        time.sleep(SETTLE)
        return self.errors_naming_the_hint(since)

    def test_bad_hints_refused_then_a_good_one_served(self) -> None:
        self.assertEqual(self.provider, [], "a window was served before any hint")
        cases = [
            ("in frame odom", hint_msg(*GOOD, frame="odom"), True, "'odom'"),
            ("with a NaN x", hint_msg(math.nan, 0.0, 5.0), True, "nan"),
            ("5 km outside the map", hint_msg(5000.0, 5000.0, 5.0), False, "outside the map"),
        ]
        for what, msg, localizer_too, named in cases:
            with self.subTest(hint=what):
                localizer, provider = self.send(msg, localizer_too)
                self.assertTrue(provider, f"the provider logged no error naming initialpose_hint for a hint {what}")
                self.assertIn(named, provider[0].msg.lower())
                if localizer_too:
                    self.assertTrue(localizer, f"the localizer logged no error naming initialpose_hint ({what})")
                    self.assertIn(named, localizer[0].msg.lower())
                self.assertEqual(self.provider, [], f"the provider served a window for a hint {what}")
                self.assertEqual(self.odom, [], f"a pose was published after a hint {what}")
        # The control: a good hint is served at once, so a window for a bad one would have been seen above.
        self.pub.publish(hint_msg(*GOOD))
        deadline = time.monotonic() + WAIT
        while time.monotonic() < deadline and not self.provider:
            time.sleep(0.1)
        self.assertTrue(self.provider, "no window for the good hint: the checks above could not see one")
        w = self.provider[0]
        i, j = int(GOOD[0] // S), int(GOOD[1] // S)
        self.assertTrue(w.i_min <= i <= w.i_max and w.j_min <= j <= w.j_max, (w.i_min, w.i_max, w.j_min, w.j_max))
        self.assertGreater(w.tiles_loaded, 0)


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "start_hint_refused", StartHintRefusedTest)
