"""Cutting a global point-cloud map into grid puzzle tiles (the paper's Algorithm 1), streaming.

Input PCDs are read chunk by chunk; each chunk is sorted by tile (grouping.py, in C++) on one of
``jobs`` threads while the next is read (parallel.map_ahead) and buffered; when the buffer passes its
share of the memory budget it is spilled to per-tile files (buffer.py). At the end every tile is
written once as a binary PCD with the input's fields and types (tile_files.py: one open, writev and
close per tile in C++, by ``jobs`` forked writers taking batches of tiles from a shared queue; each writer
hashes the files of its batch, still in the page cache, into a shared table of SHA-256 digests), while
this process builds the index and writes Autoware's ``pointcloud_map_metadata.yaml`` (index.py) and then
flushes what the writers have written so far, again and again until they finish; ``index.json``, which
holds the digests, is written last. All of it goes into a
temporary directory that is flushed to disk with a last syncfs and then replaces OUT_DIR
(atomic.atomic_directory).

Memory: ``memory_mb`` bounds the working set: about 30 % for decoding and sorting the chunks in
flight, 55 % for buffered points; the rest covers per-tile bookkeeping (about 1 kB per tile, so
proportional to the map's area, not its point count)."""

from __future__ import annotations

import functools
import hashlib
import mmap
import os
import sys
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from grid_puzzle_localization.errors import UserError
from grid_puzzle_localization.pcd import PcdChunks, PcdHeader, iter_pcd_chunks, read_pcd_header
from grid_puzzle_localization.pcd.reader import check_xyz
from grid_puzzle_localization.tiles.grid import check_grid_size, tile_filename
from grid_puzzle_localization.tiling.buffer import TileBuffer, TileSet
from grid_puzzle_localization.tiling.grouping import group_chunk
from grid_puzzle_localization.tiling.index import TileIndex, TileTable, write_autoware_metadata, write_index
from grid_puzzle_localization.tiling.parallel import SharedBatches, in_background, map_ahead
from grid_puzzle_localization.tiling.tile_files import TileFileWriter, TileHeader
from grid_puzzle_localization.util.atomic import atomic_directory, check_output_dir, sync_filesystem
from grid_puzzle_localization.util.iteration import zip_equal

MIN_MEMORY_MB = 1.0
_CHUNK_SHARE = 0.30
_BUFFER_SHARE = 0.55
_CHUNK_OVERHEAD_BYTES = 128  # per point while grouping a chunk: keys, counts and up to a group row each
MIN_TILES_TO_FORK = 2000  # below this a fork costs more than it saves
_DIGEST_BYTES = 32  # SHA-256
_HASH_BLOCK = 1 << 20


@dataclass
class TileConfig:
    grid_size: float  # tile side s [m]
    memory_mb: float = 512.0  # working-set budget [MiB]
    force: bool = False  # replace a non-empty OUT_DIR
    progress: bool = True  # progress bars (only ever shown on a terminal)
    jobs: int = 2  # grouping threads and tile-writing processes (file creation is system-call bound)
    sync: bool = True  # flush the tiles to disk (while writing, and once more) before publishing OUT_DIR


@dataclass
class TileResult:
    index: TileIndex
    spills: int
    seconds: float  # whole run [s]
    seconds_stream: float  # reading, grouping and spilling [s]
    seconds_write: float  # writing tile files, index and metadata [s]
    seconds_sync: float  # flushing to disk and publishing OUT_DIR [s]


def check_inputs(paths: Sequence[Path]) -> list[PcdHeader]:
    """Headers of the inputs; raises PcdError/UserError unless all are readable maps with the same fields."""
    if not paths:
        raise UserError("no input PCD given; pass at least one MAP.pcd")
    headers = [read_pcd_header(p) for p in paths]
    for path, header in zip_equal(paths, headers):
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
    jobs = max(1, config.jobs)
    # Up to `jobs` chunks are grouped at once: they share the chunk part of the budget.
    chunk_points = max(4096, int(budget * _CHUNK_SHARE / jobs / (2 * dtype.itemsize + _CHUNK_OVERHEAD_BYTES)))
    show = config.progress and sys.stderr.isatty()
    with atomic_directory(out_dir, durable=config.sync) as tmp:
        buffer = TileBuffer(dtype.itemsize, int(budget * _BUFFER_SHARE), tmp / ".spill")
        read = _stream(paths, headers, buffer, s, chunk_points, jobs, show)
        streamed = time.perf_counter()
        tiles = buffer.finish()
        header = TileHeader.like(headers[0])
        writer = TileFileWriter(tiles, header, tmp)
        fork = jobs > 1 and len(tiles) >= MIN_TILES_TO_FORK
        writers = jobs if fork else 1
        # Flushing what the writers have written so far, again and again while they run, overlaps the
        # writeback with them (on the other core), so the last syncfs has only the last files to do.
        flush = functools.partial(sync_filesystem, tmp) if config.sync else None
        # MAP_SHARED and anonymous: what the forked writers store here, the parent reads.
        digests = mmap.mmap(-1, max(1, len(tiles) * _DIGEST_BYTES))
        with SharedBatches(len(tiles)) as batches:
            writer_jobs = [
                functools.partial(_write_tile_files, tiles, s, writer, batches, show and k == 0, writers, digests)
                for k in range(writers)
            ]
            with in_background(writer_jobs, fork=fork, while_waiting=flush):
                index = _tile_index(s, headers[0], read, tiles, _tile_names(tiles, s, range(len(tiles))), header)
                write_autoware_metadata(tmp, index)
        raw = bytes(digests)
        digests.close()
        index.table.sha256.extend(raw[k * _DIGEST_BYTES : (k + 1) * _DIGEST_BYTES].hex() for k in range(len(tiles)))
        write_index(tmp, index)
        if buffer.spill_dir.exists():
            buffer.spill_dir.rmdir()
        written = time.perf_counter()
    index.directory = out_dir
    end = time.perf_counter()
    return TileResult(index, buffer.spills, end - start, streamed - start, written - streamed, end - written)


