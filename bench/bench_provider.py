#!/usr/bin/env python3
"""Benchmark of the grid_puzzle_map_provider node itself: the real node process, started with its
default parameters (only tiles/dir, n and k set) under a private roscore, is driven by odometry at
10 m/s in real time over a synthetic tiled map. Prints JSON.

Two maps: the issue's sparse one (500 m x 700 m, s = 2 m, 64 points per tile) and a paper-scale one
(1,600 points per tile, the density of the paper's and the demo's maps, about 27 KB per tile) with the
paper's urban window n = 25, k = 20. Each map is driven twice: with a localizer-like subscriber on
``tile_delta`` only (the experiment's setting: tiles by reference, the node reads no tile), and with
``publish_map_cloud`` on and an rviz-like subscriber on ``map_cloud`` (the node then reads the window's
files for it). The node's peak RSS is the kernel's high-water mark (VmHWM of /proc/<pid>/status) of the
node process; per-update latency is the node's own ``~status.update_ms`` (window, tile sets, delta built
and published). A bare rospy node (init_node and spin) is measured for reference: the node's floor.
Temp dirs are deleted. ``--quick``: a smoke run on a small sparse map (two 3 s drives after roscore).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rospy
from grid_puzzle_localization.msg import ProviderStatus, TileDelta
from hardware import cpu_model
from nav_msgs.msg import Odometry

from grid_puzzle_localization.experiment.processes import ManagedProcess, wait_for
from grid_puzzle_localization.experiment.ros_stack import RosCore
from grid_puzzle_localization.util.iteration import pairwise

ROOT = Path(__file__).resolve().parent.parent
NODE_SCRIPT = ROOT / "scripts" / "grid_puzzle_map_provider"
NODE = "/grid_puzzle_map_provider"
BARE_NODE = "import rospy; rospy.init_node('bare_rospy'); rospy.spin()"
WAIT = 60.0  # [s] bound on waiting for the node (never reported as a figure)
# A drive with turns inside the map: east, north, a diagonal, west [fractions of width, height].
ROUTE = [(0.12, 0.09), (0.88, 0.09), (0.88, 0.5), (0.4, 0.85), (0.12, 0.85)]


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=float, default=500.0, help="sparse map extent along x [m]")
    p.add_argument("--height", type=float, default=700.0, help="sparse map extent along y [m]")
    p.add_argument("--points-per-tile", type=int, default=64, help="sparse map")
    p.add_argument("--paper-width", type=float, default=200.0, help="paper-scale map extent along x [m]")
    p.add_argument("--paper-height", type=float, default=260.0, help="paper-scale map extent along y [m]")
    p.add_argument("--paper-points-per-tile", type=int, default=1600, help="paper-scale map")
    p.add_argument("--grid-size", type=float, default=2.0, help="s [m]")
    p.add_argument("--n", type=int, default=25)
    p.add_argument("--k", type=int, default=20)
    p.add_argument("--speed", type=float, default=10.0, help="[m/s]")
    p.add_argument("--pose-rate", type=float, default=25.0, help="odometry rate [Hz]")
    p.add_argument("--repeats", type=int, default=3, help="fresh node processes timed for the initial window")
    p.add_argument("--scenarios", default="sparse,paper_scale", help="comma-separated subset of sparse,paper_scale")
    p.add_argument("--no-map-cloud-subscriber", action="store_true", help="skip the drives with a map_cloud subscriber")
    p.add_argument("--quick", action="store_true", help="smoke run: 30 m x 30 m sparse map at 20 m/s, n 5, k 3")
    args = p.parse_args()
    if args.quick:
        args.width = args.height = 30.0
        args.points_per_tile, args.n, args.k, args.repeats, args.scenarios = 16, 5, 3, 1, "sparse"
        args.speed = 20.0
    return args


def route_poses(width: float, height: float, speed: float, rate: float) -> np.ndarray:
    """(M, 4) poses (t [s], x [m], y [m], yaw [rad]) along ROUTE at constant speed."""
    corners = np.array([(fx * width, fy * height) for fx, fy in ROUTE])
    out, t = [], 0.0
    step = speed / rate
    for a, b in pairwise(corners):
        length = float(np.hypot(*(b - a)))
        yaw = math.atan2(*(b - a)[::-1])
        for d in np.arange(0.0, length, step):
            out.append((t, *(a + (b - a) * d / length), yaw))
            t += 1.0 / rate
    return np.array(out)


def make_map(directory: Path, width: float, height: float, s: float, points_per_tile: int) -> dict:
    from fixtures.synthetic_tiles import POINT_DTYPE, write_tiles

    from grid_puzzle_localization.tiles.grid import tile_filename
    from grid_puzzle_localization.tiling.index import TileIndex, TileTable, write_index

    ni, nj = math.ceil(width / s), math.ceil(height / s)
    keys = [(i, j) for i in range(ni) for j in range(nj)]
    write_tiles(directory, keys, s, points_per_tile, seed=1)
    size = POINT_DTYPE.itemsize * points_per_tile
    table = TileTable(
        i=[i for i, _ in keys],
        j=[j for _, j in keys],
        files=[tile_filename(i, j, s) for i, j in keys],
        points=[points_per_tile] * len(keys),
        bytes=[size + 200] * len(keys),
        lower=[[i * s for i, _ in keys], [j * s for _, j in keys], [-1.0] * len(keys)],
        upper=[[(i + 1) * s for i, _ in keys], [(j + 1) * s for _, j in keys], [5.0] * len(keys)],
    )
    fields = [{"name": n, "size": 4, "type": "F", "count": 1} for n in POINT_DTYPE.names]
    write_index(directory, TileIndex(s, fields, POINT_DTYPE.itemsize, len(keys) * points_per_tile, 0, [], table))
    disk = sum(f.stat().st_size for f in directory.iterdir())
    return {"width_m": width, "height_m": height, "grid_size_m": s, "points_per_tile": points_per_tile,
            "fields": list(POINT_DTYPE.names), "tiles": len(keys), "disk_mb": round(disk / 2**20, 1)}  # fmt: skip


def percentiles(values: list[float]) -> dict:
    if not values:
        return {}
    a = np.asarray(values)
    return {"p50": round(float(np.percentile(a, 50)), 2), "p95": round(float(np.percentile(a, 95)), 2),
            "max": round(float(a.max()), 2), "mean": round(float(a.mean()), 2)}  # fmt: skip


def proc_status_mb(pid: int, name: str) -> float:
    """A memory field of /proc/<pid>/status [MiB] (VmHWM: peak resident set; VmRSS: current)."""
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(name + ":")) / 1024.0


def rollup_mb(pid: int) -> dict:
    """Anonymous and file-backed parts of the resident set [MiB] (/proc/<pid>/smaps_rollup)."""
    with open(f"/proc/{pid}/smaps_rollup") as f:
        kib = {line.split(":")[0]: int(line.split()[1]) for line in f if line.split(":")[0] in ("Anonymous", "Rss")}
    anonymous = kib["Anonymous"] / 1024
    return {"anonymous": round(anonymous, 1), "file_backed": round(kib["Rss"] / 1024 - anonymous, 1)}


@dataclass
class DriveRecord:
    """What the driver saw of one run: the node's statuses and the deltas."""

    status: list = field(default_factory=list)
    added: list[int] = field(default_factory=list)
    removed: list[int] = field(default_factory=list)
    prefetch: list[int] = field(default_factory=list)
    revisions: list[int] = field(default_factory=list)
    map_clouds: int = 0
    map_cloud_mb: float = 0.0
    lock: threading.Lock = field(default_factory=threading.Lock)


