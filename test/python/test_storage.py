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
