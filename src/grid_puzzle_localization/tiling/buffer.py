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

from grid_puzzle_localization.tiling.grouping import GROUP_DTYPE, key_positions, merge_stats, tile_spans
from grid_puzzle_localization.util.iteration import zip_equal

_IOV_MAX = 1024


@dataclass
class TileSet:
    """Every tile seen, in (i, j) order: its statistics and where its points are."""

    stats: np.ndarray  # GROUP_DTYPE row per tile: i, j, count, min, max [m] (chunk, start meaningless)
    spills: list[Path | None]  # per tile: its spill file, written first, or None
    row_begin: np.ndarray  # per tile: its buffered rows are rows[row_begin:row_end]
    row_end: np.ndarray
    row_chunk: np.ndarray  # per buffered row: the chunk, and the byte range of the tile's points in it
    row_first: np.ndarray
    row_last: np.ndarray
    chunks: list[np.ndarray]  # buffered chunks, raw bytes

    def __len__(self) -> int:
        return len(self.stats)

    def parts(self) -> Iterator[list[np.ndarray]]:
        """For each tile: its buffered points (after its spill file), as byte slices in input order. The
        row columns become plain lists first, so that a tile costs no numpy call."""
        chunk, first, last = (rows.tolist() for rows in (self.row_chunk, self.row_first, self.row_last))
        chunks = self.chunks
        for b, e in zip_equal(self.row_begin.tolist(), self.row_end.tolist()):
            yield [chunks[chunk[r]][first[r] : last[r]] for r in range(b, e)]


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
        self._spilled: list[tuple[np.ndarray, np.ndarray]] = []  # (i, j) of the tiles spilled so far

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
        rows, first, last = self._fold()
        buffered = self._tile_set(rows[first], [None] * len(first), first, last, rows)
        keys = zip_equal(buffered.stats["i"].tolist(), buffered.stats["j"].tolist())
        for (i, j), parts in zip_equal(keys, buffered.parts()):
            fd = os.open(self._spill_path(i, j), os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
            try:
                write_all(fd, parts)
            finally:
                os.close(fd)
        self._spilled.append((rows["i"][first], rows["j"][first]))
        self.spills += 1
        self._chunks = []
        self._bytes = 0

    def finish(self) -> TileSet:
        """Every tile seen; the buffered chunks move into the result (the buffer is empty afterwards)."""
        rows, first, last = self._fold()
        stats = self._stats
        row_begin = np.zeros(len(stats), dtype=np.int64)
        row_end = np.zeros(len(stats), dtype=np.int64)
        at = key_positions(stats["i"], stats["j"], rows["i"][first], rows["j"][first])
        row_begin[at], row_end[at] = first, last
        spills: list[Path | None] = [None] * len(stats)
        if self._spilled:
            i, j = (np.concatenate(keys) for keys in zip_equal(*self._spilled))
            for t in np.unique(key_positions(stats["i"], stats["j"], i, j)).tolist():
                spills[t] = self._spill_path(int(stats["i"][t]), int(stats["j"][t]))
        tiles = self._tile_set(stats, spills, row_begin, row_end, rows)
        self._chunks = []
        self._bytes = 0
        return tiles

    def _fold(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Takes the buffered group rows, sorted by (i, j, chunk), folding them into the statistics;
        returns them with each buffered tile's first row and one past its last."""
        rows = np.concatenate(self._groups) if self._groups else np.empty(0, dtype=GROUP_DTYPE)
        self._groups.clear()
        self._stats = merge_stats(np.concatenate([self._stats, rows]))
        rows = rows[np.lexsort((rows["chunk"], rows["j"], rows["i"]))]
        first, last = tile_spans(rows)
        return rows, first, last

    def _tile_set(
        self, stats: np.ndarray, spills: list[Path | None], row_begin: np.ndarray, row_end: np.ndarray, rows: np.ndarray
    ) -> TileSet:
        start = rows["start"] * self.record_bytes
        end = start + rows["count"] * self.record_bytes
        return TileSet(stats, spills, row_begin, row_end, rows["chunk"], start, end, self._chunks)

    def _spill_path(self, i: int, j: int) -> Path:
        return self.spill_dir / f"{i}_{j}.bin"


def write_all(fd: int, parts: list[bytes | np.ndarray]) -> None:
    """Writes byte buffers (bytes or 1-D uint8 arrays) to ``fd`` in order, with as few system calls as
    the kernel allows: one writev per 1024 buffers unless it writes less than asked."""
    for k in range(0, len(parts), _IOV_MAX):
        batch = parts[k : k + _IOV_MAX]
        written = os.writev(fd, batch)
        if written == sum(map(len, batch)):
            continue
        for part in batch:  # finish a partial write (e.g. > 2 GiB) buffer by buffer
            view = memoryview(part).cast("B")
            skip = min(written, len(view))
            written -= skip
            view = view[skip:]
            while len(view):
                view = view[os.write(fd, view) :]
