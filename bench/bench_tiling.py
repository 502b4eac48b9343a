#!/usr/bin/env python3
"""Benchmark of `gpm tile`: the real campus map (nova_utd_tiles, 5.05 M points) merged into one
global PCD (not timed), re-cut with s = 2 m under --memory-mb 200 in a child process whose wall time
and peak RSS are measured. Prints one JSON line (median over repeats, with hardware info). One more
run on a map four times as large (the campus map merged four times) shows that peak RSS does not
grow with the map. After each repeat, the same files are created once more by a bare loop that does
nothing else (file_creation_floor.py): the least this disk allows.

By default everything goes to the repo's file system (a temporary directory under build/), where a
user's tiles would go; --tmp-dir /dev/shm times the tiler without a disk. Each repeat writes a fresh
directory and all are deleted at the end: deleting tens of thousands of files right before creating
as many slows the creation down on some file systems (ext4 without a journal scans past inodes
deleted in the last minutes), which would time the benchmark's own clean-up, not the tiler.

--quick: a synthetic map of 100,000 points, one repeat (checks that it runs without the real data)."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from file_creation_floor import create_files
from hardware import cpu_model

from grid_puzzle_localization.pcd import merge_pcds, write_pcd, xyz_records
from grid_puzzle_localization.tiling import load_tile_index
from grid_puzzle_localization.util.iteration import exit_code, zip_equal

ROOT = Path(__file__).resolve().parents[1]
CAMPUS_TILES = ROOT.parent / "shared" / "data" / "real" / "nova_utd_tiles" / "tiles"
GPM = "import sys; from grid_puzzle_localization.cli import main; sys.exit(main())"


def run_child(args: list[str]) -> tuple[float, float, dict]:
    """(wall seconds, peak RSS MiB, the JSON summary it printed) of one child process."""
    start = time.perf_counter()
    child = subprocess.Popen(args, stdout=subprocess.PIPE)
    output = child.stdout.read()
    _, status, usage = os.wait4(child.pid, 0)
    seconds = time.perf_counter() - start
    code = exit_code(status)
    if code != 0:
        raise SystemExit(f"bench_tiling: {' '.join(args)} failed with status {code}")
    return seconds, usage.ru_maxrss / 1024.0, json.loads(output)  # ru_maxrss is in KiB on Linux


def synthetic_map(path: Path) -> int:
    """100,000 seeded points over 60 m x 60 m (900 tiles of 2 m) as one PCD, for --quick; their count."""
    rng = np.random.default_rng(0)
    n = 100_000
    points = np.column_stack([rng.uniform(0.0, 60.0, (n, 2)), rng.uniform(0.0, 3.0, n)])
    write_pcd(path, xyz_records(points))
    return n


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--grid-size", type=float, default=2.0)
    parser.add_argument("--memory-mb", type=float, default=200.0)
    parser.add_argument("--jobs", type=int, default=2, help="gpm tile --jobs")
    parser.add_argument(
        "--tmp-dir",
        type=Path,
        default=ROOT / "build",
        help="where the merged map and the tiles go (default: build/ in the repo, i.e. the repo's file system)",
    )
    parser.add_argument("--quick", action="store_true", help="synthetic small map, one repeat: checks that it runs")
    args = parser.parse_args()
    inputs = sorted(CAMPUS_TILES.glob("*.pcd"))
    if args.quick:
        args.repeats = 1
    elif not inputs:
        raise SystemExit(
            f"bench_tiling: no campus tiles in {CAMPUS_TILES}; this benchmark needs ../shared/data/real"
            " (--quick runs without it)"
        )
    args.tmp_dir.mkdir(parents=True, exist_ok=True)
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench_tiling_", dir=args.tmp_dir) as tmp:
        campus = Path(tmp) / "campus.pcd"
        points_in = synthetic_map(campus) if args.quick else merge_pcds(inputs, campus)
        seconds, rss, phases, floor = [], [], [], []
        command = [sys.executable, "-c", GPM, "tile", "--json", "--grid-size", f"{args.grid_size:g}"]
        for k in range(args.repeats):
            out = Path(tmp) / f"tiles{k}"
            os.sync()  # flush earlier writes so they do not count against this run
            wall, peak, summary = run_child(
                [*command, "--memory-mb", f"{args.memory_mb:g}", "--jobs", str(args.jobs), str(campus), "-o", str(out)]
            )
            seconds.append(wall)
            rss.append(peak)
            phases.append(summary)
            table = load_tile_index(out).table
            files = list(zip_equal(table.files, table.bytes))
            floor.append(create_files(Path(tmp) / f"files_only{k}", files, args.jobs))
        index = load_tile_index(out)
        median = statistics.median(seconds)
        # Memory must not grow with the map: the same budget on one file four times as large.
        large = Path(tmp) / "campus_x4.pcd"
        merge_pcds([campus] * 4, large)
        _, rss_x4, _ = run_child(
            [*command, "--memory-mb", f"{args.memory_mb:g}", "--jobs", str(args.jobs), str(large), "-o", f"{tmp}/x4"]
        )
        print(
            json.dumps(
                {
                    "bench": "tiling",
                    "map": "synthetic (--quick)" if args.quick else "nova_utd campus",
                    "grid_size_m": args.grid_size,
                    "memory_mb": args.memory_mb,
                    "points_in": points_in,
                    "points_out": index.points,
                    "tiles": len(index.table),
                    "seconds": round(median, 3),
                    "points_per_s": round(points_in / median),
                    "peak_rss_mb": round(max(rss), 1),
                    "peak_rss_mb_map_x4": round(rss_x4, 1),  # one run on the campus map merged 4 times
                    "bytes_in": campus.stat().st_size,
                    "bytes_tiles_data": sum(index.table.points) * index.record_bytes,
                    "bytes_tiles_total": sum(index.table.bytes),
                    "repeats": args.repeats,
                    "seconds_all": [round(s, 3) for s in seconds],
                    "seconds_stream_median": round(statistics.median(p["seconds_stream"] for p in phases), 3),
                    "seconds_write_median": round(statistics.median(p["seconds_write"] for p in phases), 3),
                    "seconds_sync_median": round(statistics.median(p["seconds_sync"] for p in phases), 3),
                    "stream_points_per_s": round(points_in / statistics.median(p["seconds_stream"] for p in phases)),
                    "files_only_seconds_median": round(statistics.median(floor), 3),
                    "timing": "seconds: median wall time of the gpm process (Python start-up included);"
                    " stream: reading + grouping + spilling; write: creating the tile files and index, with"
                    " the files written so far flushed to disk meanwhile; sync: the last syncfs and publishing OUT_DIR;"
                    " files_only: creating the same files (names, sizes) with the same flushing and nothing else,"
                    " after each repeat (file_creation_floor.py)",
                    "cpu": cpu_model(),
                    "cores": os.cpu_count(),
                    "threads_used": args.jobs,  # chunks grouped on --jobs threads
                    "processes_used": args.jobs + 1,  # then --jobs forked tile writers beside the index writer
                    "load_avg_1min": [round(load_before, 2), round(os.getloadavg()[0], 2)],  # before, after
                    "output_fs": subprocess.run(
                        ["findmnt", "-n", "-o", "FSTYPE", "-T", tmp], capture_output=True, text=True
                    ).stdout.strip(),
                }
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
