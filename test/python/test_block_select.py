"""Block map server logic without ROS: nearest-block selection against brute force, and the block cache
(merged clouds, duplicate removal, memory bound)."""

import dataclasses

import numpy as np
import pytest

from grid_puzzle_localization.blocks.block_cache import BlockCache
from grid_puzzle_localization.blocks.select import BlockSelector
from grid_puzzle_localization.blocks.server_config import BlockMapServerConfig
from grid_puzzle_localization.blocks.store import read_block_index, write_block_dir
from grid_puzzle_localization.errors import UserError


@pytest.mark.parametrize("planar", [False, True])
@pytest.mark.parametrize("k", [1, 2, 3, 50])
def test_selection_matches_brute_force(planar, k):
    rng = np.random.default_rng(k + 10 * planar)
    centroids = rng.uniform(-200.0, 200.0, size=(40, 3))
    selector = BlockSelector(centroids, k, planar)
    dims = 2 if planar else 3
    for position in rng.uniform(-250.0, 250.0, size=(200, 3)):
        d = np.linalg.norm(centroids[:, :dims] - position[:dims], axis=1)
        order = np.argsort(d)[: min(k, len(centroids))]
        indices, distances = selector.nearest(position)
        np.testing.assert_array_equal(indices, order)
        np.testing.assert_allclose(distances, d[order], rtol=1e-12)
        assert selector.select(position) == tuple(sorted(order.tolist()))


def test_empty_index_and_bad_count_are_user_errors():
    with pytest.raises(UserError, match="no blocks"):
        BlockSelector(np.empty((0, 3)), 2)
    with pytest.raises(UserError, match="num_blocks"):
        BlockSelector(np.zeros((3, 3)), 0)


@pytest.fixture
def block_dir(tmp_path):
    rng = np.random.default_rng(7)
    clouds = [np.round(rng.uniform(-5, 5, size=(50 + 10 * b, 3)) + 20.0 * b, 3) for b in range(5)]
    shared = clouds[1][:20]
    clouds[2] = np.concatenate([clouds[2], shared])  # blocks 1 and 2 overlap in 20 identical points
    write_block_dir(tmp_path / "b", ((c, c.mean(axis=0), {}) for c in clouds), "keyframe_blocks", {}, 0)
    return read_block_index(tmp_path / "b"), clouds


def as_rows(records: np.ndarray) -> np.ndarray:
    return np.stack([records[n] for n in "xyz"], axis=1)


def unique_rows(points: np.ndarray) -> np.ndarray:
    return np.unique(points.astype(np.float32), axis=0)


def test_cache_merges_selection_once_per_point(block_dir):
    index, clouds = block_dir
    cache = BlockCache(index, cache_blocks=0)
    merged = as_rows(cache.merged((1, 2)))
    expected = unique_rows(np.concatenate([clouds[1], clouds[2]]))
    assert len(merged) == len(clouds[1]) + len(clouds[2]) - 20
    np.testing.assert_array_equal(np.unique(merged, axis=0), expected)


def test_cache_keeps_only_selection_plus_cache(block_dir):
    index, _ = block_dir
    cache = BlockCache(index, cache_blocks=1)
    for selection in [(0, 1), (1, 2), (2, 3), (3, 4)]:
        cache.merged(selection)
        assert len(cache) <= len(selection) + 1
    assert cache.loads == 5  # each block read once on this forward sweep
    cache.merged((2, 3))  # 3 is selected still; 2 is the cached one (most recently used after 3, 4)
    assert cache.loads == 5
    cache.merged((0, 1))
    assert cache.loads == 7 and len(cache) == 3


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"block_dir": ""}, "block_dir is required"),
        ({"num_blocks": 0}, "num_blocks"),
        ({"cache_blocks": -1}, "cache_blocks"),
        ({"pose_type": "tf"}, "pose_type"),
        ({"initial_pose": (1.0, 2.0, 3.0)}, "initial_pose"),
        ({"initial_pose": (1.0, 2.0, float("nan"), 0.0, 0.0, 0.0)}, "initial_pose"),
    ],
)
def test_server_config_errors_name_the_parameter(changes, message):
    config = dataclasses.replace(BlockMapServerConfig(block_dir="/maps/blocks"), **changes)
    with pytest.raises(UserError, match=message):
        config.checked()


def test_failed_write_keeps_the_old_directory(block_dir, tmp_path):
    index, _ = block_dir
    before = sorted(p.name for p in index.directory.iterdir())

    def blocks():
        yield np.zeros((3, 3)), np.zeros(3), {}
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        write_block_dir(index.directory, blocks(), "keyframe_blocks", {}, 0, force=True)
    assert sorted(p.name for p in index.directory.iterdir()) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b"]  # no temporaries left
