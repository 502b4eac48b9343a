"""Pseudo-scans cut from a prior map along a trajectory: the map points within a planar radius of
each pose (no occlusion). They let Algorithm 1 stitch blocks out of the same prior map the other
modes use, when the mapping run's own scans are not available.

A pseudo-scan is carried as the indices of its points in the map, and blocks as sorted index sets
(:class:`MapSubsets`): overlapping keyframes share points exactly, a candidate is a boolean mask over
the map, and nothing is copied or re-sorted per keyframe. Discs are found through a planar grid of
the map points (:class:`DiscIndex`), which visits only the cells the disc touches.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from grid_puzzle_localization.blocks.keyframes import Scan
from grid_puzzle_localization.blocks.poses import Trajectory
from grid_puzzle_localization.blocks.voxel import check_voxel, voxel_downsample

DEFAULT_SCAN_RADIUS = 30.0  # [m] pseudo-scan range
CELLS_PER_RADIUS = 8  # grid cell edge = radius / CELLS_PER_RADIUS


class DiscIndex:
    """Map points sorted by planar grid cell (row-major in x, then y), so the cells of one x column
    that a disc touches form one contiguous slice of the sorted order."""

    def __init__(self, points: np.ndarray, radius: float) -> None:
        self.radius = float(radius)
        self.cell = self.radius / CELLS_PER_RADIUS
        xy = np.asarray(points[:, :2], dtype=np.float64)
        self.low = xy.min(axis=0) if len(xy) else np.zeros(2)
        cells = np.floor((xy - self.low) / self.cell).astype(np.int64)
        self.shape = (cells.max(axis=0) + 1) if len(xy) else np.ones(2, dtype=np.int64)
        linear = cells[:, 0] * self.shape[1] + cells[:, 1]
        self.order = np.argsort(linear, kind="stable")
        self.xy = xy[self.order]
        # starts[c] is the first sorted position of linear cell c (and of every later cell)
        self.starts = np.searchsorted(linear[self.order], np.arange(self.shape[0] * self.shape[1] + 1))

    def disc(self, centre: np.ndarray) -> np.ndarray:
        """Indices (into the original point order, unordered) of the points within ``radius`` of
        ``centre`` (x, y) [m]."""
        c = (np.asarray(centre[:2], dtype=np.float64) - self.low) / self.cell
        reach = self.radius / self.cell
        x0, x1 = max(0, math.floor(c[0] - reach)), min(int(self.shape[0]) - 1, math.floor(c[0] + reach))
        y0, y1 = max(0, math.floor(c[1] - reach)), min(int(self.shape[1]) - 1, math.floor(c[1] + reach))
        if x0 > x1 or y0 > y1:
            return np.empty(0, dtype=np.int64)
        ny = int(self.shape[1])
        spans = [np.arange(self.starts[x * ny + y0], self.starts[x * ny + y1 + 1]) for x in range(x0, x1 + 1)]
        sorted_positions = np.concatenate(spans)
        d2 = np.sum((self.xy[sorted_positions] - centre[:2]) ** 2, axis=1)
        return self.order[sorted_positions[d2 <= self.radius**2]]


class MapSubsets:
    """:class:`~grid_puzzle_localization.blocks.builder.PointSets` whose members are sorted indices into
    a prior map ``(N, 3)`` [m]. A block's points are the map's own, voxel-filtered when ``voxel > 0``."""

    def __init__(self, map_points: np.ndarray, voxel: float = 0.0) -> None:
        self.map_points = np.asarray(map_points, dtype=np.float64).reshape(-1, 3)
        self.voxel = check_voxel(voxel)

    def start(self) -> np.ndarray:
        return np.zeros(len(self.map_points), dtype=bool)

    def add(self, accumulator: np.ndarray, pose: np.ndarray, payload: np.ndarray) -> np.ndarray:
        accumulator[payload] = True
        return accumulator

    def close(self, accumulator: np.ndarray) -> np.ndarray:
        return np.flatnonzero(accumulator)

    def union(self, members: list[np.ndarray]) -> np.ndarray:
        mask = self.start()
        for m in members:
            mask[m] = True
        return self.close(mask)

    def points(self, members: np.ndarray) -> np.ndarray:
        points = self.map_points[members]
        return voxel_downsample(points, self.voxel) if self.voxel > 0.0 else points


def map_scans(points: np.ndarray, trajectory: Trajectory, radius: float) -> Iterator[Scan]:
    """One pseudo-scan per trajectory pose; its payload (loaded for keyframes only) is the indices of
    the map points ``(N, 3)`` within ``radius`` metres (in x, y) of the pose, for :class:`MapSubsets`."""
    index = DiscIndex(np.asarray(points).reshape(-1, 3), radius)
    for k in range(len(trajectory)):
        pose = trajectory.pose(k)
        yield Scan(float(trajectory.stamps[k]), pose, lambda pose=pose: index.disc(pose[:3, 3]))
