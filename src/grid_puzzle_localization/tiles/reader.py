"""One tile file into a compact numpy array, fast: tiles are small (kilobytes to a few hundred), so the
file is read in one call and decoded from that buffer (``read_pcd`` maps and chunks files of any size,
which costs more than the read for a tile). Other encodings than ``binary`` go through ``read_pcd``.

``xyz_only`` keeps x, y, z as float32: all the NDT localizer reads, 12 bytes a point instead of the
file's record (16 with intensity, more with other fields)."""

from __future__ import annotations

import os

import numpy as np

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd.header import parse_header
from grid_puzzle_localization.pcd.reader import check_binary_size, check_xyz, finite_xyz, read_pcd, xyz_records


def read_tile(path: str | os.PathLike, xyz_only: bool = True) -> np.ndarray:
    """The points of one PCD file whose x, y and z are finite, as an array that owns its memory:
    XYZ_DTYPE when ``xyz_only``, else the file's fields. Raises PcdError (or OSError) naming the file."""
    try:
        with open(path, "rb", buffering=0) as f:
            raw = f.read()
    except FileNotFoundError:
        raise PcdError(f"{path}: no such file; check the path") from None
    header = parse_header(raw, path)
    check_xyz(header, path)
    if header.data == "binary":
        check_binary_size(header, len(raw) - header.header_bytes, path)
        records = np.frombuffer(raw, dtype=header.dtype, count=header.points, offset=header.header_bytes)
        finite = finite_xyz(records)
        if finite is not None:
            records = records[finite]
    else:
        records = read_pcd(path).points  # finite x, y, z already
    if not xyz_only:
        return records.copy()  # not a view that keeps the whole file buffer alive
    return xyz_records(records)
