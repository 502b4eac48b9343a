"""Cutting a global point-cloud map into grid puzzle tiles (the paper's Algorithm 1), streaming.

Input PCDs are read chunk by chunk; each chunk is sorted by tile (grouping.py) and buffered; when
the buffer passes its share of the memory budget it is spilled to per-tile files (buffer.py). At the
end every tile is written once as a binary PCD with the input's fields and types, together with
``index.json`` and Autoware's ``pointcloud_map_metadata.yaml`` (index.py), into a temporary
directory that replaces OUT_DIR only when complete (atomic.py).

Memory: ``memory_mb`` bounds the working set: about 30 % for decoding and sorting one chunk, 55 %
for buffered points; the rest covers per-tile bookkeeping (about 1 kB per tile, so proportional to
the map's area, not its point count).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from grid_puzzle_localization.atomic import atomic_directory, check_output_dir
from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.grid import check_grid_size, tile_center, tile_filename
from grid_puzzle_localization.pcd import PcdChunks, PcdHeader, iter_pcd_chunks, read_pcd_header
from grid_puzzle_localization.pcd.reader import check_xyz
from grid_puzzle_localization.tiling.buffer import TileBuffer, TileData, write_all
from grid_puzzle_localization.tiling.grouping import group_chunk
from grid_puzzle_localization.tiling.index import TileEntry, TileIndex, write_autoware_metadata, write_index
from grid_puzzle_localization.tiling.parallel import in_background

MIN_MEMORY_MB = 1.0
_CHUNK_SHARE = 0.30
MIN_TILES_TO_FORK = 2000  # below this a fork costs more than it saves
_BUFFER_SHARE = 0.55
_CHUNK_OVERHEAD_BYTES = 128  # float64/int64 temporaries per point while grouping a chunk


@dataclass
class TileConfig:
    grid_size: float  # tile side s [m]
    memory_mb: float = 512.0  # working-set budget [MiB]
    force: bool = False  # replace a non-empty OUT_DIR
    progress: bool = True  # progress bars (only ever shown on a terminal)
    processes: int = 2  # tile-writing processes (1 or 2; file creation is system-call bound)


@dataclass
class TileResult:
    index: TileIndex
    spills: int
    seconds: float  # whole run [s]
    seconds_stream: float  # reading, grouping and spilling [s]
    seconds_write: float  # writing tile files, index and metadata [s]


def check_inputs(paths: Sequence[Path]) -> list[PcdHeader]:
    """Headers of the inputs; raises PcdError/UserError unless all are readable maps with the same fields."""
    if not paths:
        raise UserError("no input PCD given; pass at least one MAP.pcd")
    headers = [read_pcd_header(p) for p in paths]
    for path, header in zip(paths, headers, strict=True):
        check_xyz(header, path)
        if header.dtype != headers[0].dtype:
            raise UserError(
                f"{path}: fields {_describe(header)} differ from {paths[0]}: {_describe(headers[0])};"
                " all pieces of a map must have the same fields, sizes, types and counts"
            )
    return headers


def tile_map(inputs: Sequence[str | os.PathLike], out_dir: str | os.PathLike, config: TileConfig) -> TileResult:
    """Tiles the input PCDs into ``out_dir``; see the module docstring."""
    start = time.perf_counter()
    s = check_grid_size(config.grid_size)
    if not config.memory_mb >= MIN_MEMORY_MB:
        raise UserError(f"--memory-mb must be at least {MIN_MEMORY_MB:g} (got {config.memory_mb:g})")
    paths = [Path(p) for p in inputs]
    out_dir = Path(out_dir)
    headers = check_inputs(paths)
    check_output_dir(out_dir, config.force, paths)
    dtype = headers[0].dtype
    budget = config.memory_mb * 2**20
    chunk_points = max(4096, int(budget * _CHUNK_SHARE / (2 * dtype.itemsize + _CHUNK_OVERHEAD_BYTES)))
    show = config.progress and sys.stderr.isatty()
    with atomic_directory(out_dir) as tmp:
        buffer = TileBuffer(dtype.itemsize, int(budget * _BUFFER_SHARE), tmp / ".spill")
        read = _stream(paths, headers, buffer, s, chunk_points, show)
        streamed = time.perf_counter()
        tiles = list(buffer.drain())
        names = [tile_filename(t.i, t.j, s) for t in tiles]
        texts = _tile_headers(headers[0], tiles)
        fork = config.processes > 1 and len(tiles) >= MIN_TILES_TO_FORK
        with in_background(lambda: _write_tile_files(tiles, names, texts, tmp, show), fork):
            index = _tile_index(s, headers[0], read, tiles, names, texts)
            write_index(tmp, index)
            write_autoware_metadata(tmp, index)
        if buffer.spill_dir.exists():
            buffer.spill_dir.rmdir()
    index.directory = out_dir
    end = time.perf_counter()
    return TileResult(index, buffer.spills, end - start, streamed - start, end - streamed)


def _stream(
    paths: list[Path], headers: list[PcdHeader], buffer: TileBuffer, s: float, chunk_points: int, show: bool
) -> list[tuple[Path, PcdChunks]]:
    """Reads every input chunk by chunk into the tile buffer; returns the spent chunk readers (counts)."""
    read = []
    with tqdm(total=sum(h.points for h in headers), unit="pt", unit_scale=True, disable=not show) as bar:
        for path in paths:
            bar.set_description(f"reading {path.name}")
            chunks = iter_pcd_chunks(path, chunk_points)
            for chunk in chunks:
                buffer.add(*group_chunk(chunk, s))
                bar.update(len(chunk))
            bar.update(chunks.nonfinite_dropped)
            read.append((path, chunks))
    return read


def _tile_headers(header: PcdHeader, tiles: list[TileData]) -> list[bytes]:
    """Binary PCD header of each tile (the input's fields, the tile's point count)."""
    empty = dataclasses.replace(header, data="binary", width=0, height=1, points=0).text()
    return [
        empty.replace("\nWIDTH 0\n", f"\nWIDTH {t.points}\n").replace("\nPOINTS 0\n", f"\nPOINTS {t.points}\n").encode()
        for t in tiles
    ]


def _write_tile_files(tiles: list[TileData], names: list[str], texts: list[bytes], directory: Path, show: bool) -> None:
    """Creates the tile files in ``directory`` (itself atomic, so files are written in place)."""
    dir_fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)  # names resolve relative to it: no path work
    try:
        for tile, name, text in tqdm(
            zip(tiles, names, texts, strict=True), total=len(tiles), desc="writing tiles", unit="tile", disable=not show
        ):
            _write_tile(dir_fd, name, text, tile)
    finally:
        os.close(dir_fd)


def _tile_index(
    s: float,
    header: PcdHeader,
    read: list[tuple[Path, PcdChunks]],
    tiles: list[TileData],
    names: list[str],
    texts: list[bytes],
) -> TileIndex:
    record = header.record_bytes
    return TileIndex(
        grid_size=s,
        fields=[
            {"name": n, "size": z, "type": t, "count": c}
            for n, z, t, c in zip(header.fields, header.sizes, header.types, header.counts, strict=True)
        ],
        record_bytes=record,
        points=sum(t.points for t in tiles),
        nonfinite_dropped=sum(c.nonfinite_dropped for _, c in read),
        inputs=[
            {
                "path": str(p.resolve()),
                "points": c.header.points,
                "finite_points": c.points_kept,
                "data_bytes": c.header.data_bytes,
            }
            for p, c in read
        ],
        tiles=[
            TileEntry(
                key=(t.i, t.j),
                stem=name[: -len(".pcd")],
                file=name,
                center=(tile_center(t.i, s), tile_center(t.j, s)),
                points=t.points,
                bounds={"min": t.bounds_min, "max": t.bounds_max},
                bytes=len(text) + t.points * record,
                data_bytes=t.points * record,
            )
            for t, name, text in zip(tiles, names, texts, strict=True)
        ],
    )


def _write_tile(dir_fd: int, name: str, header: bytes, tile: TileData) -> None:
    fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644, dir_fd=dir_fd)
    try:
        head = [header]
        if tile.spill is not None:
            write_all(fd, head)
            with open(tile.spill, "rb") as src:
                size = os.fstat(src.fileno()).st_size
                offset = 0
                while offset < size:
                    offset += os.sendfile(fd, src.fileno(), offset, size - offset)
            os.unlink(tile.spill)
            head = []
        write_all(fd, head + tile.parts)
    finally:
        os.close(fd)


def _describe(header: PcdHeader) -> str:
    return " ".join(
        f"{n}:{t}{s}x{c}" for n, s, t, c in zip(header.fields, header.sizes, header.types, header.counts, strict=True)
    )
