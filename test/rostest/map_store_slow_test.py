#!/usr/bin/env python3
"""Issue 58, a slow map store must never lose the robot (map_store_slow.test). nginx serves the output of `gpm
tile`; bench/delay_proxy.py in front of it answers at most `rate_requests_s` requests a second (50 ms each way):
the provider's first window (counted from the tile index: 240 tiles) divided by WINDOW_S, so that window takes
about 10 s to arrive (the provider's polls of index.json, every 5 s, take their share). The stack
(test/launch/map_store_slow.launch: localization.launch with the provider nodelet) gets
tiles:=http://127.0.0.1:PROXY_PORT/map and an empty disk cache. The drive stands for STAND s, then drives on; the
initial pose (the ground truth) is given once the localizer publishes its first ~status, so scans flow while the
tiles arrive.

The proxy records when it answered each tile (the request's slot plus the one-way delay): the independent clock of
what the localizer could hold. Checked against it, the tile index and the drive's ground truth:
- no pose comes out before the tiles around the start (those meeting the square of MAP_WAIT_HALF_SIDE - 1 m about
  the true pose) have been answered; before the first pose the statuses say waiting_for_map, some with
  tiles_awaited > 0; the first pose's target holds at least those tiles' points;
- the first pose comes while a good part of the window is still in flight (nearest first);
- no status calls a search ambiguous while tiles are in flight or awaited, none says lost while tiles are awaited,
  and none says lost at all; every match after the first pose is accepted;
- every pose is within 5 cm (0.5 deg) of the ground truth, and the scans after the first pose nearly all have one.
The figures (seconds after the initial pose) are printed and, under `make reliability`, recorded. With
GPL_MAP_STORE_SLOW_TRACE=FILE the run's statuses, poses, proxy answers and log lines are written to FILE (JSON)."""

from __future__ import annotations

import asyncio
import json
import os
import re
import subprocess
import sys
import time
import unittest
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rospy
import rostest
from fixtures import localizer_replay as replay
from fixtures import nginx_server
from fixtures import synthetic_scene as ss
from fixtures.launch_group import stop_launch_group
from geometry_msgs.msg import PoseWithCovarianceStamped
from grid_puzzle_localization.msg import NdtStatus, TileDelta
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Log
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
sys.path.insert(0, str(ROOT / "test" / "python"))
from delay_proxy import DelayProxy  # noqa: E402
from fault_report import record  # noqa: E402

from grid_puzzle_localization.pcd import write_pcd  # noqa: E402
from grid_puzzle_localization.pcd.reader import xyz_records  # noqa: E402
from grid_puzzle_localization.provider.window import compute_window  # noqa: E402
from grid_puzzle_localization.tiles.grid import parse_tile_stem, tile_index  # noqa: E402
from grid_puzzle_localization.tiling import TileConfig, tile_map  # noqa: E402
from grid_puzzle_localization.tiling.index import load_tile_index  # noqa: E402

# The window as test/launch/map_store_slow.launch sets it: 4 m tiles, 8 on each side (a 68 m square at the
# standing start, 240 of the map's tiles), 5 more ahead once moving. More than the map worker's fetch batch (64):
# a window comes nearest the pose first only batch by batch.
S = 4.0  # [m] tile side
N, K = 8, 5
WINDOW_S = 10.0  # [s] the first window's tiles take this long through the proxy
ONE_WAY_DELAY = 0.05  # [s] the proxy's latency each way
MAP_WAIT_HALF_SIDE = 20.0  # [m] the localizer's default ~map_wait_half_side
STAND = 2.5  # [s of drive] standing at the start (10 s of wall time at RATE): the tiles arrive meanwhile
DRIVE = 8.0  # [s] of driving after it (40 m)
RATE = 0.25  # bag playback rate: the localizer, the provider, the proxy and the player share 2 busy cores
WAIT = 60.0  # [s] upper bound on waiting for the stack or a message (never asserted as a time)
# The first pose comes with at most this share of the window's tiles answered: the 100 tiles around the start are
# among the nearest 128 (two fetch batches, 53 % of the window), then the localizer needs the partial map of them
# and a scan (one every 0.4 s at RATE); 0.75 leaves 2 s for that on a busy machine.
FIRST_POSE_SHARE = 0.75
TOLERANCE = 0.05  # [m]
ANGLE_TOLERANCE = np.deg2rad(0.5)
REQUEST_LINE = re.compile(rb"^(?:GET|HEAD) (\S+) HTTP/1\.[01]$")


