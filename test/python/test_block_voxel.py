"""Voxel downsampling against a brute-force per-voxel mean, including coordinates too far apart for the
fast 1-D voxel key."""

from collections import defaultdict

import numpy as np
import pytest

from grid_puzzle_localization.blocks.voxel import voxel_downsample


def brute_force(points: np.ndarray, voxel: float) -> np.ndarray:
    groups = defaultdict(list)
    for p in points:
        groups[tuple(np.floor(p / voxel).astype(np.int64).tolist())].append(p)
    return np.array([np.mean(groups[k], axis=0) for k in sorted(groups)])


@pytest.mark.parametrize("spread", [5.0, 1e17])  # 1e17 m / 0.5 m voxels: the 1-D key would overflow
def test_voxel_means_match_brute_force(spread):
    rng = np.random.default_rng(2)
    points = rng.uniform(-5.0, 5.0, size=(3000, 3))
    points[:10] *= spread / 5.0
    out = voxel_downsample(points, 0.5)
    np.testing.assert_allclose(out, brute_force(points, 0.5), rtol=1e-12, atol=1e-12)


def test_filtering_twice_changes_nothing_and_zero_voxel_removes_only_duplicates():
    points = np.random.default_rng(4).uniform(-20.0, 20.0, size=(5000, 3))
    once = voxel_downsample(points, 0.7)
    np.testing.assert_allclose(voxel_downsample(once, 0.7), once, rtol=0, atol=1e-12)
    doubled = np.concatenate([points, points[:100]])
    np.testing.assert_array_equal(voxel_downsample(doubled, 0.0), np.unique(points, axis=0))
