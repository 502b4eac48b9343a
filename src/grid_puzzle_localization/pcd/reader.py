"""Reading PCD files whole (``read_pcd``) or in chunks (``iter_pcd_chunks``).

``binary`` data is read through a numpy memmap one chunk at a time, so files larger than RAM
stream; ``ascii`` is decoded line batch by line batch; ``binary_compressed`` (LZF over the whole data
section, stored field by field) cannot be streamed and is decompressed once. Points with a NaN or
infinite x, y or z are dropped and counted, never silently.

Like PCL, the reference reader, a file holds POINTS records and whatever follows them is ignored:
some recorders pad the data section (``POINTS 121023`` followed by room for 121,350 records) or
append lines. A data section shorter than POINTS records is refused as truncated.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd.ascii_codec import decode_ascii_lines
from grid_puzzle_localization.pcd.header import PcdHeader, read_pcd_header
from grid_puzzle_localization.util.pip_only import import_pip_only

XYZ = ("x", "y", "z")
XYZ_DTYPE = np.dtype([(name, "<f4") for name in XYZ])  # x, y, z as float32: 12 bytes a point
# LZF's best case: a 3-byte back reference repeats 264 bytes. A data section claiming to decompress to
# more is corrupt, and is refused before anything that size is allocated.
LZF_MAX_EXPANSION = 88


@dataclass
class PcdCloud:
    """A whole PCD file: finite points (structured array, fields and dtypes as in the file)."""

    points: np.ndarray
    header: PcdHeader
    nonfinite_dropped: int


def xyz_array(points: np.ndarray) -> np.ndarray:
    """(N, 3) float64 array of the x, y, z fields of a structured point array [m]."""
    out = np.empty((len(points), 3), dtype=np.float64)
    for k, name in enumerate(XYZ):
        out[:, k] = points[name]
    return out


def xyz_records(points: np.ndarray) -> np.ndarray:
    """x, y, z as XYZ_DTYPE records (float32): the fields of a structured point array, or the columns
    of an (N, 3) array (a view when that is already contiguous float32)."""
    if points.dtype.names:
        out = np.empty(len(points), dtype=XYZ_DTYPE)
        for name in XYZ:
            out[name] = points[name]
        return out
    return np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 3).view(XYZ_DTYPE).reshape(-1)


def finite_xyz(records: np.ndarray) -> np.ndarray | None:
    """Mask of the records whose x, y and z are all finite, or None when they all are. That common case
    costs one sum per axis: a NaN or inf makes the sum NaN or inf (a sum that overflows only sends it
    to the exact test)."""
    with np.errstate(over="ignore", invalid="ignore"):
        if all(np.isfinite(records[name].sum()) for name in XYZ):
            return None
    return np.isfinite(records["x"]) & np.isfinite(records["y"]) & np.isfinite(records["z"])


class PcdChunks:
    """Iterator over the finite points of a PCD file as structured arrays of at most ``chunk_points``
    records; a chunk without NaN/inf points may be a read-only view of the file. ``header`` is known
    at once; ``points_kept`` and ``nonfinite_dropped`` grow while iterating and are final once the
    iterator is exhausted."""

    def __init__(self, path: str | os.PathLike, chunk_points: int = 1_000_000):
        if chunk_points < 1:
            raise ValueError("chunk_points must be at least 1")
        self.path = path
        self.header = read_pcd_header(path)
        check_xyz(self.header, path)
        self.chunk_points = chunk_points
        self.points_kept = 0
        self.nonfinite_dropped = 0
        decoder = {"binary": self._binary, "binary_compressed": self._compressed, "ascii": self._ascii}
        self._blocks = decoder[self.header.data]()

    def __iter__(self) -> PcdChunks:
        return self

    def __next__(self) -> np.ndarray:
        block = next(self._blocks)
        mask = finite_xyz(block)
        kept = np.asarray(block if mask is None else block[mask])  # a plain array, even of a mapping
        self.points_kept += len(kept)
        self.nonfinite_dropped += len(block) - len(kept)
        return kept

    def _binary(self) -> Iterator[np.ndarray]:
        h = self.header
        check_binary_size(h, os.path.getsize(self.path) - h.header_bytes, self.path)
        if h.points == 0:
            return
        for start in range(0, h.points, self.chunk_points):
            # A mapping per chunk: its pages leave the resident set once the chunk is dropped, so a
            # file larger than RAM streams in bounded memory.
            count = min(self.chunk_points, h.points - start)
            offset = h.header_bytes + start * h.record_bytes
            yield np.memmap(self.path, dtype=h.dtype, mode="r", offset=offset, shape=(count,))

    def _compressed(self) -> Iterator[np.ndarray]:
        h = self.header
        records = read_compressed(self.path, h)
        for start in range(0, h.points, self.chunk_points):
            yield records[start : start + self.chunk_points]

    def _ascii(self) -> Iterator[np.ndarray]:
        h = self.header
        with open(self.path, "rb") as f:
            first_line = f.read(h.header_bytes).count(b"\n") + 1
            seen = 0
            while seen < h.points:
                wanted = min(self.chunk_points, h.points - seen)
                lines = [line for line in itertools.islice(f, wanted) if line.strip()]
                if not lines:
                    break
                yield decode_ascii_lines(lines, h.dtype, self.path, first_line + seen)
                seen += len(lines)
        if seen < h.points:
            raise PcdError(f"{self.path}: truncated: POINTS {h.points} but only {seen} data lines")


def read_compressed(path: str | os.PathLike, h: PcdHeader) -> np.ndarray:
    """Decodes a ``binary_compressed`` data section into an array of ``h.dtype`` records."""
    with open(path, "rb") as f:
        f.seek(h.header_bytes)
        sizes = f.read(8)
        if h.data_bytes == 0:
            return np.empty(0, dtype=h.dtype)
        if len(sizes) < 8:
            raise PcdError(f"{path}: truncated: the binary_compressed data section is missing")
        compressed_size, raw_size = struct.unpack("<II", sizes)
        available = os.path.getsize(path) - h.header_bytes - 8
        if compressed_size > available:
            raise PcdError(f"{path}: truncated: {compressed_size} compressed bytes declared, {available} present")
        if raw_size > LZF_MAX_EXPANSION * compressed_size:
            raise PcdError(
                f"{path}: corrupt binary_compressed sizes: {compressed_size} LZF bytes cannot decompress to"
                f" {raw_size}; re-export the file"
            )
        if raw_size != h.data_bytes:
            raise PcdError(
                f"{path}: POINTS {h.points} disagrees with the data: it decompresses to {raw_size} bytes,"
                f" not {h.points} x {h.record_bytes} = {h.data_bytes}"
            )
        payload = f.read(compressed_size)
    if len(payload) < compressed_size:
        raise PcdError(f"{path}: truncated: {compressed_size} compressed bytes declared, {len(payload)} present")
    lzf = import_pip_only("lzf", "python-lzf", f"{path}: a binary_compressed PCD")
    raw = None
    with contextlib.suppress(ValueError):  # python-lzf's "error in compressed data"
        raw = lzf.decompress(payload, raw_size)
    if raw is None or len(raw) != raw_size:
        raise PcdError(f"{path}: corrupt binary_compressed data (LZF does not decompress to {raw_size} bytes)")
    out = np.empty(h.points, dtype=h.dtype)
    offset = 0
    for name in h.dtype.names:
        field = h.dtype.fields[name][0]
        count = h.points * int(np.prod(field.shape))
        column = np.frombuffer(raw, dtype=field.base, count=count, offset=offset)
        out[name] = column.reshape((h.points, *field.shape))
        offset += column.nbytes
    return out


def check_binary_size(h: PcdHeader, available: int, path: str | os.PathLike) -> None:
    """Raises PcdError unless a ``binary`` data section of ``available`` bytes holds POINTS records (bytes
    after them are ignored, as PCL does)."""
    if available < h.data_bytes:
        raise PcdError(
            f"{path}: truncated: POINTS {h.points} x {h.record_bytes} bytes needs {h.data_bytes} bytes of data"
            f" but the file holds {available}; re-export or re-download the file"
        )


def check_xyz(header: PcdHeader, path: str | os.PathLike) -> None:
    """Raises PcdError unless the cloud has scalar x, y and z fields."""
    for name in XYZ:
        if name not in header.fields:
            raise PcdError(f"{path}: no '{name}' field (fields: {' '.join(header.fields)}); a map needs x, y and z")
        if header.counts[header.fields.index(name)] != 1:
            raise PcdError(f"{path}: field '{name}' has COUNT > 1; x, y and z must be single values")


def iter_pcd_chunks(path: str | os.PathLike, chunk_points: int = 1_000_000) -> PcdChunks:
    """Streams the finite points of a PCD file; see PcdChunks for the drop count."""
    return PcdChunks(path, chunk_points)


def read_pcd(path: str | os.PathLike) -> PcdCloud:
    """Reads a whole PCD file (any encoding); NaN/inf-xyz points are dropped and counted."""
    chunks = iter_pcd_chunks(path, chunk_points=1 << 24)
    parts = list(chunks)
    points = np.concatenate(parts) if parts else np.empty(0, dtype=chunks.header.dtype)
    return PcdCloud(points=points, header=chunks.header, nonfinite_dropped=chunks.nonfinite_dropped)
