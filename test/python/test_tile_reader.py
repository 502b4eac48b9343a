"""read_tile against the general PCD reader (read_pcd) as the reference, for every encoding."""

import numpy as np
import pytest

from grid_puzzle_localization.errors import PcdError
from grid_puzzle_localization.pcd import read_pcd, write_pcd
from grid_puzzle_localization.pcd.reader import XYZ_DTYPE
from grid_puzzle_localization.tiles.reader import read_tile

XYZI = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
WIDE = np.dtype([("intensity", "<u2"), ("z", "<f8"), ("x", "<f8"), ("y", "<f8"), ("normal", "<f4", (3,))])


def cloud(n, dtype, seed=0, nan_rows=()):
    rng = np.random.default_rng(seed)
    pts = np.zeros(n, dtype=dtype)
    for name in dtype.names:
        pts[name] = rng.uniform(-100, 100, pts[name].shape)
    for row, field in nan_rows:
        pts[field][row] = np.nan
    return pts


def xyz_of(points):
    out = np.empty(len(points), dtype=XYZ_DTYPE)
    for name in "xyz":
        out[name] = points[name]
    return out


@pytest.mark.parametrize("encoding", ["binary", "binary_compressed", "ascii"])
@pytest.mark.parametrize("dtype", [XYZI, WIDE])
def test_read_tile_equals_read_pcd(tmp_path, encoding, dtype):
    path = tmp_path / "t.pcd"
    write_pcd(path, cloud(57, dtype, nan_rows=[(3, "x"), (10, "z"), (11, "y")]), encoding=encoding)
    reference = read_pcd(path)
    assert reference.nonfinite_dropped == 3
    compact = read_tile(path)
    assert compact.dtype == XYZ_DTYPE and compact.tobytes() == xyz_of(reference.points).tobytes()
    full = read_tile(path, xyz_only=False)
    assert full.dtype == reference.points.dtype and full.tobytes() == reference.points.tobytes()
    assert full.flags.owndata and compact.flags.owndata


def test_empty_tile(tmp_path):
    write_pcd(tmp_path / "e.pcd", np.empty(0, dtype=XYZI))
    assert read_tile(tmp_path / "e.pcd").shape == (0,)


def test_bad_files_raise_pcd_errors_naming_them(tmp_path):
    path = tmp_path / "t.pcd"
    write_pcd(path, cloud(8, XYZI))
    raw = path.read_bytes()
    path.write_bytes(raw[:-5])
    with pytest.raises(PcdError, match=r"t\.pcd: truncated"):
        read_tile(path)
    path.write_bytes(raw + b"\0" * 16)  # padding after the POINTS records is ignored, as PCL does
    assert read_tile(path).tobytes() == xyz_of(cloud(8, XYZI)).tobytes()
    with pytest.raises(PcdError, match="no such file"):
        read_tile(tmp_path / "missing.pcd")
    write_pcd(path, np.zeros(3, dtype=[("x", "<f4"), ("y", "<f4")]))
    with pytest.raises(PcdError, match="no 'z' field"):
        read_tile(path)
    path.write_bytes(b"garbage\n" * 3)
    with pytest.raises(PcdError):
        read_tile(path)