class NodeRun:
    """One provider node process with the driver's subscribers; stops the node on exit."""

    def __init__(self, core, log_dir: Path, tiles: Path, args: argparse.Namespace, map_cloud_subscriber: bool):
        self.record = DriveRecord()
        params = {"tiles/dir": str(tiles), "window/n": args.n, "window/k": args.k}
        if map_cloud_subscriber:
            params["publish_map_cloud"] = True
        if rospy.has_param(NODE):
            rospy.delete_param(NODE)
        for name, value in params.items():
            rospy.set_param(f"{NODE}/{name}", value)
        self.subs = [
            rospy.Subscriber("/tile_delta", TileDelta, self._on_delta, queue_size=1000),
            rospy.Subscriber(NODE + "/status", ProviderStatus, self._on_status, queue_size=1000),
        ]
        if map_cloud_subscriber:
            self.subs.append(rospy.Subscriber("/map_cloud", rospy.AnyMsg, self._on_cloud, queue_size=2))
        self.odom = rospy.Publisher("/odom", Odometry, queue_size=100)
        argv = [sys.executable, str(NODE_SCRIPT), f"__name:={NODE[1:]}", "odom:=/odom"]
        self.process = ManagedProcess("grid_puzzle_map_provider", argv, core.env, log_dir / "provider.log")
        try:
            wait_for(
                lambda: self.odom.get_num_connections() > 0 and all(s.get_num_connections() > 0 for s in self.subs),
                WAIT,
                "the provider's topics",
                self.process,
            )
        except BaseException:
            self.process.stop()
            raise

    def _on_delta(self, msg) -> None:
        with self.record.lock:
            self.record.added.append(len(msg.added_ids))
            self.record.removed.append(len(msg.removed_ids))
            self.record.prefetch.append(len(msg.prefetch_ids))
            self.record.revisions.append(msg.revision)

    def _on_status(self, msg) -> None:
        with self.record.lock:
            self.record.status.append(msg)

    def _on_cloud(self, msg) -> None:
        with self.record.lock:
            self.record.map_clouds += 1
            self.record.map_cloud_mb = max(self.record.map_cloud_mb, len(msg._buff) / 2**20)

    def send(self, t: float, x: float, y: float, yaw: float, speed: float) -> None:
        msg = Odometry()
        msg.header.frame_id = "map"
        msg.header.stamp = rospy.Time.from_sec(t)
        msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
        msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        msg.twist.twist.linear.x = speed
        self.odom.publish(msg)

    def wait_statuses(self, count: int) -> None:
        wait_for(lambda: len(self.record.status) >= count, WAIT, f"{count} status messages", self.process)

    def close(self) -> None:
        for s in self.subs:
            s.unregister()
        self.odom.unregister()
        self.process.stop()


