"""`gpm simulate`: generate a LiDAR scenario (bag, ground truth, prior map) without a robot or roscore."""

from __future__ import annotations

import argparse

from grid_puzzle_localization.sim.recording_faults import YawSwing
from grid_puzzle_localization.sim.scenario import ScenarioConfig, generate
from grid_puzzle_localization.sim.sensors import SENSORS
from grid_puzzle_localization.sim.worlds import WORLDS
from grid_puzzle_localization.util.malloc_tuning import reuse_large_buffers


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", help=f"world to simulate: {', '.join(WORLDS)}")
    parser.add_argument(
        "-o", "--output", help="output directory (default: ./<scenario>); must be absent or empty unless --force"
    )
    parser.add_argument(
        "--sensor",
        help=f"LiDAR model: {', '.join(SENSORS)} (default: livox for courtyard, hdl32 for urban and corridor)",
    )
    parser.add_argument(
        "--seed", type=int, default=ScenarioConfig.seed,
        help="random seed; the same seed gives identical files (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--scale", type=float, default=ScenarioConfig.scale,
        help="world extent and route length factor, 0.2-1 (default %(default)s)",
    )  # fmt: skip
    parser.add_argument("--duration", type=float, help="seconds of the localization run (default: the whole route)")
    parser.add_argument(
        "--map-density",
        type=float,
        help="voxel size of the prior map [m] (default 0.05 courtyard, 0.1 urban and corridor)",
    )
    parser.add_argument(
        "--start-time", type=float, default=ScenarioConfig.start_time,
        help="bag time of the first sample [s since epoch] (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--movers",
        type=int,
        help="moving pedestrians/cars in the scans, not in the map "
        "(default 12 x scale, 20 x scale in urban, none in corridor)",
    )
    parser.add_argument(
        "--threads", type=int, default=ScenarioConfig.threads,
        help="sweep worker threads (default %(default)s; same output for any count)",
    )  # fmt: skip
    parser.add_argument(
        "--yaw-swing", type=float, nargs="?", const=YawSwing.swing_deg, metavar="DEG",
        help=f"hand-held: the yaw swings DEG from one side to the other every {YawSwing.half_period_s} s"
        f" (default {YawSwing.swing_deg:g} deg when given without a value)",
    )  # fmt: skip
    parser.add_argument(
        "--scan-rate", type=float, help="scans written per second, dividing the sensor's rate (default: every sweep)"
    )
    parser.add_argument(
        "--gap", type=float, nargs=2, action="append", default=[], metavar=("START", "LENGTH"),
        help="record nothing from START to START+LENGTH seconds into the run (repeatable)",
    )  # fmt: skip
    parser.add_argument("--no-imu", action="store_true", help="record no IMU (a LiDAR-only recording)")
    parser.add_argument("--force", action="store_true", help="replace a non-empty output directory")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    reuse_large_buffers()  # per-sweep numpy temporaries of several MB: no page faults on each reuse
    cfg = ScenarioConfig(
        world=args.scenario,
        sensor=args.sensor,
        seed=args.seed,
        scale=args.scale,
        duration=args.duration,
        map_leaf=args.map_density,
        start_time=args.start_time,
        threads=args.threads,
        movers=args.movers,
        yaw_swing=YawSwing(swing_deg=args.yaw_swing) if args.yaw_swing is not None else None,
        scan_rate=args.scan_rate,
        gaps=tuple(tuple(g) for g in args.gap),
        imu=not args.no_imu,
    )
    summary = generate(cfg, args.output or args.scenario, force=args.force, progress=not args.quiet)
    print(
        f"{summary.directory}: {summary.duration:.1f} s, {summary.sweeps} sweeps, {summary.points} points; "
        f"prior map {summary.map_points} points from {summary.map_sweeps} sweeps"
    )
    return 0
