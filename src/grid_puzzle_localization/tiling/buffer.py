"""Per-tile point buffers under a memory budget, spilled to per-tile files on disk when full.

Chunks arrive already sorted by tile (grouping.group_chunk). They stay in memory as raw record bytes
until their total passes the budget; then every tile's points are appended to the tile's spill file
and memory is freed. At the end each tile is its spill file (if any) followed by its buffered
points, which keeps input order. Only per-tile statistics (count, bounds) persist across spills.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grid_puzzle_localization.tiling.grouping import GROUP_DTYPE, merge_stats, tile_spans

_IOV_MAX = 1024


@dataclass(slots=True)
class TileData:
    """Where one tile's points are: ``spill`` file (or None) then ``parts`` (record bytes), in order."""

    i: int
    j: int
    points: int
    bounds_min: list[float]  # x, y, z [m]
    bounds_max: list[float]
    spill: Path | None
    parts: list[np.ndarray]


class TileBuffer:
    def __init__(self, record_bytes: int, limit_bytes: int, spill_dir: Path):
        self.record_bytes = record_bytes
        self.limit_bytes = limit_bytes
        self.spill_dir = spill_dir
        self.spills = 0
        self._chunks: list[np.ndarray] = []
        self._groups: list[np.ndarray] = []
        self._bytes = 0
        self._stats = np.empty(0, dtype=GROUP_DTYPE)
        self._spilled: set[tuple[int, int]] = set()

    def add(self, sorted_records: np.ndarray, groups: np.ndarray) -> None:
        """Takes a chunk sorted by tile and its group rows (``groups['chunk']`` is overwritten)."""
        groups["chunk"] = len(self._chunks)
        self._chunks.append(sorted_records.view(np.uint8).reshape(-1))
        self._groups.append(groups)
        self._bytes += sorted_records.nbytes
        if self._bytes > self.limit_bytes:
            self.spill()

    def spill(self) -> None:
        """Appends every buffered tile to its spill file and empties the buffer."""
        self.spill_dir.mkdir(exist_ok=True)
        for i, j, parts in self._buffered():
            path = self._spill_path(i, j)
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
            try:
                write_all(fd, parts)
            finally:
                os.close(fd)
            self._spilled.add((i, j))
        self.spills += 1
        self._clear()

    def drain(self) -> Iterator[TileData]:
        """Every tile seen, in (i, j) order. The buffer is empty afterwards."""
        buffered = {(i, j): parts for i, j, parts in self._buffered()}
        self._clear()
        stats = self._stats  # columns to lists once: iterating numpy rows costs microseconds each
        columns = zip(*(stats[name].tolist() for name in ("i", "j", "count", "min", "max")), strict=True)
        for i, j, count, low, high in columns:
            spill = self._spill_path(i, j) if (i, j) in self._spilled else None
            yield TileData(i, j, count, low, high, spill, buffered.get((i, j), []))

    def _buffered(self) -> Iterator[tuple[int, int, list[np.ndarray]]]:
        """(i, j, byte slices in input order) per buffered tile; folds the rows into the statistics."""
        if not self._groups:
            return
        rows = np.concatenate(self._groups)
        self._stats = merge_stats(np.concatenate([self._stats, rows]))
        rows = rows[np.lexsort((rows["chunk"], rows["j"], rows["i"]))]
        chunk = rows["chunk"].tolist()
        begin = (rows["start"] * self.record_bytes).tolist()
        end = ((rows["start"] + rows["count"]) * self.record_bytes).tolist()
        first, last = tile_spans(rows)
        ti, tj = rows["i"][first].tolist(), rows["j"][first].tolist()
        for t, (a, b) in enumerate(zip(first.tolist(), last.tolist(), strict=True)):
            yield ti[t], tj[t], [self._chunks[chunk[r]][begin[r] : end[r]] for r in range(a, b)]

    def _spill_path(self, i: int, j: int) -> Path:
        return self.spill_dir / f"{i}_{j}.bin"

    def _clear(self) -> None:
        self._chunks.clear()
        self._groups.clear()
        self._bytes = 0


def write_all(fd: int, parts: list[bytes | np.ndarray]) -> None:
    """Writes byte buffers to ``fd`` in order, with as few system calls as the kernel allows."""
    for k in range(0, len(parts), _IOV_MAX):
        batch = [memoryview(p).cast("B") for p in parts[k : k + _IOV_MAX]]
        written = os.writev(fd, batch)
        for view in batch:  # finish a partial write (e.g. > 2 GiB) buffer by buffer
            skip = min(written, len(view))
            written -= skip
            view = view[skip:]
            while len(view):
                view = view[os.write(fd, view) :]
