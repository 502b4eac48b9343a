"""Keyframe-stitched block maps: the block map paper's Algorithm 1.

Keyframe points are moved into the map frame (``T_map_robot @ T_robot_sensor``), voxel-filtered, and
accumulated into a candidate block while the keyframe's position lies within ``S`` of the candidate's
first keyframe. The first keyframe beyond ``S`` finishes the candidate and starts the next one (the
paper clears the candidate and drops that scan; keeping it leaves no gap between blocks). A finished
candidate is voxel-filtered again and judged by :func:`rules.decide`: stored as a new block, merged
into the nearest block (union voxel-filtered again, centroid recomputed), or dropped. The last,
unfinished candidate is judged the same way so the end of the run is mapped too.

A block's centroid is the mean of its (voxel-filtered) points [m].

How points are held is a :class:`PointSets`: map-frame coordinates for real scans (:class:`VoxelClouds`),
or index sets into a prior map for pseudo-scans cut from it (``map_scans.MapSubsets``), where a point
seen by many keyframes is the same index rather than a copy to be merged again.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

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


class PointSets(Protocol):
    """How a builder holds the points of keyframes, candidates and blocks ("members"): map-frame
    coordinates (:class:`VoxelClouds`, for real scans) or indices into a prior map
    (:class:`grid_puzzle_localization.blocks.map_scans.MapSubsets`, for pseudo-scans cut from it)."""

    def start(self) -> Any:
        """An empty candidate accumulator."""

    def add(self, accumulator: Any, pose: np.ndarray, payload: np.ndarray) -> Any:
        """``accumulator`` with one keyframe added: robot pose ``T_map_robot`` and its loaded points."""

    def close(self, accumulator: Any) -> np.ndarray:
        """The members of a finished candidate."""

    def union(self, members: list[np.ndarray]) -> np.ndarray:
        """The members of the union of several member sets."""

    def points(self, members: np.ndarray) -> np.ndarray:
        """Map-frame points ``(N, 3)`` [m] of a member set."""


class VoxelClouds:
    """Members are voxel-filtered map-frame points ``(N, 3)`` float64; a keyframe's points arrive in the
    sensor frame and go through ``T_map_robot @ T_robot_sensor``."""

    def __init__(self, voxel: float, extrinsic: np.ndarray | None = None) -> None:
        self.voxel = check_voxel(voxel)
        self.extrinsic = np.eye(4) if extrinsic is None else np.asarray(extrinsic, dtype=np.float64)

    def start(self) -> list[np.ndarray]:
        return []

    def add(self, accumulator: list[np.ndarray], pose: np.ndarray, payload: np.ndarray) -> list[np.ndarray]:
        cloud = transform_points(pose @ self.extrinsic, payload)
        accumulator.append(voxel_downsample(cloud[np.all(np.isfinite(cloud), axis=1)], self.voxel))
        return accumulator

    def close(self, accumulator: list[np.ndarray]) -> np.ndarray:
        return self.union(accumulator)

    def union(self, members: list[np.ndarray]) -> np.ndarray:
        return voxel_downsample(np.concatenate(members), self.voxel) if members else np.empty((0, 3))

    def points(self, members: np.ndarray) -> np.ndarray:
        return members


@dataclass
class Block:
    members: np.ndarray  # in the builder's PointSets representation
    centroid: np.ndarray  # (3,) mean of its points [m]
    keyframes: int  # keyframes stitched into it (merges add up)
    sets: PointSets

    @property
    def points(self) -> np.ndarray:
        """Map-frame points ``(N, 3)`` [m] (voxel-filtered for real scans), made on demand."""
        return self.sets.points(self.members)


@dataclass
class BuildReport:
    keyframes: int = 0
    candidates: int = 0
    actions: dict[str, int] = field(default_factory=lambda: {a.value: 0 for a in Action})


@dataclass
class _Candidate:
    origin: np.ndarray  # position of its first keyframe [m]
    accumulator: Any
    keyframes: int = 0


class BlockBuilder:
    """Feeds keyframes one at a time (:meth:`add_keyframe`), then :meth:`finish` returns the blocks.
    ``sets`` defaults to :class:`VoxelClouds` with the config's voxel."""

    def __init__(self, config: BlockConfig, sets: PointSets | None = None) -> None:
        self.config = config.checked()
        self.sets: PointSets = sets if sets is not None else VoxelClouds(config.voxel)
        self.blocks: list[Block] = []
        self.report = BuildReport()
        self._candidate: _Candidate | None = None

    def add_keyframe(self, pose: np.ndarray, payload: np.ndarray) -> None:
        """Adds a keyframe: robot pose ``T_map_robot`` (4x4) and its loaded points (for real scans
        ``(N, 3)`` in the sensor frame)."""
        position = pose[:3, 3]
        if self._candidate is not None and np.linalg.norm(position - self._candidate.origin) > self.config.block_size:
            self._close_candidate()
        if self._candidate is None:
            self._candidate = _Candidate(origin=position.copy(), accumulator=self.sets.start())
        self._candidate.accumulator = self.sets.add(self._candidate.accumulator, pose, payload)
        self._candidate.keyframes += 1
        self.report.keyframes += 1

    def finish(self) -> list[Block]:
        if self._candidate is not None:
            self._close_candidate()
        return self.blocks

    def map_points(self) -> int:
        """Points of the map the blocks represent: their union (one point per voxel for real scans).
        Stored points over this is the blocks' overlap factor."""
        return len(self.sets.points(self.sets.union([b.members for b in self.blocks]))) if self.blocks else 0

    def _close_candidate(self) -> None:
        candidate, self._candidate = self._candidate, None
        assert candidate is not None
        members = self.sets.close(candidate.accumulator)
        self.report.candidates += 1
        points = self.sets.points(members)
        if len(points) == 0:
            return  # keyframes without a single finite point: nothing to judge or store
        centroid = points.mean(axis=0)
        centroids = np.array([b.centroid for b in self.blocks]).reshape(-1, 3)
        decision = decide(centroid, centroids, self.config.block_size)
        self.report.actions[decision.action.value] += 1
        if decision.action is Action.NEW:
            self.blocks.append(Block(members, centroid, candidate.keyframes, self.sets))
        elif decision.action is Action.MERGE:
            target = self.blocks[decision.nearest]
            target.members = self.sets.union([target.members, members])
            target.centroid = target.points.mean(axis=0)
            target.keyframes += candidate.keyframes


def build_blocks(scans: Iterable[Scan], config: BlockConfig, sets: PointSets | None = None) -> BlockBuilder:
    """The finished builder (``.blocks``, ``.report``, ``.map_points()``) of ``scans`` in time order:
    keyframes are selected by ``config.keyframe_spacing``."""
    builder = BlockBuilder(config, sets)
    for scan in select_keyframes(scans, config.keyframe_spacing):
        builder.add_keyframe(scan.pose, scan.load_points())
    builder.finish()
    return builder
