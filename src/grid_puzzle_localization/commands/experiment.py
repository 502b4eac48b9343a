"""`gpm experiment`: the paper's experiment on a scenario directory (from `gpm simulate`) or on your
own bag, map and ground truth. Writes OUT/summary.json, OUT/report.md, OUT/plots/ and one directory
per mode, and prints the tables of the grid puzzle modes against the global map and the paper."""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.storage import storage_figures
from grid_puzzle_localization.experiment.config import (
    FUSIONS,
    PRESETS,
    ExperimentConfig,
    NodeRoles,
    WindowPreset,
)
from grid_puzzle_localization.experiment.maps import check_store_tiles, ensure_blocks, ensure_submaps, ensure_tiles
from grid_puzzle_localization.experiment.modes import DEFAULT_MODES, MODES
from grid_puzzle_localization.experiment.runner import run_experiment
from grid_puzzle_localization.experiment.scenario import read_scenario
from grid_puzzle_localization.experiment.start import START_MODES, StartSetting
from grid_puzzle_localization.report.markdown import printed_tables
from grid_puzzle_localization.tiles.map_store import is_map_store_url


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", nargs="?", help="scenario directory from `gpm simulate` (or use --bag/--map)")
    parser.add_argument("-o", "--out", required=True, help="output directory")
    parser.add_argument("--bag", help="rosbag with points, imu and /tf_static (overrides the scenario's)")
    parser.add_argument("--map", help="global map PCD (overrides the scenario's)")
    parser.add_argument("--ground-truth", help="ground truth TUM file (optional)")
    parser.add_argument(
        "--tiles",
        help="tile directory: reused if it holds the map tiles, else cut (OUT/tiles_s<S>); or the http(s):// URL of"
        " a map store serving them (docs/map_store.md), fetched into the stores' disk cache",
    )
    parser.add_argument(
        "--blocks", help="block map directory from `gpm blocks` (default: stitched from the map along the ground truth)"
    )
    parser.add_argument(
        "--block-size", type=float, default=ExperimentConfig.block_size_m, help="block size S [m] of built block maps"
    )
    parser.add_argument(
        "--submaps",
        help="fixed-size submap directory of the storage comparison (block_map mode): reused if it holds the map's "
        "submaps of side S, else cut (default OUT/submaps_L<S>)",
    )
    parser.add_argument(
        "--modes", nargs="+", default=list(DEFAULT_MODES), choices=MODES,
        help="modes to run: grid_puzzle has the provider nodelet in the localizer's manager, grid_puzzle_rospy the "
        "rospy provider (the paper's setup) (default: %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--preset", default=ExperimentConfig.preset, choices=sorted(PRESETS),
        help="window preset n, k, s (default %(default)s)",
    )  # fmt: skip
    parser.add_argument("--n", type=int, help="window half side [tiles] (overrides the preset)")
    parser.add_argument("--k", type=int, help="window heading extension [tiles] (overrides the preset)")
    parser.add_argument("--grid-size", type=float, help="tile side s [m] (overrides the preset)")
    parser.add_argument(
        "--rate", type=float, default=ExperimentConfig.rate,
        help="bag playback speed, times real time (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--repeats", type=int, default=ExperimentConfig.repeats,
        help="runs of each mode, interleaved (every mode once per round); the report gives the median CPU and "
        "memory over them and their spread (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--interval", type=float, default=ExperimentConfig.monitor_interval_s,
        help="monitor sampling period [s] (default %(default)s)",
    )  # fmt: skip
    parser.add_argument("--ndt-threads", type=int, help="NDT threads, 0 = all cores (default: the localizer's)")
    parser.add_argument(
        "--fusion", choices=FUSIONS,
        help="pose tracking past the NDT match: sliding_window fuses the bag's imu; auto does when it has a specific "
        "force (default: the localizer's, auto)",
    )  # fmt: skip
    parser.add_argument(
        "--initial-pose", type=float, nargs=6, metavar=("X", "Y", "Z", "ROLL", "PITCH", "YAW"),
        help="start pose [m, rad] (default: the first ground-truth pose)",
    )  # fmt: skip
    parser.add_argument(
        "--start", choices=START_MODES, default=StartSetting.mode,
        help="pose: the start pose as initial pose; hint: no pose, a coarse position on initialpose_hint (the start "
        "position offset by --hint-sigma); none: neither, the localizer's global search finds itself "
        "(default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--hint-sigma", type=float, default=StartSetting.hint_sigma_m,
        help="--start hint: standard deviation of the hint's offset in x and in y [m] (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--start-offset", type=float, nargs=2, metavar=("METRES", "DEGREES"),
        help="--start pose: move the start pose this far in a seeded random direction and turn its yaw by this "
        "angle (a wrong start)",
    )  # fmt: skip
    parser.add_argument(
        "--seed", type=int, default=StartSetting.seed,
        help="seed of the offset's direction and of the hint (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--global-search-timeout", type=float,
        help="[s] the localizer's global_localization/auto_start_timeout: search this long after the first scan "
        "without a pose (default: the localizer's, 0 = never, with --start pose; "
        f"{ExperimentConfig.start_search_timeout_s:g} with hint and none)",
    )  # fmt: skip
    parser.add_argument(
        "--settle", type=float, default=ExperimentConfig.settle_s,
        help="wait after start-up and after playback [s] (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--empty-map-seconds", type=float, default=ExperimentConfig.empty_map_s,
        help="seconds of the bag each mode also plays against an empty map, whose RSS the report subtracts "
        "for the map memory; 0 = skip (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--max-time-diff", type=float, default=ExperimentConfig.max_time_diff_s,
        help="pose association tolerance [s] (default %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--localizer-node", default=NodeRoles.localizer,
        help="node whose process runs the NDT (and, in grid_puzzle mode, the provider nodelet)",
    )  # fmt: skip
    parser.add_argument(
        "--provider-node", default=NodeRoles.map_provider,
        help="node of the tile provider (grid_puzzle_rospy: its process; grid_puzzle: its nodelet's loader)",
    )  # fmt: skip
    parser.add_argument("--block-server-node", default=NodeRoles.block_server, help="node of the block map server")


