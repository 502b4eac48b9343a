"""Block map candidate rules (new / merge / drop) at the exact 0.1 S and 0.5 S boundaries, through the
KD-tree decision and through the block builder, on layouts whose distances are exact in float64."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from grid_puzzle_localization.blocks.builder import BlockBuilder, BlockConfig
from grid_puzzle_localization.blocks.rules import Action, decide
from grid_puzzle_localization.util.iteration import zip_equal

S = 10.0  # 0.1 S == 1.0 and 0.5 S == 5.0 exactly in float64
ABOVE_1 = np.nextafter(1.0, 2.0)
ABOVE_5 = np.nextafter(5.0, 6.0)
STORED = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])


def test_thresholds_are_exact_for_the_chosen_size():
    assert 0.1 * S == 1.0 and 0.5 * S == 5.0


@pytest.mark.parametrize(
    ("candidate", "action", "nearest", "distance"),
    [
        ((0.0, 0.0, 0.0), Action.DROP, 0, 0.0),
        ((1.0, 0.0, 0.0), Action.DROP, 0, 1.0),  # d == 0.1 S: dropped
        ((0.0, 0.0, -1.0), Action.DROP, 0, 1.0),
        ((ABOVE_1, 0.0, 0.0), Action.MERGE, 0, ABOVE_1),  # just above 0.1 S: merged
        ((3.0, 4.0, 0.0), Action.MERGE, 0, 5.0),  # d == 0.5 S (3-4-5): merged
        ((103.0, 0.0, -4.0), Action.MERGE, 1, 5.0),  # nearest is the second block
        ((ABOVE_5, 0.0, 0.0), Action.NEW, 0, ABOVE_5),  # just above 0.5 S: new block
        ((50.0, 0.0, 0.0), Action.NEW, 0, 50.0),
    ],
)
def test_decision_at_boundaries(candidate, action, nearest, distance):
    decision = decide(np.array(candidate), STORED, S)
    assert decision.distance == distance
    assert decision.action is action
    assert decision.nearest == nearest


@pytest.mark.parametrize("stored", [np.empty((0, 3)), STORED[:1]])
def test_first_two_candidates_always_stored(stored):
    assert decide(np.zeros(3), stored, S).action is Action.NEW


def test_kdtree_nearest_matches_brute_force():
    rng = np.random.default_rng(3)
    centroids = rng.uniform(-500, 500, size=(200, 3))
    for query in rng.uniform(-600, 600, size=(300, 3)):
        d = cdist(query[None], centroids)[0]
        decision = decide(query, centroids, S)
        assert decision.nearest == int(np.argmin(d))
        assert decision.distance == pytest.approx(d.min(), rel=1e-12)


def _keyframe(builder: BlockBuilder, robot_y: float, point: tuple[float, float, float]) -> None:
    """One keyframe whose single map-frame point is ``point``; robots 20 m apart (> S) along y, so every
    keyframe is its own candidate and the point is its centroid. Integer y keeps point - robot + robot exact."""
    pose = np.eye(4)
    pose[1, 3] = robot_y
    builder.add_keyframe(pose, np.array([point]) - pose[:3, 3])


def test_builder_applies_the_rules_in_order():
    builder = BlockBuilder(BlockConfig(block_size=S, keyframe_spacing=0.0, voxel=0.0))
    candidates = [
        (0.0, 0.0, 0.0),  # 1st: stored (#0)
        (3.0, 4.0, 0.0),  # 2nd: stored (#1) although 0.5 S from #0
        (100.0, 0.0, 0.0),  # new (#2)
        (1.0, 0.0, 0.0),  # 0.1 S from #0: dropped
        (103.0, -4.0, 0.0),  # 0.5 S from #2: merged, #2 centroid -> (101.5, -2, 0)
        (200.0, 0.0, 0.0),  # new (#3)
        (np.nextafter(205.0, 206.0), 0.0, 0.0),  # just above 0.5 S from #3: new (#4)
        (200.0, 0.0, ABOVE_1),  # just above 0.1 S from #3: merged
    ]
    for k, point in enumerate(candidates):
        _keyframe(builder, 20.0 * k, point)
    blocks = builder.finish()
    expected = [
        [(0.0, 0.0, 0.0)],
        [(3.0, 4.0, 0.0)],
        [(100.0, 0.0, 0.0), (103.0, -4.0, 0.0)],
        [(200.0, 0.0, 0.0), (200.0, 0.0, ABOVE_1)],
        [(np.nextafter(205.0, 206.0), 0.0, 0.0)],
    ]
    assert len(blocks) == len(expected)
    for block, points in zip_equal(blocks, expected):
        np.testing.assert_array_equal(np.sort(block.points, axis=0), np.sort(np.array(points), axis=0))
        np.testing.assert_array_equal(block.centroid, np.mean(points, axis=0))
        assert block.keyframes == len(points)
    assert builder.report.actions == {"new": 5, "merge": 2, "drop": 1}
    assert builder.report.candidates == 8


def test_candidate_spans_keyframes_within_block_size():
    builder = BlockBuilder(BlockConfig(block_size=S, keyframe_spacing=0.0, voxel=0.0))
    for x in [0.0, 4.0, 10.0, 10.5, 12.0, 20.5]:  # 10.0 is within S of 0.0, 10.5 is not; 20.5 == S from 10.5
        pose = np.eye(4)
        pose[0, 3] = x
        builder.add_keyframe(pose, np.zeros((1, 3)))
    blocks = builder.finish()
    assert [b.keyframes for b in blocks] == [3, 3]
    np.testing.assert_array_equal(blocks[0].centroid, [14.0 / 3.0, 0.0, 0.0])
