#!/usr/bin/env python3
"""Faults against the running localization stack (see localizer_faults.test).

The package's launch files (ndt_localizer.launch, grid_puzzle_map_provider.launch) start the localizer nodelet
in tiles mode, its manager, last_pose_hint and the map provider under roslaunch, all with respawn="true". One
synthetic drive is played with `rosbag play --clock`; during it:
1. the map provider is killed with SIGKILL: respawned, it sends the localizer a reset delta of the window; the
   trajectory must go on within 5 cm of the ground truth, no scan lost. The ground truth stands in for the
   uninterrupted run: ndt_localizer.test holds the uninterrupted tiles run to 5 cm of it, and this test checks the
   poses before the kill against the same 5 cm.
2. the localizer's nodelet manager is killed with SIGKILL: both respawn; the new nodelet has no pose and must
   publish nothing until its global search around the last published position (initialpose_hint) finds the
   vehicle; from then on within 5 cm. The recovery time is from the kill to the first pose published again."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import synthetic_scene as ss
from fixtures.synthetic_bag import write_drive_bag
from fixtures.synthetic_tiles import write_map_tiles
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus, TileDelta
from nav_msgs.msg import Odometry
from scipy.spatial.transform import Rotation
from std_msgs.msg import Header

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from fault_report import record
from ros_process import node_pid

NAME = "/localizer_faults_test"
START = 1000.0  # bag time of the first scan [s]
DURATION = 14.0  # [s] of drive
PROVIDER_KILL = 3.0  # [s from the start, bag time]
LOCALIZER_KILL = 7.0
RATE = 0.25  # playback rate: the localizer, the provider and the player share 2 busy cores
TILE = 10.0  # [m]
WAIT = 60.0  # [s] upper bound on waiting for a process or a connection (never asserted as a time)
TOLERANCE = 0.05  # [m]
LAUNCH = """<launch>
  <param name="use_sim_time" value="true"/>
  <include file="$(find grid_puzzle_localization)/launch/ndt_localizer.launch">
    <arg name="config" value="$(find grid_puzzle_localization)/test/rostest/ndt_localizer_test.yaml"/>
    <arg name="global_search_timeout" value="0.3"/>
  </include>
  <param name="ndt_localizer/map_source" value="tiles"/>
  <param name="ndt_localizer/resend_service" value="grid_puzzle_map_provider/resend"/>
  <param name="ndt_localizer/publish_tf" value="false"/>
  <include file="$(find grid_puzzle_localization)/launch/grid_puzzle_map_provider.launch">
    <arg name="tile_dir" value="{tiles}"/>
  </include>
  <param name="grid_puzzle_map_provider/tiles/grid_size" value="{tile}"/>
  <param name="grid_puzzle_map_provider/window/n" value="7"/>
  <param name="grid_puzzle_map_provider/window/k" value="2"/>