def drive(
    core, log_dir: Path, tiles: Path, args: argparse.Namespace, width: float, height: float, rviz: bool, floor: float
) -> dict:
    """Starts a node, drives the route in real time and returns the figures of that run."""
    poses = route_poses(width, height, args.speed, args.pose_rate)
    run = NodeRun(core, log_dir, tiles, args, rviz)
    try:
        pid = run.process.pid
        rss_start = proc_status_mb(pid, "VmRSS")
        t0 = time.monotonic() + 0.5
        for t, x, y, yaw in poses:
            time.sleep(max(0.0, t0 + t - time.monotonic()))
            run.send(t + 1.0, x, y, yaw, args.speed)
        time.sleep(2.0)  # the last update and its messages
        run.wait_statuses(1)
        peak = proc_status_mb(pid, "VmHWM")
        rss_end = proc_status_mb(pid, "VmRSS")
        parts = rollup_mb(pid)
    finally:
        run.close()
    rec = run.record
    status = rec.status
    first = status[0]
    target = floor + 10.0
    update_ms = [m.update_ms for m in status[1:]]
    return {
        "subscribers": "tile_delta, map_cloud (rviz-like)" if rviz else "tile_delta (localizer-like)",
        "route_m": round(float(np.sum(np.hypot(*np.diff(poses[:, 1:3], axis=0).T))), 1),
        "drive_s": round(float(poses[-1, 0]), 1),
        "poses_sent": len(poses),
        "updates": len(update_ms),
        "initial_window": {"update_ms": round(first.update_ms, 1), "tiles": first.tiles_loaded},
        "update_ms": percentiles(update_ms),
        "tiles_in_window_max": max(m.tiles_loaded for m in status),
        "tiles_added_per_update": percentiles(rec.added[1:]),
        "tiles_removed_per_update": percentiles(rec.removed[1:]),
        "tiles_prefetch_per_update": percentiles(rec.prefetch[1:]),
        "deltas_received": len(rec.revisions),
        "delta_revisions_contiguous": rec.revisions == list(range(1, len(rec.revisions) + 1)),
        "map_clouds_received": rec.map_clouds,
        "map_cloud_mb_max": round(rec.map_cloud_mb, 2),
        "memory_mib": {
            "rss_at_start": round(rss_start, 1),
            "peak_rss": round(peak, 1),
            "rss_at_end": round(rss_end, 1),
            "at_end": parts,
            "target_rss": round(target, 1),
        },
        "targets_met": {
            "update_p95_le_50ms": bool(np.percentile(update_ms, 95) <= 50.0),
            "rss_le_bare_rospy_plus_10mb": bool(peak <= target),
        },
    }


