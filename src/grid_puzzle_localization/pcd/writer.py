"""Writing PCD files atomically: whole arrays (``write_pcd``) or streamed (``PcdStreamWriter``).

Every write goes to a temporary file in the target's directory that replaces the target only once
complete, so a reader never sees a half-written file and a failure leaves the old file (or none).
"""

from __future__ import annotations

import contextlib
import os
import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd.ascii_codec import encode_ascii
from grid_puzzle_localization.pcd.header import IDENTITY_VIEWPOINT, PcdHeader, header_for
from grid_puzzle_localization.util.atomic import atomic_write
from grid_puzzle_localization.util.pip_only import import_pip_only

_ASCII_BATCH = 200_000
_MAX_POINTS = 10**18  # reserves header room for a point count of up to 19 digits


def packed(points: np.ndarray, header: PcdHeader) -> np.ndarray:
    """``points`` as contiguous packed records of ``header.dtype`` (drops numpy padding/alignment)."""
    if points.dtype == header.dtype:
        return np.ascontiguousarray(points)
    out = np.empty(len(points), dtype=header.dtype)
    for name in header.dtype.names:
        out[name] = points[name]
    return out


def write_pcd(
    path: str | os.PathLike,
    points: np.ndarray,
    encoding: str = "binary",
    viewpoint: tuple[float, ...] = IDENTITY_VIEWPOINT,
) -> PcdHeader:
    """Writes a structured point array as an unorganised PCD (fields and dtypes kept) and returns the
    header written. ``encoding`` is ``binary``, ``binary_compressed`` or ``ascii``."""
    points = np.asarray(points)
    header = header_for(points.dtype, len(points), encoding, path, viewpoint)
    records = packed(points, header)
    with atomic_write(path, "wb", fsync=False) as f:
        f.write(header.text().encode("ascii"))
        if encoding == "binary":
            records.tofile(f)
        elif encoding == "binary_compressed":
            f.write(_compressed(records))
        else:
            for start in range(0, len(records), _ASCII_BATCH):
                f.write(encode_ascii(records[start : start + _ASCII_BATCH]))
    return header


def _compressed(records: np.ndarray) -> bytes:
    """LZF-compressed data section: each field's values for all points, field after field."""
    raw = b"".join(np.ascontiguousarray(records[name]).tobytes() for name in records.dtype.names)
    if not raw:
        return struct.pack("<II", 0, 0)
    # LZF's worst case grows incompressible data by about 1/32; give it that room so it never refuses.
    lzf = import_pip_only("lzf", "python-lzf", "writing a binary_compressed PCD")
    data = lzf.compress(raw, len(raw) + len(raw) // 16 + 64)
    return struct.pack("<II", len(data), len(raw)) + data


class PcdStreamWriter:
    """Writes a binary PCD of unknown final size chunk by chunk::

        with PcdStreamWriter(path, dtype) as w:
            for chunk in chunks:
                w.append(chunk)

    The header's WIDTH and POINTS are fixed when the block exits normally, then the file is renamed
    onto ``path``; on an exception the temporary file is removed and ``path`` is untouched."""

    def __init__(self, path: str | os.PathLike, dtype: np.dtype, viewpoint: tuple[float, ...] = IDENTITY_VIEWPOINT):
        self.path = Path(path)
        self.header = header_for(np.dtype(dtype), 0, "binary", path, viewpoint)
        self.points = 0
        self._reserved = len(header_for(self.header.dtype, _MAX_POINTS, "binary", path, viewpoint).text())
        self._context: contextlib.AbstractContextManager | None = None
        self._file: BinaryIO | None = None

    def __enter__(self) -> PcdStreamWriter:
        self._context = atomic_write(self.path, "wb", fsync=False)
        self._file = self._context.__enter__()
        self._file.write(self.header.text(self._reserved).encode("ascii"))
        return self

    def append(self, chunk: np.ndarray) -> None:
        """Appends records; ``chunk`` must have the same field names (in order) as the writer's dtype."""
        if self._file is None:
            raise RuntimeError("PcdStreamWriter.append outside its with-block")
        if chunk.dtype.names != self.header.dtype.names:
            raise PcdError(
                f"{self.path}: cannot append fields {chunk.dtype.names} to a cloud with fields {self.header.fields}"
            )
        packed(chunk, self.header).tofile(self._file)
        self.points += len(chunk)

    def __exit__(self, exc_type, exc, tb) -> bool:
        assert self._context is not None and self._file is not None
        if exc_type is None:
            final = header_for(self.header.dtype, self.points, "binary", self.path, self.header.viewpoint)
            self._file.seek(0)
            self._file.write(final.text(self._reserved).encode("ascii"))
            self.header = final
        self._file = None
        return bool(self._context.__exit__(exc_type, exc, tb))
