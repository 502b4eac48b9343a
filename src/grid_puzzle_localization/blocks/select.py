"""Nearest-block selection for the block map server: a KD-tree over the block centroids."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from grid_puzzle_localization.errors import UserError


class BlockSelector:
    """Selects the ``num_blocks`` blocks whose centroids lie nearest a position [m] (in x, y only when
    ``planar``). Positions index the centroid rows."""

    def __init__(self, centroids: np.ndarray, num_blocks: int, planar: bool = False) -> None:
        centroids = np.asarray(centroids, dtype=np.float64).reshape(-1, 3)
        if len(centroids) == 0:
            raise UserError("the block index lists no blocks; rebuild it with `gpm blocks` or `gpm submaps`")
        if num_blocks < 1:
            raise UserError(f"num_blocks must be at least 1 (got {num_blocks})")
        self.dims = 2 if planar else 3
        self.k = min(int(num_blocks), len(centroids))
        self._tree = cKDTree(centroids[:, : self.dims])

    def nearest(self, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Indices and distances [m] of the selected blocks, nearest first."""
        query = np.asarray(position, dtype=np.float64).reshape(3)[: self.dims]
        if not np.all(np.isfinite(query)):
            raise ValueError(f"position {query.tolist()} is not finite")
        distances, indices = self._tree.query(query, k=self.k)
        return np.atleast_1d(indices).astype(np.int64), np.atleast_1d(distances)

    def select(self, position: np.ndarray) -> tuple[int, ...]:
        """The selected block indices in ascending order (a selection is a set; this is its key)."""
        return tuple(sorted(int(i) for i in self.nearest(position)[0]))
