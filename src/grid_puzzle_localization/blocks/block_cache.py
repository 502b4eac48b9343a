"""Loading and merging the selected blocks, with memory bounded to the selection plus a small cache."""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from grid_puzzle_localization.blocks.store import BlockIndex
from grid_puzzle_localization.pcd import read_pcd, xyz_records
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE


class BlockCache:
    """Holds the points of the selected blocks and of at most ``cache_blocks`` recently used others."""

    def __init__(self, index: BlockIndex, cache_blocks: int = 0) -> None:
        self.index = index
        self.cache_blocks = max(0, int(cache_blocks))
        self._blocks: OrderedDict[int, np.ndarray] = OrderedDict()  # position -> XYZ_DTYPE records, LRU order
        self.loads = 0  # block files read so far

    def __len__(self) -> int:
        return len(self._blocks)

    def merged(self, selection: tuple[int, ...]) -> np.ndarray:
        """The union of the selected blocks as XYZ_DTYPE records, exact duplicate points (the shared part of
        overlapping fixed-size submaps) kept once. Blocks outside the selection and the cache are freed."""
        parts = [self._get(position) for position in selection]
        for position in list(self._blocks):
            if len(self._blocks) <= len(selection) + self.cache_blocks:
                break
            if position not in selection:
                del self._blocks[position]
        merged = np.concatenate(parts) if parts else np.empty(0, dtype=XYZ_DTYPE)
        if len(parts) > 1:
            merged = np.unique(merged)  # sorts by (x, y, z); the cloud is unordered anyway
        return merged

    def _get(self, position: int) -> np.ndarray:
        if position in self._blocks:
            self._blocks.move_to_end(position)
            return self._blocks[position]
        records = xyz_records(read_pcd(self.index.directory / self.index.blocks[position].file).points)
        self._blocks[position] = records
        self.loads += 1
        return records
