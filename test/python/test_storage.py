"""Storage figures against byte counts known from the file layout."""

import numpy as np

from grid_puzzle_localization.evaluation.storage import map_storage
from grid_puzzle_localization.pcd.writer import write_pcd


def cloud(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    points = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
    for name in ("x", "y", "z"):
        points[name] = rng.uniform(-9.0, 9.0, n)
    return points


def test_map_storage_splits_header_and_data(tmp_path):
    path = tmp_path / "map.pcd"
    header = write_pcd(path, cloud(5000))
    fig = map_storage(path)
    assert fig["data_bytes"] == 5000 * 16
    assert fig["header_bytes"] == len(header.text().encode())
    assert fig["bytes"] == fig["data_bytes"] + fig["header_bytes"] == path.stat().st_size
    assert fig["disk_bytes"] % 512 == 0 and fig["disk_bytes"] >= fig["bytes"]


def test_tiles_storage_conserves_data_bytes(tmp_path):
    from grid_puzzle_localization.evaluation.storage import storage_figures
    from grid_puzzle_localization.tiling.tiler import TileConfig, tile_map

    points = cloud(20000, seed=3)
    write_pcd(tmp_path / "map.pcd", points)
    tile_map([tmp_path / "map.pcd"], tmp_path / "tiles", TileConfig(grid_size=2.0, progress=False))
    fig = storage_figures(tmp_path / "map.pcd", tmp_path / "tiles")
    tiles = fig["tiles"]
    files = sorted((tmp_path / "tiles").glob("*.pcd"))
    # Points in [-9, 9) m on 2 m tiles: indices -5..4 on each axis, 10 x 10 tiles, each point in one.
    assert tiles["files"] == len(files) == 100
    assert tiles["data_bytes"] == fig["global_map"]["data_bytes"] == 20000 * 16
    assert tiles["data_overhead_bytes"] == 0 and tiles["points_tiles"] == 20000
    assert tiles["bytes"] == sum(f.stat().st_size for f in files) == tiles["data_bytes"] + tiles["header_bytes"]
    assert tiles["overlap_factor"] == 1.0 and tiles["mean_bytes_per_file"] == tiles["bytes"] / 100
