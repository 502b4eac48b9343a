"""Re-checking a tiled map against its input (``gpm tile --verify``).

Conservation is checked without holding either side in memory: both the input's finite points and
all tile points are reduced to an order-independent multiset checksum of their raw record bytes
(a per-record 64-bit hash, mixed non-linearly, summed mod 2**64), so equal checksums mean the same
records bit for bit, each exactly once, up to a 2**-64 chance. Each tile's points are also checked
to lie in the tile's own cell, and each tile file against its index entry.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grid_puzzle_localization.pcd import iter_pcd_chunks, read_pcd_header
from grid_puzzle_localization.tiles.grid import parse_tile_stem, tile_index
from grid_puzzle_localization.tiling.index import load_tile_index

_CHUNK = 1 << 18
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


@dataclass
class VerifyReport:
    tiles: int = 0
    points_in: int = 0  # finite input points
    nonfinite_in: int = 0  # dropped by the tiler, as by any reader
    points_tiles: int = 0
    misplaced_points: int = 0  # tile points outside their tile's cell
    bytes_in_data: int = 0  # record bytes of the finite input points
    bytes_tiles_data: int = 0  # record bytes in all tiles
    bytes_tiles_headers: int = 0  # PCD header bytes of all tiles
    bytes_tiles_total: int = 0  # file sizes of all tiles (data + headers)
    bytes_tiles_disk: int = 0  # allocated on disk (file system blocks)
    checksum_in: int = 0
    checksum_tiles: int = 0
    problems: list[str] = field(default_factory=list)

    @property
    def block_overhead(self) -> int:
        """Bytes the file system allocates beyond the file sizes (block rounding)."""
        return self.bytes_tiles_disk - self.bytes_tiles_total

    @property
    def ok(self) -> bool:
        return not self.problems


def multiset_checksum(chunks: Iterable[np.ndarray]) -> tuple[int, int]:
    """(points, order-independent checksum) of the raw bytes of the records in ``chunks``."""
    total = 0
    points = 0
    weights = None
    for chunk in chunks:
        raw = np.ascontiguousarray(chunk).view(np.uint8).reshape(len(chunk), chunk.dtype.itemsize)
        if weights is None:
            weights = np.random.default_rng(0x6770).integers(1, 2**63, raw.shape[1], dtype=np.uint64) | np.uint64(1)
        for start in range(0, len(raw), _CHUNK):
            h = raw[start : start + _CHUNK].astype(np.uint64) @ weights
            h ^= h >> np.uint64(30)  # splitmix64 finaliser: the sum must not be linear in the bytes
            h *= _MIX1
            h ^= h >> np.uint64(27)
            h *= _MIX2
            h ^= h >> np.uint64(31)
            total = (total + int(h.sum(dtype=np.uint64))) % 2**64
        points += len(chunk)
    return points, total


def _count_misplaced(chunks: Iterable[np.ndarray], key: tuple[int, int], s: float, report: VerifyReport):
    """Passes chunks through, counting points outside tile ``key`` into the report."""
    for chunk in chunks:
        inside = (tile_index(chunk["x"], s) == key[0]) & (tile_index(chunk["y"], s) == key[1])
        report.misplaced_points += int(np.count_nonzero(~inside))
        yield chunk


def verify_tiles(out_dir: str | os.PathLike, inputs: Sequence[str | os.PathLike]) -> VerifyReport:
    """Checks a tiled map against its input PCD(s); problems are listed in the report, not raised."""
    index = load_tile_index(out_dir)
    report = VerifyReport(tiles=len(index.tiles))
    s = index.grid_size
    for path in inputs:
        chunks = iter_pcd_chunks(path)
        n, checksum = multiset_checksum(chunks)
        report.points_in += n
        report.nonfinite_in += chunks.nonfinite_dropped
        report.checksum_in = (report.checksum_in + checksum) % 2**64
        report.bytes_in_data += n * chunks.header.record_bytes
    listed = {entry.file for entry in index.tiles}
    for extra in sorted(p.name for p in Path(out_dir).glob("*.pcd") if p.name not in listed):
        report.problems.append(f"{extra}: tile file not in the index")
    for entry in index.tiles:
        path = index.path(entry)
        header = read_pcd_header(path)
        stat = path.stat()
        report.bytes_tiles_headers += header.header_bytes
        report.bytes_tiles_data += header.data_bytes
        report.bytes_tiles_total += stat.st_size
        report.bytes_tiles_disk += stat.st_blocks * 512
        if (header.points, stat.st_size) != (entry.points, entry.bytes):
            report.problems.append(
                f"{entry.file}: {header.points} points, {stat.st_size} bytes; index says {entry.points}, {entry.bytes}"
            )
        if parse_tile_stem(entry.stem, s) != entry.key:
            report.problems.append(f"{entry.file}: name does not match tile key {entry.key}")
        n, checksum = multiset_checksum(_count_misplaced(iter_pcd_chunks(path), entry.key, s, report))
        report.points_tiles += n
        report.checksum_tiles = (report.checksum_tiles + checksum) % 2**64
    if report.misplaced_points:
        report.problems.append(f"{report.misplaced_points} tile points lie outside their tile's cell")
    if report.points_tiles != report.points_in:
        report.problems.append(f"tiles hold {report.points_tiles} points, the input {report.points_in} finite points")
    if report.bytes_tiles_data != report.bytes_in_data:
        report.problems.append(f"tiles hold {report.bytes_tiles_data} data bytes, the input {report.bytes_in_data}")
    if report.checksum_tiles != report.checksum_in:
        report.problems.append("tile records differ from the input records (checksum mismatch)")
    return report
