#!/usr/bin/env python3
"""Benchmark of the grid puzzle tile provider's work: a synthetic tiled map (default 500 m x 700 m,
s = 2 m, with index.json), driven at 10 m/s in real time with n = 25, k = 20. Prints JSON.

The parent process writes the map into a temp dir (timed separately, not part of any figure) and
runs the measured drive in a child process, so the child's peak RSS is that of a process running the
store exactly as the node does: window tracker, tile store with prefetch, TileDelta and map_cloud
messages built and serialised (no ROS master needed). The temp dir is deleted afterwards.
"""

from __future__ import annotations

import argparse
import io
import itertools
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--width", type=float, default=500.0, help="map extent along x [m]")
    p.add_argument("--height", type=float, default=700.0, help="map extent along y [m]")
    p.add_argument("--grid-size", type=float, default=2.0, help="s [m]")
    p.add_argument("--n", type=int, default=25)
    p.add_argument("--k", type=int, default=20)
    p.add_argument("--points-per-tile", type=int, default=64)
    p.add_argument("--speed", type=float, default=10.0, help="[m/s]")
    p.add_argument("--pose-rate", type=float, default=25.0, help="odometry rate [Hz]")
    p.add_argument("--cache-mb", type=float, default=None, help="[MiB]; default: the provider's default")
    p.add_argument("--repeats", type=int, default=3, help="fresh processes timed for the initial window load")
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument(
        "--phase", choices=("initial", "drive", "drive_no_map_cloud"), default="drive", help=argparse.SUPPRESS
    )
    return p.parse_args()


# A drive with turns inside the map: east, north, a diagonal, west [fractions of width, height].
ROUTE = [(0.12, 0.09), (0.88, 0.09), (0.88, 0.5), (0.4, 0.85), (0.12, 0.85)]


def route_poses(width: float, height: float, speed: float, rate: float) -> np.ndarray:
    """(M, 3) poses (t [s], x [m], y [m]) along ROUTE at constant speed."""
    corners = np.array([(fx * width, fy * height) for fx, fy in ROUTE])
    out, t = [], 0.0
    step = speed / rate
    for a, b in itertools.pairwise(corners):
        length = float(np.hypot(*(b - a)))
        for d in np.arange(0.0, length, step):
            out.append((t, *(a + (b - a) * d / length)))
            t += 1.0 / rate
    return np.array(out)


def make_map(directory: Path, args: argparse.Namespace) -> dict:
    from grid_puzzle_localization.grid import tile_filename, tile_stem
    from grid_puzzle_localization.synthetic_tiles import POINT_DTYPE, write_tiles
    from grid_puzzle_localization.tiling.index import TileEntry, TileIndex, write_index

    s = args.grid_size
    ni, nj = math.ceil(args.width / s), math.ceil(args.height / s)
    keys = [(i, j) for i in range(ni) for j in range(nj)]
    start = time.perf_counter()
    write_tiles(directory, keys, s, args.points_per_tile, seed=1)
    size = POINT_DTYPE.itemsize * args.points_per_tile
    entries = [
        TileEntry((i, j), tile_stem(i, j, s), tile_filename(i, j, s), ((i + 0.5) * s, (j + 0.5) * s),
                  args.points_per_tile, {"min": [i * s, j * s, -1.0], "max": [(i + 1) * s, (j + 1) * s, 5.0]},
                  size + 200, size)
        for i, j in keys
    ]  # fmt: skip
    fields = [{"name": n, "size": 4, "type": "F", "count": 1} for n in POINT_DTYPE.names]
    write_index(directory, TileIndex(s, fields, POINT_DTYPE.itemsize, len(keys) * args.points_per_tile, 0, [], entries))
    disk = sum(f.stat().st_size for f in directory.iterdir())
    return {
        "tiles": len(keys),
        "disk_mb": round(disk / 2**20, 1),
        "generation_s": round(time.perf_counter() - start, 1),
    }


