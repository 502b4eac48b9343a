"""Fixed-size overlapping submaps: the "traditional submap" of the grid puzzle paper's Fig. 1.

Squares of side ``L`` [m] are laid out with stride ``s = L (1 - o)`` for an overlap ratio ``o`` in
[0, 1), anchored at the map origin: square ``(i, j)`` covers ``[i s, i s + L) x [j s, j s + L)`` in x
and y (all heights). A point lies in every square that covers it, ``L / s`` squares per axis on
average, so the cut stores about ``1 / (1 - o)^2`` times the map's points. Only non-empty squares
are kept.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.util.iteration import zip_equal


@dataclass(frozen=True)
class SubmapConfig:
    side: float = 50.0  # L [m]
    overlap: float = 0.5  # o: fraction of L shared by neighbouring squares, in [0, 1)

    @property
    def stride(self) -> float:
        """Distance between neighbouring square origins [m]: L (1 - o)."""
        return self.side * (1.0 - self.overlap)

    def checked(self) -> SubmapConfig:
        if not (math.isfinite(self.side) and self.side > 0.0):
            raise UserError(f"submap side must be a positive number of metres (got {self.side}); e.g. --side 50")
        if not (math.isfinite(self.overlap) and 0.0 <= self.overlap < 1.0):
            raise UserError(f"overlap ratio must lie in [0, 1) (got {self.overlap}); e.g. --overlap 0.5")
        return self


def cut_submaps(points: np.ndarray, config: SubmapConfig) -> Iterator[tuple[tuple[int, int], np.ndarray]]:
    """Yields ``((i, j), points)`` for each non-empty square in ascending (i, j) order; ``points``
    ``(N, 3)`` [m] is the map. Memory: one int per stored point, about ``N / (1 - o)^2``."""
    config = config.checked()
    s, side = config.stride, config.side
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    base = np.floor(points[:, :2] / s).astype(np.int64)  # the square with the largest index covering each point
    reach = math.ceil(side / s)  # squares behind it that may still cover the point, per axis
    keys, members = [], []
    for a in range(reach):
        for b in range(reach):
            cell = base - (a, b)
            inside = np.all(points[:, :2] - cell * s < side, axis=1)
            keys.append(cell[inside])
            members.append(np.flatnonzero(inside))
    cells = np.concatenate(keys)
    rows = np.concatenate(members)
    order = np.lexsort((rows, cells[:, 1], cells[:, 0]))
    cells, rows = cells[order], rows[order]
    starts = np.flatnonzero(np.any(np.diff(cells, axis=0) != 0, axis=1)) + 1
    for group_cells, group_rows in zip_equal(np.split(cells, starts), np.split(rows, starts)):
        if len(group_rows):
            yield (int(group_cells[0, 0]), int(group_cells[0, 1])), points[group_rows]
