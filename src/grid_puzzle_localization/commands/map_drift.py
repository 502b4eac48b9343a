"""`gpm map-drift`: how much of a trajectory's error on a simulated scenario is the prior map's own drift."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.evaluation.metrics import ErrorStats, interpolated_reference
from grid_puzzle_localization.evaluation.trajectory import read_tum
from grid_puzzle_localization.experiment.config import ExperimentConfig
from grid_puzzle_localization.experiment.scenario import read_scenario
from grid_puzzle_localization.sim.map_drift import DEFAULT_RADIUS, map_displacement, split_errors
from grid_puzzle_localization.sim.scenario import ScenarioConfig, mapping_estimate, runs
from grid_puzzle_localization.sim.worlds import make_world


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", help="scenario directory from `gpm simulate` (its scenario.yaml rebuilds the runs)")
    parser.add_argument("trajectories", nargs="*", type=Path, help="TUM trajectories to split (e.g. an experiment's)")
    parser.add_argument(
        "--radius", type=float, default=DEFAULT_RADIUS,
        help="[m] mapping sweeps within this distance make up the map at a position (default %(default)s)",
    )  # fmt: skip


def _cm(stats: ErrorStats) -> str:
    return f"{100 * stats.rmse:.2f} / {100 * stats.max:.2f}"


def run(args: argparse.Namespace) -> int:
    inputs = read_scenario(args.scenario)
    parameters = inputs.settings.get("parameters")
    if not parameters or inputs.ground_truth is None:
        raise UserError(f"{args.scenario} is not a simulated scenario (no scenario.yaml parameters or ground truth)")
    cfg = ScenarioConfig.from_parameters(parameters).resolved()
    _, mapping = runs(cfg, make_world(cfg.world, cfg.seed, cfg.scale))
    estimate = mapping_estimate(cfg, mapping)
    truth = read_tum(inputs.ground_truth)
    route = truth.xyz[:: max(1, len(truth) // 20000)]
    along = map_displacement(mapping, estimate, route, args.radius)
    along = np.linalg.norm(along[np.all(np.isfinite(along), axis=1)], axis=1)
    print(f"| {args.scenario} | poses | APE RMSE / max [cm] | map's displacement [cm] | the tracker's own [cm] |")
    print("|---|---:|---:|---:|---:|")
    print(f"| the map along the ground truth | {len(along)} | | {_cm(ErrorStats.of(along))} | |")
    for path in args.trajectories:
        track = read_tum(path)
        try:
            at = interpolated_reference(truth, track, ExperimentConfig.max_time_diff_s)
        except UserError as e:
            raise UserError(f"{path}: {e}; is it a run of {args.scenario}?") from None
        track = type(track)(track.t[at.index], track.xyz[at.index], track.quat[at.index])
        split = split_errors(at.xyz, track, map_displacement(mapping, estimate, at.xyz, args.radius))
        print(
            f"| {path} | {split.against_truth.pairs} | {_cm(split.against_truth)} | {_cm(split.map_displacement)} |"
            f" {_cm(split.tracker)} |"
        )
    return 0
