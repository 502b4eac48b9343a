"""A top view of a map for the plots: every k-th point's x and y, at most a bounded number of them, read in
chunks so that a map larger than RAM stays cheap."""

from __future__ import annotations

import os

import numpy as np

from grid_puzzle_localization.pcd.reader import iter_pcd_chunks

MAP_VIEW_POINTS = 200_000  # points drawn at most: a dense enough grey for a map of a few km


def map_top_view(path: str | os.PathLike, max_points: int = MAP_VIEW_POINTS) -> np.ndarray:
    """(N, 2) float32 x, y [m] of every k-th finite point of the PCD map, k chosen so that N <= max_points."""
    chunks = iter_pcd_chunks(path)
    stride = max(1, -(-chunks.header.points // max_points))
    parts, seen = [], 0
    for chunk in chunks:
        picked = chunk[(-seen) % stride :: stride]
        parts.append(np.stack([picked["x"], picked["y"]], axis=1).astype(np.float32))
        seen += len(chunk)
    return np.concatenate(parts) if parts else np.empty((0, 2), np.float32)
