#!/usr/bin/env python3
"""CPU starvation of the localizer (see localizer_starvation.test).

A synthetic drive is played in real time (10 scans/s, `rosbag play --clock`) to the localizer nodelet. For
LOAD seconds of the drive the test runs two busy processes per core, each in a session of its own, and sets
the niceness of the localizer's session to 10 (the kernel shares CPU between sessions first, autogroup; a scan
costs the localizer so little that busy processes of equal weight leave it enough). How much CPU that still
leaves depends on the machine: on a fast one the localizer keeps up. So the load starts with the localizer's
process stopped (SIGSTOP) for STARVED seconds, the limit of starvation on any machine: the scans of that time
arrive at once when it continues. The localizer must then skip scans rather than queue them: the drops are
counted in ~status (scans_dropped), and the scans it does match are recent ones (bounded lag). When the load
goes (busy processes killed, niceness 0 again) it must catch up: lag back to normal and every pose within 5 cm
of the ground truth."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import synthetic_scene as ss
from grid_puzzle_localization.msg import NdtStatus
from nav_msgs.msg import Odometry

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "python"))
from fault_report import record
from ros_process import node_pid

START = replay.START
DURATION = 12.0  # [s] of drive
LOAD = (3.0, 7.0)  # [s from the start, bag time] busy processes running
STARVED = 1.0  # [s of bag time] at the start of the load, the localizer's process stopped (10 scan periods)
BUSY_PER_CORE = 2
CATCH_UP = 1.0  # [s] after the load: the scans then must be matched promptly again
MAX_LAG = 1.0  # [s] from a scan's stamp to its status, once caught up (10 scan periods; the machine is shared)
TOLERANCE = 0.05  # [m]
WAIT = 60.0  # [s] upper bound on waiting for a connection (never asserted as a time)


def set_session_niceness(pid: int, niceness: int) -> None:
    """Niceness of the session (autogroup) of ``pid``: the kernel shares CPU between sessions first, so a
    process's own niceness ranks it only within its session. Nothing where there is no autogroup."""
    autogroup = Path(f"/proc/{pid}/autogroup")
    if autogroup.exists():
        autogroup.write_text(str(niceness))


class LocalizerStarvationTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        bag = cls.write_drive("localizer_starvation_test", ss.Drive(duration=DURATION, x0=-8.0))
        cls.poses: dict[float, np.ndarray] = {}
        cls.statuses: list[tuple[float, float, NdtStatus]] = []  # (bag time received, stamp, status), from START
        rospy.Subscriber("/odom", Odometry, cls._on_odom, queue_size=100)
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, cls._on_status, queue_size=100)
        replay.wait_until_subscribed([replay.publish_map(ss.sample_map(cls.scene))], "the localizer")
        time.sleep(replay.MAP_BUILD)
        manager = node_pid("/manager", "/localizer_starvation_test", WAIT)
        play = subprocess.Popen(["rosbag", "play", "--clock", "-q", "-d", "2", str(bag)])
        load: list[subprocess.Popen] = []
        stopped = False
        try:
            while play.poll() is None and rospy.Time.now().to_sec() - START < LOAD[0]:
                time.sleep(0.01)
            busy = [sys.executable, "-c", "while True: pass"]
            # Each in a session of its own: with the kernel's autogroup scheduling, CPU is shared between
            # sessions first, so busy loops in the test's session would only compete with each other.
            set_session_niceness(manager, 10)
            load = [
                subprocess.Popen(busy, start_new_session=True) for _ in range(BUSY_PER_CORE * (os.cpu_count() or 1))
            ]
            os.kill(manager, signal.SIGSTOP)
            stopped = True
            while play.poll() is None and rospy.Time.now().to_sec() - START < LOAD[0] + STARVED:
                time.sleep(0.01)
            os.kill(manager, signal.SIGCONT)
            stopped = False
            while play.poll() is None and rospy.Time.now().to_sec() - START < LOAD[1]:
                time.sleep(0.01)
        finally:
            if stopped:
                os.kill(manager, signal.SIGCONT)
            for p in load:
                p.kill()
                p.wait()
            set_session_niceness(manager, 0)
        play.wait(timeout=DURATION + WAIT)
        time.sleep(2.0)

    @classmethod
    def _on_odom(cls, msg: Odometry) -> None:
        p = msg.pose.pose.position
        cls.poses[replay.since_start(msg.header.stamp.to_sec())] = np.array([p.x, p.y, p.z])

    @classmethod
    def _on_status(cls, msg: NdtStatus) -> None:
        cls.statuses.append((rospy.Time.now().to_sec() - START, msg.header.stamp.to_sec() - START, msg))

    def dropped_by(self, t: float) -> int:
        """status.scans_dropped of the last status received before bag time ``t``."""
        before = [s.scans_dropped for received, _, s in self.statuses if received < t]
        return before[-1] if before else 0

    def test_drops_counted_under_load_then_catches_up_within_5cm(self) -> None:
        self.assertTrue(self.statuses, "no status")
        counts = [s.scans_dropped for _, _, s in self.statuses]
        self.assertEqual(counts, sorted(counts), "scans_dropped must only grow")
        under_load = self.dropped_by(LOAD[1] + CATCH_UP) - self.dropped_by(LOAD[0])
        self.assertGreater(under_load, 0, "no scan dropped while both cores were busy")
        # Caught up: scans after the load are matched within MAX_LAG of their stamp, and every pose is right.
        settled = LOAD[1] + CATCH_UP
        late = [(received, stamp, s) for received, stamp, s in self.statuses if stamp >= settled]
        self.assertGreaterEqual(len(late), 0.5 * (DURATION - settled) * self.drive.rate, "too few scans matched")
        lag = max(received - stamp for received, stamp, _ in late)
        self.assertLess(lag, MAX_LAG, "the localizer did not catch up after the load")
        self.assertTrue(all(s.match_accepted for _, _, s in late), "a scan after the load was not matched")
        errors = {t: float(np.linalg.norm(xyz - self.drive.pose(t)[:3, 3])) for t, xyz in self.poses.items()}
        worst = max(errors, key=errors.get)
        self.assertLess(errors[worst], TOLERANCE, f"worst error at {worst:.1f} s")
        # Recovery: from the end of the load to the first scan matched within MAX_LAG of its stamp.
        prompt = [received for received, stamp, _ in self.statuses if stamp >= LOAD[1] and received - stamp < MAX_LAG]
        lag_under_load = max((r - s for r, s, _ in self.statuses if LOAD[0] <= s < LOAD[1]), default=float("nan"))
        record(
            f"CPU starvation: {BUSY_PER_CORE} busy processes per core and the localizer's session at niceness 10"
            f" for {LOAD[1] - LOAD[0]:g} s of a real-time drive, its process stopped for the first {STARVED:g} s",
            f"{under_load} scans dropped and counted; largest lag under load {lag_under_load:.2f} s",
            round(min(prompt) - LOAD[1], 2) if prompt else None,
            data_lost=f"{under_load} scans skipped (counted in ~status)",
            scans_dropped=under_load,
            max_error_m=round(errors[worst], 4),
        )


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "localizer_starvation", LocalizerStarvationTest)
