"""Keyframe-stitched block maps: the block map paper's Algorithm 1.

Keyframe points are moved into the map frame (``T_map_robot @ T_robot_sensor``), voxel-filtered, and
accumulated into a candidate block while the keyframe's position lies within ``S`` of the candidate's
first keyframe. The first keyframe beyond ``S`` finishes the candidate and starts the next one (the
paper clears the candidate and drops that scan; keeping it leaves no gap between blocks). A finished
candidate is voxel-filtered again and judged by :func:`rules.decide`: stored as a new block, merged
into the nearest block (union voxel-filtered again, centroid recomputed), or dropped. The last,
unfinished candidate is judged the same way so the end of the run is mapped too.

A block's centroid is the mean of its (voxel-filtered) points [m].
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from grid_puzzle_localization.blocks.keyframes import Scan, select_keyframes
from grid_puzzle_localization.blocks.poses import transform_points
from grid_puzzle_localization.blocks.rules import Action, decide
from grid_puzzle_localization.blocks.voxel import check_voxel, voxel_downsample
from grid_puzzle_localization.errors import UserError


@dataclass(frozen=True)
class BlockConfig:
    block_size: float = 50.0  # S [m]: a candidate spans keyframes within S of its first keyframe
    keyframe_spacing: float = 1.0  # [m] travelled between keyframes; 0 keeps every scan
    voxel: float = 0.2  # downsample voxel edge [m]; 0: no voxel filter, exact duplicates kept once

    def checked(self) -> BlockConfig:
        if not (math.isfinite(self.block_size) and self.block_size > 0.0):
            raise UserError(f"block size must be a positive number of metres (got {self.block_size}); e.g. --size 50")
        if not (math.isfinite(self.keyframe_spacing) and self.keyframe_spacing >= 0.0):
            raise UserError(
                f"keyframe spacing must be >= 0 metres (got {self.keyframe_spacing}); e.g. --keyframe-spacing 1"
            )
        check_voxel(self.voxel)
        return self


@dataclass
class Block:
    points: np.ndarray  # (N, 3) float64, map frame [m], voxel-filtered
    centroid: np.ndarray  # (3,) mean of points [m]
    keyframes: int  # keyframes stitched into it (merges add up)


@dataclass
class BuildReport:
    keyframes: int = 0
    candidates: int = 0
    actions: dict[str, int] = field(default_factory=lambda: {a.value: 0 for a in Action})


@dataclass
class _Candidate:
    origin: np.ndarray  # position of its first keyframe [m]
    parts: list[np.ndarray]
    keyframes: int = 0


class BlockBuilder:
    """Feeds keyframes one at a time (:meth:`add_keyframe`), then :meth:`finish` returns the blocks."""

    def __init__(self, config: BlockConfig, extrinsic: np.ndarray | None = None) -> None:
        self.config = config.checked()
        self.extrinsic = np.eye(4) if extrinsic is None else np.asarray(extrinsic, dtype=np.float64)
        self.blocks: list[Block] = []
        self.report = BuildReport()
        self._candidate: _Candidate | None = None

    def add_keyframe(self, pose: np.ndarray, points: np.ndarray) -> None:
        """Adds a keyframe: robot pose ``T_map_robot`` (4x4) and its points ``(N, 3)`` in the sensor frame."""
        position = pose[:3, 3]
        if self._candidate is not None and np.linalg.norm(position - self._candidate.origin) > self.config.block_size:
            self._close_candidate()
        if self._candidate is None:
            self._candidate = _Candidate(origin=position.copy(), parts=[])
        cloud = transform_points(pose @ self.extrinsic, points)
        self._candidate.parts.append(voxel_downsample(cloud[np.all(np.isfinite(cloud), axis=1)], self.config.voxel))
        self._candidate.keyframes += 1
        self.report.keyframes += 1

    def finish(self) -> list[Block]:
        if self._candidate is not None:
            self._close_candidate()
        return self.blocks

    def _close_candidate(self) -> None:
        candidate, self._candidate = self._candidate, None
        assert candidate is not None
        points = voxel_downsample(np.concatenate(candidate.parts), self.config.voxel)
        self.report.candidates += 1
        if len(points) == 0:
            return  # keyframes without a single finite point: nothing to judge or store
        centroid = points.mean(axis=0)
        centroids = np.array([b.centroid for b in self.blocks]).reshape(-1, 3)
        decision = decide(centroid, centroids, self.config.block_size)
        self.report.actions[decision.action.value] += 1
        if decision.action is Action.NEW:
            self.blocks.append(Block(points, centroid, candidate.keyframes))
        elif decision.action is Action.MERGE:
            target = self.blocks[decision.nearest]
            target.points = voxel_downsample(np.concatenate([target.points, points]), self.config.voxel)
            target.centroid = target.points.mean(axis=0)
            target.keyframes += candidate.keyframes


def union_points(blocks: list[Block], voxel: float) -> int:
    """Points of the map the blocks represent: their union, one point per voxel (distinct points when
    ``voxel == 0``). Stored points over this is the blocks' overlap factor."""
    if not blocks:
        return 0
    return len(voxel_downsample(np.concatenate([b.points for b in blocks]), voxel))


def build_blocks(
    scans: Iterable[Scan], config: BlockConfig, extrinsic: np.ndarray | None = None
) -> tuple[list[Block], BuildReport]:
    """Blocks from ``scans`` (in time order): keyframes are selected by ``config.keyframe_spacing``."""
    builder = BlockBuilder(config, extrinsic)
    for scan in select_keyframes(scans, config.keyframe_spacing):
        builder.add_keyframe(scan.pose, scan.load_points())
    return builder.finish(), builder.report