def percentiles(values: list[float]) -> dict:
    if not values:
        return {}
    a = np.asarray(values)
    return {"p50": round(float(np.percentile(a, 50)), 2), "p95": round(float(np.percentile(a, 95)), 2),
            "max": round(float(a.max()), 2), "mean": round(float(a.mean()), 2)}  # fmt: skip


def proc_status_mb(field: str) -> float:
    """A memory field of /proc/self/status [MiB]: VmHWM is the peak resident set of this process
    image (unlike ru_maxrss, not inherited from the parent across fork and exec), VmRSS the current."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ":")) / 1024.0


def rss_mb() -> float:
    return proc_status_mb("VmHWM")


def current_rss_mb() -> float:
    return proc_status_mb("VmRSS")


def child(args: argparse.Namespace) -> dict:
    """The measured drive (runs in its own process, set up as the node sets itself up)."""
    from grid_puzzle_localization.malloc_tuning import pin_mmap_threshold

    pin_mmap_threshold()
    from genpy import Time
    from std_msgs.msg import Header

    from grid_puzzle_localization.provider_config import TilesConfig
    from grid_puzzle_localization.ros.cloud_msg import cloud_from_parts
    from grid_puzzle_localization.ros.provider_msgs import tile_delta
    from grid_puzzle_localization.tile_directory import open_tile_directory
    from grid_puzzle_localization.tile_store import TileStore
    from grid_puzzle_localization.window import PoseSample, WindowConfig, WindowTracker

    rss_after_imports = rss_mb()
    cache_mb = args.cache_mb if args.cache_mb is not None else TilesConfig.cache_mb
    config = WindowConfig(n=args.n, k=args.k)
    poses = route_poses(args.width, args.height, args.speed, args.pose_rate)

    def serialised(msg) -> int:
        buff = io.BytesIO()
        msg.serialize(buff)
        return buff.tell()

    # Initial window: open the directory, load the first window, build its reset delta.
    start = time.perf_counter()
    directory = open_tile_directory(args.child)
    tracker = WindowTracker(config, directory.grid_size)
    store = TileStore(directory, cache_mb)
    window = tracker.update(PoseSample(poses[0, 1], poses[0, 2], poses[0, 0]))
    delta = store.update(window, tracker.predicted_windows())
    serialised(tile_delta(Header(frame_id="map"), 1, True, directory.grid_size, window, delta.added, []))
    initial = {"load_ms": (time.perf_counter() - start) * 1e3, "tiles": len(delta.added)}
    if args.phase == "initial":
        store.close()
        return initial
    rss_after_initial = rss_mb()

    update_ms, cloud_ms, added, removed, window_bytes = [], [], [], [], []
    skipped = 0
    t0 = time.monotonic()
    k = 1
    while k < len(poses):
        due = t0 + poses[k, 0]
        now = time.monotonic()
        if now < due:
            time.sleep(due - now)
        else:  # behind schedule: serve only the latest pose that is due, as the node does
            latest = k + int((now - due) * args.pose_rate)
            skipped += min(latest, len(poses) - 1) - k
            k = min(latest, len(poses) - 1)
        t, x, y = poses[k]
        k += 1
        start = time.perf_counter()
        window = tracker.update(PoseSample(x, y, t))
        if window is None:
            continue
        delta = store.update(window, tracker.predicted_windows())
        header = Header(frame_id="map", stamp=Time.from_sec(t))
        serialised(tile_delta(header, k, False, directory.grid_size, window, delta.added, delta.removed))
        update_ms.append((time.perf_counter() - start) * 1e3)
        added.append(len(delta.added))
        removed.append(len(delta.removed))
        if args.phase == "drive" and (delta.added or delta.removed):
            start = time.perf_counter()
            serialised(cloud_from_parts([p for _, p in store.loaded()], store.dtype, header=header))
            cloud_ms.append((time.perf_counter() - start) * 1e3)
        window_bytes.append(store.stats().bytes)
    stats = store.stats()
    store.close()
    loaded_peak = max(window_bytes)
    peak = rss_mb()
    rss_end = current_rss_mb()
    return {
        "route_m": round(float(np.sum(np.hypot(*np.diff(poses[:, 1:], axis=0).T))), 1),
        "drive_s": round(float(poses[-1, 0]), 1),
        "poses": len(poses),
        "poses_skipped_behind_schedule": skipped,
        "updates": len(update_ms),
        "initial_window": initial,
        "update_ms": percentiles(update_ms),
        "map_cloud_ms": percentiles(cloud_ms),
        "tiles_added_per_update": percentiles(added),
        "tiles_removed_per_update": percentiles(removed),
        "cache": {
            "cache_mb": cache_mb,
            "hits": stats.cache_hits,
            "misses": stats.cache_misses,
            "hit_rate": round(stats.hit_rate, 4),
            "hit_rate_after_initial_window": round(
                stats.cache_hits / max(1, stats.cache_hits + stats.cache_misses - initial["tiles"]), 4
            ),
            "prefetched_tiles": stats.prefetched,
        },
        "memory": {
            "loaded_window_mb_max": round(loaded_peak / 2**20, 2),
            "rss_after_imports_mb": round(rss_after_imports, 1),
            "peak_rss_after_initial_window_mb": round(rss_after_initial, 1),
            "peak_rss_mb": round(peak, 1),
            "rss_at_end_mb": round(rss_end, 1),
            "target_rss_mb": round(2 * loaded_peak / 2**20 + 60.0, 1),
        },
        "targets_met": {
            "update_p95_le_50ms": bool(np.percentile(update_ms, 95) <= 50.0),
            "rss_le_2x_window_plus_60mb": bool(peak <= 2 * loaded_peak / 2**20 + 60.0),
        },
    }


def hardware() -> dict:
    model = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), model)
    except OSError:
        pass
    return {"cpu_model": model, "cores": os.cpu_count(), "threads_used": 2, "python": platform.python_version()}


def run_child(directory: Path, phase: str) -> dict:
    run = subprocess.run(
        [sys.executable, os.path.abspath(__file__), *sys.argv[1:], "--child", str(directory), "--phase", phase],
        capture_output=True,
        text=True,
        check=False,
    )
    if run.returncode != 0:
        raise RuntimeError(f"benchmark child ({phase}) failed:\n{run.stderr}")
    return json.loads(run.stdout)


def main() -> int:
    args = parse_args()
    if args.child:
        print(json.dumps(child(args)))
        return 0
    directory = Path(tempfile.mkdtemp(prefix="gpm_bench_provider_"))
    try:
        made = make_map(directory, args)
        # The initial load in fresh processes (the first one of them also drives), median reported.
        initial = [run_child(directory, "drive")]
        initial += [run_child(directory, "initial") for _ in range(args.repeats - 1)]
        measured = initial[0]
        loads = [measured["initial_window"]["load_ms"]] + [r["load_ms"] for r in initial[1:]]
        measured["initial_window"] = {
            "load_ms_median": round(float(np.median(loads)), 1),
            "load_ms_all": [round(ms, 1) for ms in loads],
            "tiles": measured["initial_window"]["tiles"],
        }
        # The same drive with publish_map_cloud: false, for its latency and memory.
        lean = run_child(directory, "drive_no_map_cloud")
        measured["without_map_cloud"] = {key: lean[key] for key in ("update_ms", "memory", "targets_met")}
    finally:
        shutil.rmtree(directory, ignore_errors=True)
    result = {
        "benchmark": "grid_puzzle_map_provider",
        "map": {"width_m": args.width, "height_m": args.height, "grid_size_m": args.grid_size,
                "points_per_tile": args.points_per_tile, **made},
        "window": {"n": args.n, "k": args.k, "speed_mps": args.speed, "pose_rate_hz": args.pose_rate},
        **measured,
        "hardware": hardware(),
        "notes": "tile files were just written, so reads hit the OS page cache; update_ms covers window,"
        " store update and the TileDelta built and serialised; map_cloud_ms the merged cloud built and serialised",
    }  # fmt: skip
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
