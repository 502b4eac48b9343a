"""The tile index (``index.json``) and the Autoware metadata (``pointcloud_map_metadata.yaml``).

A tiled map directory holds one binary PCD per non-empty tile, named ``grid.tile_filename(i, j, s)``
(``{cx}_{cy}.pcd``, see the grid module for the number format), plus these two files.

``index.json`` schema (version 1)::

    {
      "format": "grid_puzzle_tiles", "version": 1,
      "grid_size": 2.0,                 # tile side s [m]
      "origin": [0.0, 0.0],             # tiles are anchored here: i = floor((x - ox) / s); always 0, 0
      "fields": [{"name": "x", "size": 4, "type": "F", "count": 1}, ...],   # of every tile and input
      "record_bytes": 12,               # bytes per point
      "points": 5052377,                # total points in all tiles
      "nonfinite_dropped": 0,           # input points with NaN/inf x, y or z (not in any tile)
      "inputs": [                       # POINTS and data bytes as declared; finite points tiled
        {"path": "/abs/map.pcd", "points": 5052377, "finite_points": 5052377, "data_bytes": 60628524}],
      "tiles": [                        # sorted by key
        {"key": [i, j], "stem": "1.0_-3.0", "file": "1.0_-3.0.pcd", "center": [cx, cy],
         "points": 1234,
         "bounds": {"min": [x, y, z], "max": [x, y, z]},   # of the tile's points [m]
         "bytes": 15047, "data_bytes": 14808},              # file size; of which point records
        ...
      ]
    }

``pointcloud_map_metadata.yaml`` is what Autoware's pointcloud_map_loader reads for partial and
differential loading: ``x_resolution`` and ``y_resolution`` (the tile side [m]) and, per file, the
lower-left corner ``[min_x, min_y]`` of its cell.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

from grid_puzzle_localization.atomic import atomic_write
from grid_puzzle_localization.errors import UserError

INDEX_FILE = "index.json"
AUTOWARE_METADATA_FILE = "pointcloud_map_metadata.yaml"
FORMAT = "grid_puzzle_tiles"
VERSION = 1


@dataclass(frozen=True)
class TileEntry:
    key: tuple[int, int]
    stem: str
    file: str
    center: tuple[float, float]
    points: int
    bounds: dict[str, list[float]]
    bytes: int
    data_bytes: int

    def json_text(self) -> str:
        """The entry as compact JSON, formatted directly: building a dict per tile for json.dumps costs
        three times as much on 1e5 tiles. Floats are written with repr, as json does; names need no
        escaping (grid.tile_stem writes digits, '-', '.' and '_' only)."""
        (i, j), (cx, cy), (x0, y0, z0), (x1, y1, z1) = self.key, self.center, self.bounds["min"], self.bounds["max"]
        return (
            f'{{"key":[{i},{j}],"stem":"{self.stem}","file":"{self.file}","center":[{cx!r},{cy!r}],'
            f'"points":{self.points},"bounds":{{"min":[{x0!r},{y0!r},{z0!r}],"max":[{x1!r},{y1!r},{z1!r}]}},'
            f'"bytes":{self.bytes},"data_bytes":{self.data_bytes}}}'
        )


@dataclass
class TileIndex:
    grid_size: float
    fields: list[dict]
    record_bytes: int
    points: int
    nonfinite_dropped: int
    inputs: list[dict]
    tiles: list[TileEntry]
    origin: tuple[float, float] = (0.0, 0.0)
    directory: Path = field(default=Path("."), compare=False)

    def path(self, entry: TileEntry) -> Path:
        return self.directory / entry.file

    def by_key(self) -> dict[tuple[int, int], TileEntry]:
        return {entry.key: entry for entry in self.tiles}

    def json_text(self) -> str:
        head = {
            "format": FORMAT,
            "version": VERSION,
            "grid_size": self.grid_size,
            "origin": list(self.origin),
            "fields": self.fields,
            "record_bytes": self.record_bytes,
            "points": self.points,
            "nonfinite_dropped": self.nonfinite_dropped,
            "inputs": self.inputs,
        }
        tiles = ",".join(t.json_text() for t in self.tiles)
        return f'{json.dumps(head, separators=(",", ":"))[:-1]},"tiles":[{tiles}]}}'


def write_index(directory: Path, index: TileIndex) -> None:
    with atomic_write(directory / INDEX_FILE, "wb", fsync=False) as f:
        f.write(index.json_text().encode())


def write_autoware_metadata(directory: Path, index: TileIndex) -> None:
    s = index.grid_size
    lines = [f"x_resolution: {s!r}", f"y_resolution: {s!r}"]
    lines += [f'"{t.file}": [{t.key[0] * s!r}, {t.key[1] * s!r}]' for t in index.tiles]
    with atomic_write(directory / AUTOWARE_METADATA_FILE, "wb", fsync=False) as f:
        f.write(("\n".join(lines) + "\n").encode())


def load_tile_index(directory: str | os.PathLike) -> TileIndex:
    """Reads ``index.json`` of a tiled map directory. Raises UserError when absent or not an index."""
    directory = Path(directory)
    path = directory / INDEX_FILE
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError:
        raise UserError(f"{path}: no tile index; is {directory} the output of `gpm tile`?") from None
    except (OSError, ValueError) as err:
        raise UserError(f"{path}: not a readable tile index ({err})") from None
    if not isinstance(raw, dict) or raw.get("format") != FORMAT or raw.get("version") != VERSION:
        raise UserError(f"{path}: not a version {VERSION} {FORMAT} index; re-run `gpm tile`")
    try:
        tiles = [TileEntry(**{**t, "key": tuple(t["key"]), "center": tuple(t["center"])}) for t in raw.pop("tiles")]
        for key in ("format", "version"):
            raw.pop(key)
        return TileIndex(**{**raw, "origin": tuple(raw["origin"])}, tiles=tiles, directory=directory)
    except (KeyError, TypeError) as err:
        raise UserError(f"{path}: malformed tile index ({err}); re-run `gpm tile`") from None
