"""Which tiles a tile directory holds: from its index file when present, otherwise by scanning the
``<cx>_<cy>.pcd`` names. Keys are kept as one sorted array of 64-bit codes (the ``array`` module: no
Python object per tile), so a map of a million tiles costs 8 MB and a window query is two binary searches
per row of tiles. No numpy: the provider node imports this module and stays at rospy's memory floor."""

from __future__ import annotations

import array
import bisect
import functools
import math
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Tuple

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiles.grid import check_grid_size, parse_tile_stem, tile_filename
from grid_puzzle_localization.tiling.index import FORMAT, INDEX_FILE, VERSION

Key = Tuple[int, int]  # typing's: a runtime alias, and Python 3.8 (Noetic) has no tuple[...]
_OFFSET = 1 << 31  # codes hold i + 2^31 and j + 2^31, so they sort as (i, j) do
_LOW = (1 << 32) - 1


def encode_key(i: int, j: int) -> int:
    """One unsigned 64-bit code per tile index, ordered as the (i, j) pairs are (by i, then j). Exact for
    |i|, |j| < 2^31 (s = 0.1 m still covers UTM northings); raises ValueError beyond."""
    if not (-_OFFSET <= i < _OFFSET and -_OFFSET <= j < _OFFSET):
        raise ValueError(f"tile index ({i}, {j}) is beyond +-2^31")
    return ((i + _OFFSET) << 32) | (j + _OFFSET)


def decode_key(code: int) -> Key:
    return (code >> 32) - _OFFSET, (code & _LOW) - _OFFSET


def sorted_codes(keys: Iterable[Key]) -> array.array:
    return array.array("Q", sorted(encode_key(int(i), int(j)) for i, j in keys))


@dataclass(frozen=True)
class TileDirectory:
    """The tiles of one directory. ``codes`` are their encode_key codes, sorted."""

    path: Path
    grid_size: float  # s [m]
    codes: array.array
    source: str  # "index" or "scan"
    unparsable: tuple[str, ...] = field(default=())  # *.pcd names that are not tiles of side s

    def __len__(self) -> int:
        return len(self.codes)

    def tile_path(self, key: Key) -> Path:
        return self.path / tile_filename(key[0], key[1], self.grid_size)

    def codes_in_box(self, i_min: int, i_max: int, j_min: int, j_max: int) -> list[int]:
        """Codes of the existing tiles with i_min <= i <= i_max and j_min <= j <= j_max, sorted."""
        i_min, i_max = max(i_min, self.bounds[0]), min(i_max, self.bounds[1])
        out: list[int] = []
        for i in range(i_min, i_max + 1):
            lo = bisect.bisect_left(self.codes, encode_key(i, max(j_min, -_OFFSET)))
            hi = bisect.bisect_right(self.codes, encode_key(i, min(j_max, _OFFSET - 1)), lo)
            out.extend(self.codes[lo:hi])
        return out

    def codes_in(self, window) -> list[int]:
        """Codes of the existing tiles inside ``window`` (anything with i_min, i_max, j_min, j_max)."""
        return self.codes_in_box(window.i_min, window.i_max, window.j_min, window.j_max)

    def existing_in(self, window) -> list[Key]:
        """The (i, j) keys of existing tiles inside ``window``, sorted."""
        return [decode_key(c) for c in self.codes_in(window)]

    @functools.cached_property
    def bounds(self) -> tuple[int, int, int, int]:
        """(i_min, i_max, j_min, j_max) over all tiles."""
        low = [c & _LOW for c in self.codes]
        return decode_key(self.codes[0])[0], decode_key(self.codes[-1])[0], min(low) - _OFFSET, max(low) - _OFFSET


def scan_tiles(path: Path, s: float) -> tuple[array.array, tuple[str, ...]]:
    """Keys of the ``*.pcd`` files of ``path`` whose names parse as tiles of side ``s``, and the names
    that do not."""
    keys, bad = [], []
    with os.scandir(path) as entries:
        for entry in entries:
            if not entry.name.endswith(".pcd"):
                continue
            try:
                keys.append(parse_tile_stem(entry.name[: -len(".pcd")], s))
            except ValueError:
                bad.append(entry.name)
    return sorted_codes(keys), tuple(sorted(bad))


