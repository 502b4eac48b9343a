"""The prior map: scans of a separate mapping run, placed at drifted poses, voxel-filtered.

A LiDAR-inertial SLAM map is not exact: every scan sits at the estimated pose, which wanders a few
centimetres around the truth. :func:`drifted` makes that estimate from the true mapping trajectory:
a smooth random translation (sum of sinusoids with periods of 40-300 s) whose horizontal norm peaks at
``DriftBounds.horizontal`` and vertical part at ``DriftBounds.vertical``, and a rotation about the
base (yaw up to ``DriftBounds.yaw``, roll/pitch up to ``DriftBounds.tilt``). A map point at range r
from the sensor is therefore off by at most

    horizontal + vertical + (yaw + 2 tilt) r   (plus range noise and voxel averaging),

which :meth:`DriftBounds.point_bound` returns. :class:`VoxelMap` averages the points in each voxel of
``leaf`` metres (position and intensity centroids), accumulating tile by tile so memory stays bounded
by the number of occupied voxels (28 bytes each).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from grid_puzzle_localization.sim.lidar import Mount
from grid_puzzle_localization.sim.trajectory import RATE, Trajectory, transform
from grid_puzzle_localization.util.iteration import zip_equal

MAP_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
_OFFSET = 1 << 20  # voxel indices are stored biased by this, 21 bits per axis
_TILE_SHIFT = 8  # tiles of 256 x 256 voxels
_FLUSH_POINTS = 2_000_000  # merge pending points into the tiles once this many are waiting


@dataclass(frozen=True)
class DriftBounds:
    """Peak pose error of the mapping run's trajectory estimate: metres and radians."""

    horizontal: float = 0.05
    vertical: float = 0.03
    yaw: float = 3.0e-4
    tilt: float = 2.0e-4

    def point_bound(self, sensor_range: np.ndarray | float) -> np.ndarray | float:
        """Largest displacement [m] of a map point seen at ``sensor_range`` [m] (noise-free)."""
        return self.horizontal + self.vertical + (self.yaw + 2 * self.tilt) * np.asarray(sensor_range)


def _smooth_signal(t: np.ndarray, rng: np.random.Generator, components: int = 4) -> np.ndarray:
    """Random smooth signal in [-1, 1] (peak exactly 1 over ``t``), periods 40-300 s."""
    period = rng.uniform(40.0, 300.0, components)
    phase = rng.uniform(0.0, 2 * np.pi, components)
    weight = rng.uniform(0.3, 1.0, components)
    s = np.sum(weight[:, None] * np.sin(2 * np.pi * t[None, :] / period[:, None] + phase[:, None]), axis=0)
    peak = np.max(np.abs(s))
    return s / peak if peak > 0 else s


def drifted(truth: Trajectory, bounds: DriftBounds, rng: np.random.Generator) -> Trajectory:
    """The SLAM estimate of ``truth``: smooth translation and rotation errors within ``bounds``."""
    t = np.arange(len(truth.position)) / RATE
    dx, dy = _smooth_signal(t, rng), _smooth_signal(t, rng)
    horizontal = np.hypot(dx, dy)
    scale = bounds.horizontal / max(float(horizontal.max()), 1e-12)
    dp = np.stack([dx * scale, dy * scale, bounds.vertical * _smooth_signal(t, rng)], axis=1)
    angles = np.stack(
        [
            bounds.tilt * _smooth_signal(t, rng),
            bounds.tilt * _smooth_signal(t, rng),
            bounds.yaw * _smooth_signal(t, rng),
        ],
        axis=1,
    )
    # Each error angle stays within its bound because the small rotations are applied as one rotation vector.
    dq = Rotation.from_rotvec(angles)
    quat = (dq * Rotation.from_quat(truth.quat)).as_quat()
    flips = np.concatenate([[1.0], np.sign(np.sum(quat[1:] * quat[:-1], axis=1))])
    quat *= np.cumprod(np.where(flips == 0, 1.0, flips))[:, None]
    return Trajectory(truth.position + dp, quat, truth.route)


