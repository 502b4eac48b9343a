"""Storage table: files, bytes and overlap factors of a global map, a partition and overlapping submaps,
against file-system sizes and the closed-form duplication of the fixed cut."""

import json

import numpy as np

from grid_puzzle_localization.blocks.storage import storage_table
from grid_puzzle_localization.cli import main
from grid_puzzle_localization.pcd import write_pcd

XYZ32 = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])


def test_storage_rows(tmp_path, capsys):
    c = (np.arange(48) + 0.5) * 0.25  # 12 m x 12 m uniform grid
    x, y = np.meshgrid(c, c, indexing="ij")
    cloud = np.zeros(x.size, dtype=XYZ32)
    cloud["x"], cloud["y"] = x.ravel(), y.ravel()
    global_map = tmp_path / "map.pcd"
    write_pcd(global_map, cloud)
    # A partition (overlap 0) stands in for tiles; 4 m squares at 50 % overlap store each point 4 times.
    assert main(["submaps", str(global_map), str(tmp_path / "tiles"), "--side", "4", "--overlap", "0"]) == 0
    assert main(["submaps", str(global_map), str(tmp_path / "sub"), "--side", "4", "--overlap", "0.5"]) == 0
    rows = storage_table(global_map, tiles=tmp_path / "tiles", submaps=tmp_path / "sub")
    assert [r.name for r in rows] == ["global map", "grid puzzle tiles", "fixed-size submaps"]
    n = len(cloud)
    for row, directory, files, factor in [
        (rows[1], tmp_path / "tiles", 9, 1.0),
        (rows[2], tmp_path / "sub", 49, 4.0),
    ]:
        pcds = sorted(directory.glob("*.pcd"))
        assert row.files == len(pcds) == files
        assert row.bytes == sum(p.stat().st_size for p in pcds)
        assert row.stored_points == factor * n and row.map_points == n
        assert row.overlap_factor == factor
        assert row.mean_bytes_per_file == row.bytes / files
    assert rows[0].files == 1 and rows[0].bytes == global_map.stat().st_size and rows[0].overlap_factor == 1.0
    assert main(["storage", str(global_map), "--submaps", str(tmp_path / "sub"), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed[1]["overlap_factor"] == 4.0 and printed[1]["files"] == 49


def test_blocks_row_needs_an_index(tmp_path, capsys):
    write_pcd(tmp_path / "map.pcd", np.zeros(3, dtype=XYZ32))
    (tmp_path / "blocks").mkdir()
    assert main(["storage", str(tmp_path / "map.pcd"), "--blocks", str(tmp_path / "blocks")]) == 2
    assert "index.yaml" in capsys.readouterr().err