# Streaming scan of index.json (schema: tiling/index.py). A match must be followed by its delimiter
# inside the buffer, so a number cut at a chunk boundary is never taken for a shorter one.
_KEY = re.compile(rb'"key"\s*:\s*\[\s*(-?\d+)\s*,\s*(-?\d+)\s*\]')
_HEADER = re.compile(rb'"(format|version|grid_size)"\s*:\s*("[^"\\]*"|[-+0-9.eE]+)(?=\s*[,}])')
_OVERLAP = 256  # [bytes] kept from the previous chunk: longer than any match


def read_index_keys(path: Path, chunk_bytes: int = 1 << 20) -> tuple[float, array.array]:
    """Grid size [m] and the sorted codes of the tile keys of a tiler index, read in chunks: memory stays at
    one chunk plus the keys, where ``json.loads`` (or ``tiling.load_tile_index``, which keeps a TileEntry per tile)
    peaks at 30 to 135 MB for a 500 m x 700 m map at s = 2 m. Tile keys are the only ``"key"`` members
    of the schema; the test checks the result against ``load_tile_index``."""
    codes = array.array("Q")
    header: dict[str, bytes] = {}
    try:
        with open(path, "rb") as f:
            tail = b""
            while chunk := f.read(chunk_bytes):
                buf = tail + chunk
                consumed = 0
                for m in _KEY.finditer(buf):
                    codes.append(encode_key(int(m[1]), int(m[2])))
                    consumed = m.end()
                for m in _HEADER.finditer(buf):
                    header.setdefault(m[1].decode(), m[2])
                tail = buf[max(consumed, len(buf) - _OVERLAP) :]
        if header.get("format") != b'"%s"' % FORMAT.encode() or header.get("version") != str(VERSION).encode():
            raise ValueError(f"not a version {VERSION} {FORMAT} index")
        if "grid_size" not in header:
            raise ValueError("no grid_size")
        s = check_grid_size(float(header["grid_size"]))
    except (OSError, ValueError, UserError) as err:  # ValueError: also a key beyond +-2^31
        raise UserError(f"{path}: not a readable tile index ({err}); re-run `gpm tile`") from None
    return s, array.array("Q", sorted(codes))


def open_tile_directory(path: str | os.PathLike, grid_size: float | None = None) -> TileDirectory:
    """Opens a tile directory through its index, or by scanning it when there is none. ``grid_size``
    [m] is required without an index and must match the index when both are given. Raises UserError
    when the directory is missing or holds no tiles."""
    path = Path(path)
    if not path.is_dir():
        raise UserError(f"tile directory {path} does not exist; write one with `gpm tile` or fix the path")
    if (path / INDEX_FILE).is_file():
        s, codes = read_index_keys(path / INDEX_FILE)
        if grid_size is not None and not math.isclose(float(grid_size), s, rel_tol=1e-9):
            raise UserError(
                f"grid size {grid_size} m disagrees with {path / INDEX_FILE}, which says {s} m;"
                " leave the grid size unset (0) to use the index's"
            )
        if len(codes) == 0:
            raise UserError(f"tile directory {path}: its index lists no tiles; re-run `gpm tile` on a non-empty map")
        return TileDirectory(path, s, codes, "index")
    if grid_size is None:
        raise UserError(
            f"tile directory {path} has no index file, so the grid size is unknown;"
            " pass it (--grid-size / tiles/grid_size)"
        )
    s = check_grid_size(grid_size)
    codes, bad = scan_tiles(path, s)
    if len(codes) == 0:
        hint = f" ({len(bad)} .pcd files with other names, e.g. {bad[0]})" if bad else ""
        raise UserError(f"tile directory {path} holds no tile files named <cx>_<cy>.pcd for s = {s} m{hint}")
    return TileDirectory(path, s, codes, "scan", bad)
