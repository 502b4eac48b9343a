"""Storage overhead of the map representations: bytes, files, overlap factor, mean bytes per file.

Every row counts the ``*.pcd`` files of its input (file sizes on disk, point counts from the PCD
headers, so nothing is loaded). The overlap factor is stored points / map points: the points the
representation keeps on disk over the points of the map it represents. Tiles and fixed-size submaps
are cut from the global map, so their map is the global map; keyframe-stitched blocks are built
from scans, so their map is the union of the blocks (one point per voxel, ``map_points`` in their
index). A partition scores 1; each duplicated point adds to it.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path

from grid_puzzle_localization.blocks.store import INDEX_FILE, read_block_index
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import read_pcd_header


@dataclass(frozen=True)
class StorageRow:
    name: str
    files: int
    bytes: int
    stored_points: int
    map_points: int

    @property
    def overlap_factor(self) -> float:
        return self.stored_points / self.map_points if self.map_points else float("nan")

    @property
    def mean_bytes_per_file(self) -> float:
        return self.bytes / self.files if self.files else float("nan")

    def as_dict(self) -> dict[str, object]:
        return {**asdict(self), "overlap_factor": self.overlap_factor, "mean_bytes_per_file": self.mean_bytes_per_file}


def pcd_files(path: str | os.PathLike) -> list[Path]:
    """The PCD file itself, or the ``*.pcd`` files of a directory (sorted)."""
    path = Path(path)
    if path.is_file():
        return [path]
    if path.is_dir():
        return sorted(path.glob("*.pcd"))
    raise UserError(f"{path} is neither a PCD file nor a directory; check the path")


def storage_row(name: str, files: Iterable[Path], map_points: int) -> StorageRow:
    files = list(files)
    return StorageRow(
        name=name,
        files=len(files),
        bytes=sum(f.stat().st_size for f in files),
        stored_points=sum(read_pcd_header(f).points for f in files),
        map_points=int(map_points),
    )


def storage_table(
    global_map: str | os.PathLike,
    tiles: str | os.PathLike | None = None,
    blocks: str | os.PathLike | None = None,
    submaps: str | os.PathLike | None = None,
) -> list[StorageRow]:
    """Rows for the global map, grid puzzle tiles, keyframe-stitched blocks and fixed-size submaps
    (in that order; a representation given as None is left out)."""
    map_points = read_pcd_header(global_map).points
    rows = [storage_row("global map", [Path(global_map)], map_points)]
    if tiles is not None:
        rows.append(storage_row("grid puzzle tiles", pcd_files(tiles), map_points))
    if blocks is not None:
        if not (Path(blocks) / INDEX_FILE).is_file():
            raise UserError(f"{blocks} has no {INDEX_FILE}; give a directory written by `gpm blocks`")
        rows.append(storage_row("keyframe-stitched blocks", pcd_files(blocks), read_block_index(blocks).map_points))
    if submaps is not None:
        rows.append(storage_row("fixed-size submaps", pcd_files(submaps), map_points))
    return rows


def markdown_table(rows: list[StorageRow]) -> str:
    lines = [
        "| map | files | bytes | stored points | map points | overlap factor | mean bytes per file |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    lines += [
        f"| {r.name} | {r.files} | {r.bytes} | {r.stored_points} | {r.map_points} | {r.overlap_factor:.3f} "
        f"| {r.mean_bytes_per_file:.0f} |"
        for r in rows
    ]
    return "\n".join(lines) + "\n"
