"""`gpm tile`: cut a global map into grid puzzle tiles, or verify a tiled map against its input."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiling.tiler import TileConfig, tile_map
from grid_puzzle_localization.tiling.verify import verify_tiles
from grid_puzzle_localization.util.malloc_tuning import reuse_large_buffers


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.usage = (
        "gpm tile --grid-size S MAP.pcd [MORE.pcd ...] -o OUT_DIR [--memory-mb MB] [--force]\n"
        "       gpm tile --verify OUT_DIR MAP.pcd [MORE.pcd ...]"
    )
    parser.add_argument("inputs", nargs="+", type=Path, metavar="MAP.pcd", help="input map PCD(s), same fields")
    parser.add_argument("-s", "--grid-size", type=float, help="tile side s [m]")
    parser.add_argument("-o", "--output", type=Path, metavar="OUT_DIR", help="output directory for the tiles")
    parser.add_argument(
        "--memory-mb", type=float, default=TileConfig.memory_mb, help="working-set budget [MiB] (default %(default)s)"
    )
    parser.add_argument("--force", action="store_true", help="replace a non-empty OUT_DIR")
    parser.add_argument(
        "--jobs",
        type=int,
        default=TileConfig.jobs,
        help="grouping threads and tile-writing processes (default %(default)s)",
    )
    parser.add_argument(
        "--no-sync",
        action="store_true",
        help="do not flush the tiles to disk before publishing OUT_DIR (faster; after a power loss"
        " OUT_DIR may hold empty tiles)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar even on a terminal")
    parser.add_argument("--json", action="store_true", help="print the tiling summary as one JSON line")
    parser.add_argument("--verify", type=Path, metavar="OUT_DIR", help="re-check a tiled map against MAP.pcd")


def run(args: argparse.Namespace) -> int:
    if args.verify is not None:
        return _verify(args)
    if args.grid_size is None or args.output is None:
        raise UserError("tiling needs --grid-size S and -o OUT_DIR (or --verify OUT_DIR to check a tiled map)")
    config = TileConfig(
        grid_size=args.grid_size,
        memory_mb=args.memory_mb,
        force=args.force,
        progress=not args.no_progress,
        jobs=args.jobs,
        sync=not args.no_sync,
    )
    reuse_large_buffers()  # each chunk's sort temporaries would otherwise fault in fresh pages
    result = tile_map(args.inputs, args.output, config)
    index = result.index
    if args.json:
        summary = {
            "points": index.points,
            "tiles": len(index.table),
            "nonfinite_dropped": index.nonfinite_dropped,
            "spills": result.spills,
            "seconds": result.seconds,
            "seconds_stream": result.seconds_stream,
            "seconds_write": result.seconds_write,
            "seconds_sync": result.seconds_sync,
        }
        print(json.dumps(summary))
        return 0
    print(
        f"{index.points} points in {len(index.table)} tiles of {index.grid_size:g} m -> {args.output}"
        f" ({index.nonfinite_dropped} NaN/inf points dropped, {result.spills} spills, {result.seconds:.2f} s)"
    )
    return 0


def _verify(args: argparse.Namespace) -> int:
    report = verify_tiles(args.verify, args.inputs)
    rows = [
        ("tiles", report.tiles),
        ("input finite points", report.points_in),
        ("input NaN/inf points (dropped)", report.nonfinite_in),
        ("tile points", report.points_tiles),
        ("points outside their tile", report.misplaced_points),
        ("input data bytes", report.bytes_in_data),
        ("tile data bytes", report.bytes_tiles_data),
        ("tile header bytes", report.bytes_tiles_headers),
        ("tile file bytes (data + headers)", report.bytes_tiles_total),
        ("file system block overhead bytes", report.block_overhead),
        ("records bit for bit (checksum)", "equal" if report.checksum_in == report.checksum_tiles else "DIFFERENT"),
    ]
    for name, value in rows:
        print(f"{name:34s} {value}")
    for problem in report.problems:
        print(f"PROBLEM: {problem}")
    print("conservation: OK" if report.ok else "conservation: FAILED")
    return 0 if report.ok else 1
