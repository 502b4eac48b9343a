"""Replays an experiment directory (`gpm simulate` or `gpm import`) through the core localizer without ROS, as
fast as it runs, against the whole map from the first scan's reference pose, with the localizer's default
parameters. Prints one JSON line: scans with an accepted match, scans published, and the translation error of the
published poses against the reference (median, max, RMSE). For working on tracking: a minute of real-time
playback through `gpm experiment` takes a few seconds here. --trace FILE keeps the per-scan CSV; other options go to
bench_localizer (e.g. --resolution 1.0)."""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import rosbag
from bench_input import write_header, write_scan, write_scan_count

from grid_puzzle_localization.blocks.poses import pose_matrix, read_tum
from grid_puzzle_localization.experiment.scenario import read_scenario
from grid_puzzle_localization.pcd import read_pcd, xyz_array
from grid_puzzle_localization.ros.msgs.cloud import cloud_to_array

QUANTILES = (("p50", 50), ("p95", 95), ("p99", 99), ("max", 100))  # of the per-scan time


def _transform(t) -> np.ndarray:
    q, p = t.rotation, t.translation
    return pose_matrix(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]))


def write_input(scenario: Path, out: Path) -> int:
    """The bench_localizer input (format in bench_localizer.cpp) of `scenario`; returns the scan count."""
    inputs = read_scenario(scenario)
    reference = read_tum(inputs.ground_truth)
    topics = inputs.settings.get("topics") or {}
    points_topic = topics.get("points", "points")
    cloud = xyz_array(read_pcd(inputs.global_map).points).astype(np.float32)
    mount, gyro, scans = np.eye(4), [], []
    with rosbag.Bag(str(inputs.bag)) as bag:
        for topic, msg, _ in bag.read_messages():
            if topic == "/tf_static":
                mount = _transform(msg.transforms[0].transform)
            elif msg._type == "sensor_msgs/Imu":
                w = msg.angular_velocity
                gyro.append([msg.header.stamp.to_sec(), w.x, w.y, w.z])
            elif topic == points_topic:
                records = cloud_to_array(msg)
                times = records["time"] if "time" in (records.dtype.names or ()) else np.zeros(0)
                scans.append((msg.header.stamp.to_sec(), xyz_array(records).astype(np.float32), times))
    stamps = np.array([scan[0] for scan in scans])
    truth, inside = reference.interpolate(stamps)
    if not inside.all():
        raise SystemExit(f"{scenario}: {int((~inside).sum())} scans lie outside the reference poses' time span")
    with out.open("wb") as f:
        write_header(f, 10.0, cloud, mount, np.asarray(gyro, dtype=np.float64))
        write_scan_count(f, len(scans))
        for i, (stamp, points, times) in enumerate(scans):
            write_scan(f, stamp, truth[i], points, times)
    return len(scans)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", type=Path)
    parser.add_argument("--trace", type=Path, help="per-scan CSV (default: a temporary file)")
    workspace = Path(os.environ["GPL_WS"])  # exported by tools/env.sh
    parser.add_argument("--exe", type=Path, default=workspace / "devel/lib/grid_puzzle_localization/bench_localizer")
    args, bench_options = parser.parse_known_args()  # the rest goes to bench_localizer (e.g. --resolution 1.0)
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "input.bin"
        write_input(args.scenario, data)
        trace = args.trace or Path(tmp) / "trace.csv"
        command = [str(args.exe), str(data), "replay", "--trace", str(trace), *bench_options]
        done = subprocess.run(command, capture_output=True)
        if done.returncode != 0:
            sys.stderr.write(done.stderr.decode())
            return done.returncode
        with open(trace, newline="") as f:
            table = list(csv.DictReader(f))
    columns = ("published", "accepted", "global_search", "error_m", "scan_ms")
    rows = {name: np.array([float(r[name]) for r in table]) for name in columns}
    published = rows["published"] > 0
    errors = rows["error_m"][published]
    print(
        json.dumps(
            {
                "scenario": str(args.scenario),
                "scans": len(table),
                "accepted": int((rows["accepted"] > 0).sum()),
                "published": int(published.sum()),
                "global_searches": int((rows["global_search"] > 0).sum()),
                "error_m": {
                    "median": round(float(np.median(errors)), 3) if errors.size else None,
                    "max": round(float(errors.max()), 3) if errors.size else None,
                    "rmse": round(float(np.sqrt(np.mean(errors**2))), 3) if errors.size else None,
                },
                "scan_ms": {q: round(float(np.percentile(rows["scan_ms"], p)), 1) for q, p in QUANTILES},
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
