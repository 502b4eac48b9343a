"""`gpm submaps`: cut a global map into fixed-size overlapping square submaps (block directory layout)."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from grid_puzzle_localization.blocks.fixed_cut import SubmapConfig, cut_submaps
from grid_puzzle_localization.blocks.store import BlockIndex, write_block_dir
from grid_puzzle_localization.pcd import read_pcd, xyz_array

KIND = "fixed_submaps"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = SubmapConfig()
    parser.add_argument("map", help="global map PCD (map frame)")
    parser.add_argument("output", help="directory to write (numbered PCDs, centroids.txt, index.yaml)")
    parser.add_argument("--side", type=float, default=defaults.side, help="square side L [m] (default: %(default)s)")
    parser.add_argument(
        "--overlap",
        type=float,
        default=defaults.overlap,
        help="overlap ratio o in [0, 1); squares are L (1 - o) apart (default: %(default)s)",
    )
    parser.add_argument("--force", action="store_true", help="replace a non-empty output directory")


def write_submaps(points: np.ndarray, config: SubmapConfig, output, map_path, force: bool) -> BlockIndex:
    """Cuts ``points`` (the map at ``map_path``) into submaps and writes them as a block directory."""
    stride = config.stride
    return write_block_dir(
        output,
        (
            (cloud, cloud.mean(axis=0), {"cell": [i, j], "origin": [i * stride, j * stride], "side": config.side})
            for (i, j), cloud in cut_submaps(points, config)
        ),
        KIND,
        {"side": config.side, "overlap": config.overlap, "stride": stride, "map": str(map_path)},
        len(points),
        force=force,
    )


def run(args: argparse.Namespace) -> int:
    config = SubmapConfig(args.side, args.overlap).checked()
    points = xyz_array(read_pcd(args.map).points)
    index = write_submaps(points, config, args.output, args.map, args.force)
    stored = sum(b.points for b in index.blocks)
    total = sum(b.bytes for b in index.blocks)
    files = len(index.blocks)
    print(
        f"gpm submaps: {files} submaps in {args.output}; {stored} points stored for a {len(points)}-point map "
        f"(overlap factor {stored / max(len(points), 1):.3f}); {total} bytes, "
        f"{total / max(files, 1):.0f} bytes per file",
        file=sys.stderr,
    )
    return 0