@dataclass(frozen=True)
class StandingStart(ss.Drive):
    """The drive of ss.Drive, after standing ``stand`` [s] at its start."""

    stand: float = STAND

    def pose(self, t: float) -> np.ndarray:
        return super().pose(max(0.0, t - self.stand))


class RequestLines:
    """A client's stream reader for the proxy that hands the path of each request line passing through to
    ``seen`` (in order, before the proxy counts the request's head)."""

    def __init__(self, reader: asyncio.StreamReader, seen) -> None:
        self._reader = reader
        self._seen = seen
        self._partial = b""

    async def read(self, n: int = -1) -> bytes:
        chunk = await self._reader.read(n)
        lines = (self._partial + chunk).split(b"\r\n")
        self._partial = lines.pop()[-4096:]
        for line in lines:
            match = REQUEST_LINE.match(line)
            if match:
                self._seen(match.group(1).decode(errors="replace"))
        return chunk


class RecordingProxy(DelayProxy):
    """DelayProxy that notes when each request was answered: its slot (passed on to nginx, which answers at once on
    localhost) plus the one-way delay back, in time.monotonic() of this process. ``answers``: (time, path)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._unslotted: list[str] = []
        self.answers: list[tuple[float, str]] = []

    async def _serve(self, client_reader, client_writer) -> None:
        await super()._serve(RequestLines(client_reader, self._unslotted.append), client_writer)

    def _request_slot(self, arrived: float, heads: int) -> float:
        slot = super()._request_slot(arrived, heads)
        for _ in range(heads):  # one head per chunk from libcurl: the slot is that request's
            path = self._unslotted.pop(0) if self._unslotted else "?"
            self.answers.append((slot + self.delay, path))
        return slot


class MapStoreSlowTest(replay.DriveReplayTest):
    @classmethod
    def setUpClass(cls) -> None:
        if nginx_server.binary() is None:
            raise unittest.SkipTest("nginx is not installed (apt-get install nginx-light)")
        bag = cls.write_drive("map_store_slow_test", StandingStart(duration=STAND + DRIVE, x0=-8.0))
        tmp = Path(cls.tmp.name)
        write_pcd(tmp / "map.pcd", xyz_records(ss.sample_map(cls.scene)))
        (tmp / "www").mkdir()
        tile_map([tmp / "map.pcd"], tmp / "www" / "map", TileConfig(grid_size=S, progress=False, sync=False))
        cls.points = {e.key: e.points for e in load_tile_index(tmp / "www" / "map").tiles}
        # The provider's first window: a pose without a heading yet (standing start) has the plain square of n
        # tiles about its tile; the tiles of it the map has.
        start = cls.drive.pose(0.0)
        x, y = start[0, 3], start[1, 3]
        cls.window = set(compute_window(x, y, None, S, N, K).keys()) & set(cls.points)
        # The tiles under the first scan: those the start waits for, less a metre so none only touches the square.
        half = MAP_WAIT_HALF_SIDE - 1.0
        cls.near = {
            k
            for k in cls.window
            if tile_index(x - half, S) <= k[0] <= tile_index(x + half, S)
            and tile_index(y - half, S) <= k[1] <= tile_index(y + half, S)
        }
        cls.rate_requests = len(cls.window) / WINDOW_S
        cls.server = nginx_server.NginxServer(tmp / "www")
        cls.server.start()
        cls.proxy = RecordingProxy(cls.server.port, one_way_delay_s=ONE_WAY_DELAY, rate_requests_s=cls.rate_requests)
        cls.proxy.start()
        cls.url = f"http://127.0.0.1:{cls.proxy.port}/map"
        cls.status: list[tuple[float, NdtStatus]] = []  # (arrival, status)
        cls.odom: list[tuple[float, float, np.ndarray]] = []  # (arrival, stamp, 4x4)
        cls.deltas: list[TileDelta] = []
        cls.logs: list[Log] = []
        rospy.Subscriber("/ndt_localizer/status", NdtStatus, cls.on_status, queue_size=100)
        rospy.Subscriber("/odom", Odometry, cls.on_odom, queue_size=100)
        rospy.Subscriber("/tile_delta", TileDelta, cls.deltas.append, queue_size=100)
        rospy.Subscriber("/rosout", Log, cls.logs.append, queue_size=1000)
        env = dict(os.environ, XDG_CACHE_HOME=str(tmp / "cache"))  # an empty disk cache: every tile is fetched
        cls.stack_log = open(tmp / "stack.log", "wb")  # noqa: SIM115 (closed in tearDownClass)
        cls.stack = subprocess.Popen(
            ["roslaunch", "grid_puzzle_localization", "map_store_slow.launch", f"tiles:={cls.url}"],
            env=env,
            stdout=cls.stack_log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        try:
            cls.run_drive(bag)
        except Exception:
            cls.stop_stack()
            raise

    @classmethod
    def on_status(cls, msg: NdtStatus) -> None:
        cls.status.append((time.monotonic(), msg))

    @classmethod
    def on_odom(cls, msg: Odometry) -> None:
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat([o.x, o.y, o.z, o.w]).as_matrix()
        m[:3, 3] = [p.x, p.y, p.z]
        cls.odom.append((time.monotonic(), round(msg.header.stamp.to_sec(), 3), m))

    @classmethod
    def run_drive(cls, bag: Path) -> None:
        # The provider nodelet shares the localizer's process, and so its connection.
        pose_pub = rospy.Publisher("/initialpose", PoseWithCovarianceStamped, queue_size=1, latch=True)
        replay.wait_until_subscribed([pose_pub], "the localizer and the provider nodelet")
        play = subprocess.Popen(["rosbag", "play", "--clock", "-q", "-d", "2", "-r", str(RATE), str(bag)])
        deadline = time.monotonic() + WAIT
        while not cls.status and play.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if not cls.status:
            play.kill()
            raise RuntimeError(f"no ~status from the localizer within {WAIT:g} s of the bag's start (one per scan)")
        cls.first_status_state = cls.status[0][1].state
        cls.initial_pose_at = time.monotonic()
        pose_pub.publish(replay.initial_pose_msg(cls.drive.pose(0.0)))
        play.wait(timeout=(STAND + DRIVE) / RATE + WAIT)
        time.sleep(replay.LINGER / RATE)
        trace = os.environ.get("GPL_MAP_STORE_SLOW_TRACE")
        if trace:
            cls.write_trace(Path(trace))

    @classmethod
    def write_trace(cls, path: Path) -> None:
        """What the run saw, in seconds after the initial pose (arrival) and of the drive (stamp), as JSON."""
        t0 = cls.initial_pose_at

        def drive_time(stamp: float) -> float:
            return round(stamp - replay.START, 2)

        status = [
            {
                "at": round(t - t0, 3),
                "stamp": drive_time(st.header.stamp.to_sec()),
                **{f: getattr(st, f) for f in ("state", "tiles_in_flight", "tiles_awaited", "target_points")},
                **{f: getattr(st, f) for f in ("match_accepted", "lost", "published", "global_search_reason")},
            }
            for t, st in cls.status
        ]
        odom = [{"at": round(t - t0, 3), "stamp": drive_time(s)} for t, s, _ in cls.odom]
        answers = [{"at": round(t - t0, 3), "path": p} for t, p in cls.proxy.answers]
        log = [{"stamp": drive_time(m.header.stamp.to_sec()), "node": m.name, "msg": m.msg} for m in cls.logs]
        path.write_text(json.dumps({"status": status, "odom": odom, "answers": answers, "log": log}, indent=1))

    @classmethod
    def stop_stack(cls) -> None:
        stop_launch_group(cls.stack)
        cls.stack_log.close()
        cls.proxy.stop()
        cls.server.close()

    @classmethod
    def tearDownClass(cls) -> None:
        cls.stop_stack()
        super().tearDownClass()

    # ------------------------------------------------------------ what the proxy and the localizer did

    def tile_answers(self) -> dict[tuple[int, int], float]:
        """The first answer [monotonic s] to each tile of the map, by key."""
        answered: dict[tuple[int, int], float] = {}
        for t, path in self.proxy.answers:
            name = path.rsplit("/", 1)[-1]
            if name.endswith(".pcd"):
                answered.setdefault(parse_tile_stem(name[: -len(".pcd")], S), t)
        return answered

    def first_pose(self) -> tuple[float, float]:
        """(arrival [monotonic s], stamp [s]) of the first pose published."""
        self.assertTrue(self.odom, f"no pose was published; localizer log:\n{self.localizer_log()}")
        arrival, stamp, _ = self.odom[0]
        return arrival, stamp

    def localizer_log(self) -> str:
        lines = [m.msg for m in self.logs if "ndt_localizer" in m.name or "localizer_manager" in m.name]
        return "\n".join(lines[-30:])

    def after_pose(self, t: float) -> float:
        return round(t - self.initial_pose_at, 2)

    # ------------------------------------------------------------ the tests

    def test_1_the_first_window_is_the_one_counted(self) -> None:
        deltas = [d for d in self.deltas if d.added_ids]
        self.assertTrue(deltas, "no tile delta with tiles came from the provider")
        first = {parse_tile_stem(t, S) for t in deltas[0].added_ids}
        # The rate was chosen for this window: WINDOW_S through the proxy.
        self.assertEqual(first, self.window, "the provider's first window is not the one the rate was computed for")
        self.assertLessEqual(self.near, self.window)
        self.assertGreater(len(self.window), 2 * len(self.near), "the window is hardly larger than its near tiles")

    def test_2_starts_once_the_nearest_tiles_arrived_well_before_the_window(self) -> None:
        arrival, stamp = self.first_pose()
        answered = self.tile_answers()
        missing = sorted(self.window - set(answered))
        self.assertFalse(missing, f"tiles of the window never answered by the proxy: {missing}")
        near_done = max(answered[k] for k in self.near)
        window_done = max(answered[k] for k in self.window)
        # No pose before the tiles under the first scan had all come.
        self.assertGreater(arrival, near_done, "a pose came out before the tiles around the start had all arrived")
        # Until the first pose the localizer said it waits: for the initial pose, then for the map's tiles.
        before = [
            st for t, st in self.status if t > self.initial_pose_at and round(st.header.stamp.to_sec(), 3) < stamp
        ]
        self.assertFalse([st for st in before if st.published], "a status before the first pose says published")
        states = {st.state for st in before}
        self.assertLessEqual(states, {"waiting_for_map", "waiting_for_initial_pose"}, "states before the first pose")
        waiting = [st for st in before if st.state == "waiting_for_map" and st.tiles_awaited > 0]
        self.assertTrue(waiting, f"no status waiting_for_map with tiles_awaited > 0 before the first pose: {states}")
        # The first pose's map holds at least the points of the tiles under the first scan (the tile index).
        first = [st for _, st in self.status if round(st.header.stamp.to_sec(), 3) == stamp]
        self.assertTrue(first, "no status for the scan of the first pose")
        near_points = sum(self.points[k] for k in self.near)
        self.assertGreaterEqual(first[0].target_points, near_points, "the first pose's map lacks tiles near the start")
        self.assertEqual(first[0].state, "tracking")
        # ... and it came well before the whole window had (nearest first).
        self.assertLess(arrival, window_done, "the first pose came only after the whole window had arrived")
        share = sum(1 for k in self.window if answered[k] < arrival) / len(self.window)
        self.assertLessEqual(share, FIRST_POSE_SHARE, f"{share:.0%} of the window had arrived at the first pose")
        window_points = sum(self.points[k] for k in self.window)
        held = [t for t, st in self.status if st.target_points >= window_points]
        figures = {
            "window_tiles": len(self.window),
            "near_tiles": len(self.near),
            "rate_requests_s": round(self.rate_requests, 2),
            "first_tile_s": self.after_pose(min(answered[k] for k in self.window)),
            "near_tiles_arrived_s": self.after_pose(near_done),
            "first_pose_s": self.after_pose(arrival),
            "window_arrived_s": self.after_pose(window_done),
            "localizer_holds_window_s": self.after_pose(held[0]) if held else None,
            "window_share_at_first_pose": round(share, 2),
            "first_status_state": self.first_status_state,
            "statuses_waiting_for_map": len(waiting),
        }
        print(f"map_store_slow figures: {figures}", flush=True)
        rospy.loginfo("map_store_slow figures: %s", figures)
        record(
            "slow map store: the first window takes 10 s to arrive (rate-limited requests)",
            "waits for the tiles around the start, then tracks within 5 cm while the rest arrives",
            figures["first_pose_s"],
            **figures,
        )

    def test_3_no_ambiguous_search_or_lost_for_missing_tiles(self) -> None:
        in_flight = [st for _, st in self.status if st.tiles_awaited > 0 or st.tiles_in_flight > 0]
        self.assertTrue(in_flight, "no status saw tiles in flight: the store was not slow")
        ambiguous = [
            (round(st.header.stamp.to_sec() - replay.START, 1), st.global_search_reason)
            for st in in_flight
            if "ambiguous" in st.global_search_reason
        ]
        self.assertFalse(ambiguous, f"searches called ambiguous while tiles were missing: {ambiguous[:5]}")
        lost = [
            round(st.header.stamp.to_sec() - replay.START, 1) for _, st in self.status if st.lost and st.tiles_awaited
        ]
        self.assertFalse(lost, f"statuses lost while tiles were awaited, at {lost[:10]} s")

    def test_4_tracks_within_5cm_with_a_pose_for_nearly_every_scan(self) -> None:
        _, stamp = self.first_pose()
        poses = {s: m for _, s, m in self.odom}
        self.assert_within(poses, TOLERANCE, ANGLE_TOLERANCE)
        after = [s for s in self.drive.stamps if replay.START + s >= stamp]
        got = [s for s in poses if s >= stamp]
        self.assertGreaterEqual(
            len(got), 0.9 * len(after), f"{len(got)} poses for the {len(after)} scans after the first"
        )
        lost = [round(st.header.stamp.to_sec() - replay.START, 1) for _, st in self.status if st.lost]
        self.assertFalse(lost, f"the localizer said lost at {lost[:10]} s")
        after_first = [st for _, st in self.status if round(st.header.stamp.to_sec(), 3) >= stamp]
        refused = [
            round(st.header.stamp.to_sec() - replay.START, 1)
            for st in after_first
            if st.state == "tracking" and not st.match_accepted
        ]
        self.assertFalse(refused, f"matches refused after the first pose at {refused[:10]} s")
        # A scan whose prediction reaches tiles still in flight waits for them (not matched on a partial map).
        waits = [st for st in after_first if st.state != "tracking"]
        self.assertTrue(all(st.state == "waiting_for_map" and st.tiles_awaited > 0 for st in waits), waits[:3])
        error, where = self.worst(poses, self.truth)
        print(f"map_store_slow track: {len(got)} poses for {len(after)} scans, worst {error:.4f} m {where}", flush=True)


if __name__ == "__main__":
    rostest.rosrun("grid_puzzle_localization", "map_store_slow", MapStoreSlowTest)