def to_map(estimate: Trajectory, mount: Mount, t_start: float, points: np.ndarray) -> np.ndarray:
    """Map-frame positions (n, 3) of lidar-frame ``points`` (fields x y z time) placed at the estimated
    pose of each point's time (a deskewed SLAM scan)."""
    pos, rot = estimate.frames(t_start + points["time"].astype(np.float64))
    local = np.stack([points["x"], points["y"], points["z"]]).astype(np.float64)
    return transform(rot, mount.rotation @ local + mount.translation[:, None], pos).T


class VoxelMap:
    """Centroid voxel filter with bounded memory: add point batches, then iterate the result in tiles."""

    def __init__(self, leaf: float) -> None:
        self.leaf = float(leaf)
        self._tiles: dict[int, tuple[np.ndarray, ...]] = {}
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._pending_points = 0

    def add(self, xyz: np.ndarray, intensity: np.ndarray) -> None:
        self._pending.append((np.asarray(xyz, dtype=np.float64), np.asarray(intensity, dtype=np.float64)))
        self._pending_points += len(xyz)
        if self._pending_points >= _FLUSH_POINTS:
            self._flush()

    @property
    def voxel_count(self) -> int:
        self._flush()
        return sum(len(v[0]) for v in self._tiles.values())

    def _flush(self) -> None:
        if not self._pending:
            return
        xyz = np.concatenate([p[0] for p in self._pending])
        inten = np.concatenate([p[1] for p in self._pending])
        self._pending, self._pending_points = [], 0
        idx = np.floor(xyz / self.leaf).astype(np.int64)
        offset = xyz - idx * self.leaf
        key = ((idx[:, 0] + _OFFSET) << 42) | ((idx[:, 1] + _OFFSET) << 21) | (idx[:, 2] + _OFFSET)
        # Reduce the batch to per-voxel sums first (many points share a voxel), then merge tile by tile.
        key, inv = np.unique(key, return_inverse=True)
        count = np.bincount(inv).astype(np.float64)
        sums = np.stack([np.bincount(inv, weights=offset[:, j]) for j in range(3)], axis=1)
        sum_i = np.bincount(inv, weights=inten)
        mask = (1 << 21) - 1
        tile = (((key >> 42) & mask) >> _TILE_SHIFT) << 32 | (((key >> 21) & mask) >> _TILE_SHIFT)
        order = np.argsort(tile, kind="stable")
        tile, key, sums, sum_i, count = tile[order], key[order], sums[order], sum_i[order], count[order]
        starts = np.flatnonzero(np.concatenate([[True], tile[1:] != tile[:-1]]))
        ends = np.append(starts[1:], len(tile))
        for a, b in zip_equal(starts, ends):
            self._merge(int(tile[a]), key[a:b], sums[a:b], sum_i[a:b], count[a:b])

    def _merge(self, tile: int, key: np.ndarray, sums: np.ndarray, sum_i: np.ndarray, count: np.ndarray) -> None:
        """Adds per-voxel sums (``key`` sorted and unique) to a tile's running means."""
        if tile in self._tiles:
            k0, o0, i0, c0 = self._tiles[tile]
            c0 = c0.astype(np.float64)
            key = np.concatenate([k0, key])
            sums = np.concatenate([o0.astype(np.float64) * c0[:, None], sums])
            sum_i = np.concatenate([i0.astype(np.float64) * c0, sum_i])
            count = np.concatenate([c0, count])
            key, inv = np.unique(key, return_inverse=True)
            sums = np.stack([np.bincount(inv, weights=sums[:, j]) for j in range(3)], axis=1)
            sum_i = np.bincount(inv, weights=sum_i)
            count = np.bincount(inv, weights=count)
        mean = (sums / count[:, None]).astype(np.float32)
        self._tiles[tile] = (key, mean, (sum_i / count).astype(np.float32), count.astype(np.uint32))

    def chunks(self) -> Iterator[np.ndarray]:
        """The filtered map (MAP_DTYPE), one tile per chunk, tiles and voxels in a fixed order."""
        self._flush()
        mask = (1 << 21) - 1
        for tile in sorted(self._tiles):
            key, mean, mean_i, _ = self._tiles[tile]
            idx = np.stack([(key >> 42) & mask, (key >> 21) & mask, key & mask], axis=1) - _OFFSET
            xyz = idx * self.leaf + mean.astype(np.float64)
            out = np.empty(len(key), dtype=MAP_DTYPE)
            out["x"], out["y"], out["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
            out["intensity"] = mean_i
            yield out
