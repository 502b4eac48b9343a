"""Writing the tile files of a TileSet: binary PCDs with the input's fields, one open, writev and
close per tile in the package's C++ library (native.py: src/tiling_native/tile_writing.cpp), so a batch of
tiles costs a few Python calls instead of a dozen per tile."""

from __future__ import annotations

import ctypes
import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grid_puzzle_localization.pcd import PcdHeader
from grid_puzzle_localization.tiling import native
from grid_puzzle_localization.tiling.buffer import TileSet

_POWERS_OF_TEN = 10 ** np.arange(19, dtype=np.int64)


@dataclass(frozen=True)
class TileHeader:
    """Binary PCD header of a tile of n points with the input's fields: fixed text around n, which
    appears twice (WIDTH and POINTS). The writer formats each tile's header."""

    before_width: str
    before_points: str
    after_points: str

    @classmethod
    def like(cls, header: PcdHeader) -> TileHeader:
        empty = dataclasses.replace(header, data="binary", width=0, height=1, points=0).text()
        head, rest = empty.split("\nWIDTH 0\n")
        middle, tail = rest.split("\nPOINTS 0\n")
        return cls(f"{head}\nWIDTH ", f"\n{middle}\nPOINTS ", f"\n{tail}")

    def sizes(self, counts: np.ndarray) -> np.ndarray:
        """Header bytes of a tile of n points for each n in ``counts``, without formatting them."""
        digits = np.searchsorted(_POWERS_OF_TEN, np.maximum(counts, 1), side="right")
        return len(self.before_width) + len(self.before_points) + len(self.after_points) + 2 * digits


class TileFileWriter:
    """Creates the files of the tiles of ``tiles`` in ``directory``, in batches of consecutive tiles.
    Built once before the writers fork, so that they share its arrays."""

    def __init__(self, tiles: TileSet, header: TileHeader, directory: Path):
        self.directory = directory
        self._tiles = tiles
        self._counts = np.ascontiguousarray(tiles.stats["count"])
        self._header = [text.encode() for text in (header.before_width, header.before_points, header.after_points)]
        self._row_arrays = [
            np.ascontiguousarray(a, dtype=np.int64)
            for a in (tiles.row_begin, tiles.row_end, tiles.row_chunk, tiles.row_first, tiles.row_last)
        ]
        self._chunk_addresses = np.array([chunk.ctypes.data for chunk in tiles.chunks], dtype=np.uintp)

    def write(self, dir_fd: int, which: range, names: list[str]) -> None:
        """Creates the files ``names`` of tiles ``which`` in the directory, open as ``dir_fd``; raises
        OSError naming the file when one cannot be written (the files before it are complete)."""
        begin, end, chunk, first, last = (a.ctypes.data for a in self._row_arrays)
        offset = which.start * 8  # int64 per tile
        chunks = self._chunk_addresses.ctypes.data
        spills = self._tiles.spills[which.start : which.stop]
        failed_path = ctypes.c_char_p()
        error = native.library().gpm_write_tiles(
            dir_fd,
            len(which),
            native.c_strings(names),
            native.c_strings(["" if spill is None else str(spill) for spill in spills]),
            self._counts.ctypes.data + offset,
            *self._header,
            begin + offset,
            end + offset,
            chunk,
            first,
            last,
            chunks,
            ctypes.byref(failed_path),
        )
        if error:
            raise OSError(error, os.strerror(error), str(self.directory / os.fsdecode(failed_path.value)))
