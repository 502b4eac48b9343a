"""Synthetic tile directories for tests and benchmarks: random points inside each tile, written with the
package's PCD writer under the tiler's file names."""

from __future__ import annotations

import os
from collections.abc import Iterable

import numpy as np

from grid_puzzle_localization.grid import tile_filename
from grid_puzzle_localization.pcd import write_pcd

POINT_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])


def tile_points(i: int, j: int, s: float, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points uniformly inside tile (i, j) [m], strictly inside so float32 rounding cannot
    push a point into a neighbour."""
    pts = np.empty(count, dtype=POINT_DTYPE)
    margin = s * 1e-3
    pts["x"] = i * s + rng.uniform(margin, s - margin, count)
    pts["y"] = j * s + rng.uniform(margin, s - margin, count)
    pts["z"] = rng.uniform(-1.0, 5.0, count)
    pts["intensity"] = rng.uniform(0.0, 255.0, count)
    return pts


def write_tiles(
    directory: str | os.PathLike, keys: Iterable[tuple[int, int]], s: float, count: int, seed: int = 0
) -> None:
    """Writes one binary PCD of ``count`` points per key into ``directory`` (created if needed)."""
    os.makedirs(directory, exist_ok=True)
    rng = np.random.default_rng(seed)
    for i, j in keys:
        write_pcd(os.path.join(directory, tile_filename(int(i), int(j), s)), tile_points(int(i), int(j), s, count, rng))
