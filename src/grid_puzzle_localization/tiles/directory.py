"""Which tiles a tile directory holds: from its index file when present, otherwise by scanning the
``<cx>_<cy>.pcd`` names. Keys are kept as one sorted (N, 2) int64 array (no Python object per tile), so
a map of a million tiles costs 16 MB and a window query is two binary searches plus a slice."""

from __future__ import annotations

import array
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.provider.window import Window
from grid_puzzle_localization.tiles.grid import check_grid_size, parse_tile_stem, tile_filename
from grid_puzzle_localization.tiling.index import FORMAT, INDEX_FILE, VERSION


@dataclass(frozen=True)
class TileDirectory:
    """The tiles of one directory. ``keys`` are the (i, j) indices sorted by i, then j."""

    path: Path
    grid_size: float  # s [m]
    keys: np.ndarray
    source: str  # "index" or "scan"
    unparsable: tuple[str, ...] = field(default=())  # *.pcd names that are not tiles of side s

    def tile_path(self, key: tuple[int, int]) -> Path:
        return self.path / tile_filename(key[0], key[1], self.grid_size)

    def existing_in(self, window: Window) -> np.ndarray:
        """The (M, 2) keys of existing tiles inside ``window``."""
        lo = np.searchsorted(self.keys[:, 0], window.i_min, side="left")
        hi = np.searchsorted(self.keys[:, 0], window.i_max, side="right")
        band = self.keys[lo:hi]
        return band[(band[:, 1] >= window.j_min) & (band[:, 1] <= window.j_max)]

    def codes_in(self, window: Window) -> np.ndarray:
        """``existing_in`` as one int64 code per tile (see encode_keys)."""
        return encode_keys(self.existing_in(window))

    @property
    def bounds(self) -> tuple[int, int, int, int]:
        """(i_min, i_max, j_min, j_max) over all tiles."""
        return (
            int(self.keys[:, 0].min()),
            int(self.keys[:, 0].max()),
            int(self.keys[:, 1].min()),
            int(self.keys[:, 1].max()),
        )


def encode_keys(keys: np.ndarray) -> np.ndarray:
    """One int64 per (i, j) row: i * 2^32 + (j mod 2^32), exact for |i|, |j| < 2^31 (s = 0.1 m still
    covers UTM northings). Python ints of these codes are cheap set and dict keys."""
    return (keys[:, 0] << 32) | (keys[:, 1] & 0xFFFFFFFF)


def decode_key(code: int) -> tuple[int, int]:
    j = code & 0xFFFFFFFF
    return code >> 32, j - (1 << 32) if j >= 1 << 31 else j


def sorted_keys(keys: np.ndarray) -> np.ndarray:
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 2)
    return keys[np.lexsort((keys[:, 1], keys[:, 0]))]


def scan_tiles(path: Path, s: float) -> tuple[np.ndarray, tuple[str, ...]]:
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
    return sorted_keys(np.array(keys, dtype=np.int64)), tuple(sorted(bad))


# Streaming scan of index.json (schema: tiling/index.py). A match must be followed by its delimiter
# inside the buffer, so a number cut at a chunk boundary is never taken for a shorter one.
_KEY = re.compile(rb'"key"\s*:\s*\[\s*(-?\d+)\s*,\s*(-?\d+)\s*\]')
_HEADER = re.compile(rb'"(format|version|grid_size)"\s*:\s*("[^"\\]*"|[-+0-9.eE]+)(?=\s*[,}])')
_OVERLAP = 256  # [bytes] kept from the previous chunk: longer than any match


def read_index_keys(path: Path, chunk_bytes: int = 1 << 20) -> tuple[float, np.ndarray]:
    """Grid size [m] and tile keys of a tiler index, read in chunks: memory stays at one chunk plus
    the keys, where ``json.loads`` (or ``tiling.load_tile_index``, which keeps a TileEntry per tile)
    peaks at 30 to 135 MB for a 500 m x 700 m map at s = 2 m. Tile keys are the only ``"key"`` members
    of the schema; the test checks the result against ``load_tile_index``."""
    keys = array.array("q")
    header: dict[str, bytes] = {}
    try:
        with open(path, "rb") as f:
            tail = b""
            while chunk := f.read(chunk_bytes):
                buf = tail + chunk
                consumed = 0
                for m in _KEY.finditer(buf):
                    keys.extend((int(m[1]), int(m[2])))
                    consumed = m.end()
                for m in _HEADER.finditer(buf):
                    header.setdefault(m[1].decode(), m[2])
                tail = buf[max(consumed, len(buf) - _OVERLAP) :]
        if header.get("format") != b'"%s"' % FORMAT.encode() or header.get("version") != str(VERSION).encode():
            raise ValueError(f"not a version {VERSION} {FORMAT} index")
        if "grid_size" not in header:
            raise ValueError("no grid_size")
        s = check_grid_size(float(header["grid_size"]))
    except (OSError, ValueError, OverflowError, UserError) as err:  # OverflowError: a key beyond int64
        raise UserError(f"{path}: not a readable tile index ({err}); re-run `gpm tile`") from None
    return s, sorted_keys(np.frombuffer(keys, dtype=np.int64).copy())


def open_tile_directory(path: str | os.PathLike, grid_size: float | None = None) -> TileDirectory:
    """Opens a tile directory through its index, or by scanning it when there is none. ``grid_size``
    [m] is required without an index and must match the index when both are given. Raises UserError
    when the directory is missing or holds no tiles."""
    path = Path(path)
    if not path.is_dir():
        raise UserError(f"tile directory {path} does not exist; write one with `gpm tile` or fix the path")
    if (path / INDEX_FILE).is_file():
        s, keys = read_index_keys(path / INDEX_FILE)
        if grid_size is not None and not math.isclose(float(grid_size), s, rel_tol=1e-9):
            raise UserError(
                f"grid size {grid_size} m disagrees with {path / INDEX_FILE}, which says {s} m;"
                " leave the grid size unset (0) to use the index's"
            )
        if len(keys) == 0:
            raise UserError(f"tile directory {path}: its index lists no tiles; re-run `gpm tile` on a non-empty map")
        return TileDirectory(path, s, keys, "index")
    if grid_size is None:
        raise UserError(
            f"tile directory {path} has no index file, so the grid size is unknown;"
            " pass it (--grid-size / tiles/grid_size)"
        )
    s = check_grid_size(grid_size)
    keys, bad = scan_tiles(path, s)
    if len(keys) == 0:
        hint = f" ({len(bad)} .pcd files with other names, e.g. {bad[0]})" if bad else ""
        raise UserError(f"tile directory {path} holds no tile files named <cx>_<cy>.pcd for s = {s} m{hint}")
    return TileDirectory(path, s, keys, "scan", bad)
