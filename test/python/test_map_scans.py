"""Pseudo-scans cut from a prior map: the grid disc query against brute force, and index-set blocks
against the same keyframes carried as coordinates."""

import numpy as np
import pytest

from grid_puzzle_localization.blocks.builder import BlockBuilder, BlockConfig
from grid_puzzle_localization.blocks.map_scans import DiscIndex, MapSubsets
from grid_puzzle_localization.util.iteration import zip_equal


@pytest.mark.parametrize("radius", [0.7, 5.0, 30.0])
def test_disc_matches_brute_force(radius):
    rng = np.random.default_rng(3)
    points = rng.uniform([-40, -25, -2], [60, 35, 8], size=(20000, 3))
    index = DiscIndex(points, radius)
    centres = [*rng.uniform([-60, -45], [80, 55], size=(40, 2)), (-40.0, -25.0), (500.0, 500.0)]
    for centre in centres:
        centre = np.asarray(centre)
        expected = np.flatnonzero(np.sum((points[:, :2] - centre) ** 2, axis=1) <= radius**2)
        np.testing.assert_array_equal(np.sort(index.disc(centre)), expected)


def test_index_blocks_equal_coordinate_blocks():
    """Identity poses, so a keyframe's sensor-frame points are its map points: with no voxel filter the
    two representations must give the same blocks, centroids and decisions. Distinct points on a 1/8 m
    lattice keep (p - x) + x exact for integer x, so coordinate copies of a point compare equal."""
    rng = np.random.default_rng(4)
    points = np.unique(np.round(rng.uniform([0, -10, 0], [120, 10, 3], size=(5000, 3)) * 8) / 8, axis=0)
    index = DiscIndex(points, 8.0)
    config = BlockConfig(block_size=20.0, keyframe_spacing=0.0, voxel=0.0)
    by_index = BlockBuilder(config, sets=MapSubsets(points))
    by_coordinates = BlockBuilder(config)
    for x in [*np.arange(0.0, 120.0, 3.0), *np.arange(118.0, 40.0, -4.0)]:  # out and partly back
        pose = np.eye(4)
        pose[0, 3] = x
        disc = index.disc(pose[:3, 3])
        by_index.add_keyframe(pose, disc)
        by_coordinates.add_keyframe(pose, points[disc] - pose[:3, 3])
    a, b = by_index.finish(), by_coordinates.finish()
    assert by_index.report == by_coordinates.report
    assert by_index.report.actions["merge"] + by_index.report.actions["drop"] > 0  # the way back overlaps
    assert [x.keyframes for x in a] == [x.keyframes for x in b]
    for x, y in zip_equal(a, b):
        np.testing.assert_allclose(np.sort(x.points, axis=0), np.sort(y.points, axis=0), atol=1e-9)
        np.testing.assert_allclose(x.centroid, y.centroid, atol=1e-9)
    assert by_index.map_points() == by_coordinates.map_points()
