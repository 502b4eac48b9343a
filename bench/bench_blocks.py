#!/usr/bin/env python3
"""Block map benchmark on the real nova_utd_tiles campus map (../shared/data/real): prints JSON.

- global map: all tiles merged (written once as one binary PCD);
- fixed-size overlapping submaps: `gpm submaps` (side L, overlap o), timed;
- keyframe-stitched blocks: Algorithm 1 on pseudo-scans of the real map (map points within a radius of
  keyframes on a depth-first walk over the occupied 25 m tiles, so the walk backtracks over mapped
  ground and the merge/drop rules fire), timed;
- storage table: global map, the real 25 m grid tiles, blocks, submaps;
- block server: load + merge time of the 2 nearest blocks (cache off) at keyframe positions.

Times are medians over --repeats runs (wall clock, one thread). Usage: bench_blocks.py [--repeats 3]
Prints one JSON line. --quick: a synthetic 100 m x 100 m map, one repeat (checks that it runs without the data).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from hardware import cpu_model
from scipy.spatial import cKDTree

from grid_puzzle_localization.blocks.block_cache import BlockCache
from grid_puzzle_localization.blocks.builder import BlockBuilder, BlockConfig
from grid_puzzle_localization.blocks.select import BlockSelector
from grid_puzzle_localization.blocks.storage import storage_table
from grid_puzzle_localization.blocks.store import read_block_index, write_block_dir
from grid_puzzle_localization.cli import main as gpm
from grid_puzzle_localization.pcd import iter_pcd_chunks, read_pcd_header, write_pcd, xyz_array, xyz_records
from grid_puzzle_localization.util.iteration import pairwise

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real" / "nova_utd_tiles"
TILE = 25.0  # [m] side of the data set's tiles
SCAN_RADIUS = 30.0  # [m] pseudo-scan range
WALK_TILES = 80  # occupied tiles the depth-first walk visits
STEP = 2.0  # [m] between keyframes on the walk


def load_map() -> tuple[np.ndarray, list[Path]]:
    files = sorted((DATA / "tiles").glob("*.pcd"))
    if not files:
        raise SystemExit(
            f"bench_blocks: no campus tiles in {DATA / 'tiles'}; this benchmark needs ../shared/data/real"
            " (--quick runs without it)"
        )
    parts = [xyz_array(chunk) for f in files if read_pcd_header(f).points for chunk in iter_pcd_chunks(f)]
    return np.concatenate(parts), files


def synthetic_map(tmp: Path) -> tuple[np.ndarray, Path]:
    """20,000 seeded points over 4 x 4 of the data set's tiles and those tiles (gpm tile), for --quick."""
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0.0, 4 * TILE, (20_000, 2)), rng.uniform(0.0, 3.0, 20_000)])
    write_pcd(tmp / "synthetic.pcd", xyz_records(points))
    with contextlib.redirect_stdout(sys.stderr):  # stdout holds the JSON line only
        status = gpm(["tile", str(tmp / "synthetic.pcd"), "-o", str(tmp / "tiles"), "--grid-size", f"{TILE:g}"])
    if status != 0:
        raise SystemExit("bench_blocks: gpm tile failed on the synthetic map")
    return points, tmp / "tiles"


def walk(points: np.ndarray) -> np.ndarray:
    """Keyframe positions [m]: a depth-first walk (with its backtracking) over occupied tiles, STEP apart."""
    cells = {tuple(c) for c in np.floor(points[:, :2] / TILE).astype(int).tolist()}
    start = min(cells)
    route, seen, stack = [start], {start}, [start]
    while stack and len(seen) < WALK_TILES:
        i, j = stack[-1]
        nxt = next(
            ((i + a, j + b) for a, b in ((1, 0), (0, 1), (-1, 0), (0, -1)) if (i + a, j + b) in cells - seen), None
        )
        if nxt is None:
            stack.pop()
            if stack:
                route.append(stack[-1])
            continue
        seen.add(nxt)
        stack.append(nxt)
        route.append(nxt)
    centres = (np.array(route, dtype=float) + 0.5) * TILE
    path = [centres[0]]
    for a, b in pairwise(centres):
        n = max(1, round(float(np.linalg.norm(b - a)) / STEP))
        path += [a + (b - a) * t for t in np.arange(1, n + 1) / n]
    return np.array(path)