</launch>
"""


class Recorder:
    """Odometry, statuses and tile deltas with their arrival time (monotonic)."""

    def __init__(self) -> None:
        self.odom: list[tuple[float, float, np.ndarray]] = []  # (arrival, stamp from the start, xyz)
        self.status: list[tuple[float, float, NdtStatus]] = []
        self.resets: list[float] = []  # arrival of reset deltas
        rospy.Subscriber("/odom", Odometry, self._on_odom, queue_size=100)
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, self._on_status, queue_size=100)
        rospy.Subscriber("/tile_delta", TileDelta, self._on_delta, queue_size=100)

    def _on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose.position
        self.odom.append((time.monotonic(), msg.header.stamp.to_sec() - START, np.array([p.x, p.y, p.z])))

    def _on_status(self, msg: NdtStatus) -> None:
        self.status.append((time.monotonic(), msg.header.stamp.to_sec() - START, msg))

    def _on_delta(self, msg: TileDelta) -> None:
        if msg.reset:
            self.resets.append(time.monotonic())


class LocalizerFaultsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node(NAME.lstrip("/"))
        cls.tmp = tempfile.TemporaryDirectory()
        tmp = Path(cls.tmp.name)
        scene = ss.make_scene()
        cls.drive = ss.Drive(duration=DURATION, x0=-8.0)
        write_drive_bag(tmp / "drive.bag", scene, cls.drive, start=START)
        write_map_tiles(ss.sample_map(scene), tmp / "tiles", TILE)
        (tmp / "stack.launch").write_text(LAUNCH.format(tiles=tmp / "tiles", tile=TILE))
        cls.rec = Recorder()
        cls.log = open(tmp / "roslaunch.log", "w")  # noqa: SIM115 (closed in tearDownClass)
        cls.launch = subprocess.Popen(["roslaunch", str(tmp / "stack.launch")], stdout=cls.log, stderr=cls.log)
        try:
            cls.run_drive()
        except Exception:
            cls.stop_launch()
            raise

    @classmethod
    def run_drive(cls) -> None:
        # Not latched: a respawned localizer must not take the start pose again.
        pose_pub = rospy.Publisher("/initialpose", PoseWithCovarianceStamped, queue_size=1)
        deadline = time.monotonic() + WAIT
        while pose_pub.get_num_connections() < 2 and time.monotonic() < deadline:  # the localizer and the provider
            time.sleep(0.2)
        if pose_pub.get_num_connections() < 2:
            raise RuntimeError(f"localizer and provider not subscribed to /initialpose within {WAIT} s; see the log")
        msg = PoseWithCovarianceStamped(header=Header(frame_id="map"))
        start = cls.drive.pose(0.0)
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        p.x, p.y, p.z = start[:3, 3]
        o.x, o.y, o.z, o.w = Rotation.from_matrix(start[:3, :3]).as_quat()
        pose_pub.publish(msg)
        time.sleep(4.0)  # the provider's first window reaches the localizer, which reads the tiles
        cls.pids = {
            "provider": node_pid("/grid_puzzle_map_provider", NAME, WAIT),
            "manager": node_pid("/localizer_manager", NAME, WAIT),
        }
        cls.kills: dict[str, float] = {}  # monotonic time of each kill
        play = subprocess.Popen(
            ["rosbag", "play", "--clock", "-q", "-d", "2", "-r", str(RATE), f"{cls.tmp.name}/drive.bag"]
        )
        for name, at in (("provider", PROVIDER_KILL), ("manager", LOCALIZER_KILL)):
            while play.poll() is None and (rospy.Time.now().to_sec() - START) < at:
                time.sleep(0.01)
            cls.kills[name] = time.monotonic()
            os.kill(cls.pids[name], signal.SIGKILL)
        play.wait(timeout=DURATION / RATE + WAIT)
        time.sleep(2.0)
        cls.respawned = {
            name: node_pid(f"/{node}", NAME, WAIT, other_than=cls.pids[name])
            for name, node in (("provider", "grid_puzzle_map_provider"), ("manager", "localizer_manager"))
        }

    @classmethod
    def stop_launch(cls) -> None:
        cls.launch.send_signal(signal.SIGINT)
        try:
            cls.launch.wait(timeout=WAIT)
        except subprocess.TimeoutExpired:
            cls.launch.kill()
        cls.log.close()

    @classmethod
    def tearDownClass(cls) -> None:
        cls.stop_launch()
        cls.tmp.cleanup()

    def error(self, t: float, xyz: np.ndarray) -> float:
        return float(np.linalg.norm(xyz - self.drive.pose(t)[:3, 3]))

    def test_provider_sigkill_trajectory_within_5cm(self) -> None:
        kill = self.kills["provider"]
        resets = [t for t in self.rec.resets if t > kill]
        self.assertTrue(resets, "no reset delta after the provider was killed")
        until = self.kills["manager"]
        poses = [(s, xyz) for arrival, s, xyz in self.rec.odom if arrival < until]
        after = [(s, xyz) for arrival, s, xyz in self.rec.odom if kill < arrival < until]
        self.assertGreaterEqual(len(after), 5, "too few poses between the provider kill and the localizer kill")
        worst = max(poses, key=lambda p: self.error(*p))
        self.assertLess(self.error(*worst), TOLERANCE, f"worst error at {worst[0]:.1f} s")
        before = max(self.error(s, xyz) for arrival, s, xyz in self.rec.odom if arrival < kill)
        statuses = [st for arrival, _, st in self.rec.status if kill < arrival < until]
        self.assertTrue(all(st.match_accepted for st in statuses), "a scan was not matched after the provider kill")
        record(
            "map provider SIGKILL mid-drive, localizer running (tiles)",
            "respawned, reset delta; trajectory within 5 cm of ground truth",
            round(resets[0] - kill, 2),
            max_error_before_m=round(before, 4),
            max_error_after_m=round(max(self.error(s, xyz) for s, xyz in after), 4),
        )

    def test_localizer_sigkill_resumes_by_global_search_around_last_pose(self) -> None:
        kill = self.kills["manager"]
        after = [(arrival, s, xyz) for arrival, s, xyz in self.rec.odom if arrival > kill]
        self.assertTrue(after, "no pose published after the localizer was killed")
        first_arrival, first_stamp, _ = after[0]
        # Lost (no pose) until the search found the vehicle: the first pose published again is a match ...
        matched = {round(s, 3) for _, s, st in self.rec.status if st.match_accepted}
        self.assertIn(round(first_stamp, 3), matched, "the first pose after the respawn was not a match")
        # ... and no pose after it is off (none published from a stale or guessed pose).
        worst = max(after, key=lambda p: self.error(p[1], p[2]))
        self.assertLess(self.error(worst[1], worst[2]), TOLERANCE, f"worst error after the respawn at {worst[1]:.1f} s")
        later = [s for _, s, _ in after]
        self.assertGreaterEqual(len(later), 5, "too few poses after the respawn")
        published = {round(s, 3) for _, s, _ in self.rec.odom}
        for arrival, s, st in self.rec.status:
            if arrival > kill:
                self.assertEqual(st.published, round(s, 3) in published, f"status.published wrong at {s:.1f} s")
        last_before = max(s for arrival, s, _ in self.rec.odom if arrival < kill)
        record(
            "localizer nodelet manager SIGKILL mid-drive",
            "manager and nodelet respawned; no pose until the global search around the last pose; then within 5 cm",
            round(first_arrival - kill, 2),
            data_lost=f"{first_stamp - last_before:.1f} s of drive without a pose (bag time, played at {RATE}x)",
            max_error_after_m=round(self.error(worst[1], worst[2]), 4),
        )


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "localizer_faults", LocalizerFaultsTest)