def _stream(
    paths: list[Path],
    headers: list[PcdHeader],
    buffer: TileBuffer,
    s: float,
    chunk_points: int,
    threads: int,
    show: bool,
) -> list[tuple[Path, PcdChunks]]:
    """Reads every input chunk by chunk into the tile buffer, grouping chunks on ``threads`` threads
    (in input order); returns the spent chunk readers (counts)."""
    read = []
    with _progress(show, total=sum(h.points for h in headers), unit="pt", unit_scale=True) as bar:
        for path in paths:
            bar.set_description(f"reading {path.name}")
            chunks = iter_pcd_chunks(path, chunk_points)
            for records, groups in map_ahead(functools.partial(group_chunk, s=s), chunks, threads):
                buffer.add(records, groups)
                bar.update(len(records))
            bar.update(chunks.nonfinite_dropped)
            read.append((path, chunks))
    return read


def _write_tile_files(
    tiles: TileSet,
    s: float,
    writer: TileFileWriter,
    batches: SharedBatches,
    show: bool,
    writers: int,
    digests: mmap.mmap,
) -> None:
    """Creates the tile files of the batches it takes (in a directory that is itself atomic, so files
    are written in place) and stores the SHA-256 of each in ``digests`` (32 bytes at 32 x its number)."""
    dir_fd = os.open(writer.directory, os.O_RDONLY | os.O_DIRECTORY)  # names resolve relative to it
    try:
        share = len(tiles) // writers  # about what each writer takes
        with _progress(show, total=share, desc=f"writing tiles (writer 1 of {writers})", unit="tile") as bar:
            for which in batches:
                names = _tile_names(tiles, s, which)
                writer.write(dir_fd, which, names)
                for k, name in zip_equal(which, names):
                    digests[k * _DIGEST_BYTES : (k + 1) * _DIGEST_BYTES] = _file_sha256(dir_fd, name)
                bar.update(len(which))
    finally:
        os.close(dir_fd)


def _file_sha256(dir_fd: int, name: str) -> bytes:
    """SHA-256 of file ``name`` in the directory open as ``dir_fd`` (just written: read from the page cache)."""
    fd = os.open(name, os.O_RDONLY, dir_fd=dir_fd)
    try:
        digest = hashlib.sha256()
        while block := os.read(fd, _HASH_BLOCK):
            digest.update(block)
        return digest.digest()
    finally:
        os.close(fd)


def _tile_names(tiles: TileSet, s: float, which: range) -> list[str]:
    """File names of tiles ``which``: each writer names its own tiles, the index names them all."""
    stats = tiles.stats[which.start : which.stop]
    return [tile_filename(i, j, s) for i, j in zip_equal(stats["i"].tolist(), stats["j"].tolist())]


def _tile_index(
    s: float,
    header: PcdHeader,
    read: list[tuple[Path, PcdChunks]],
    tiles: TileSet,
    names: list[str],
    tile_header: TileHeader,
) -> TileIndex:
    record = header.record_bytes
    stats = tiles.stats
    counts = stats["count"]
    return TileIndex(
        grid_size=s,
        fields=[
            {"name": n, "size": z, "type": t, "count": c}
            for n, z, t, c in zip_equal(header.fields, header.sizes, header.types, header.counts)
        ],
        record_bytes=record,
        points=int(counts.sum()),
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
        table=TileTable(
            i=stats["i"].tolist(),
            j=stats["j"].tolist(),
            files=names,
            points=counts.tolist(),
            bytes=(tile_header.sizes(counts) + counts * record).tolist(),
            lower=stats["min"].T.tolist(),
            upper=stats["max"].T.tolist(),
            sha256=[],  # filled once the writers have hashed their files
        ),
    )


def _progress(show: bool, iterable: Iterable | None = None, **options):
    """A tqdm bar when ``show``; otherwise ``iterable`` itself, or a bar that shows nothing. tqdm is
    imported only to show a bar: it adds 20 ms to every start-up."""
    if show:
        from tqdm import tqdm

        return tqdm(iterable, **options)
    return iterable if iterable is not None else _NoBar()


class _NoBar:
    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc_info) -> None:
        pass

    def update(self, n: int = 1) -> None:
        pass

    def set_description(self, text: str) -> None:
        pass


def _describe(header: PcdHeader) -> str:
    return " ".join(
        f"{n}:{t}{s}x{c}" for n, s, t, c in zip_equal(header.fields, header.sizes, header.types, header.counts)
    )
