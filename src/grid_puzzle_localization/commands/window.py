"""`gpm window`: prints the grid puzzle window for a position (and a previous one for the heading) as
JSON, with the same code the provider node runs. Use it to check n, k and s before a run."""

from __future__ import annotations

import argparse
import json
import math
import sys

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.window import PoseSample, WindowConfig, WindowTracker, compute_window
from grid_puzzle_localization.tiles.directory import open_tile_directory
from grid_puzzle_localization.tiles.grid import check_grid_size, tile_center, tile_filename


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--grid-size", type=float, help="tile side s [m] (read from the index of --tiles when omitted)")
    parser.add_argument("--n", type=int, default=WindowConfig.n, help="half side of the default square [tiles]")
    parser.add_argument("--k", type=int, default=WindowConfig.k, help="extension toward the heading [tiles]")
    parser.add_argument(
        "--preset", default=WindowConfig.preset, help="urban or courtyard: the paper's n and k (overrides --n/--k)"
    )
    parser.add_argument("--x", type=float, required=True, help="agent position x [m]")
    parser.add_argument("--y", type=float, required=True, help="agent position y [m]")
    parser.add_argument("--prev-x", type=float, help="previous position x [m] (heading = direction of travel)")
    parser.add_argument("--prev-y", type=float, help="previous position y [m]")
    parser.add_argument("--yaw", type=float, help="heading from the pose's yaw [rad] instead of the motion")
    parser.add_argument("--update-distance", type=float, default=WindowConfig.update_distance, help="[m]; 0 = s / 2")
    parser.add_argument("--tiles", help="tile directory: list only the tiles that exist there")


def run(args: argparse.Namespace) -> int:
    if (args.prev_x is None) != (args.prev_y is None):
        raise UserError("give both --prev-x and --prev-y, or neither")
    directory = open_tile_directory(args.tiles, args.grid_size) if args.tiles else None
    if directory is None and args.grid_size is None:
        raise UserError("--grid-size is required without --tiles (for example --grid-size 2)")
    s = directory.grid_size if directory else check_grid_size(args.grid_size)
    config = WindowConfig(
        n=args.n,
        k=args.k,
        preset=args.preset,
        update_distance=args.update_distance,
        heading_source="yaw" if args.yaw is not None else "motion",
    )
    tracker = WindowTracker(config, s)
    here = PoseSample(args.x, args.y, yaw=args.yaw)
    note = ""
    if args.prev_x is not None:
        tracker.update(PoseSample(args.prev_x, args.prev_y, yaw=args.yaw))
    window = tracker.update(here)
    if window is None:  # the node would keep its previous window; show this position's, without heading
        note = f"moved only {math.hypot(args.x - args.prev_x, args.y - args.prev_y):g} m, not more than the"
        note += f" update distance {tracker.update_distance:g} m: no heading, plain square"
        window = compute_window(args.x, args.y, None, s, tracker.config.n, tracker.config.k)
    keys = directory.existing_in(window) if directory else window.keys()
    out = {
        "grid_size": s,
        "n": tracker.config.n,
        "k": tracker.config.k,
        "center_tile": list(window.center),
        "center": [tile_center(window.center[0], s), tile_center(window.center[1], s)],
        "theta_rad": None if math.isnan(window.theta) else window.theta,
        "theta_deg": None if math.isnan(window.theta) else math.degrees(window.theta),
        "sector": window.sector,
        "u_range": list(window.u_range),
        "v_range": list(window.v_range),
        "bounds": {"i_min": window.i_min, "i_max": window.i_max, "j_min": window.j_min, "j_max": window.j_max},
        "tiles_in_window": (window.i_max - window.i_min + 1) * (window.j_max - window.j_min + 1),
        "existing_only": directory is not None,
        "tiles": [{"key": [int(i), int(j)], "file": tile_filename(int(i), int(j), s)} for i, j in keys],
    }
    if note:
        out["note"] = note
    if directory is not None and directory.unparsable:
        out["unparsable_files"] = list(directory.unparsable)
    json.dump(out, sys.stdout, indent=1)
    sys.stdout.write("\n")
    return 0
