"""`gpm storage`: storage overhead table of a global map and the representations made from it."""

from __future__ import annotations

import argparse
import json

from grid_puzzle_localization.blocks.storage import markdown_table, storage_table


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", help="global map PCD")
    parser.add_argument("--tiles", help="directory of grid puzzle tiles (gpm tile)")
    parser.add_argument("--blocks", help="directory of keyframe-stitched blocks (gpm blocks)")
    parser.add_argument("--submaps", help="directory of fixed-size overlapping submaps (gpm submaps)")
    parser.add_argument("--json", action="store_true", help="print JSON rows instead of a Markdown table")


def run(args: argparse.Namespace) -> int:
    rows = storage_table(args.map, args.tiles, args.blocks, args.submaps)
    print(json.dumps([r.as_dict() for r in rows], indent=2) if args.json else markdown_table(rows), end="\n")
    return 0
