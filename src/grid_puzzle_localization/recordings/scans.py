"""Scan files of a recording: PCD (any encoding, fields as in the file) or KITTI ``.bin`` (float32 x y z
intensity records), in the sensor frame, taken in natural file-name order (``2.pcd`` before ``10.pcd``)."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from grid_puzzle_localization.errors import PcdError, UserError
from grid_puzzle_localization.pcd import read_pcd

SCAN_SUFFIXES = (".pcd", ".bin")
KITTI_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])


def natural_key(path: Path) -> list[tuple]:
    """Sort key of a file name with its digit runs compared as numbers."""
    return [(0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.split(r"(\d+)", path.name)]


def scan_files(directory: str | os.PathLike) -> list[Path]:
    """The scan files of ``directory`` (one kind only), in natural name order."""
    directory = Path(directory)
    if not directory.is_dir():
        raise UserError(f"scan directory {directory} does not exist; give a folder of .pcd or KITTI .bin scans")
    by_suffix = {s: sorted(directory.glob(f"*{s}"), key=natural_key) for s in SCAN_SUFFIXES}
    present = [s for s in SCAN_SUFFIXES if by_suffix[s]]
    if not present:
        raise UserError(f"scan directory {directory} holds no .pcd or .bin files")
    if len(present) > 1:
        raise UserError(f"scan directory {directory} mixes .pcd and .bin files; keep one kind of scan in it")
    return by_suffix[present[0]]


def read_scan(path: Path) -> np.ndarray:
    """The finite points of one scan file as a structured array (x, y, z and whatever else the file holds)."""
    if path.suffix == ".bin":
        try:
            size = path.stat().st_size
        except OSError as err:
            raise UserError(f"{path}: cannot read ({err.strerror})") from None
        if size % KITTI_DTYPE.itemsize:
            raise UserError(
                f"{path}: {size} bytes is not a whole number of KITTI records (x y z intensity, 4 float32 each);"
                " the file is truncated or not a KITTI scan"
            )
        points = np.fromfile(path, dtype=KITTI_DTYPE)
        finite = np.isfinite(points["x"]) & np.isfinite(points["y"]) & np.isfinite(points["z"])
        return points[finite]
    try:
        return read_pcd(path).points
    except PcdError as err:
        raise UserError(f"unreadable scan: {err}") from None
