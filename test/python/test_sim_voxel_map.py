"""The prior map's streaming voxel filter against a brute-force centroid filter."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from grid_puzzle_localization.sim import mapping
from grid_puzzle_localization.sim.mapping import VoxelMap


@pytest.mark.parametrize("flush_points", [50_000, 10_000_000])
def test_voxel_map_equals_brute_force_centroids(monkeypatch, flush_points):
    monkeypatch.setattr(mapping, "_FLUSH_POINTS", flush_points)
    rng = np.random.default_rng(4)
    pts = rng.uniform([-300.0, -40.0, -5.0], [40.0, 300.0, 30.0], (400_000, 3))
    pts[::3] = pts[::3].round(0) + 0.01  # many points share voxels, across batches
    inten = rng.uniform(0.0, 255.0, len(pts))
    leaf = 0.7
    vm = VoxelMap(leaf)
    for i in range(0, len(pts), 30_000):
        vm.add(pts[i : i + 30_000], inten[i : i + 30_000])
    out = np.concatenate(list(vm.chunks()))

    idx = np.floor(pts / leaf).astype(np.int64)
    ref_idx, inv = np.unique(idx, axis=0, return_inverse=True)
    n = np.bincount(inv)
    ref = np.stack([np.bincount(inv, weights=pts[:, j]) / n for j in range(3)], axis=1)
    ref_i = np.bincount(inv, weights=inten) / n

    got = np.stack([out["x"], out["y"], out["z"]], axis=1).astype(np.float64)
    assert len(out) == len(ref_idx) == vm.voxel_count
    dist, match = cKDTree(got).query(ref)
    assert dist.max() < 1e-4
    assert len(np.unique(match)) == len(ref)  # one output point per voxel
    np.testing.assert_allclose(out["intensity"][match], ref_i, rtol=1e-5)
