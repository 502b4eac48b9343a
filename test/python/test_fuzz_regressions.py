"""Inputs the fuzzers (test/fuzz) found, replayed through the Python readers: each is refused with a UserError
naming the file, never another exception. And a header claiming 10^12 points is refused before anything of
that size is allocated (traced by tracemalloc, which sees numpy's allocations)."""

from __future__ import annotations

import re
import shutil
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from grid_puzzle_localization.errors import PcdError, UserError
from grid_puzzle_localization.pcd.reader import read_pcd
from grid_puzzle_localization.pcd.writer import write_pcd
from grid_puzzle_localization.tiles.directory import open_tile_directory
from grid_puzzle_localization.tiles.reader import read_tile
from grid_puzzle_localization.tiling.index import INDEX_FILE, load_tile_index

REGRESSIONS = Path(__file__).resolve().parents[1] / "fuzz" / "regressions"
TRILLION = 10**12


@pytest.mark.parametrize("name", sorted(p.name for p in (REGRESSIONS / "pcd").iterdir()))
def test_pcd_regressions_are_refused_naming_the_file(tmp_path, name):
    path = tmp_path / name
    shutil.copy(REGRESSIONS / "pcd" / name, path)
    for read in (read_pcd, read_tile):
        with pytest.raises(PcdError, match=re.escape(str(path))):
            read(path)


@pytest.mark.parametrize("name", sorted(p.name for p in (REGRESSIONS / "tile_index").iterdir()))
def test_tile_index_regressions_are_refused_naming_the_directory(tmp_path, name):
    """The key scan of open_tile_directory may accept an index whose other members are broken; the full
    load_tile_index must refuse every one of them."""
    shutil.copy(REGRESSIONS / "tile_index" / name, tmp_path / INDEX_FILE)
    try:
        open_tile_directory(tmp_path)
    except UserError as err:
        assert str(tmp_path) in str(err)
    with pytest.raises(UserError, match=re.escape(str(tmp_path))):
        load_tile_index(tmp_path)


def _claim_trillion_points(path: Path, encoding: str) -> None:
    """A valid six-point file whose header then claims 10^12 points (WIDTH and POINTS agree)."""
    points = np.zeros(6, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    write_pcd(path, points, encoding)
    raw = path.read_bytes()
    path.write_bytes(
        raw.replace(b"WIDTH 6\n", b"WIDTH %d\n" % TRILLION).replace(b"POINTS 6\n", b"POINTS %d\n" % TRILLION)
    )


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_trillion_points_refused_before_allocation(tmp_path, encoding):
    path = tmp_path / f"trillion_{encoding}.pcd"
    _claim_trillion_points(path, encoding)
    for read in (read_pcd, read_tile):
        tracemalloc.start()
        try:
            with pytest.raises(PcdError, match=f"{re.escape(str(path))}.*POINTS {TRILLION}"):
                read(path)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 32 << 20, f"{read.__name__} allocated {peak} bytes before refusing"
