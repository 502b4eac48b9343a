"""atheris target: the Python PCD readers (read_pcd, the chunked iterator, the tile reader) on arbitrary
file contents. An accepted file yields finite points only, the same ones through every reader."""

from __future__ import annotations

import atheris
import numpy as np
from harness import rejects_cleanly, run, scratch_dir

with atheris.instrument_imports(include=["grid_puzzle_localization"]):
    from grid_puzzle_localization.pcd.reader import iter_pcd_chunks, read_pcd, xyz_array, xyz_records
    from grid_puzzle_localization.tiles.reader import read_tile

PATH = scratch_dir() / "input.pcd"


def read_all() -> None:
    cloud = read_pcd(PATH)
    xyz = xyz_array(cloud.points)
    assert np.isfinite(xyz).all(), "read_pcd kept a non-finite point"
    chunked = [xyz_array(c) for c in iter_pcd_chunks(PATH, chunk_points=3)]
    assert np.array_equal(np.concatenate(chunked) if chunked else np.empty((0, 3)), xyz), "chunked read differs"
    tile = read_tile(PATH)
    assert np.array_equal(tile, xyz_records(cloud.points)), "read_tile differs from read_pcd"


def test_one_input(data: bytes) -> None:
    PATH.write_bytes(data)
    rejects_cleanly(read_all, PATH)


if __name__ == "__main__":
    run(test_one_input)
