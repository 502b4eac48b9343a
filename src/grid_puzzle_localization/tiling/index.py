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
         "bytes": 15047, "data_bytes": 14808,               # file size; of which point records
         "sha256": "9f86d0...0a08"},                        # SHA-256 of the whole file, lowercase hex
        ...
      ]
    }

``pointcloud_map_metadata.yaml`` is what Autoware's pointcloud_map_loader reads for partial and
differential loading: ``x_resolution`` and ``y_resolution`` (the tile side [m]) and, per file, the
lower-left corner ``[min_x, min_y]`` of its cell.

``sha256`` lets a reader that fetches tiles from elsewhere (the HTTP map store, docs/map_store.md) check
each file before it uses it. Indexes written before it existed have no ``sha256`` and stay readable
(the column is then None); an index either has it on every tile or on none.
"""

from __future__ import annotations

import functools
import itertools
import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.tiles.grid import check_grid_size, tile_center
from grid_puzzle_localization.util.atomic import atomic_write
from grid_puzzle_localization.util.iteration import zip_equal

INDEX_FILE = "index.json"
AUTOWARE_METADATA_FILE = "pointcloud_map_metadata.yaml"
FORMAT = "grid_puzzle_tiles"
VERSION = 1
JSON_BATCH = 1024  # tiles per part of the index text


@dataclass(frozen=True)
class TileEntry:
    """One tile of an index, as a reader of the index sees it."""

    key: tuple[int, int]
    stem: str
    file: str
    center: tuple[float, float]
    points: int
    bounds: dict[str, list[float]]
    bytes: int
    data_bytes: int
    sha256: str | None = None  # of the file, lowercase hex; None in indexes written before checksums


@dataclass(frozen=True)
class TileTable:
    """The tiles of an index as columns, in key order: the tiler fills and formats them for 1e5 tiles
    without a Python object per tile. Centres, stems and data bytes follow from the other columns."""

    i: list[int]
    j: list[int]
    files: list[str]
    points: list[int]
    bytes: list[int]  # file size, header included
    lower: list[list[float]]  # [x, y, z] columns of the tiles' minimum [m]
    upper: list[list[float]]  # [x, y, z] columns of the tiles' maximum [m]
    sha256: list[str] | None = None  # SHA-256 of each file, lowercase hex; None: an index without checksums

    def __len__(self) -> int:
        return len(self.files)

    @classmethod
    def from_json(cls, tiles: list[dict]) -> TileTable:
        """From the parsed ``tiles`` array of an index; KeyError/TypeError when an entry is malformed."""

        def column(end: str, axis: int) -> list[float]:
            return _typed([t["bounds"][end][axis] for t in tiles], (int, float), f"bounds {end}")

        return cls(
            i=_typed([t["key"][0] for t in tiles], int, "key"),
            j=_typed([t["key"][1] for t in tiles], int, "key"),
            files=_typed([t["file"] for t in tiles], str, "file"),
            points=_typed([t["points"] for t in tiles], int, "points"),
            bytes=_typed([t["bytes"] for t in tiles], int, "bytes"),
            lower=[column("min", axis) for axis in range(3)],
            upper=[column("max", axis) for axis in range(3)],
            sha256=_checksums(tiles),
        )

    def rows(self, grid_size: float, record_bytes: int) -> Iterator[tuple]:
        """Per tile, in key order: i, j, stem, file, cx, cy, points, min x y z, max x y z, bytes and
        data bytes (the derived columns: stem, centre, data bytes, computed here), then the checksum
        (None without checksums)."""
        sums = self.sha256 if self.sha256 is not None else itertools.repeat(None, len(self))
        columns = zip_equal(self.i, self.j, self.files, self.points, self.bytes, *self.lower, *self.upper, sums)
        for i, j, f, n, b, x0, y0, z0, x1, y1, z1, digest in columns:
            yield (
                i,
                j,
                f[: -len(".pcd")],
                f,
                tile_center(i, grid_size),
                tile_center(j, grid_size),
                n,
                x0,
                y0,
                z0,
                x1,
                y1,
                z1,
                b,
                n * record_bytes,
                digest,
            )

    def json_parts(self, grid_size: float, record_bytes: int) -> Iterator[bytes]:
        """The tiles as a compact JSON array, in parts of up to JSON_BATCH tiles that join into the whole
        text, so that it is never held whole (the index of 1e6 tiles is hundreds of MB). The text is what
        json.dumps writes (floats as repr; bounds are finite, the tiler drops non-finite points; file names
        need no escaping: grid.tile_stem writes digits, '-', '.' and '_' only), formatted per tile with one
        f-string, several times faster than building the dicts for json.dumps."""
        rows = self.rows(grid_size, record_bytes)
        yield b"["
        for start in range(0, len(self), JSON_BATCH):
            text = ",".join(
                f'{{"key":[{i},{j}],"stem":"{stem}","file":"{f}","center":[{cx!r},{cy!r}],"points":{n},'
                f'"bounds":{{"min":[{x0!r},{y0!r},{z0!r}],"max":[{x1!r},{y1!r},{z1!r}]}},'
                f'"bytes":{b},"data_bytes":{data}{_sha256_member(digest)}}}'
                for i, j, stem, f, cx, cy, n, x0, y0, z0, x1, y1, z1, b, data, digest in itertools.islice(
                    rows, JSON_BATCH
                )
            )
            yield (b"," if start else b"") + text.encode()
        yield b"]"


def _sha256_member(digest: str | None) -> str:
    return "" if digest is None else f',"sha256":"{digest}"'


def _typed(values: list, kind: type | tuple[type, ...], what: str) -> list:
    """``values`` when each is a ``kind`` (JSON true/false are not numbers here), else TypeError."""
    for v in values:
        if not isinstance(v, kind) or isinstance(v, bool):
            raise TypeError(f"tile {what} {v!r} has the wrong type")
    return values


def _checksums(tiles: list[dict]) -> list[str] | None:
    """The ``sha256`` column: None when no tile has one (an index written before checksums); ValueError
    when only some have one, TypeError when one is not 64 lowercase hex digits."""
    sums = [t.get("sha256") for t in tiles]
    if all(d is None for d in sums):
        return None
    if any(d is None for d in sums):
        raise ValueError("some tiles have a sha256 and others have none")
    for d in sums:
        if not (isinstance(d, str) and len(d) == 64 and all(c in "0123456789abcdef" for c in d)):
            raise TypeError(f"tile sha256 {d!r} is not 64 lowercase hex digits")
    return sums


@dataclass
class TileIndex:
    grid_size: float
    fields: list[dict]
    record_bytes: int
    points: int
    nonfinite_dropped: int
    inputs: list[dict]
    table: TileTable
    origin: tuple[float, float] = (0.0, 0.0)
    directory: Path = field(default=Path("."), compare=False)

    @functools.cached_property
    def tiles(self) -> list[TileEntry]:
        """The tiles as entries, in key order (built on first use)."""
        return [
            TileEntry(
                key=(i, j),
                stem=stem,
                file=f,
                center=(cx, cy),
                points=n,
                bounds={"min": [x0, y0, z0], "max": [x1, y1, z1]},
                bytes=b,
                data_bytes=data,
                sha256=digest,
            )
            for i, j, stem, f, cx, cy, n, x0, y0, z0, x1, y1, z1, b, data, digest in self.table.rows(
                self.grid_size, self.record_bytes
            )
        ]

    def path(self, entry: TileEntry) -> Path:
        return self.directory / entry.file

    def json_parts(self) -> Iterator[bytes]:
        """The index as compact JSON, in parts (see TileTable.json_parts)."""
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
        yield f'{json.dumps(head, separators=(",", ":"))[:-1]},"tiles":'.encode()
        yield from self.table.json_parts(self.grid_size, self.record_bytes)
        yield b"}"


def write_index(directory: Path, index: TileIndex) -> None:
    with atomic_write(directory / INDEX_FILE, "wb", fsync=False) as f:
        f.writelines(index.json_parts())


def write_autoware_metadata(directory: Path, index: TileIndex) -> None:
    s, t = index.grid_size, index.table
    lines = [f"x_resolution: {s!r}", f"y_resolution: {s!r}"]
    lines += [f'"{f}": [{i * s!r}, {j * s!r}]' for f, i, j in zip_equal(t.files, t.i, t.j)]
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
    except (OSError, ValueError, RecursionError) as err:  # RecursionError: arrays nested too deep
        raise UserError(f"{path}: not a readable tile index ({err})") from None
    if not isinstance(raw, dict) or raw.get("format") != FORMAT or raw.get("version") != VERSION:
        raise UserError(f"{path}: not a version {VERSION} {FORMAT} index; re-run `gpm tile`")
    try:
        table = TileTable.from_json(raw.pop("tiles"))
        for key in ("format", "version"):
            raw.pop(key)
        _typed([raw["record_bytes"], raw["points"], raw["nonfinite_dropped"]], int, "count")
        grid_size = check_grid_size(raw.pop("grid_size"))
        return TileIndex(
            **{**raw, "origin": tuple(raw["origin"])}, grid_size=grid_size, table=table, directory=directory
        )
    except (KeyError, IndexError, TypeError, ValueError, UserError) as err:
        raise UserError(f"{path}: malformed tile index ({err}); re-run `gpm tile`") from None