def initial_loads(core, log_dir: Path, tiles: Path, args: argparse.Namespace, width: float, height: float) -> list:
    """update_ms of the first window in repeats - 1 more fresh node processes."""
    poses = route_poses(width, height, args.speed, args.pose_rate)
    out = []
    for _ in range(args.repeats - 1):  # the drive's own first window is the first repeat
        run = NodeRun(core, log_dir, tiles, args, False)
        try:
            run.send(1.0, poses[0, 1], poses[0, 2], poses[0, 3], 0.0)
            run.wait_statuses(1)
            out.append(round(run.record.status[0].update_ms, 1))
        finally:
            run.close()
    return out


def bare_rospy_rss(core, log_dir: Path) -> dict:
    """RSS of a node that only imports rospy, calls init_node and spins."""
    proc = ManagedProcess("bare_rospy", [sys.executable, "-c", BARE_NODE], core.env, log_dir / "bare.log")
    try:
        time.sleep(5.0)
        return {"rss": round(proc_status_mb(proc.pid, "VmRSS"), 1), **rollup_mb(proc.pid)}
    finally:
        proc.stop()


def scenario(
    core, log_dir: Path, args: argparse.Namespace, width: float, height: float, points: int, floor: float
) -> dict:
    tiles = Path(tempfile.mkdtemp(prefix="gpm_bench_provider_"))
    try:
        made = make_map(tiles, width, height, args.grid_size, points)
        plain = drive(core, log_dir, tiles, args, width, height, rviz=False, floor=floor)
        loads = [plain["initial_window"]["update_ms"], *initial_loads(core, log_dir, tiles, args, width, height)]
        plain["initial_window"]["update_ms_median"] = round(float(np.median(loads)), 1)
        plain["initial_window"]["update_ms_all"] = loads
        out = {"map": made, "drive": plain}
        if not args.no_map_cloud_subscriber:
            out["drive_with_map_cloud_subscriber"] = drive(
                core, log_dir, tiles, args, width, height, rviz=True, floor=floor
            )
    finally:
        shutil.rmtree(tiles, ignore_errors=True)
    return out


def hardware() -> dict:
    return {
        "cpu_model": cpu_model(),
        "cores": os.cpu_count(),
        "node_threads": "worker, map_cloud publisher when on (+ rospy's)",
        "python": platform.python_version(),
        "load_average_1_5_15_at_end": [round(v, 2) for v in os.getloadavg()],
    }


def main() -> int:
    args = parse_args()
    log_dir = Path(tempfile.mkdtemp(prefix="gpm_bench_provider_logs_"))
    load_before = [round(v, 2) for v in os.getloadavg()]
    try:
        with RosCore(log_dir) as core:
            os.environ.update(core.env)
            rospy.init_node("bench_provider_driver", disable_signals=True)
            bare = bare_rospy_rss(core, log_dir)
            result = {
                "benchmark": "grid_puzzle_map_provider",
                "window": {"n": args.n, "k": args.k, "speed_mps": args.speed, "pose_rate_hz": args.pose_rate},
                "bare_rospy_node_mib": bare,
            }
            maps = {
                "sparse": (args.width, args.height, args.points_per_tile),
                "paper_scale": (args.paper_width, args.paper_height, args.paper_points_per_tile),
            }
            for name in args.scenarios.split(","):
                if name not in maps:
                    raise SystemExit(f"--scenarios: unknown scenario '{name}'; use sparse and/or paper_scale")
                result[name] = scenario(core, log_dir, args, *maps[name], floor=bare["rss"])
            rospy.signal_shutdown("benchmark done")
    except Exception:
        print(f"benchmark failed; logs kept in {log_dir}", file=sys.stderr)
        raise
    shutil.rmtree(log_dir, ignore_errors=True)
    result["hardware"] = {**hardware(), "load_average_1_at_start": load_before[0]}
    result["notes"] = (
        "MiB throughout; tiles travel by reference (the node reads no tile unless map_cloud is on and"
        " subscribed); update_ms is the node's ~status.update_ms (window, tile sets, tile_delta built and"
        " published; map_cloud has a thread of its own); peak_rss is the node process's VmHWM;"
        " target_rss = the bare rospy node's RSS + 10"
    )
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