def config_from_args(args: argparse.Namespace) -> ExperimentConfig:
    scenario = read_scenario(args.scenario) if args.scenario else None
    bag = args.bag or (scenario.bag if scenario else None)
    global_map = args.map or (scenario.global_map if scenario else None)
    if bag is None or global_map is None:
        raise UserError("give a scenario directory, or --bag and --map (and optionally --ground-truth)")
    gt = args.ground_truth or (scenario.ground_truth if scenario else None)
    p = PRESETS[args.preset]
    window = WindowPreset(
        args.n if args.n is not None else p.n,
        args.k if args.k is not None else p.k,
        args.grid_size if args.grid_size is not None else p.grid_size_m,
    )
    return ExperimentConfig(
        out_dir=Path(args.out),
        bag=Path(bag),
        global_map=Path(global_map),
        ground_truth=Path(gt) if gt else None,
        tiles=(args.tiles if is_map_store_url(args.tiles) else Path(args.tiles)) if args.tiles else None,
        blocks=Path(args.blocks) if args.blocks else None,
        submaps=Path(args.submaps) if args.submaps else None,
        block_size_m=args.block_size,
        modes=list(dict.fromkeys(args.modes)),
        preset=args.preset,
        window=window,
        rate=args.rate,
        repeats=args.repeats,
        monitor_interval_s=args.interval,
        max_time_diff_s=args.max_time_diff,
        settle_s=args.settle,
        empty_map_s=args.empty_map_seconds,
        ndt_threads=args.ndt_threads,
        fusion=args.fusion,
        initial_pose=list(args.initial_pose) if args.initial_pose else None,
        start=StartSetting(
            mode=args.start,
            hint_sigma_m=args.hint_sigma,
            offset_m=args.start_offset[0] if args.start_offset else 0.0,
            offset_deg=args.start_offset[1] if args.start_offset else 0.0,
            seed=args.seed,
        ),
        global_search_timeout_s=args.global_search_timeout,
        roles=NodeRoles(args.localizer_node, args.provider_node, args.block_server_node),
        scenario_name=scenario.name if scenario else "custom",
    )


def run(args: argparse.Namespace) -> int:
    cfg = config_from_args(args)
    cfg.check()
    cfg.out_dir.mkdir(parents=True, exist_ok=True)
    if isinstance(cfg.tiles, str):  # a map store: its tiles are not on this disk, so no storage figures of them
        tiles = check_store_tiles(cfg.tiles, cfg.window.grid_size_m)
    else:
        tiles = ensure_tiles(
            cfg.global_map, cfg.tiles or cfg.out_dir / f"tiles_s{cfg.window.grid_size_m:g}", cfg.window.grid_size_m
        )
    blocks = submaps = None
    if "block_map" in cfg.modes:
        size = cfg.block_size_m
        blocks = cfg.blocks or ensure_blocks(cfg.global_map, cfg.ground_truth, cfg.out_dir / f"blocks_S{size:g}", size)
        submaps = ensure_submaps(cfg.global_map, cfg.submaps or cfg.out_dir / f"submaps_L{size:g}", size)
        cfg = dataclasses.replace(cfg, blocks=blocks)
    local_tiles = None if isinstance(tiles, str) else tiles
    summary = run_experiment(cfg, tiles, storage_figures(cfg.global_map, local_tiles, blocks, submaps))
    print("\n".join(printed_tables(summary)))
    print(f"\nreport: {cfg.out_dir / 'report.md'}, plots: {cfg.out_dir / 'plots'}/")
    return 0
