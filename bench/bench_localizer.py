"""`make bench-localizer`: a synthetic drive (fixtures.synthetic_scene) through the core
localizer without roscore. Writes the scans, the gyro samples and the map to a temporary input file, runs the
C++ bench_localizer once per map mode (cloud: the merged window rebuilt per change; tiles: incremental deltas)
and once as the control (repeat: the same scan against a fixed map at every slot, whose spread is the machine's
own), then bench_fusion (the sliding-window update per scan), and prints one JSON line per run, with the machine
it ran on. --quick: a 2 s drive (checks that it runs)."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
from bench_input import write_header, write_scan, write_scan_count
from fixtures import synthetic_scene as ss
from hardware import cpu_model

ROOT = Path(__file__).resolve().parents[1]


# White noise of the simulated gyro [rad/s], about a MEMS IMU's at 100 Hz.
GYRO_NOISE = 0.002


def write_input(path: Path, drive: ss.Drive, imu_rate: float, seed: int) -> None:
    """The C++ program's input (format in bench_localizer.cpp). The street runs 40 m past the end of the
    drive; ``imu_rate`` [Hz] of gyro samples over the whole drive, 0 for none."""
    scene = ss.make_scene(length=drive.x0 + drive.speed * drive.duration + 40.0)
    rng = np.random.default_rng(seed)
    with path.open("wb") as f:
        imu_t = np.arange(0.0, drive.duration, 1.0 / imu_rate) if imu_rate > 0 else np.zeros(0)
        gyro = drive.angular_velocity(imu_t) + rng.normal(0.0, GYRO_NOISE, size=(imu_t.size, 3))
        write_header(f, drive.rate, ss.sample_map(scene), ss.lidar_mount(), np.column_stack([imu_t, gyro]))
        write_scan_count(f, len(drive.stamps))
        for t in drive.stamps:
            pose = drive.pose(float(t))
            write_scan(f, float(t), pose, ss.scan(scene, pose, rng), np.zeros(0))  # instantaneous scans


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--duration", type=float, default=60.0, help="drive length [s] at 10 Hz (default 60)")
    parser.add_argument("--imu-rate", type=float, default=100.0, help="gyro samples [Hz], 0 = no IMU (default 100)")
    parser.add_argument("--tile-size", type=float, default=10.0, help="tile side [m] (default 10)")
    parser.add_argument("--window", type=int, default=3, help="tiles on each side of the vehicle (default 3)")
    parser.add_argument("--threads", type=int, help="NDT OpenMP threads, 0 = all cores (default: the localizer's)")
    parser.add_argument("--quick", action="store_true", help="a 2 s drive: checks that it runs")
    parser.add_argument("--trace", type=Path, help="write per-scan CSV traces to DIR/<mode>.csv (cloud, tiles)")
    workspace = Path(os.environ["GPL_WS"])  # exported by tools/env.sh (the Makefile sources it)
    parser.add_argument("--exe", type=Path, default=workspace / "devel/lib/grid_puzzle_localization/bench_localizer")
    args = parser.parse_args()
    if args.quick:
        args.duration = 2.0
    # Other processes compete for the cores: the load average says how much (latency tails depend on it).
    hardware = {"cpu_model": cpu_model(), "cores": os.cpu_count(), "load_average_1min": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "drive.bin"
        write_input(data, ss.Drive(duration=args.duration), args.imu_rate, seed=1)
        for mode in ("cloud", "tiles", "repeat"):
            cmd = [str(args.exe), str(data), mode, "--tile-size", str(args.tile_size), "--window", str(args.window)]
            if args.threads is not None:
                cmd += ["--threads", str(args.threads)]
            if args.trace is not None and mode != "repeat":
                args.trace.mkdir(parents=True, exist_ok=True)
                cmd += ["--trace", str(args.trace / f"{mode}.csv")]
            out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
            print(json.dumps({**json.loads(out), **hardware}), flush=True)
    # The sliding-window fusion's per-scan update (its own closed-form drive, no map).
    fusion_cmd = [str(args.exe.with_name("bench_fusion"))] + (["--scans", "40"] if args.quick else [])
    out = subprocess.run(fusion_cmd, check=True, capture_output=True, text=True).stdout
    print(json.dumps({**json.loads(out), **hardware}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
