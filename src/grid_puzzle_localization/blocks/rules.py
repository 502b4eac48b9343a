"""The block map paper's rule for a finished candidate block (Algorithm 1, lines 14-25).

With ``d`` the distance from the candidate's centroid to the nearest stored block centroid and ``S``
the block size [m]:

- the first two candidates are always stored as new blocks;
- ``d > 0.5 S``: a new block;
- ``0.1 S < d <= 0.5 S``: merged into the nearest block (whose centroid is then recomputed);
- ``d <= 0.1 S``: dropped as an excessive overlap.

The paper writes the merge band as an open interval; the boundary ``d = 0.5 S`` merges here, so every
distance has exactly one outcome.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

ALWAYS_STORED = 2  # the paper stores its first two candidates unconditionally ("if C is 0 or 1")
DROP_FRACTION = 0.1  # of S: at or below, the candidate is dropped
MERGE_FRACTION = 0.5  # of S: at or below (and above the drop bound), it is merged


class Action(enum.Enum):
    NEW = "new"
    MERGE = "merge"
    DROP = "drop"


@dataclass(frozen=True)
class Decision:
    action: Action
    nearest: int  # index of the nearest stored block, -1 when none was looked up
    distance: float  # distance to it [m], inf when none was looked up


def classify(distance: float, block_size: float) -> Action:
    """Outcome for a candidate whose centroid lies ``distance`` metres from the nearest block."""
    if distance > MERGE_FRACTION * block_size:
        return Action.NEW
    if distance > DROP_FRACTION * block_size:
        return Action.MERGE
    return Action.DROP


def decide(candidate_centroid: np.ndarray, centroids: np.ndarray, block_size: float) -> Decision:
    """Decision for a candidate given the stored centroids ``(C, 3)`` [m], nearest found by a KD-tree."""
    if len(centroids) < ALWAYS_STORED:
        return Decision(Action.NEW, -1, float("inf"))
    distance, nearest = cKDTree(centroids).query(np.asarray(candidate_centroid, dtype=np.float64))
    return Decision(classify(float(distance), block_size), int(nearest), float(distance))
