#!/usr/bin/env python3
"""Faults against the running localization stack (see localizer_faults.test).

The package's launch files (ndt_localizer.launch, grid_puzzle_map_provider.launch) start the localizer nodelet
in tiles mode, its manager and the map provider under roslaunch, all with respawn="true". One
synthetic drive is played with `rosbag play --clock`; during it, in bag time:
- TILE_FAULTS: three tiles ahead of the vehicle are damaged (one deleted, one truncated, one replaced by a
  directory: the test runs as root, so a file made unreadable with chmod would still be read), then the tile
  directory is moved away and back. The localizer must name each bad file and the missing directory in its
  errors, once per delta that names them, keep matching on the tiles it has, ask for the whole window when the
  directory is back, and read the repaired files at the next reset (the provider's respawn below). The tiles it
  holds are checked through status.target_points against the window that the deltas describe.
- PROVIDER_KILL: the rospy map provider is killed with SIGKILL (the nodelet, which lives in the localizer's
  manager, is asked for a reset with ~resend instead): respawned, it sends the localizer a reset delta of the
  window; the trajectory must go on within 5 cm of the ground truth, every scan matched. The ground truth stands
  in for the uninterrupted run: ndt_localizer.test holds the uninterrupted tiles run to 5 cm of it, and this test
  checks the poses before the kill against the same 5 cm.
- LOCALIZER_KILL: the localizer's nodelet manager is killed with SIGKILL (with the provider nodelet in it: that
  one resumes its window at the pose it saved in its own ~last_pose): both respawn; the new nodelet has no
  pose and must publish nothing until its global search around the last published position finds the vehicle;
  from then on within 5 cm. That position is the one the killed nodelet saved on the parameter server
  (~last_pose, polled during the drive and read at the kill): the respawned nodelet logs that it searches around
  it, and no other node (no relay of the pose) runs in the stack. The recovery time is from the kill to the first
  pose published."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import numpy as np
import rosgraph
import rosnode
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from fixtures.saved_pose import SavedPoseSampler, read_saved_pose
from fixtures.synthetic_bag import write_drive_bag
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus, TileDelta
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Log
from std_srvs.srv import Trigger

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from fault_report import record
from ros_process import node_pid

from grid_puzzle_localization.pcd import write_pcd
from grid_puzzle_localization.pcd.reader import xyz_records
from grid_puzzle_localization.tiles.grid import parse_tile_stem
from grid_puzzle_localization.tiling.index import load_tile_index

NAME = "/localizer_faults_test"
START = replay.START  # bag time of the first scan [s]
DURATION = 17.0  # [s] of drive
DAMAGE, DIR_GONE, DIR_BACK, REPAIR = 1.0, 1.2, 2.4, 7.5  # [s from the start, bag time] the tile faults
PROVIDER_KILL = 8.0
LOCALIZER_KILL = 11.0
# The provider moves the window every 5 m (half a tile): these tiles enter at about 6 s (x = 22 m).
DAMAGED = {(11, -1): "deleted", (11, 0): "truncated", (11, 1): "a directory"}
RATE = 0.25  # playback rate: the localizer, the provider and the player share 2 busy cores
TILE = 10.0  # [m]
WAIT = 60.0  # [s] upper bound on waiting for a process or a connection (never asserted as a time)
TOLERANCE = 0.05  # [m]
LOCALIZER = "/ndt_localizer"
RESUMES = re.compile(r"resumes searching around \(([-0-9.]+), ([-0-9.]+)\)")  # the respawned nodelet's INFO
# The respawned provider's INFO: where it serves the window until a pose arrives.
SERVES = re.compile(r"serves the window around \(([-0-9.]+), ([-0-9.]+)\)")
LAUNCH = """<launch>
  <param name="use_sim_time" value="true"/>
  <include file="$(find grid_puzzle_localization)/launch/ndt_localizer.launch">
    <arg name="config" value="$(find grid_puzzle_localization)/test/rostest/ndt_localizer_test.yaml"/>
    <arg name="global_search_timeout" value="0.3"/>
  </include>
  <param name="ndt_localizer/map_source" value="tiles"/>
  <param name="ndt_localizer/resend_service" value="grid_puzzle_map_provider/resend"/>
  <param name="ndt_localizer/publish_tf" value="false"/>
  <!-- No read-ahead: a tile read ahead before it was damaged would be served, intact, from the cache. -->
  <param name="ndt_localizer/tiles/cache_mb" value="0.0"/>
  <include file="$(find grid_puzzle_localization)/launch/grid_puzzle_map_provider.launch">
    <arg name="tile_dir" value="{tiles}"/>
    <arg name="provider" value="{provider}"/>
  </include>
  <param name="grid_puzzle_map_provider/tiles/grid_size" value="{tile}"/>
  <param name="grid_puzzle_map_provider/window/n" value="7"/>
  <param name="grid_puzzle_map_provider/window/k" value="2"/>
