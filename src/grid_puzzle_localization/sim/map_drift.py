"""How far a simulated prior map is from the world it was cast from, where a localizer uses it.

The mapping run placed each sweep at its drifted pose estimate (sim/mapping.py). A world point q seen from the
mapping pose at time t therefore sits in the map at D(t) q, with D(t) = T_est(t) T_true(t)^-1. A localizer that
matched the map perfectly would be displaced the same way: at position p, by the displacement of the map around p.
:func:`map_displacement` takes it as the mean of D(t) p - p over the mapping sweeps within ``radius`` (horizontal)
of p, the sweeps whose points make up the map there. The drift varies over periods of 40-300 s of the mapping run,
so the radius changes the figure little.

Against the ground truth, a trajectory's error then splits into the map's displacement (no tracker can do better
against the ground truth) and the rest, which is the tracker's: :func:`split_errors`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.evaluation.metrics import ErrorStats
from grid_puzzle_localization.evaluation.trajectory import Trajectory as PoseTrack
from grid_puzzle_localization.sim.trajectory import Trajectory

SWEEP_RATE = 10.0  # [Hz] mapping poses sampled for the displacement (the sweeps of the mapping run)
DEFAULT_RADIUS = 25.0  # [m]


def map_displacement(
    truth: Trajectory, estimate: Trajectory, positions: np.ndarray, radius: float = DEFAULT_RADIUS
) -> np.ndarray:
    """(k, 3) [m]: the map's displacement at each of ``positions`` (k, 3), from the mapping run's ``truth`` and
    its drifted ``estimate``; NaN rows where no mapping sweep is within ``radius``."""
    t = np.arange(0.0, truth.duration, 1.0 / SWEEP_RATE)
    p_true, q_true = truth.interpolate(t)
    p_est, q_est = estimate.interpolate(t)
    drift_rot = (Rotation.from_quat(q_est) * Rotation.from_quat(q_true).inv()).as_matrix()
    positions = np.asarray(positions, dtype=np.float64)
    out = np.full((len(positions), 3), np.nan)
    for i, near in enumerate(cKDTree(p_true[:, :2]).query_ball_point(positions[:, :2], radius)):
        if near:
            rel = positions[i] - p_true[near]
            moved = np.einsum("kij,kj->ki", drift_rot[near], rel) + p_est[near]
            out[i] = moved.mean(axis=0) - positions[i]
    return out


@dataclass(frozen=True)
class SplitErrors:
    """A trajectory's translation error against the ground truth [m], the map's displacement at its poses, and
    what is left of the error once the map's displacement is taken out (the tracker's own)."""

    against_truth: ErrorStats
    map_displacement: ErrorStats
    tracker: ErrorStats


def split_errors(truth_xyz: np.ndarray, estimate: PoseTrack, displacement: np.ndarray) -> SplitErrors:
    """``truth_xyz`` (k, 3): the ground truth at ``estimate``'s times; ``displacement`` (k, 3): the map's there.
    Poses with no displacement (no mapping sweep near) are left out of all three."""
    ok = np.all(np.isfinite(displacement), axis=1)
    error = estimate.xyz[ok] - truth_xyz[ok]
    return SplitErrors(
        ErrorStats.of(np.linalg.norm(error, axis=1)),
        ErrorStats.of(np.linalg.norm(displacement[ok], axis=1)),
        ErrorStats.of(np.linalg.norm(error - displacement[ok], axis=1)),
    )
