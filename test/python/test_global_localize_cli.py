"""`gpm global-localize` on a synthetic street (fixtures.synthetic_scene) against the pose the scan was
taken from: the map as tiles (only the tiles around the search are loaded), as one PCD file, and the
errors a user can cause."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from fixtures import synthetic_scene as ss

from grid_puzzle_localization.blocks.store import write_block_dir
from grid_puzzle_localization.cli import main
from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array, xyz_records
from grid_puzzle_localization.tiling.tiler import TileConfig, tile_map

GRID = 10.0  # [m] tile side


@pytest.fixture(scope="module")
def street(tmp_path_factory):
    """A tiled map, the same map as one PCD, a scan and the lidar's true pose (the scan's base frame)."""
    root = tmp_path_factory.mktemp("street")
    scene = ss.make_scene(length=100.0)
    map_pcd = root / "map.pcd"
    write_pcd(map_pcd, xyz_records(ss.sample_map(scene)))
    tile_map([map_pcd], root / "tiles", TileConfig(grid_size=GRID, progress=False, sync=False))
    map_to_base = ss.pose_matrix(np.array([42.0, 1.5, 0.0]), 2.5)
    scan_pcd = root / "scan.pcd"
    write_pcd(scan_pcd, xyz_records(ss.scan(scene, map_to_base, np.random.default_rng(3))))
    return root, map_to_base @ ss.lidar_mount()


def localize(capsys, *argv):
    code = main(["global-localize", *argv])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if out.out.strip() else None), out.err


def assert_at(answer, truth):
    assert answer["found"], answer["reason"]
    assert math.hypot(answer["x"] - truth[0, 3], answer["y"] - truth[1, 3]) < 0.1
    assert answer["z"] == pytest.approx(truth[2, 3], abs=0.1)
    yaw = math.atan2(truth[1, 0], truth[0, 0])
    assert abs(math.remainder(answer["yaw"] - yaw, 2 * math.pi)) < math.radians(1.0)
    assert abs(answer["roll"]) < math.radians(1.0) and abs(answer["pitch"]) < math.radians(1.0)
    assert answer["score"] > answer["runner_up_score"] >= 0.0 and answer["seconds"] > 0.0


def test_tile_directory_loads_only_the_tiles_around_the_search(capsys, street):
    root, truth = street
    args = ["--map", str(root / "tiles"), "--scan", str(root / "scan.pcd"), "--threads", "2"]
    code, answer, err = localize(capsys, *args, "--center", "50", "-6", "--size", "30")
    assert code == 0, err
    assert_at(answer, truth)
    # The search square plus the scan's 40 m reach: x 25..75 +- 40, y -21..9 +- 40, of a 140 m x 60 m map.
    tiles_total = len(list((root / "tiles").glob("*.pcd")))
    assert 0 < answer["tiles_loaded"] < tiles_total


def test_pcd_map_and_yaw_interval(capsys, street):
    root, truth = street
    code, answer, err = localize(
        capsys, "--map", str(root / "map.pcd"), "--scan", str(root / "scan.pcd"), "--center", "38", "4",
        "--yaw-center", "140", "--yaw-range", "30", "--threads", "2",
    )  # fmt: skip
    assert code == 0, err
    assert_at(answer, truth)
    assert answer["tiles_loaded"] == 1


def test_block_directory_loads_only_the_blocks_overlapping_the_search(capsys, street):
    root, truth = street
    points = xyz_array(read_pcd(root / "map.pcd").points)
    slabs = [points[(points[:, 0] >= x0) & (points[:, 0] < x0 + 30.0)] for x0 in np.arange(-30.0, 110.0, 20.0)]
    write_block_dir(root / "blocks", ((p, p.mean(axis=0), {}) for p in slabs), "fixed_submaps", {}, len(points))
    code, answer, err = localize(
        capsys, "--map", str(root / "blocks"), "--scan", str(root / "scan.pcd"), "--center", "42", "1.5",
        "--size", "10", "--threads", "2",
    )  # fmt: skip
    assert code == 0, err
    assert_at(answer, truth)
    # x 37..47 plus the scan's 40 m reach (-3..87) overlaps every slab but the last (x 90..106).
    assert answer["tiles_loaded"] == len(slabs) - 1


def test_errors_name_the_input(capsys, street, tmp_path):
    root, _ = street
    scan = str(root / "scan.pcd")
    code, _, err = localize(capsys, "--map", str(root / "tiles"), "--scan", scan, "--center", "900", "900")
    assert code == 2 and "no tiles" in err and "move --center" in err
    code, _, err = localize(capsys, "--map", str(root / "tiles"), "--scan", str(tmp_path / "none.pcd"))
    assert code == 2 and "none.pcd does not exist" in err
    empty = tmp_path / "empty.pcd"
    write_pcd(empty, xyz_records(np.zeros((0, 3), dtype=np.float32)))
    code, answer, err = localize(capsys, "--map", str(root / "map.pcd"), "--scan", str(empty), "--center", "40", "0")
    assert code == 1 and not answer["found"] and "no finite points" in err


def test_tile_directory_by_url_gives_the_same_pose_and_a_dead_server_is_named(capsys, street, tmp_path, monkeypatch):
    from fixtures import nginx_server

    if nginx_server.binary() is None:
        pytest.skip("nginx is not installed (nginx-light)")
    root, truth = street
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))  # the map store's disk cache
    server = nginx_server.NginxServer(root)
    server.start()
    try:
        url = server.url("/tiles")
        args = ["--scan", str(root / "scan.pcd"), "--threads", "2", "--center", "50", "-6", "--size", "30"]
        code, by_url, err = localize(capsys, "--map", url, *args)
        assert code == 0, err
        assert_at(by_url, truth)
        code, by_path, err = localize(capsys, "--map", str(root / "tiles"), *args)
        assert (by_url["x"], by_url["y"], by_url["yaw"]) == (by_path["x"], by_path["y"], by_path["yaw"])
        assert by_url["tiles_loaded"] == by_path["tiles_loaded"]
    finally:
        server.close()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "empty_cache"))
    code, answer, err = localize(capsys, "--map", url, *args)
    assert code == 2 and answer is None
    assert f"{url}/index.json" in err and "holds no index" in err, err
