"""`gpm import`: a folder of scans with poses and times as an experiment directory (the layout `gpm simulate`
writes), for `gpm experiment DIR`."""

from __future__ import annotations

import argparse
from pathlib import Path

from grid_puzzle_localization.recordings.experiment_dir import ImportConfig, import_recording
from grid_puzzle_localization.recordings.poses import POSE_FORMATS
from grid_puzzle_localization.recordings.selection import PLAY_CHOICES, Selection


def add_arguments(parser: argparse.ArgumentParser) -> None:
    d, s = ImportConfig(Path(), Path()), Selection()
    parser.add_argument("scans", help="folder of scans in the sensor frame: .pcd files or KITTI .bin files")
    parser.add_argument("poses", help="poses of the scans (base frame in map): KITTI 3x4 lines, TUM, or 4x4 blocks")
    parser.add_argument("-o", "--output", required=True, help="experiment directory to write (absent or empty)")
    parser.add_argument("--times", help="scan times [s], one a line (not needed with TUM poses)")
    parser.add_argument("--pose-format", choices=POSE_FORMATS, help="default: from the numbers on the first line")
    parser.add_argument("--first", type=int, default=s.first, help="first scan used (0-based, default 0)")
    parser.add_argument("--last", type=int, help="last scan used (inclusive, default the last)")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--map-every", type=int, metavar="N", help="every N-th used scan builds the map")
    source.add_argument("--map-range", type=int, nargs=2, metavar=("A", "B"), help="scans A..B build the map")
    source.add_argument("--map", help="use this map PCD (map frame) instead of building one; all scans are played")
    parser.add_argument(
        "--play", choices=PLAY_CHOICES, default=s.play, help="scans played: those not in the map (rest) or all"
    )
    parser.add_argument(
        "--map-voxel", type=float, default=d.map_voxel, help=f"map voxel size [m] (default {d.map_voxel})"
    )
    parser.add_argument(
        "--drop-fraction", type=float, default=s.drop_fraction, help="drop this fraction of the played scans at random"
    )
    parser.add_argument(
        "--gap", type=float, nargs=2, action="append", default=[], metavar=("START", "LENGTH"),
        help="cut the played scans from START to START+LENGTH seconds after the first one (repeatable)",
    )  # fmt: skip
    parser.add_argument("--seed", type=int, default=s.seed, help="seed of --drop-fraction (default 0)")
    parser.add_argument(
        "--extrinsic", type=float, nargs=7, default=d.extrinsic, metavar=("X", "Y", "Z", "QX", "QY", "QZ", "QW"),
        help="base -> lidar transform (default identity: the poses are the sensor's)",
    )  # fmt: skip
    parser.add_argument("--topic", default=d.topic, help=f"points topic in the bag (default {d.topic})")
    parser.add_argument("--map-frame", default=d.map_frame, help=f"default {d.map_frame}")
    parser.add_argument("--base-frame", default=d.base_frame, help=f"default {d.base_frame}")
    parser.add_argument("--lidar-frame", default=d.lidar_frame, help=f"default {d.lidar_frame}")
    parser.add_argument("--force", action="store_true", help="replace a non-empty output directory")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    selection = Selection(
        first=args.first,
        last=args.last,
        map_every=args.map_every,
        map_range=tuple(args.map_range) if args.map_range else None,
        own_map=args.map is not None,
        play=args.play,
        drop_fraction=args.drop_fraction,
        gaps=tuple(tuple(g) for g in args.gap),
        seed=args.seed,
    )
    cfg = ImportConfig(
        scans=Path(args.scans),
        poses=Path(args.poses),
        times=Path(args.times) if args.times else None,
        pose_format=args.pose_format,
        selection=selection,
        map_file=Path(args.map) if args.map else None,
        map_voxel=args.map_voxel,
        extrinsic=tuple(args.extrinsic),
        topic=args.topic,
        map_frame=args.map_frame,
        base_frame=args.base_frame,
        lidar_frame=args.lidar_frame,
    )
    summary = import_recording(cfg, args.output, force=args.force, progress=not args.quiet)
    print(
        f"{summary.directory}: {summary.scans_played} scans played over {summary.duration_s:.1f} s"
        f" ({summary.scans_dropped} dropped, {summary.scans_cut} cut by gaps); map {summary.map_points} points"
        f" from {summary.map_scans} scans"
    )
    return 0
