"""Fixed-size overlapping submaps: stored points and submap count against closed forms on a uniform grid,
each submap against a brute-force square membership, and the `gpm submaps` output."""

import math

import numpy as np
import pytest

from grid_puzzle_localization.blocks.fixed_cut import SubmapConfig, cut_submaps
from grid_puzzle_localization.blocks.store import read_block_index
from grid_puzzle_localization.cli import main
from grid_puzzle_localization.pcd import read_pcd, write_pcd, xyz_array

H = 0.25  # grid spacing [m]; divides every side and stride below
WIDTH = 12.0  # [m]; a multiple of every stride below
SIDE = 4.0


def uniform_grid() -> np.ndarray:
    c = (np.arange(int(WIDTH / H)) + 0.5) * H
    x, y, z = np.meshgrid(c, c, [0.0, 1.5], indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


@pytest.mark.parametrize("overlap", [0.0, 0.25, 0.5, 0.75])  # strides 4, 3, 2, 1 m, exact in float64
def test_overlap_factor_and_count_match_closed_form(overlap):
    config = SubmapConfig(SIDE, overlap)
    stride = config.stride
    points = uniform_grid()
    submaps = list(cut_submaps(points, config))
    # Per axis, every interval [k s, k s + L) on the grid holds L / H grid lines and there is one per
    # s / H lines, so a point lies in L / s squares on average; squares reaching in from below the origin
    # add ceil(L / s) - 1 non-empty squares per axis.
    stored = sum(len(cloud) for _, cloud in submaps)
    assert stored == len(points) * (SIDE / stride) ** 2
    assert len(submaps) == (WIDTH / stride + math.ceil(SIDE / stride) - 1) ** 2
    for (i, j), cloud in submaps:
        inside = (
            (points[:, 0] >= i * stride)
            & (points[:, 0] < i * stride + SIDE)
            & (points[:, 1] >= j * stride)
            & (points[:, 1] < j * stride + SIDE)
        )
        np.testing.assert_array_equal(np.sort(cloud, axis=0), np.sort(points[inside], axis=0))


def test_zero_overlap_is_a_partition():
    points = np.random.default_rng(1).uniform(-30.0, 30.0, size=(5000, 3))
    submaps = list(cut_submaps(points, SubmapConfig(7.0, 0.0)))
    merged = np.concatenate([cloud for _, cloud in submaps])
    np.testing.assert_array_equal(np.sort(merged, axis=0), np.sort(points, axis=0))


@pytest.mark.parametrize(
    ("side", "overlap", "message"),
    [(0.0, 0.5, "submap side"), (10.0, 1.0, "overlap ratio"), (10.0, -0.1, "overlap ratio"), (math.nan, 0.5, "side")],
)
def test_bad_config_is_a_user_error(tmp_path, capsys, side, overlap, message):
    cloud = np.zeros(1, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    write_pcd(tmp_path / "map.pcd", cloud)
    args = ["submaps", str(tmp_path / "map.pcd"), str(tmp_path / "out"), "--side", str(side), "--overlap", str(overlap)]
    assert main(args) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_gpm_submaps_writes_the_index(tmp_path):
    points = uniform_grid()
    cloud = np.empty(len(points), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
    cloud["x"], cloud["y"], cloud["z"] = points.T
    write_pcd(tmp_path / "map.pcd", cloud)
    out = tmp_path / "submaps"
    assert main(["submaps", str(tmp_path / "map.pcd"), str(out), "--side", "4", "--overlap", "0.5"]) == 0
    index = read_block_index(out)
    assert index.kind == "fixed_submaps" and index.map_points == len(points)
    assert sum(b.points for b in index.blocks) == 4 * len(points)  # (L / s)^2 with s = L / 2
    for entry in index.blocks:
        stored = xyz_array(read_pcd(out / entry.file).points)
        i, j = entry.extra["cell"]
        assert np.all((stored[:, 0] >= 2.0 * i) & (stored[:, 0] < 2.0 * i + 4.0))
        assert np.all((stored[:, 1] >= 2.0 * j) & (stored[:, 1] < 2.0 * j + 4.0))
        assert entry.points == len(stored) and entry.bytes == (out / entry.file).stat().st_size
        np.testing.assert_allclose(entry.centroid, stored.mean(axis=0), atol=1e-12)
