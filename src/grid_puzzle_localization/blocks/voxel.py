"""Voxel-grid downsampling: one point per occupied voxel, at the mean of the points in it.

The grid is anchored at the origin (voxel ``floor(p / v)``), so filtering an already filtered cloud
returns it unchanged up to rounding (each mean lies inside its own voxel) and clouds filtered
separately line up.
"""

from __future__ import annotations

import numpy as np

from grid_puzzle_localization.errors import UserError


def check_voxel(voxel: float) -> float:
    """Returns the voxel edge [m] as a float (0 disables the filter); raises UserError when negative."""
    voxel = float(voxel)
    if not (np.isfinite(voxel) and voxel >= 0.0):
        raise UserError(
            f"voxel size must be >= 0 metres (got {voxel}); e.g. --voxel 0.2, or 0 for distinct points only"
        )
    return voxel


def voxel_downsample(points: np.ndarray, voxel: float) -> np.ndarray:
    """Means of ``points`` ``(N, 3)`` [m] per voxel of edge ``voxel`` [m], as ``(M, 3)`` float64, in
    ascending voxel order. ``voxel == 0`` only keeps each distinct point once (sorted), so overlapping
    scans cut from one map do not pile up copies."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return points
    if voxel == 0.0:
        return np.unique(points, axis=0)
    keys = np.floor(points / voxel).astype(np.int64)
    linear = _linear(keys)
    _, inverse, counts = np.unique(
        linear, return_inverse=True, return_counts=True, axis=0 if linear.ndim == 2 else None
    )
    inverse = inverse.reshape(-1)
    sums = np.stack([np.bincount(inverse, weights=points[:, k], minlength=len(counts)) for k in range(3)], axis=1)
    return sums / counts[:, None]


def _linear(keys: np.ndarray) -> np.ndarray:
    """One int64 per voxel index row, ordered like the rows (x most significant): sorting 1-D keys is
    several times faster than sorting rows. Falls back to the rows when the extent does not fit."""
    low = keys.min(axis=0)
    extent = keys.max(axis=0) - low + 1
    if float(extent[0]) * float(extent[1]) * float(extent[2]) >= 2.0**62:
        return keys  # np.unique on rows: same order, slower
    shifted = keys - low
    return (shifted[:, 0] * extent[1] + shifted[:, 1]) * extent[2] + shifted[:, 2]
