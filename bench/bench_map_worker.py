"""`make bench-map-worker`: what the map worker spends keeping a window of tiles current, per metre driven.

Each stretch of kitti00_far (real HDL-64E keyframes with OXTS RTK GNSS/INS poses, imported as `make experiment-real`
imports them, cut into the urban preset's 2 m tiles: bench_map_store_throttled.kitti_stretch) is driven through the
core localizer at its own stamps (bench_localizer tiles mode, the tiles named by reference in the tile directory as
the provider names them, a 51 x 51 tile window that follows the pose), once per window update distance:
- 1 m: the paper's s / 2 (the provider's default, window/update_distance 0);
- 4 m: fewer, larger updates.
REPEATS runs each, interleaved. One JSON line per run: the map worker thread's CPU time over the drive (the first
window is loaded before it), per metre, and split into reading and folding tiles; the tiles read, the window updates,
the localizer's error against the reference. Then one summary line per stretch and distance with the medians and the
ratio to the 1 m runs.
--quick: bench-localizer's synthetic street (10 m tiles, 7 x 7 window), 5 m and 20 m, one run each; `make test` runs
it to check that the benchmark works. Without ../shared (tools/shared_data.py), one line says the kitti00_far runs
were skipped.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import tempfile
from pathlib import Path

import bench_map_store
import bench_map_store_throttled
from hardware import cpu_model

BENCH = "map_worker"
DISTANCES = (1.0, 4.0)  # [m]
QUICK_DISTANCES = (5.0, 20.0)
REPEATS = 3


def drive(bin_dir: Path, stretch: bench_map_store_throttled.Stretch, distance: float) -> dict:
    """One drive of ``stretch`` with the window recomputed after ``distance`` [m]; bench_localizer's JSON line."""
    cmd = [str(bin_dir / "bench_localizer"), str(stretch.data), "tiles", "--tile-size", str(stretch.tile_size)]
    cmd += ["--window", str(stretch.half_window), "--tile-source", str(stretch.tiles), "--pace", "stamps"]
    cmd += ["--update-distance", str(distance)]
    done = subprocess.run(cmd, check=True, stdout=subprocess.PIPE, text=True)  # its stderr is ours
    return json.loads(done.stdout)


def run_stretch(bin_dir: Path, stretch: bench_map_store_throttled.Stretch, distances, repeats: int) -> None:
    hardware = {"cpu_model": cpu_model(), "cores": os.cpu_count()}
    runs: dict[float, list[dict]] = {d: [] for d in distances}
    for repeat in range(repeats):
        for distance in distances:  # interleaved: a slow spell of the machine falls on every distance alike
            out = drive(bin_dir, stretch, distance)
            worker = out["map_worker"]
            row = {
                "bench": BENCH,
                "stretch": stretch.name,
                "update_distance_m": distance,
                "repeat": repeat,
                "distance_m": out["distance_m"],
                "window_updates": out["target_updates"],
                "tiles_read": worker["tiles_read"],
                "map_worker_cpu_ms": worker["cpu_ms"],
                "map_worker_cpu_ms_per_m": worker["cpu_ms_per_m"],
                "read_cpu_ms": worker["read_cpu_ms"],
                "fold_cpu_ms": worker["fold_cpu_ms"],
                "scan_thread_cpu_ms_p50": out["scan_thread_cpu_ms"]["p50"],
                "mean_error_m": out["translation_error_m"]["mean"],
                "max_error_m": out["translation_error_m"]["max"],
                "rejected_matches": out["rejected_matches"],
                "load_average_1min": os.getloadavg()[0],
                **hardware,
            }
            runs[distance].append(row)
            print(json.dumps(row), flush=True)
    base = statistics.median(r["map_worker_cpu_ms_per_m"] for r in runs[distances[0]])
    for distance in distances:
        rows = runs[distance]
        per_m = statistics.median(r["map_worker_cpu_ms_per_m"] for r in rows)
        summary = {
            "bench": BENCH,
            "summary": True,
            "stretch": stretch.name,
            "update_distance_m": distance,
            "repeats": len(rows),
            "map_worker_cpu_ms_per_m": round(per_m, 3),
            "x_first_distance": round(per_m / base, 3) if base > 0 else None,
            "read_cpu_ms": round(statistics.median(r["read_cpu_ms"] for r in rows), 1),
            "fold_cpu_ms": round(statistics.median(r["fold_cpu_ms"] for r in rows), 1),
            "other_cpu_ms": round(
                statistics.median(r["map_worker_cpu_ms"] - r["read_cpu_ms"] - r["fold_cpu_ms"] for r in rows), 1
            ),
            "window_updates": statistics.median(r["window_updates"] for r in rows),
            "mean_error_m": round(statistics.median(r["mean_error_m"] for r in rows), 4),
            "max_error_m": round(max(r["max_error_m"] for r in rows), 4),
            "ndt_threads": 1,
            **hardware,
        }
        print(json.dumps(summary), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the synthetic street, one run per distance")
    args = parser.parse_args()
    bin_dir = Path(os.environ["GPL_WS"]) / "devel/lib/grid_puzzle_localization"  # tools/env.sh exports GPL_WS
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        if args.quick:
            street = bench_map_store.street_drive(tmp)
            stretch = bench_map_store_throttled.Stretch(
                street.route, street.data, street.www / "map", street.tile_size, street.half_window
            )
            run_stretch(bin_dir, stretch, QUICK_DISTANCES, 1)
            return 0
        if not (bench_map_store_throttled.KITTI / "scans").is_dir():
            where = bench_map_store_throttled.KITTI
            print(json.dumps({"bench": BENCH, "skipped": f"the kitti00_far keyframes are not at {where}"}), flush=True)
            return 0
        for name in bench_map_store_throttled.STRETCHES:
            run_stretch(bin_dir, bench_map_store_throttled.kitti_stretch(name, tmp), DISTANCES, REPEATS)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
