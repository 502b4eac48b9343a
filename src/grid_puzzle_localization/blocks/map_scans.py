"""Pseudo-scans cut from a prior map along a trajectory: the map points within a planar radius of
each pose, in the robot frame (no occlusion). They let Algorithm 1 stitch blocks out of the same
prior map the other modes use, when the mapping run's own scans are not available."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from scipy.spatial import cKDTree

from grid_puzzle_localization.blocks.keyframes import Scan
from grid_puzzle_localization.blocks.poses import Trajectory

DEFAULT_SCAN_RADIUS = 30.0  # [m] pseudo-scan range


def map_scans(points: np.ndarray, trajectory: Trajectory, radius: float) -> Iterator[Scan]:
    """One scan per trajectory pose; its points (loaded for keyframes only) are the map points
    ``(N, 3)`` [m] within ``radius`` metres (in x, y) of the pose, expressed in the robot frame."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tree = cKDTree(points[:, :2])

    def load(pose: np.ndarray) -> np.ndarray:
        near = points[tree.query_ball_point(pose[:2, 3], radius)]
        return (near - pose[:3, 3]) @ pose[:3, :3]  # R^T (p - t) for row vectors

    for k in range(len(trajectory)):
        pose = trajectory.pose(k)
        yield Scan(float(trajectory.stamps[k]), pose, lambda pose=pose: load(pose))