def build_blocks(points: np.ndarray, tree: cKDTree, path: np.ndarray, config: BlockConfig):
    builder = BlockBuilder(config)
    for xy in path:
        pose = np.eye(4)
        pose[:2, 3] = xy
        scan = points[tree.query_ball_point(xy, SCAN_RADIUS)] - pose[:3, 3]  # sensor frame, identity extrinsic
        builder.add_keyframe(pose, scan)
    builder.finish()
    return builder


def median_seconds(fn, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--side", type=float, default=50.0, help="fixed submap side L [m]")
    parser.add_argument("--overlap", type=float, default=0.5, help="fixed submap overlap ratio o")
    parser.add_argument("--block-size", type=float, default=50.0, help="block size S [m]")
    parser.add_argument("--voxel", type=float, default=0.2, help="block voxel [m]")
    parser.add_argument("--quick", action="store_true", help="synthetic small map, one repeat: checks that it runs")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="gpm_bench_blocks_") as tmp:
        tmp = Path(tmp)
        if args.quick:
            args.repeats = 1
            points, tile_dir = synthetic_map(tmp)
            tile_files = sorted(tile_dir.glob("*.pcd"))
        else:
            points, tile_files = load_map()
            tile_dir = DATA / "tiles"
        write_pcd(tmp / "map.pcd", xyz_records(points))
        submap_args = ["submaps", str(tmp / "map.pcd"), str(tmp / "submaps"), "--force"]
        submap_args += ["--side", str(args.side), "--overlap", str(args.overlap)]
        with contextlib.redirect_stdout(sys.stderr):  # stdout holds the JSON line only
            cut_s, _ = median_seconds(lambda: gpm(submap_args), args.repeats)
        tree = cKDTree(points[:, :2])
        path = walk(points)
        config = BlockConfig(args.block_size, 0.0, args.voxel)
        build_s, builder = median_seconds(lambda: build_blocks(points, tree, path, config), args.repeats)
        blocks, report, union = builder.blocks, builder.report, builder.map_points()
        write_block_dir(
            tmp / "blocks",
            ((b.points, b.centroid, {"keyframes": b.keyframes}) for b in blocks),
            "keyframe_blocks",
            {},
            union,
        )
        rows = storage_table(tmp / "map.pcd", tile_dir, tmp / "blocks", tmp / "submaps")
        server = {}
        for name in ("blocks", "submaps"):
            index = read_block_index(tmp / name)
            selector = BlockSelector(index.centroids(), 2, planar=True)
            cache = BlockCache(index, 0)
            loads, previous = [], None
            for xy in path[:: max(1, len(path) // 200)]:
                selection = selector.select(np.array([xy[0], xy[1], 0.0]))
                if selection != previous:
                    start = time.perf_counter()
                    merged = cache.merged(selection)
                    loads.append((time.perf_counter() - start, len(merged)))
                    previous = selection
            server[name] = {
                "switches": len(loads),
                "median_load_merge_ms": 1e3 * statistics.median(t for t, _ in loads),
                "median_points": int(statistics.median(n for _, n in loads)),
            }
    print(
        json.dumps(
            {
                "benchmark": "bench_blocks",
                "data": "synthetic (--quick)" if args.quick else "nova_utd_tiles (real campus map)",
                "hardware": {"cpu": cpu_model(), "cores": os.cpu_count(), "threads_used": 1},
                "repeats": args.repeats,
                "map_points": len(points),
                "map_tile_files": len(tile_files),
                "fixed_submaps": {"side_m": args.side, "overlap": args.overlap, "median_cut_and_write_s": cut_s},
                "keyframe_blocks": {
                    "block_size_m": args.block_size,
                    "voxel_m": args.voxel,
                    "scan_radius_m": SCAN_RADIUS,
                    "keyframes": report.keyframes,
                    "walk_m": float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
                    "candidates": report.candidates,
                    "actions": report.actions,
                    "blocks": len(blocks),
                    "median_build_s": build_s,
                },
                "storage": [r.as_dict() for r in rows],
                "server_2_nearest": server,
            }
        )
    )


if __name__ == "__main__":
    main()