</launch>
"""


class Recorder:
    """Odometry, statuses, tile deltas and the localizer's errors, with their arrival time (monotonic). The window
    is mirrored from the deltas (a reset starts over) to know which tiles the localizer should hold."""

    def __init__(self) -> None:
        self.odom: list[tuple[float, float, np.ndarray]] = []  # (arrival, stamp from the start, xyz)
        self.status: list[tuple[float, float, NdtStatus]] = []
        self.window: set[tuple[int, int]] = set()
        self.windows: list[tuple[float, frozenset]] = []  # (arrival, window after the delta)
        self.resets: list[float] = []  # arrival of reset deltas
        self.added: list[tuple[float, set]] = []  # (arrival, tiles the delta adds)
        self.errors: list[tuple[float, str]] = []
        self.resumes: list[tuple[float, np.ndarray]] = []  # (arrival, (x, y) the respawned nodelet searches around)
        self.serves: list[tuple[float, np.ndarray]] = []  # (arrival, (x, y) the respawned provider serves around)
        rospy.Subscriber("/odom", Odometry, self._on_odom, queue_size=100)
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, self._on_status, queue_size=100)
        rospy.Subscriber("/tile_delta", TileDelta, self._on_delta, queue_size=100)
        rospy.Subscriber("/rosout", Log, self._on_log, queue_size=1000)

    def _on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose.position
        self.odom.append((time.monotonic(), replay.since_start(msg.header.stamp.to_sec()), np.array([p.x, p.y, p.z])))

    def _on_status(self, msg: NdtStatus) -> None:
        self.status.append((time.monotonic(), replay.since_start(msg.header.stamp.to_sec()), msg))

    def _on_delta(self, msg: TileDelta) -> None:
        now = time.monotonic()
        if msg.reset:
            self.resets.append(now)
            self.window.clear()
        self.window -= {parse_tile_stem(t, TILE) for t in msg.removed_ids}
        self.window |= {parse_tile_stem(t, TILE) for t in msg.added_ids}
        self.added.append((now, {parse_tile_stem(t, TILE) for t in msg.added_ids}))
        self.windows.append((now, frozenset(self.window)))

    def _on_log(self, msg: Log) -> None:
        if msg.level >= Log.ERROR:
            self.errors.append((time.monotonic(), msg.msg))
        for pattern, found in ((RESUMES, self.resumes), (SERVES, self.serves)):
            match = pattern.search(msg.msg)
            if match:
                found.append((time.monotonic(), np.array([float(match.group(1)), float(match.group(2))])))

    def window_at(self, t: float) -> frozenset:
        before = [w for arrival, w in self.windows if arrival <= t]
        return before[-1] if before else frozenset()


class LocalizerFaultsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        rospy.init_node(NAME.lstrip("/"))
        cls.tmp = tempfile.TemporaryDirectory()
        tmp = Path(cls.tmp.name)
        scene = ss.make_scene()
        cls.drive = ss.Drive(duration=DURATION, x0=-8.0)
        write_drive_bag(tmp / "drive.bag", scene, cls.drive, start=START)
        # Tiled by `gpm tile`, with its index: the provider then lists a tile whose file went missing (without an
        # index it would rescan the directory on each change and simply drop the tile).
        write_pcd(tmp / "map.pcd", xyz_records(ss.sample_map(scene)))
        subprocess.run(
            ["gpm", "tile", str(tmp / "map.pcd"), "-s", str(TILE), "-o", str(tmp / "tiles"), "--no-progress"],
            check=True,
            stdout=subprocess.DEVNULL,
        )
        index = load_tile_index(tmp / "tiles")
        cls.points = {e.key: e.points for e in index.tiles}
        cls.files = {e.key: e.file for e in index.tiles}
        cls.provider = rospy.get_param("~provider")
        (tmp / "stack.launch").write_text(LAUNCH.format(tiles=tmp / "tiles", tile=TILE, provider=cls.provider))
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
        # The provider nodelet shares the localizer's process, and so its connection.
        connections = 2 if cls.provider == "rospy" else 1
        replay.wait_until_subscribed([pose_pub], "the localizer and the provider", connections=connections)
        pose_pub.publish(replay.initial_pose_msg(cls.drive.pose(0.0)))
        time.sleep(4.0)  # the provider's first window reaches the localizer, which reads the tiles
        cls.pids = {
            "provider": node_pid("/grid_puzzle_map_provider", NAME, WAIT),
            "manager": node_pid("/localizer_manager", NAME, WAIT),
        }
        cls.kills: dict[str, float] = {}  # monotonic time of each fault
        cls.saved = SavedPoseSampler(LOCALIZER, NAME)  # the localizer's ~last_pose during the drive
        cls.kill_stamps: dict[str, float] = {}  # bag time of each fault [s from the start]
        play = subprocess.Popen(
            ["rosbag", "play", "--clock", "-q", "-d", "2", "-r", str(RATE), f"{cls.tmp.name}/drive.bag"]
        )
        tiles = Path(cls.tmp.name) / "tiles"
        events = (
            ("damage", DAMAGE, cls.damage_tiles),
            ("dir_gone", DIR_GONE, lambda: tiles.rename(tiles.with_name("tiles.away"))),
            ("dir_back", DIR_BACK, lambda: tiles.with_name("tiles.away").rename(tiles)),
            ("repair", REPAIR, cls.repair_tiles),
            ("provider", PROVIDER_KILL, cls.reset_provider),
            ("manager", LOCALIZER_KILL, lambda: os.kill(cls.pids["manager"], signal.SIGKILL)),
        )
        for name, at, act in events:
            while play.poll() is None and (rospy.Time.now().to_sec() - START) < at:
                time.sleep(0.01)
            cls.kills[name] = time.monotonic()
            cls.kill_stamps[name] = rospy.Time.now().to_sec() - START
            act()
        # What the killed nodelet left on the parameter server: nothing writes it until the respawn publishes.
        cls.saved_at_kill = read_saved_pose(rosgraph.Master(NAME), LOCALIZER)
        play.wait(timeout=DURATION / RATE + WAIT)
        time.sleep(2.0)
        cls.saved.stop()
        cls.respawned = {
            name: node_pid(f"/{node}", NAME, WAIT, other_than=cls.pids[name])
            for name, node in (("provider", "grid_puzzle_map_provider"), ("manager", "localizer_manager"))
        }

    @classmethod
    def reset_provider(cls) -> None:
        """The rospy provider is killed with SIGKILL (respawned, it sends a reset delta). The nodelet cannot die
        alone (it lives in the localizer's manager, killed below): it is asked for a reset with ~resend."""
        if cls.provider == "rospy":
            os.kill(cls.pids["provider"], signal.SIGKILL)
        else:
            rospy.ServiceProxy("/grid_puzzle_map_provider/resend", Trigger)()

    @classmethod
    def tile_path(cls, key: tuple[int, int]) -> Path:
        return Path(cls.tmp.name) / "tiles" / cls.files[key]

    @classmethod
    def damage_tiles(cls) -> None:
        cls.originals = {key: cls.tile_path(key).read_bytes() for key in DAMAGED}
        for key, how in DAMAGED.items():
            path = cls.tile_path(key)
            path.unlink()
            if how == "truncated":
                path.write_bytes(cls.originals[key][: len(cls.originals[key]) // 2])
            elif how == "a directory":
                path.mkdir()

    @classmethod
    def repair_tiles(cls) -> None:
        for key, data in cls.originals.items():
            path = cls.tile_path(key)
            if path.is_dir():
                path.rmdir()
            path.write_bytes(data)

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

    def held_points(self, arrival: float, missing: set) -> int:
        """Points of the window the deltas described at ``arrival``, without the ``missing`` tiles."""
        return sum(self.points.get(k, 0) for k in self.rec.window_at(arrival) - missing)

    def first_consistent(self, since: float, missing: set) -> float | None:
        """Arrival of the first status after ``since`` whose map holds exactly the window's tiles but ``missing``."""
        for arrival, _, st in self.rec.status:
            if arrival > since and st.target_points == self.held_points(arrival, missing):
                return arrival
        return None

    def test_tile_faults_named_matching_goes_on_and_recovers(self) -> None:
        f = self.kills
        errors = [m for t, m in self.rec.errors if f["damage"] < t < f["manager"]]
        tile_dir = str(Path(self.tmp.name) / "tiles")
        gone = [m for m in errors if f"'{tile_dir}' does not exist" in m]
        self.assertTrue(gone, f"no error names the missing tile directory; errors: {errors[:5]}")
        for key, how in DAMAGED.items():
            path = str(self.tile_path(key))
            named = [m for m in errors if path in m]
            # Once per delta that named the tile while it was bad, not once per scan.
            deltas = sum(1 for t, keys in self.rec.added if f["damage"] < t < f["repair"] and key in keys)
            self.assertGreaterEqual(len(named), 1, f"no error names the {how} tile {path}; errors: {errors[:5]}")
            self.assertLessEqual(len(named), deltas, f"the {how} tile reported {len(named)} times in {deltas} deltas")
        statuses = [st for t, _, st in self.rec.status if f["damage"] < t < f["provider"]]
        self.assertTrue(statuses and all(st.match_accepted for st in statuses), "matching stopped during the faults")
        # The directory back: the next delta asks for the window, whose reset is read whole.
        dir_back = self.first_consistent(f["dir_back"], set())
        self.assertIsNotNone(dir_back, "the map never matched the window after the directory came back")
        # The bad tiles entered: all but them were loaded ...
        damaged = set(DAMAGED)
        entered = [t for t, keys in self.rec.added if t > f["dir_back"] and damaged & keys]
        self.assertTrue(entered and entered[0] < f["repair"], "the damaged tiles did not enter the window in time")
        self.assertIsNotNone(self.first_consistent(entered[0], damaged), "the good tiles of the delta were not kept")
        # ... and read once repaired, at the next reset (the provider's respawn).
        repaired = self.first_consistent(f["repair"], set())
        self.assertIsNotNone(repaired, "the repaired tiles were never read")
        record(
            "tile directory moved away and back under the running localizer",
            "error naming the directory; matching on the tiles held; whole window asked for with the next delta",
            round(dir_back - f["dir_back"], 2),
        )
        record(
            "tile deleted, truncated, replaced by a directory, under the running localizer",
            "one error per delta naming each file, the rest of the window loaded; files read again at the next reset",
            round(repaired - f["repair"], 2),
            data_lost="none (the damaged tiles are missing from the map until they are back and a reset comes)",
        )

    def test_provider_sigkill_trajectory_within_5cm(self) -> None:
        if self.provider != "rospy":
            self.skipTest("the provider nodelet dies only with the localizer's manager (the manager kill)")
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

    def test_saved_pose_follows_the_drive(self) -> None:
        kill = self.kills["manager"]
        before = [(stamp - START, pose) for arrival, stamp, pose in self.saved.samples if arrival < kill]
        # At the default 0.5 Hz, a write every 2 s of the 44 s (at 0.25x) before the kill.
        self.assertGreaterEqual(len(before), 5, f"~last_pose changed only {len(before)} times before the kill")
        for s, pose in before:
            self.assertLess(self.error(s, pose[:3, 3]), TOLERANCE, f"~last_pose at {s:.1f} s off the ground truth")
        self.assertIsNotNone(self.saved_at_kill, "no ~last_pose on the parameter server at the kill")
        stamp, pose = self.saved_at_kill
        self.assertLess(self.error(stamp - START, pose[:3, 3]), TOLERANCE, "~last_pose at the kill off the truth")
        last_published = max(s for arrival, s, _ in self.rec.odom if arrival < kill)
        # Saved at most a save period (2 s wall, 0.5 s of bag time at 0.25x) before the last pose published;
        # 2 s of bag time under load.
        self.assertGreater(stamp - START, last_published - 2.0, "~last_pose at the kill lags the drive")

    def test_localizer_sigkill_resumes_by_global_search_around_last_pose(self) -> None:
        kill = self.kills["manager"]
        # No process relays the pose: only the stack, the test and roslaunch's rosout are on the master.
        nodes = rosnode.get_node_names()
        self.assertFalse([n for n in nodes if "last_pose" in n], f"a relay node runs: {nodes}")
        # The respawned nodelet took the pose the killed one saved as the centre of its search.
        self.assertIsNotNone(self.saved_at_kill, "no ~last_pose on the parameter server at the kill")
        resumes = [xy for arrival, xy in self.rec.resumes if arrival > kill]
        self.assertTrue(resumes, "the respawned nodelet did not log that it resumes around the saved pose")
        saved_xy = self.saved_at_kill[1][:2, 3]
        self.assertLess(float(np.linalg.norm(resumes[0] - saved_xy)), 0.01, f"searches around {resumes[0]}")
        if self.provider == "nodelet":
            # Killed with the manager, the provider nodelet served its window at the pose it had saved (where the
            # vehicle was, to within the drive between its saves), so the localizer's search had a map.
            serves = [xy for arrival, xy in self.rec.serves if arrival > kill]
            self.assertTrue(serves, "the respawned provider nodelet did not resume its window at its saved pose")
            self.assertLess(float(np.linalg.norm(serves[0] - saved_xy)), 5.0, f"window around {serves[0]}")
        # A pose for a scan stamped before the kill comes from the dying process, even when it arrives after the
        # kill (its status may never have gone out); the respawn only sees scans played after it started.
        respawn = self.kill_stamps["manager"]
        after = [(arrival, s, xyz) for arrival, s, xyz in self.rec.odom if arrival > kill and s > respawn]
        self.assertTrue(after, "no pose published after the localizer was killed")
        first_arrival, first_stamp, _ = after[0]
        # Lost (no pose) until the search found the vehicle: the first pose published again is a match ...
        matched = {s for _, s, st in self.rec.status if st.match_accepted}
        self.assertIn(first_stamp, matched, "the first pose after the respawn was not a match")
        # ... and no pose after it is off (none published from a stale or guessed pose).
        worst = max(after, key=lambda p: self.error(p[1], p[2]))
        self.assertLess(self.error(worst[1], worst[2]), TOLERANCE, f"worst error after the respawn at {worst[1]:.1f} s")
        later = [s for _, s, _ in after]
        self.assertGreaterEqual(len(later), 5, "too few poses after the respawn")
        published = {s for _, s, _ in self.rec.odom}
        for arrival, s, st in self.rec.status:
            if arrival > kill and s > respawn:
                self.assertEqual(st.published, s in published, f"status.published wrong at {s:.1f} s")
        last_before = max(s for arrival, s, _ in self.rec.odom if arrival < kill)
        record(
            "localizer nodelet manager SIGKILL mid-drive",
            "manager and nodelet respawned; no pose until the global search around the saved ~last_pose; then "
            "within 5 cm",
            round(first_arrival - kill, 2),
            data_lost=f"{first_stamp - last_before:.1f} s of drive without a pose (bag time, played at {RATE}x)",
            max_error_after_m=round(self.error(worst[1], worst[2]), 4),
        )


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "localizer_faults", LocalizerFaultsTest)
