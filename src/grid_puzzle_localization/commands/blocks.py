"""`gpm blocks`: keyframe-stitched block maps (the block map paper's Algorithm 1) from a bag plus a TUM
trajectory, or from a directory of keyframe PCDs plus a pose file."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable

from grid_puzzle_localization.blocks.builder import BlockConfig, PointSets, VoxelClouds, build_blocks
from grid_puzzle_localization.blocks.keyframes import Scan
from grid_puzzle_localization.blocks.map_scans import DEFAULT_SCAN_RADIUS
from grid_puzzle_localization.blocks.poses import parse_extrinsic, read_tum
from grid_puzzle_localization.blocks.store import write_block_dir
from grid_puzzle_localization.errors import UserError

KIND = "keyframe_blocks"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = BlockConfig()
    parser.add_argument("output", help="block directory to write (numbered PCDs, centroids.txt, index.yaml)")
    source = parser.add_argument_group(
        "input (a bag with --trajectory, --keyframes with --poses, or --map with --trajectory)"
    )
    source.add_argument("--bag", help="ROS bag holding the scans (sensor_msgs/PointCloud2)")
    source.add_argument("--topic", default="points", help="cloud topic in the bag (default: %(default)s)")
    source.add_argument("--trajectory", help="TUM file of the robot pose T_map_robot, interpolated to scan stamps")
    source.add_argument("--keyframes", help="directory of keyframe PCDs (sensor frame), taken in file-name order")
    source.add_argument("--poses", help="TUM file with one robot pose per keyframe PCD, in the same order")
    source.add_argument(
        "--map", help="prior map PCD: keyframes are its points within --scan-radius of the --trajectory poses"
    )
    source.add_argument(
        "--scan-radius",
        type=float,
        default=DEFAULT_SCAN_RADIUS,
        help="pseudo-scan range for --map [m] (default: %(default)s)",
    )
    parser.add_argument(
        "--extrinsic",
        nargs=7,
        type=float,
        metavar=("X", "Y", "Z", "QX", "QY", "QZ", "QW"),
        help="sensor->robot transform T_robot_sensor [m, quaternion]; default: the bag's /tf_static edge "
        "from --robot-frame to the cloud frame, or identity for --keyframes",
    )
    parser.add_argument("--robot-frame", default="base_link", help="robot frame in the bag (default: %(default)s)")
    parser.add_argument(
        "--size", type=float, default=defaults.block_size, help="block size S [m] (default: %(default)s)"
    )
    parser.add_argument(
        "--keyframe-spacing",
        type=float,
        default=defaults.keyframe_spacing,
        help="distance between keyframes [m], 0 keeps every scan (default: %(default)s)",
    )
    parser.add_argument(
        "--voxel", type=float, default=defaults.voxel, help="downsample voxel [m], 0 for none (default: %(default)s)"
    )
    parser.add_argument("--force", action="store_true", help="replace a non-empty output directory")


def _scans(args: argparse.Namespace, config: BlockConfig) -> tuple[Iterable[Scan], PointSets, dict]:
    """(scans, how their points are held, source description) from the arguments."""
    if sum(1 for given in (args.bag, args.keyframes, args.map) if given) > 1:
        raise UserError("give one input: --bag (with --trajectory), --keyframes (with --poses) or --map")
    if args.bag:
        if not args.trajectory:
            raise UserError("--bag needs --trajectory, a TUM file of the robot poses")
        from grid_puzzle_localization.ros.bags.scans import BagScans, bag_extrinsic  # rosbag only when needed

        extrinsic = (
            parse_extrinsic(args.extrinsic) if args.extrinsic else bag_extrinsic(args.bag, args.topic, args.robot_frame)
        )
        scans = BagScans(args.bag, args.topic, read_tum(args.trajectory))
        source = {"bag": str(args.bag), "topic": args.topic, "trajectory": str(args.trajectory)}
        return scans, VoxelClouds(config.voxel, extrinsic), {**source, "extrinsic": extrinsic.tolist()}
    if args.keyframes:
        if not args.poses:
            raise UserError("--keyframes needs --poses, a TUM file with one pose per keyframe PCD")
        from grid_puzzle_localization.blocks.pcd_keyframes import pcd_keyframe_scans

        scans = pcd_keyframe_scans(args.keyframes, args.poses)
        extrinsic = parse_extrinsic(args.extrinsic)
        source = {"keyframes": str(args.keyframes), "poses": str(args.poses), "extrinsic": extrinsic.tolist()}
        return scans, VoxelClouds(config.voxel, extrinsic), source
    if args.map:
        if not args.trajectory:
            raise UserError("--map needs --trajectory, a TUM file of the poses to cut pseudo-scans at")
        if not args.scan_radius > 0.0:
            raise UserError(f"--scan-radius must be > 0 m (got {args.scan_radius})")
        from grid_puzzle_localization.blocks.map_scans import MapSubsets, map_scans
        from grid_puzzle_localization.pcd import read_pcd, xyz_array

        points = xyz_array(read_pcd(args.map).points)
        scans = map_scans(points, read_tum(args.trajectory), args.scan_radius)
        source = {"map": str(args.map), "trajectory": str(args.trajectory), "scan_radius": args.scan_radius}
        return scans, MapSubsets(points, config.voxel), source
    raise UserError(
        "no input: give --bag BAG --trajectory TUM, --keyframes DIR --poses TUM, or --map PCD --trajectory TUM"
    )


def run(args: argparse.Namespace) -> int:
    config = BlockConfig(args.size, args.keyframe_spacing, args.voxel).checked()
    scans, sets, source = _scans(args, config)
    builder = build_blocks(scans, config, sets=sets)
    blocks, report = builder.blocks, builder.report
    if not blocks:
        raise UserError(f"no block was built from {source}: no keyframe with finite points lies inside the poses")
    map_points = builder.map_points()
    params = {
        "block_size": config.block_size,
        "keyframe_spacing": config.keyframe_spacing,
        "voxel": config.voxel,
        **source,
    }
    index = write_block_dir(
        args.output,
        ((b.points, b.centroid, {"keyframes": b.keyframes}) for b in blocks),
        KIND,
        params,
        map_points,
        force=args.force,
    )
    stored = sum(b.points for b in index.blocks)
    skipped = getattr(scans, "skipped", 0)
    print(
        f"gpm blocks: {len(index.blocks)} blocks in {args.output} from {report.keyframes} keyframes, "
        f"{report.candidates} candidates ({report.actions}); {stored} points stored, map {map_points} points, "
        f"overlap factor {stored / map_points:.3f}; {sum(b.bytes for b in index.blocks)} bytes"
        + (f"; {skipped} scans outside the trajectory skipped" if skipped else ""),
        file=sys.stderr,
    )
    return 0
